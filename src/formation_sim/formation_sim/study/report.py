"""A study's report from its rows alone: a Markdown table (report.md) and four figures.

- the audit table: per guarantee of Theorems 1 and 2 (connectivity, convergence, Zeno, the rate as
  printed), the runs, checks, violations and the smallest margin with its case;
- the runs per algorithm and sampling: how many, failed, events per agent, final error;
- events_vs_n.png: events per agent against n, per algorithm (event-triggered runs);
- saved_vs_periodic.png: for each team that also ran the periodic baseline, the events ETA saves
  against the periodic run with the fewest events whose final error is at most ETA's;
- inter_event_vs_xi.png: each run's least inter-event time against its least ξ_i;
- edge_vs_delta.png: each run's largest edge length (exact between events) over Δ, against n;
- with runs that stop at a fraction of their initial error (`until_error`): how they ended
  (`stops_table`: the target reached, the rounding floor, the horizon) and stop_time_vs_rate.png,
  each run's time to its stop against its threshold's rate, beside the time ln(1/fraction)/rate in
  which the threshold itself falls by that fraction.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from formation_sim.sim.files import write_atomically
from formation_sim.study.errors import StudyError
from formation_sim.study.store import ROWS_FILE, read_rows

GUARANTEES = (
    ('connectivity: ‖x_i − x_j‖ < Δ at every instant', 'conn'),
    ("convergence: V, error within the proof's bound at every event", 'conv'),
    ('Zeno: t_{k+1} - t_k >= ξ_i', 'zeno'),
    ('Theorem 2 rate as printed: V_d < k^d_V e^{-2β_d t} (printed chain)', 'printed'),
)
TEAM_COLUMNS = (
    'algorithm',
    'n',
    'p',
    'graph',
    'degree',
    'slack',
    'seed',
    'delta',
    'alpha',
    'beta',
    'beta1',
    'k3',
    'beta_d',
    'max_speed',
    'horizon',
    'speed_scale',
    'threshold_floor',
)


def audit_table(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per theorem and guarantee: runs audited, checks, violations, smallest margin and its case."""
    table = []
    for theorem, algorithm in (('1', 'eta1'), ('2', 'eta2')):
        mine = [r for r in rows if r['algorithm'] == algorithm and r['status'] == 'ok']
        for label, prefix in GUARANTEES:
            audited = [r for r in mine if r.get(f'{prefix}_checks')]
            if not audited:
                continue
            margins = [
                (r[f'{prefix}_margin'], r['case']) for r in audited if r[f'{prefix}_margin'] is not None
            ]
            worst = min(margins) if margins else (None, None)
            table.append(
                {
                    'theorem': theorem,
                    'guarantee': label,
                    'runs': len(audited),
                    'checks': sum(r[f'{prefix}_checks'] for r in audited),
                    'violations': sum(r[f'{prefix}_violations'] for r in audited),
                    'runs_violated': sum(1 for r in audited if r[f'{prefix}_violations']),
                    'smallest_margin': worst[0],
                    'case': worst[1],
                }
            )
    return table


def runs_table(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    groups = defaultdict(list)
    for row in rows:
        groups[(row['algorithm'], row['sampling'])].append(row)
    table = []
    for (algorithm, sampling), group in sorted(groups.items()):
        ok = [r for r in group if r['status'] == 'ok']
        events = [r['events_per_agent'] for r in ok if r['events_per_agent'] is not None]
        errors = [r['final_formation_error'] for r in ok if r['final_formation_error'] is not None]
        table.append(
            {
                'algorithm': algorithm,
                'sampling': sampling,
                'runs': len(group),
                'failed': len(group) - len(ok),
                'events_per_agent_median': float(np.median(events)) if events else None,
                'final_error_median': float(np.median(errors)) if errors else None,
                'wall_time': sum(r['wall_time'] or 0.0 for r in group),
            }
        )
    return table


STOPS = ('error_reached', 'rounding_floor', 'horizon')  # formation_sim.sim.stop's reasons


def stops_table(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per algorithm, the event runs with a stop at a fraction of their error: how each ended, and
    the median and largest time of its stop (empty when no row has such a stop)."""
    table = []
    for algorithm in ('eta1', 'eta2'):
        mine = [r for r in rows if r['algorithm'] == algorithm and r['status'] == 'ok' and r.get('stop')]
        if not mine:
            continue
        times = [r['stop_time'] for r in mine if r['stop_time'] is not None]
        entry: dict[str, Any] = {'algorithm': algorithm, 'runs': len(mine)}
        entry.update({reason: sum(1 for r in mine if r['stop'] == reason) for reason in STOPS})
        entry['stop_time_median'] = float(np.median(times)) if times else None
        entry['stop_time_max'] = max(times) if times else None
        table.append(entry)
    return table


def periodic_savings(rows: list[dict[str, Any]]) -> list[tuple[dict[str, Any], float]]:
    """(ETA row, events saved as a fraction) against the cheapest periodic run of the same team
    whose final error is at most ETA's; teams without such a periodic run are left out."""
    teams = defaultdict(lambda: {'event': [], 'periodic': []})
    for row in rows:
        if row['status'] == 'ok' and row['sampling'] in ('event', 'periodic'):
            teams[tuple(row[c] for c in TEAM_COLUMNS)][row['sampling']].append(row)
    savings = []
    for team in teams.values():
        for eta in team['event']:
            matching = [
                r['total_events']
                for r in team['periodic']
                if r['final_formation_error'] <= eta['final_formation_error']
            ]
            if matching:
                savings.append((eta, 1.0 - eta['total_events'] / min(matching)))
    return savings


def _cell(value: Any) -> str:
    if value is None:
        return '–'
    if isinstance(value, float):
        return f'{value:.4g}'
    return str(value)


def markdown(columns: tuple[str, ...], table: list[dict[str, Any]]) -> str:
    lines = ['| ' + ' | '.join(columns) + ' |', '|' + '---|' * len(columns)]
    lines += ['| ' + ' | '.join(_cell(row[c]) for c in columns) + ' |' for row in table]
    return '\n'.join(lines)


def _figures(rows: list[dict[str, Any]], out: Path) -> list[str]:
    import matplotlib as mpl

    mpl.use('Agg')
    import matplotlib.pyplot as plt

    event = [r for r in rows if r['status'] == 'ok' and r['sampling'] == 'event']
    names = []

    def save(fig, name: str) -> None:
        fig.tight_layout()
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        names.append(name)

    fig, ax = plt.subplots(figsize=(6, 4))
    for algorithm, marker in (('eta1', 'o'), ('eta2', 's')):
        chosen = [r for r in event if r['algorithm'] == algorithm]
        if chosen:
            ax.scatter(
                [r['n'] for r in chosen],
                [r['events_per_agent'] for r in chosen],
                s=8,
                marker=marker,
                label=algorithm.upper(),
                alpha=0.6,
            )
    ax.set(xlabel='n (agents)', ylabel='events per agent', title='Events against team size')
    ax.legend()
    save(fig, 'events_vs_n.png')

    savings = periodic_savings(rows)
    if savings:
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.scatter([r['n'] for r, _ in savings], [100.0 * s for _, s in savings], s=10)
        ax.axhline(0.0, color='k', lw=0.5)
        ax.set(
            xlabel='n (agents)',
            ylabel='events saved [%]',
            title='Against periodic sampling at equal final error',
        )
        save(fig, 'saved_vs_periodic.png')

    pairs = [
        (r['xi_min'], r['min_inter_event_time']) for r in event if r['xi_min'] and r['min_inter_event_time']
    ]
    if pairs:
        fig, ax = plt.subplots(figsize=(6, 4))
        xi, gap = np.array(pairs).T
        ax.loglog(xi, gap, '.', ms=4)
        line = [min(xi.min(), gap.min()), max(xi.max(), gap.max())]
        ax.loglog(line, line, 'k--', lw=0.8, label='t_{k+1} - t_k = ξ_i')
        ax.set(xlabel='least ξ_i (proof)', ylabel='least inter-event time (run)', title='Zeno bound')
        ax.legend()
        save(fig, 'inter_event_vs_xi.png')

    audited = [r for r in event if r['max_edge_exact'] is not None]
    if audited:
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.scatter([r['n'] for r in audited], [r['max_edge_exact'] / r['delta'] for r in audited], s=8)
        ax.axhline(1.0, color='r', lw=0.8, label='Δ')
        ax.set(
            xlabel='n (agents)',
            ylabel='largest edge length / Δ (exact between events)',
            title='Largest edge against Δ',
        )
        ax.legend()
        save(fig, 'edge_vs_delta.png')

    stopped = [r for r in event if r.get('stop') and r['stop_time'] and r['rate'] and r['until_error']]
    if stopped:
        save(_stop_time_figure(plt, stopped), 'stop_time_vs_rate.png')
    return names


def _stop_time_figure(plt, stopped: list[dict[str, Any]]):
    """Each run's time of its stop against its threshold's rate, beside ln(1/fraction)/rate."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for reason, marker in zip(STOPS, ('o', 'x', 's'), strict=True):
        chosen = [r for r in stopped if r['stop'] == reason]
        if chosen:
            ax.loglog(
                [r['rate'] for r in chosen],
                [r['stop_time'] for r in chosen],
                marker,
                ms=3,
                alpha=0.6,
                label=reason,
            )
    fraction = stopped[0]['until_error']
    rates = np.array(sorted(r['rate'] for r in stopped))
    ax.loglog(rates, math.log(1.0 / fraction) / rates, 'k--', lw=0.8, label='ln(1/fraction) / rate')
    ax.set(
        xlabel="threshold's rate (β or β_d) [1/s]",
        ylabel='time of the stop [s]',
        title=f'Time to {100 * fraction:g} % of the initial error',
    )
    ax.legend()
    return fig


def report_text(rows: list[dict[str, Any]], figures: list[str]) -> str:
    savings = periodic_savings(rows)
    parts = [
        '# Study report',
        '',
        f'{len(rows)} rows, {sum(r["status"] != "ok" for r in rows)} failed.',
        '',
        '## Guarantees of Theorems 1 and 2, event by event',
        '',
        markdown(
            (
                'theorem',
                'guarantee',
                'runs',
                'checks',
                'violations',
                'runs_violated',
                'smallest_margin',
                'case',
            ),
            audit_table(rows),
        ),
        '',
        '## Runs',
        '',
        markdown(
            (
                'algorithm',
                'sampling',
                'runs',
                'failed',
                'events_per_agent_median',
                'final_error_median',
                'wall_time',
            ),
            runs_table(rows),
        ),
        '',
    ]
    stops = stops_table(rows)
    if stops:
        columns = ('algorithm', 'runs', *STOPS, 'stop_time_median', 'stop_time_max')
        parts += ['## How the runs ended', '', markdown(columns, stops), '']
    if savings:
        values = np.array([s for _, s in savings])
        parts += [
            f'Events saved against periodic sampling at equal final error: {len(values)} teams, median '
            f'{100 * np.median(values):.1f} %, least {100 * values.min():.1f} %, most '
            f'{100 * values.max():.1f} %.',
            '',
        ]
    parts += [f'![{name}]({name})' for name in figures]
    return '\n'.join(parts) + '\n'


def write_report(folder: str | Path, *, out: str | Path | None = None) -> Path:
    """Write report.md and the figures for the study in `folder` into `out` (default folder/report)."""
    folder = Path(folder)
    if not (folder / ROWS_FILE).exists():
        raise StudyError(
            f'{folder}: no {ROWS_FILE}: not a study folder (formation study SPEC --out {folder} makes one)'
        )
    rows = read_rows(folder)
    if not rows:
        raise StudyError(f'{folder / ROWS_FILE}: no rows yet')
    out = Path(out) if out is not None else folder / 'report'
    out.mkdir(parents=True, exist_ok=True)
    figures = _figures(rows, out)
    return write_atomically(out / 'report.md', report_text(rows, figures))
