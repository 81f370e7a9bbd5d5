"""Two runs of a scenario side by side: events, messages, trajectories, triggering times.

A run is given as a run folder, a bag, or a summary.json. With a bag (a folder's `bag/` or the
bag itself) everything comes from the bag (`formation_sim.analysis.load.load_bag_run`); otherwise from
summary.json (triggering times, counters) and the trajectory beside it, if any (the output
of `formation simulate`, including `--period` runs: `trajectory/`, or an older run's `trajectory.npz`).

- Triggering times are matched per agent index by index: the k-th trigger of agent i in A
  against the k-th in B, for k below the smaller count; a count mismatch is reported per agent
  with both counts, and the first index at which the two sequences differ at all.
- Trajectories are compared on the common times: every sample time of either run inside both
  runs' time spans, each run linearly interpolated there (exact for runs sampled at the same
  times, and for single integrators between their events).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from formation_sim.analysis.errors import AnalysisError, CompareError
from formation_sim.analysis.figures import pyplot
from formation_sim.analysis.load import load_bag_run, locate
from formation_sim.analysis.markers import agent_colour
from formation_sim.analysis.report import bag_summary, json_safe
from formation_sim.sim.errors import TrajectoryError
from formation_sim.sim.samples import LEGACY_TRAJECTORY_FILE, load_trajectory
from formation_sim.sim.summary import load_summary


@dataclass(kw_only=True)
class RunData:
    """What a comparison needs of one run, whatever it was read from."""

    label: str
    source: str
    scenario: str
    dynamics: str
    mode: str
    horizon: float
    agent_ids: tuple[int, ...]
    edges: list[tuple[int, int, np.ndarray]]  # (i, j, d_ij)
    trigger_times: dict[int, list[float]]
    messages_sent: int
    sensing_calls: int
    times: np.ndarray | None = None  # (K,)
    positions: np.ndarray | None = None  # (K, n, p)
    extra: dict = field(default_factory=dict)

    @property
    def total_events(self) -> int:
        return sum(len(times) for times in self.trigger_times.values())


def load_run(path: str | Path, *, label: str, scenario=None, progress=None) -> RunData:
    """A run from a run folder, a bag or a summary.json (a bag is preferred when present)."""
    try:
        location = locate(path)
    except AnalysisError as error:
        raise CompareError(str(error)) from None
    if location.bag is not None:
        try:
            run = load_bag_run(location.bag, run_dir=location.run_dir, scenario=scenario, progress=progress)
        except AnalysisError as error:
            raise CompareError(str(error)) from None
        record = run.record
        summary = bag_summary(record)
        return RunData(
            label=label,
            source=f'bag {location.bag}',
            scenario=record.scenario.name,
            dynamics=record.scenario.dynamics,
            mode=record.mode,
            horizon=record.horizon,
            agent_ids=record.scenario.agent_ids,
            edges=[(edge.i, edge.j, np.asarray(edge.d)) for edge in record.scenario.edges],
            trigger_times={agent: list(times) for agent, times in record.trigger_times.items()},
            messages_sent=summary['messages_sent'],
            sensing_calls=summary['sensing_calls'],
            times=np.asarray(record.sample_times, dtype=float),
            positions=np.asarray(record.sample_positions, dtype=float),
            extra=dict(record.extra),
        )
    try:
        summary = load_summary(location.summary)
    except (OSError, ValueError) as error:
        raise CompareError(f'{location.summary}: {error}') from None
    try:
        samples = load_trajectory(location.summary.parent)
    except TrajectoryError as error:
        raise CompareError(str(error)) from None
    times = positions = None
    source = f'summary {location.summary}'
    if samples is not None:
        times, positions = samples.times, samples.positions
        source += f' + {samples.path.name + "/" if samples.path is not None else LEGACY_TRAJECTORY_FILE}'
    agent_ids = tuple(sorted(int(agent) for agent in summary['trigger_times']))
    return RunData(
        label=label,
        source=source,
        scenario=summary['scenario'],
        dynamics=summary['dynamics'],
        mode=summary['mode'],
        horizon=float(summary['horizon']),
        agent_ids=agent_ids,
        edges=[
            (int(edge['i']), int(edge['j']), np.asarray(edge['d'], dtype=float)) for edge in summary['edges']
        ],
        trigger_times={
            int(agent): [float(t) for t in times_] for agent, times_ in summary['trigger_times'].items()
        },
        messages_sent=int(summary['messages_sent']),
        sensing_calls=int(summary['sensing_calls']),
        times=times,
        positions=positions,
        extra=dict(summary.get('extra') or {}),
    )


# ------------------------------------------------------------------------------ comparisons


@dataclass(frozen=True, kw_only=True)
class AgentTriggers:
    agent: int
    count_a: int
    count_b: int
    compared: int  # min(count_a, count_b)
    max_deviation: float | None  # max_k |t_a[k] - t_b[k]| over the compared indices
    first_difference: int | None  # first k with t_a[k] != t_b[k] (None: identical prefix)

    @property
    def counts_match(self) -> bool:
        return self.count_a == self.count_b


def compare_triggers(a: RunData, b: RunData) -> list[AgentTriggers]:
    result = []
    for agent in a.agent_ids:
        ta = np.asarray(a.trigger_times[agent], dtype=float)
        tb = np.asarray(b.trigger_times[agent], dtype=float)
        compared = min(ta.size, tb.size)
        differ = np.flatnonzero(ta[:compared] != tb[:compared])
        result.append(
            AgentTriggers(
                agent=agent,
                count_a=int(ta.size),
                count_b=int(tb.size),
                compared=compared,
                max_deviation=float(np.max(np.abs(ta[:compared] - tb[:compared]))) if compared else None,
                first_difference=int(differ[0]) if differ.size else None,
            )
        )
    return result


@dataclass(frozen=True, kw_only=True)
class TrajectoryDeviation:
    times: np.ndarray  # the common times
    deviation: np.ndarray  # (T,) max over agents of ||x_a(t) - x_b(t)||
    per_agent: dict[int, float]  # max over time per agent
    max_deviation: float
    at_time: float


def interpolate(times: np.ndarray, positions: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Positions (K, n, p) sampled at `times`, linearly interpolated at `at` -> (T, n, p)."""
    _, n, p = positions.shape
    out = np.empty((at.size, n, p))
    for k in range(n):
        for axis in range(p):
            out[:, k, axis] = np.interp(at, times, positions[:, k, axis])
    return out


def compare_trajectories(a: RunData, b: RunData) -> TrajectoryDeviation | None:
    if a.times is None or b.times is None:
        return None
    if a.positions.shape[1:] != b.positions.shape[1:]:
        raise CompareError(
            f'{a.label} has states of shape {a.positions.shape[1:]}, {b.label} {b.positions.shape[1:]}'
        )
    start = max(a.times[0], b.times[0])
    end = min(a.times[-1], b.times[-1])
    common = np.union1d(a.times, b.times)
    common = common[(common >= start) & (common <= end)]
    if common.size == 0:
        raise CompareError(
            f'the runs share no time span ({a.label}: [{a.times[0]}, {a.times[-1]}], {b.label}: '
            f'[{b.times[0]}, {b.times[-1]}])'
        )
    xa = interpolate(a.times, a.positions, common)
    xb = interpolate(b.times, b.positions, common)
    distance = np.linalg.norm(xa - xb, axis=2)  # (T, n)
    deviation = distance.max(axis=1)
    worst = int(np.argmax(deviation))
    return TrajectoryDeviation(
        times=common,
        deviation=deviation,
        per_agent={agent: float(distance[:, k].max()) for k, agent in enumerate(a.agent_ids)},
        max_deviation=float(deviation[worst]),
        at_time=float(common[worst]),
    )


def _check_comparable(a: RunData, b: RunData) -> list[str]:
    if a.agent_ids != b.agent_ids:
        raise CompareError(
            f'the runs have different agents: {a.label} {list(a.agent_ids)}, {b.label} {list(b.agent_ids)}'
        )
    notes = []
    if a.scenario != b.scenario:
        notes.append(f'different scenario names: {a.scenario!r} and {b.scenario!r}')
    if a.horizon != b.horizon:
        notes.append(
            f'different horizons: {a.horizon!r} and {b.horizon!r}; trajectories are compared on the '
            'common span'
        )
    edges_a = [(i, j) for i, j, _ in a.edges]
    edges_b = [(i, j) for i, j, _ in b.edges]
    if edges_a != edges_b:
        notes.append(f'different graphs: {edges_a} and {edges_b}')
    return notes


def compare_runs(a: RunData, b: RunData) -> dict[str, Any]:
    """The comparison as a JSON-ready dictionary."""
    notes = _check_comparable(a, b)
    triggers = compare_triggers(a, b)
    trajectory = compare_trajectories(a, b)
    deviations = [entry.max_deviation for entry in triggers if entry.max_deviation is not None]
    mismatched = [entry for entry in triggers if not entry.counts_match]
    return json_safe(
        {
            'schema': 'formation-compare/1',
            'runs': {
                key: {
                    'label': run.label,
                    'source': run.source,
                    'scenario': run.scenario,
                    'dynamics': run.dynamics,
                    'mode': run.mode,
                    'clock': run.extra.get('clock'),
                    'period': run.extra.get('period'),
                    'horizon': run.horizon,
                    'total_events': run.total_events,
                    'messages_sent': run.messages_sent,
                    'sensing_calls': run.sensing_calls,
                }
                for key, run in (('a', a), ('b', b))
            },
            'notes': notes,
            'events_equal': not mismatched and a.total_events == b.total_events,
            'count_mismatches': [
                f'agent {entry.agent}: {entry.count_a} events in A, {entry.count_b} in B (compared the '
                f'first {entry.compared})'
                for entry in mismatched
            ],
            'triggers': [
                {
                    'agent': entry.agent,
                    'events_a': entry.count_a,
                    'events_b': entry.count_b,
                    'compared': entry.compared,
                    'max_deviation': entry.max_deviation,
                    'first_difference': entry.first_difference,
                }
                for entry in triggers
            ],
            'max_trigger_deviation': max(deviations) if deviations else None,
            'trajectory': None
            if trajectory is None
            else {
                'common_times': int(trajectory.times.size),
                'max_deviation': trajectory.max_deviation,
                'at_time': trajectory.at_time,
                'per_agent': trajectory.per_agent,
            },
        }
    )


def render_markdown(report: dict[str, Any]) -> str:
    a, b = report['runs']['a'], report['runs']['b']

    def cell(value):
        if value is None:
            return '—'
        return f'{value:.6g}' if isinstance(value, float) else str(value)

    lines = [
        f'# Comparison: {a["label"]} vs {b["label"]}',
        '',
        '| | A | B |',
        '|---|---|---|',
        f'| source | {a["source"]} | {b["source"]} |',
        f'| scenario | {a["scenario"]} | {b["scenario"]} |',
        f'| mode | {a["mode"]}{" (period " + cell(a["period"]) + ")" if a["period"] else ""} | '
        f'{b["mode"]}{" (period " + cell(b["period"]) + ")" if b["period"] else ""} |',
        f'| clock | {cell(a["clock"])} | {cell(b["clock"])} |',
        f'| horizon [s] | {cell(a["horizon"])} | {cell(b["horizon"])} |',
        f'| events | {a["total_events"]} | {b["total_events"]} |',
        f'| messages (triggering information) | {a["messages_sent"]} | {b["messages_sent"]} |',
        f'| sensing calls | {a["sensing_calls"]} | {b["sensing_calls"]} |',
        '',
    ]
    for note in report['notes']:
        lines.append(f'Note: {note}.')
    if report['notes']:
        lines.append('')
    lines += ['## Triggering times (matched per agent, index by index)', '']
    if report['count_mismatches']:
        lines.append('**Event counts differ:** ' + '; '.join(report['count_mismatches']) + '.')
    else:
        lines.append('Event counts are equal for every agent.')
    lines += [
        '',
        f'Largest deviation over all matched triggers: {cell(report["max_trigger_deviation"])} s.',
        '',
        '| agent | events A | events B | compared | max deviation [s] | first differing index |',
        '|---|---|---|---|---|---|',
    ]
    for entry in report['triggers']:
        first = entry['first_difference']
        lines.append(
            f'| {entry["agent"]} | {entry["events_a"]} | {entry["events_b"]} | {entry["compared"]} | '
            f'{cell(entry["max_deviation"])} | {cell(first) if first is not None else "none (identical)"} |'
        )
    lines += ['', '## Trajectories', '']
    trajectory = report['trajectory']
    if trajectory is None:
        lines.append('Not compared: a run has no trajectory (summary.json without trajectory/).')
    else:
        lines.append(
            "Largest distance between the two runs' positions of an agent: "
            f'{cell(trajectory["max_deviation"])} '
            f'at t = {cell(trajectory["at_time"])} s, over {trajectory["common_times"]} common times.'
        )
        lines += ['', '| agent | max deviation |', '|---|---|']
        for agent, value in trajectory['per_agent'].items():
            lines.append(f'| {agent} | {cell(value)} |')
    return '\n'.join(lines) + '\n'


# ---------------------------------------------------------------------------------- figures


def overlay_figures(a: RunData, b: RunData, out_dir: str | Path, *, dpi: int = 100) -> dict[str, Any]:
    """Trajectories, rasters, deviation and formation error of both runs; returns title -> (file,
    artists)."""
    plt = pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Any] = {}
    if a.positions is not None and b.positions is not None and a.positions.shape[2] >= 2:
        written['trajectories'] = _overlay_trajectories(plt, a, b, out, dpi)
    written['triggering times'] = _overlay_triggers(plt, a, b, out, dpi)
    deviation = compare_trajectories(a, b)
    if deviation is not None:
        written['deviation and formation error'] = _overlay_deviation(plt, a, b, deviation, out, dpi)
    return written


def _overlay_trajectories(plt: Any, a: RunData, b: RunData, out: Path, dpi: int) -> tuple[str, Any]:
    """Both runs' planar paths, A solid and B dashed, one colour per agent."""
    fig, ax = plt.subplots(figsize=(6.4, 5.5))
    lines = {}
    for k, agent in enumerate(a.agent_ids):
        colour = agent_colour(k)
        (lines[('a', agent)],) = ax.plot(
            a.positions[:, k, 0], a.positions[:, k, 1], '-', color=colour, lw=1.4, label=f'agent {agent} A'
        )
        (lines[('b', agent)],) = ax.plot(
            b.positions[:, k, 0], b.positions[:, k, 1], '--', color=colour, lw=1.0, label=f'agent {agent} B'
        )
        ax.plot([a.positions[0, k, 0]], [a.positions[0, k, 1]], 'o', mfc='none', mec=colour, ms=9)
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_title(f'trajectories: A {a.label} (solid), B {b.label} (dashed)', fontsize=9)
    ax.legend(fontsize=7, loc='best')
    return _save(plt, fig, out / 'overlay_trajectories.png', dpi, lines)


def _overlay_triggers(plt: Any, a: RunData, b: RunData, out: Path, dpi: int) -> tuple[str, Any]:
    """Both runs' triggering times per agent, A's ticks above B's."""
    fig, ax = plt.subplots(figsize=(7.0, 0.6 * len(a.agent_ids) + 2.0))
    events = {}
    for k, agent in enumerate(a.agent_ids):
        (events[('a', agent)],) = ax.eventplot(
            a.trigger_times[agent],
            lineoffsets=k + 1 + 0.2,
            linelengths=0.35,
            colors=[agent_colour(k)],
            linewidths=0.7,
        )
        (events[('b', agent)],) = ax.eventplot(
            b.trigger_times[agent],
            lineoffsets=k + 1 - 0.2,
            linelengths=0.35,
            colors=[agent_colour(k)],
            linewidths=0.7,
            alpha=0.6,
        )
    ax.set_yticks(range(1, len(a.agent_ids) + 1))
    ax.set_yticklabels([str(agent) for agent in a.agent_ids])
    ax.set_xlim(0.0, max(a.horizon, b.horizon))
    ax.set_xlabel('t [s]')
    ax.set_ylabel('agent (upper ticks A, lower B)')
    ax.set_title(
        f'triggering times: A {a.label} ({a.total_events}), B {b.label} ({b.total_events})', fontsize=9
    )
    return _save(plt, fig, out / 'overlay_triggers.png', dpi, events)


def _overlay_deviation(
    plt: Any, a: RunData, b: RunData, deviation: TrajectoryDeviation, out: Path, dpi: int
) -> tuple[str, Any]:
    """The runs' largest distance over time above, each run's formation error below."""
    fig, (ax_dev, ax_err) = plt.subplots(2, 1, figsize=(6.4, 6.0))
    positive = deviation.deviation > 0.0
    lines = {}
    if positive.any():
        (lines['deviation'],) = ax_dev.semilogy(
            deviation.times[positive], deviation.deviation[positive], 'k', lw=1.0
        )
    ax_dev.set_title(
        f'max over agents of ||x_A - x_B|| (max {deviation.max_deviation:.3g}; zero values not drawn)',
        fontsize=9,
    )
    ax_dev.set_xlabel('t [s]')
    for key, run, style in (('a', a, '-'), ('b', b, '--')):
        errors = _formation_error(run)
        keep = errors > 0.0
        (lines[f'error {key}'],) = ax_err.semilogy(
            run.times[keep], errors[keep], style, lw=1.1, label=f'{key.upper()} {run.label}'
        )
    ax_err.set_title('formation error max ||x_i - x_j - d_ij||', fontsize=9)
    ax_err.set_xlabel('t [s]')
    ax_err.legend(fontsize=7)
    return _save(plt, fig, out / 'overlay_deviation.png', dpi, lines)


def _formation_error(run: RunData) -> np.ndarray:
    index = {agent: k for k, agent in enumerate(run.agent_ids)}
    errors = [
        np.linalg.norm(run.positions[:, index[i]] - run.positions[:, index[j]] - d, axis=1)
        for i, j, d in run.edges
    ]
    return np.max(errors, axis=0)


def _save(plt, fig, path: Path, dpi: int, artists) -> tuple[str, Any]:
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path.name, artists


def write_comparison(
    report: dict[str, Any], out_dir: str | Path, figures: dict[str, Any] | None = None
) -> tuple[Path, Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    markdown = render_markdown(report)
    if figures:
        markdown += '\n## Figures\n\n' + ''.join(
            f'![{title}]({name})\n' for title, (name, _) in figures.items()
        )
        report = {**report, 'figures': {title: name for title, (name, _) in figures.items()}}
    md_path, json_path = out / 'compare.md', out / 'compare.json'
    md_path.write_text(markdown, encoding='utf-8')
    json_path.write_text(json.dumps(report, indent=1, allow_nan=False) + '\n', encoding='utf-8')
    return md_path, json_path


def within(report: dict[str, Any], tolerance: float) -> bool:
    """Equal event counts, and triggering times and trajectories within `tolerance`."""
    if not report['events_equal']:
        return False
    deviation = report['max_trigger_deviation']
    if deviation is not None and not deviation <= tolerance:
        return False
    trajectory = report['trajectory']
    return trajectory is None or (
        isinstance(trajectory['max_deviation'], float)
        and math.isfinite(trajectory['max_deviation'])
        and trajectory['max_deviation'] <= tolerance
    )
