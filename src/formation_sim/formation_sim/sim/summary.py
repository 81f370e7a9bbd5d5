"""`summary.json` and the trajectory folder of a run, whichever implementation produced it.

Schema `formation-summary/1`, key by key (all times in seconds, agent ids and edges "i-j" as string
keys):

- `schema`: "formation-summary/1"
- `scenario`, `dynamics`, `mode`, `horizon`, `n_agents`, `dimension`, `delta`: what was run
- `trigger_times`: agent -> list of triggering times, t_1 = 0 included
- `event_counts`, `total_events`: agent -> number of triggers; their sum
- `min_inter_event_time`: agent -> smallest t_{k+1} - t_k (null with fewer than two triggers)
- `messages_sent`, `sensing_calls`: triggering-information messages (one per trigger per neighbour);
  sensing calls
- `edges`: list of {i, j, d, max_length, min_range_slack = Δ - max_length, final_error}
- `max_edge_length`: the largest `max_length` (must stay < Δ: connectivity preserved)
- `final_formation_error`: max over edges of ||x_i - x_j - d_ij|| at the horizon
- `final_positions`, `final_velocities`: agent -> vector (velocities null for single integrators)
- `theorem_constants`: `formation_sim.model.theory.TheoremConstants.to_dict()` (the paper's time s =
  κt), with `speed_scale` κ when not 1 and `threshold_floor`
  (`formation_sim.model.threshold_floor.FloorBounds.to_dict()`) when c0 > 0; or {"error": ...}
- `xi_check`: agent -> {xi, min_inter_event_time, holds}: Theorem 1 (iii) / 2 (iii), or c0/c_i with
  a threshold floor; ξ in seconds (ξ_i / κ)
- `wall_time`: seconds the run took
- `extra`: implementation-specific details (e.g. the distributed run's domain id)
- `extra.stop`: engine runs with `until_error` or `stop_at_floor` (formation_sim.sim.stop): {reason
  (horizon, error_reached, rounding_floor), time (= `horizon`, the run's end), horizon (asked for),
  until_error, initial_error, error, message}
- `extra.failure`: distributed runs: null if the run reached the horizon; else {kind, message,
  agents, time, step, wall_time, detected_by[, process][, followed]} — what stopped it first
  (`followed`: agent -> the error of each agent that then stopped on its own) (kind: agent_lost,
  agent_failed, robot_lost (a robot whose poses stopped), recorder_lost, process_lost,
  process_failed, connectivity_lost, stall, discovery, protocol, interrupted, recording_incomplete,
  error), which agents, at which sim time and step (the summary then covers the run up to
  `extra.reached_time`)
- `extra.published`, `extra.recording`: distributed runs: messages published per topic from step 0
  on; {complete, missing, foreign, published, recorded}: the bag against it
  (`formation_sim.analysis.accounting`)
- `extra.summary_source`, `extra.processes`: only when `formation run` wrote the summary because the
  simulator could not: how, and every process's exit
- `extra.rejected_messages`: distributed runs: {total, by_reason, by_agent, simulator}: messages
  refused as malformed or implausible, per reason (`formation_msgs_py.lockstep.REJECT_REASONS`)
- `extra.foreign_messages`: distributed runs: how many of them were refused for their tag, none or
  not the run key's (`untagged`, `forged`: docs/HOSTILE_TRAFFIC.md, "Tags"); `replayed` ones are
  counted under their reason only
- `extra.non_finite`: only when a value was not a finite number (NaN or infinite: JSON has
  neither): where it was (e.g. 'edges[0].max_length') -> 'nan', 'inf' or '-inf'; it is written null
- `extra.injected_faults`: distributed runs: {dropped, delayed, by_agent}: triggering information
  dropped or delayed by fault injection (a test facility)

`max_length` is taken over the samples (every event time and the sampling grid) and, for runs
that keep no event samples (`formation simulate --samples grid|none`), over each edge's two
agents' triggering times (`formation_sim.sim.samples.EdgeLengths`). For single integrators an
edge's length is convex between those times, so either way this is the exact maximum.

The samples go to the run folder's `trajectory/` (format: `formation_sim.sim.samples`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from formation_agent.core.speed_scale import real_duration
from formation_sim.model import theory
from formation_sim.model.scenario import load_scenario
from formation_sim.model.threshold_floor import floor_bounds
from formation_sim.sim.errors import SummaryError, TrajectoryError
from formation_sim.sim.files import write_atomically
from formation_sim.sim.record import RunRecord
from formation_sim.sim.samples import edge_maxima, load_trajectory, write_trajectory

if TYPE_CHECKING:
    from collections.abc import Iterable

    from formation_msgs_py.lockstep import AgentReport
    from formation_sim.model.scenario import Scenario

SCHEMA = 'formation-summary/1'
SUMMARY_FILE = 'summary.json'
Json = dict[str, Any]  # a JSON object as json.loads gives it

# summary.json's keys, in the order it is written: what was run; what the run's samples give (a
# run without samples, `RunSummary.started` false, has none of these); the wall time and `extra`.
_RUN_KEYS = ('scenario', 'dynamics', 'mode', 'horizon', 'n_agents', 'dimension', 'delta')
_SAMPLED_KEYS = (
    'trigger_times',
    'event_counts',
    'total_events',
    'min_inter_event_time',
    'messages_sent',
    'sensing_calls',
    'edges',
    'max_edge_length',
    'final_formation_error',
    'final_positions',
    'final_velocities',
    'theorem_constants',
    'xi_check',
)


@dataclass(kw_only=True)
class RunSummary:
    """summary.json, typed (the module docstring gives each key): written with `write`, read
    with `read` (or `from_dict`), and `to_dict()` is the file's object, key for key in the order it
    is written, so that a summary read and written again is the same bytes.

    A run without samples (it never reached t = 0) has `started` false and none of the sampled
    keys; `extra` is the implementation's details, `extra['failure']` what stopped the run.
    """

    scenario: str
    dynamics: str
    mode: str
    horizon: float
    n_agents: int
    dimension: int
    delta: float
    wall_time: float | None
    extra: Json = field(default_factory=dict)
    schema: str = SCHEMA
    # The sampled keys (None in a run without samples; final_velocities is None also for single
    # integrators).
    trigger_times: dict[str, list[float]] | None = None
    event_counts: dict[str, int] | None = None
    total_events: int | None = None
    min_inter_event_time: dict[str, float | None] | None = None
    messages_sent: int | None = None
    sensing_calls: int | None = None
    edges: list[Json] | None = None
    max_edge_length: float | None = None
    final_formation_error: float | None = None
    final_positions: dict[str, list[float]] | None = None
    final_velocities: dict[str, list[float]] | None = None
    theorem_constants: Json | None = None
    xi_check: dict[str, Json] | None = None

    @property
    def started(self) -> bool:
        """Whether the run has samples (it reached t = 0): the sampled keys are written."""
        return self.trigger_times is not None

    @property
    def failure(self) -> Json | None:
        """`extra.failure`: what stopped the run early, or None."""
        failure: Json | None = self.extra.get('failure')
        return failure

    def to_dict(self) -> Json:
        """summary.json's object, in the order it is written."""
        keys = ('schema', *_RUN_KEYS, *(_SAMPLED_KEYS if self.started else ()), 'wall_time', 'extra')
        return {key: getattr(self, key) for key in keys}

    @classmethod
    def from_dict(cls, data: object, *, source: str = 'summary') -> RunSummary:
        """A summary.json's object; SummaryError naming `source` and the rule it breaks (not an
        object, another schema, a key missing or unknown)."""
        if not isinstance(data, dict):
            raise SummaryError(f'{source}: a summary is a JSON object, got {type(data).__name__}')
        if data.get('schema') != SCHEMA:
            raise SummaryError(f'{source}: not a {SCHEMA} file (schema={data.get("schema")!r})')
        started = 'trigger_times' in data
        needed = (*_RUN_KEYS, *(_SAMPLED_KEYS if started else ()), 'wall_time', 'extra')
        if missing := [key for key in needed if key not in data]:
            raise SummaryError(f'{source}: a {SCHEMA} summary has the keys {missing}; this one has not')
        known = {'schema', *needed}
        if unknown := sorted(set(data) - known):
            raise SummaryError(f'{source}: keys a {SCHEMA} summary does not have: {unknown}')
        if not isinstance(data['extra'], dict):
            raise SummaryError(f'{source}: extra is an object, got {type(data["extra"]).__name__}')
        return cls(**{key: data[key] for key in known})

    @classmethod
    def read(cls, path: str | Path) -> RunSummary:
        """Read a summary.json (a run folder or the file itself); SummaryError if it is not one."""
        path = Path(path)
        if path.is_dir():
            path = path / SUMMARY_FILE
        try:
            data = json.loads(path.read_text(encoding='utf-8'))
        except ValueError as error:
            raise SummaryError(f'{path}: not JSON ({error})') from None
        return cls.from_dict(data, source=str(path))

    def write(self, path: str | Path) -> Path:
        """Write it as `path`, whole or not at all (`write_summary_file`)."""
        return write_summary_file(self, path)


def build_summary(record: RunRecord) -> Json:
    """The summary of a `RunRecord` as summary.json's object (see the module docstring for the
    schema): `summary_of(record).to_dict()`."""
    return summary_of(record).to_dict()


def summary_of(record: RunRecord) -> RunSummary:
    """The `RunSummary` of a `RunRecord`."""
    scenario = record.scenario
    ids = list(scenario.agent_ids)
    index = {agent: k for k, agent in enumerate(ids)}
    final_x = np.asarray(record.sample_positions[-1])
    maxima = edge_maxima(scenario, record.samples)
    final_errors = [
        np.linalg.norm(final_x[index[edge.i]] - final_x[index[edge.j]] - edge.d) for edge in scenario.edges
    ]
    edges = [
        {
            'i': edge.i,
            'j': edge.j,
            'd': np.asarray(edge.d).tolist(),
            'max_length': float(longest),
            'min_range_slack': float(scenario.delta - longest),
            'final_error': float(error),
        }
        for edge, longest, error in zip(scenario.edges, maxima, final_errors)
    ]
    gaps = {
        agent: (float(np.diff(times).min()) if len(times) > 1 else None)
        for agent, times in record.trigger_times.items()
    }
    try:
        constants = theory.theorem_constants(scenario)
        constants_dict = constants.to_dict()
        xi = constants.xi
        if (floor := floor_bounds(scenario)) is not None:  # c0 > 0: the floor's guarantees
            constants_dict['threshold_floor'] = floor.to_dict()
            xi = floor.xi
        if scenario.speed_scale != 1.0:  # the constants are the paper's time; ξ_i in seconds is ξ_i / κ
            constants_dict['speed_scale'] = scenario.speed_scale
            xi = (
                None
                if xi is None
                else {agent: real_duration(v, scenario.speed_scale) for agent, v in xi.items()}
            )
    except ValueError as err:
        constants_dict = {'error': str(err)}
        xi = None
    xi_check = {}
    for agent in ids:
        bound = None if xi is None else xi.get(agent)
        gap = gaps[agent]
        xi_check[str(agent)] = {
            'xi': bound,
            'min_inter_event_time': gap,
            'holds': None if bound is None or gap is None else bool(gap >= bound),
        }
    velocities = record.sample_velocities
    return RunSummary(
        scenario=scenario.name,
        dynamics=scenario.dynamics,
        mode=record.mode,
        horizon=record.horizon,
        n_agents=len(ids),
        dimension=int(final_x.shape[1]),
        delta=scenario.delta,
        trigger_times={str(a): list(map(float, t)) for a, t in record.trigger_times.items()},
        event_counts={str(a): len(t) for a, t in record.trigger_times.items()},
        total_events=record.total_events,
        min_inter_event_time={str(a): g for a, g in gaps.items()},
        messages_sent=record.messages_sent,
        sensing_calls=record.sensing_calls,
        edges=edges,
        max_edge_length=max(e['max_length'] for e in edges),
        final_formation_error=max(e['final_error'] for e in edges),
        final_positions={str(a): final_x[index[a]].tolist() for a in ids},
        final_velocities=None
        if velocities is None
        else {str(a): velocities[-1][index[a]].tolist() for a in ids},
        theorem_constants=constants_dict,
        xi_check=xi_check,
        wall_time=record.wall_time,
        extra=record.extra,
    )


def unstarted_summary(scenario: Scenario, *, horizon: float, mode: str, extra: Json) -> RunSummary:
    """The summary of a run that has no samples (it never reached t = 0, or left neither summary
    nor bag): what was to be run, and `extra` (its failure)."""
    return RunSummary(
        scenario=scenario.name,
        dynamics=scenario.dynamics,
        mode=mode,
        horizon=horizon,
        n_agents=len(scenario.agent_ids),
        dimension=scenario.dimension,
        delta=scenario.delta,
        wall_time=None,
        extra=extra,
    )


def run_failure(
    kind: str, message: str, *, agents: Iterable[int], detected_by: str, **details: object
) -> Json:
    """summary.json's `extra.failure` (the module docstring gives its kinds), built here for every
    way a run stops early — by the time keeper (`formation_sim.runtime.nodes.run_book.failure_extra`) and
    by the orchestrator (`formation_sim.runtime.launch.results`: a time keeper that left no summary, a
    process that failed, a recording left incomplete). Its keys in one order: kind, message,
    agents, then `time`, `step` and `wall_time` when the caller knows them, detected_by, then the
    other `details` as given (an edge's length, the process, who asked for a stop)."""
    entry: Json = {'kind': kind, 'message': message, 'agents': list(agents)}
    entry.update({key: details.pop(key) for key in ('time', 'step', 'wall_time') if key in details})
    entry['detected_by'] = detected_by
    entry.update(details)
    return entry


def lateness_extra(planned: dict[int, dict[int, float]], trigger_times: dict[int, list[float]]) -> Json:
    """Wall clock: `extra.lateness` and `extra.max_lateness`, per agent trigger time − planned time
    over the triggers whose plan a Status announced (`planned`: agent -> trigger number k ->
    `Status.last_planned` of the Status that first counted k triggers)."""
    per_agent = {}
    for agent, plans in planned.items():
        times = trigger_times.get(agent, [])
        late = [times[k - 1] - when for k, when in sorted(plans.items()) if 0 < k <= len(times)]
        if late:
            per_agent[str(agent)] = {'max': max(late), 'mean': float(np.mean(late))}
    return {
        'lateness': per_agent,
        'max_lateness': max((entry['max'] for entry in per_agent.values()), default=0.0),
    }


def saturation_extra(reports: Iterable[AgentReport | None]) -> Json:
    """Robot runs: `extra.saturation`, the commands the agents' robot adapters clipped to their
    limits (the theorems assume none), from each agent's latest report (`AgentReport.saturation`:
    kind -> count, largest value requested, limit): in total, per kind and per agent."""
    total = 0
    by_kind: dict[str, Json] = {}
    by_agent: dict[str, dict[str, int]] = {}
    for report in reports:
        if report is None:
            continue
        for kind, clipped in sorted(report.saturation.items()):
            if not clipped.count:
                continue
            total += clipped.count
            entry = by_kind.setdefault(
                kind, {'count': 0, 'largest_requested': 0.0, 'allowed': clipped.allowed}
            )
            entry['count'] += clipped.count
            entry['largest_requested'] = max(entry['largest_requested'], clipped.largest_requested)
            by_agent.setdefault(str(report.agent), {})[kind] = clipped.count
    return {'total': total, 'by_kind': by_kind, 'by_agent': by_agent}


def write_summary(record: RunRecord, out_dir: str | Path) -> Path:
    """Write `summary.json` and the trajectory (unless the run streamed it there already) into
    `out_dir`; return the summary's path. The small summary first: on a disk about to fill up it is
    what matters most."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = summary_of(record).write(out / SUMMARY_FILE)
    if record.samples.path is None or record.samples.path.parent.resolve() != out.resolve():
        write_trajectory(record.samples, out, agent_ids=record.scenario.agent_ids)
    return path


def write_summary_file(summary: RunSummary, path: str | Path) -> Path:
    """Write a summary as `path` (summary.json), whole or not at all.  JSON holds no
    NaN or infinity: a value that is not finite (what a run fed bad input could make) is written
    as null, and `extra.non_finite` names it with what it was (`finite_or_null`), so that the
    summary is always written and always strict JSON (issue 28)."""
    clean, replaced = finite_or_null(summary.to_dict())
    if replaced:
        extra = clean.get('extra') if isinstance(clean.get('extra'), dict) else {}
        clean['extra'] = {**extra, 'non_finite': replaced}
    return write_atomically(path, json.dumps(clean, indent=1, allow_nan=False) + '\n')


def finite_or_null(value: Any, where: str = '') -> tuple[Any, dict[str, str]]:
    """`value` (JSON-like: dicts, lists, tuples, numbers) with every float that is NaN or
    infinite (numpy's too) replaced by None, and {where it was: 'nan' | 'inf' | '-inf'}, where
    is a path such as 'edges[0].max_length'."""
    replaced: dict[str, str] = {}

    def clean(item: Any, path: str) -> Any:
        if isinstance(item, dict):
            return {key: clean(inner, f'{path}.{key}' if path else str(key)) for key, inner in item.items()}
        if isinstance(item, (list, tuple)):
            return [clean(inner, f'{path}[{k}]') for k, inner in enumerate(item)]
        if isinstance(item, (float, np.floating)) and not np.isfinite(item):
            replaced[path] = repr(float(item))
            return None
        return item

    return clean(value, where), replaced


def load_summary(path: str | Path) -> Json:
    """Read a summary.json (a run folder or the file itself) as its object, through `RunSummary`
    (SummaryError if it is not one)."""
    return RunSummary.read(path).to_dict()


def load_record(run_dir: str | Path, scenario: Scenario | None = None) -> RunRecord:
    """Rebuild the `RunRecord` of a run folder from `summary.json` and its trajectory (memory-mapped).

    The scenario is read from the folder's `scenario.yaml` (written by `formation run`) unless
    given. Counters and triggering times come from the summary, samples from the trajectory
    (`formation_sim.sim.samples.load_trajectory`; TrajectoryError if there is none).
    """
    run_dir = Path(run_dir)
    summary = RunSummary.read(run_dir)
    if scenario is None:
        scenario = load_scenario(run_dir / 'scenario.yaml')
    samples = load_trajectory(run_dir)
    if samples is None:
        raise TrajectoryError(f'{run_dir}: holds no trajectory')
    return RunRecord(
        scenario=scenario,
        horizon=summary.horizon,
        mode=summary.mode,
        trigger_times={int(a): list(t) for a, t in (summary.trigger_times or {}).items()},
        samples=samples,
        messages_sent=summary.messages_sent or 0,
        sensing_calls=summary.sensing_calls or 0,
        wall_time=summary.wall_time,
        extra=summary.extra,
    )
