"""A run rebuilt from its rosbag2 bag alone: every metric recomputed, checked and reported.

`load_bag_run(bag)` reads the bag once and rebuilds the `RunRecord` the simulator had:

- triggering times from the TriggerInfo messages (`/agent_<i>/trigger_info/to_<j>`): one message
  per neighbour per trigger, so agent i triggered at t iff some message from i is stamped t;
  messages are grouped by (sender, stamp) and each group must reach every neighbour once;
- the trajectories from `/formation/state` (WorldState: exact positions and velocities at every
  event time and on the sample grid), the horizon and the clock mode from `/formation/step`;
- messages sent = TriggerInfo messages recorded, sensing calls = `/formation/sensing_log` entries;
- the scenario from `/formation/scenario` (std_msgs/String holding the scenario YAML) when the
  bag has it, else from `scenario.yaml` of the run folder holding the bag, else from the
  `scenario` the caller gives (`formation analyze --scenario`). Whatever its source, it must
  agree with the bag: same agents, the first state equal to its initial state, every
  TriggerInfo topic an edge of its graph.

Every cross-check the bag allows (Status counters, sensing log, commands, a state sample at
every event) becomes a `Check` in the report rather than an error: a bag with a lost message is
still worth analysing, and the report says what is wrong.

`run_series` evaluates the paper's quantities over the samples (edge lengths, formation error,
tension ν or ν_d, Lyapunov V or V_d), `theory_bounds` the guarantees of Theorems 1 and 2
they must respect, and `diff_summaries` lists where a bag's metrics differ from its
summary.json.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from formation_msgs_py.codec import (
    MessageError,
    decode_status,
    decode_step,
    decode_trigger_info,
    decode_world_state,
)
from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME
from formation_msgs_py.topics import SCENARIO_TOPIC, SENSING_LOG_TOPIC, STATE_TOPIC, STATUS_TOPIC, STEP_TOPIC
from formation_sim import theory
from formation_sim.engine import RunRecord
from formation_sim.recorder import RecorderError, decode, read_bag
from formation_sim.scenario import Scenario, ScenarioError, load_scenario
from formation_sim.summary import SUMMARY_FILE, build_summary

SCENARIO_FILE = 'scenario.yaml'
BAG_DIR = 'bag'
TRIGGER_INFO_TOPIC = re.compile(r'^/agent_(\d+)/trigger_info/to_(\d+)$')
COMMAND_TOPIC = re.compile(r'^/agent_(\d+)/(cmd_vel|cmd_accel)$')

# summary.json keys a bag cannot give back: wall-clock measurements of the live run. Besides
# these, `extra` holds implementation-specific details (summary.py); those of its keys the bag
# does not give (e.g. the simulator's own rejection counts) are listed as not recomputed.
NOT_IN_BAG = ('wall_time',)

ProgressCallback = Callable[[int, int | None], None]


class AnalysisError(ValueError):
    """A bag or run folder that cannot be analysed; the message says what is missing or wrong."""


@dataclass(frozen=True, kw_only=True)
class Check:
    """One consistency or theorem check: what was checked, whether it held, the numbers."""

    name: str
    ok: bool
    detail: str

    def to_dict(self) -> dict[str, Any]:
        return {'name': self.name, 'ok': self.ok, 'detail': self.detail}


@dataclass(frozen=True, kw_only=True)
class RunLocation:
    """Where a run's pieces are: the bag, the run folder, its summary.json."""

    bag: Path | None
    run_dir: Path | None
    summary: Path | None


def locate(path: str | Path) -> RunLocation:
    """Find the bag and the run folder from a run folder, a bag folder, a .mcap file or a summary.json."""
    path = Path(path)
    if not path.exists():
        raise AnalysisError(f'{path}: no such file or folder')
    if path.is_file():
        if path.suffix == '.mcap':
            bag = path.parent
        elif path.name == SUMMARY_FILE or path.suffix == '.json':
            run_dir = path.parent
            bag = run_dir / BAG_DIR
            return RunLocation(bag=bag if _is_bag(bag) else None, run_dir=run_dir, summary=path)
        else:
            raise AnalysisError(f'{path}: expected a run folder, a bag folder, a .mcap file or a summary.json')
    elif _is_bag(path):
        bag = path
    elif _is_bag(path / BAG_DIR):
        bag = path / BAG_DIR
    else:
        summary = path / SUMMARY_FILE
        if summary.is_file():
            return RunLocation(bag=None, run_dir=path, summary=summary)
        raise AnalysisError(f'{path}: neither a bag (metadata.yaml or .mcap), nor a run folder with bag/ or {SUMMARY_FILE}')
    run_dir = bag.parent if (bag.parent / SUMMARY_FILE).is_file() or (bag.parent / SCENARIO_FILE).is_file() else None
    summary = run_dir / SUMMARY_FILE if run_dir is not None and (run_dir / SUMMARY_FILE).is_file() else None
    return RunLocation(bag=bag, run_dir=run_dir, summary=summary)


def _is_bag(path: Path) -> bool:
    return path.is_dir() and ((path / 'metadata.yaml').is_file() or any(path.glob('*.mcap')))


# ----------------------------------------------------------------------------------------- the bag


@dataclass(kw_only=True)
class BagRun:
    """A run as rebuilt from its bag."""

    bag: Path
    record: RunRecord
    scenario_source: str
    topics: dict[str, str]  # name -> type
    counts: dict[str, int]  # name -> messages
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(check.ok for check in self.checks)


def scenario_from_yaml(text: str, *, source: str) -> Scenario:
    """A scenario from YAML text, read exactly as `load_scenario` reads a file."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / 'scenario.yaml'
        path.write_text(text, encoding='utf-8')
        try:
            return load_scenario(path)
        except ScenarioError as error:
            raise AnalysisError(f'{source}: {str(error).replace(str(path), "scenario")}') from None


def _message_total(bag: Path) -> int | None:
    try:
        from rosbags.rosbag2 import Reader

        with Reader(bag) as reader:
            return int(reader.message_count)
    except Exception:  # noqa: BLE001 - only for the progress display
        return None


@dataclass
class _Collected:
    topics: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    scenario_text: str | None = None
    states: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    statuses: dict[int, list] = field(default_factory=lambda: defaultdict(list))
    sensing: list[tuple[int, float]] = field(default_factory=list)
    # (sender, stamp) -> receivers, in bag order (duplicates kept, to be reported)
    infos: dict[tuple[int, float], list[int]] = field(default_factory=lambda: defaultdict(list))
    info_total: int = 0
    commands: dict[int, int] = field(default_factory=lambda: defaultdict(int))
    problems: list[str] = field(default_factory=list)


def _read(bag: Path, progress: ProgressCallback | None) -> _Collected:
    got = _Collected()
    total = _message_total(bag) if progress is not None else None
    number = 0
    try:
        for message in read_bag(bag):
            number += 1
            if progress is not None and number % 2000 == 0:
                progress(number, total)
            topic, msgtype = message.topic, message.msgtype
            got.topics.setdefault(topic, msgtype)
            got.counts[topic] += 1
            try:
                _dispatch(got, topic, msgtype, message.rawdata)
            except MessageError as error:
                got.problems.append(f'{topic} message {got.counts[topic]}: {error}')
        if progress is not None:
            progress(number, total)
    except RecorderError as error:
        raise AnalysisError(f'{bag}: {error}') from None
    except Exception as error:
        if type(error).__module__.startswith('rosbags'):
            hint = '' if (bag / 'metadata.yaml').is_file() else ' (no metadata.yaml: if its recorder was killed, recover it with formation_sim.recorder.reindex)'
            raise AnalysisError(f'{bag}: cannot read the bag: {error}{hint}') from None
        raise
    return got


def _dispatch(got: _Collected, topic: str, msgtype: str, rawdata: bytes) -> None:
    array = msgtype == 'std_msgs/msg/Float64MultiArray'
    if (match := TRIGGER_INFO_TOPIC.match(topic)) and array:
        info = decode_trigger_info(decode(rawdata, msgtype))
        sender, receiver = int(match.group(1)), int(match.group(2))
        if (info.sender, info.receiver) != (sender, receiver):
            raise MessageError(f'carries sender {info.sender} and receiver {info.receiver}, not the topic\'s {sender} -> {receiver}')
        got.infos[(info.sender, info.stamp)].append(info.receiver)
        got.info_total += 1
    elif topic == STATE_TOPIC and array:
        got.states.append(decode_world_state(decode(rawdata, msgtype)))
    elif topic == STEP_TOPIC and array:
        got.steps.append(decode_step(decode(rawdata, msgtype)))
    elif topic == STATUS_TOPIC and array:
        status = decode_status(decode(rawdata, msgtype))
        got.statuses[status.agent].append(status)
    elif topic == SENSING_LOG_TOPIC and msgtype == 'std_msgs/msg/String':
        try:
            entry = json.loads(decode(rawdata, msgtype).data)
            got.sensing.append((int(entry['agent']), float(entry['time'])))
        except (ValueError, KeyError, TypeError) as error:
            raise MessageError(f'sensing log entry is not {{"agent", "time", ...}} JSON: {error}') from None
    elif topic == SCENARIO_TOPIC and msgtype == 'std_msgs/msg/String':
        got.scenario_text = decode(rawdata, msgtype).data
    elif match := COMMAND_TOPIC.match(topic):
        got.commands[int(match.group(1))] += 1


def _resolve_scenario(got: _Collected, run_dir: Path | None, fallback: Scenario | str | Path | None) -> tuple[Scenario, str]:
    if got.scenario_text is not None:
        return scenario_from_yaml(got.scenario_text, source=f'the bag\'s {SCENARIO_TOPIC}'), f'bag topic {SCENARIO_TOPIC}'
    if run_dir is not None and (run_dir / SCENARIO_FILE).is_file():
        path = run_dir / SCENARIO_FILE
        try:
            return load_scenario(path), f'run folder file {path}'
        except ScenarioError as error:
            raise AnalysisError(str(error)) from None
    if fallback is not None:
        if isinstance(fallback, Scenario):
            return fallback, 'given by the caller'
        try:
            return load_scenario(fallback), f'--scenario {fallback}'
        except ScenarioError as error:
            raise AnalysisError(str(error)) from None
    raise AnalysisError(
        f'the bag has no {SCENARIO_TOPIC} topic and no {SCENARIO_FILE} lies next to it: '
        'give the scenario (formation analyze --scenario NAME_OR_YAML)'
    )


def _check_scenario_matches(scenario: Scenario, got: _Collected, states) -> None:
    """Refuse a scenario that is not the bag's run (analysing it would be meaningless)."""
    first = states[0]
    if tuple(first.agent_ids) != scenario.agent_ids:
        raise AnalysisError(f'the bag\'s agents {list(first.agent_ids)} are not the scenario\'s {list(scenario.agent_ids)}')
    if first.positions.shape[1] != scenario.dimension:
        raise AnalysisError(f'the bag\'s states have dimension {first.positions.shape[1]}, the scenario {scenario.dimension}')
    if (first.velocities is None) != (scenario.dynamics == 'single'):
        raise AnalysisError(f'the bag\'s states {"lack" if first.velocities is None else "carry"} velocities; the scenario is {scenario.dynamics!r}')
    if first.time == 0.0:
        for k, agent in enumerate(scenario.agent_ids):
            if not np.array_equal(first.positions[k], scenario.positions[k]):
                raise AnalysisError(
                    f'agent {agent} starts at {first.positions[k].tolist()} in the bag but at '
                    f'{scenario.positions[k].tolist()} in the scenario {scenario.name!r}'
                )
            if scenario.velocities is not None and not np.array_equal(first.velocities[k], scenario.velocities[k]):
                raise AnalysisError(
                    f'agent {agent} starts with velocity {first.velocities[k].tolist()} in the bag but '
                    f'{scenario.velocities[k].tolist()} in the scenario {scenario.name!r}'
                )
    for sender, _ in got.infos:
        if sender not in scenario.agent_ids:
            raise AnalysisError(f'the bag has triggering information from agent {sender}, not an agent of {scenario.name!r}')
    for (sender, _), receivers in got.infos.items():
        stray = set(receivers) - set(scenario.neighbours(sender))
        if stray:
            raise AnalysisError(f'the bag has messages {sender} -> {sorted(stray)}, which are not edges of {scenario.name!r}')


def load_bag_run(
    bag: str | Path,
    *,
    run_dir: str | Path | None = None,
    scenario: Scenario | str | Path | None = None,
    progress: ProgressCallback | None = None,
) -> BagRun:
    """Rebuild the run recorded in `bag` (see the module docstring for what comes from where).

    `scenario` is used only when neither the bag nor `run_dir` holds the scenario.
    """
    bag = Path(bag)
    got = _read(bag, progress)
    if not got.states:
        raise AnalysisError(f'{bag}: no {STATE_TOPIC} messages: the trajectories cannot be rebuilt (topics: {sorted(got.topics)})')
    run_dir = None if run_dir is None else Path(run_dir)
    found, source = _resolve_scenario(got, run_dir, scenario)
    states = sorted(got.states, key=lambda state: state.time)  # stable: ties keep bag order
    _check_scenario_matches(found, got, states)
    checks = [Check(name='decoding', ok=not got.problems, detail='; '.join(got.problems[:10]) or 'every formation message follows its layout')]

    # Samples: one per distinct time (a repeat of a time must repeat the state).
    times, positions, velocities, repeats = [], [], [], []
    for state in states:
        if times and state.time == times[-1]:
            if not np.array_equal(state.positions, positions[-1]):
                repeats.append(state.time)
            continue
        times.append(state.time)
        positions.append(np.asarray(state.positions, dtype=float))
        if state.velocities is not None:
            velocities.append(np.asarray(state.velocities, dtype=float))
    checks.append(Check(name='state samples', ok=not repeats, detail=f'{len(times)} samples' + (f'; different states at the same time {repeats[:5]}' if repeats else '')))

    trigger_times: dict[int, list[float]] = {agent: [] for agent in found.agent_ids}
    missing, duplicated = [], []
    for (sender, stamp), receivers in got.infos.items():
        trigger_times[sender].append(stamp)
        expected = set(found.neighbours(sender))
        if len(receivers) != len(set(receivers)):
            duplicated.append(f'{sender} @ {stamp!r}')
        if set(receivers) != expected:
            missing.append(f'{sender} @ {stamp!r} -> {sorted(expected - set(receivers))}')
    for agent in trigger_times:
        trigger_times[agent].sort()
    checks.append(
        Check(
            name='one TriggerInfo per neighbour per trigger',
            ok=not missing and not duplicated,
            detail=f'{got.info_total} messages for {sum(map(len, trigger_times.values()))} triggers'
            + (f'; missing: {missing[:5]}' if missing else '')
            + (f'; duplicated: {duplicated[:5]}' if duplicated else ''),
        )
    )

    steps = got.steps
    final = [step for step in steps if step.flags & STEP_FLAG_FINAL]
    realtime = any(step.flags & STEP_FLAG_REALTIME for step in steps)
    if final:
        horizon = final[-1].time
    else:
        horizon = times[-1]
        checks.append(Check(name='final step', ok=False, detail=f'no final {STEP_TOPIC} message: the run did not finish; horizon taken as the last state time {horizon!r}'))
    if times[-1] != horizon:
        checks.append(Check(name='final state', ok=False, detail=f'the last state is at t={times[-1]!r}, the run ended at t={horizon!r}'))
    events = sorted({t for agent_times in trigger_times.values() for t in agent_times})
    sampled = set(times)
    unsampled = [t for t in events if t not in sampled]
    checks.append(Check(name='a state sample at every event', ok=not unsampled, detail=f'{len(events)} distinct event times' + (f'; without a sample: {unsampled[:5]}' if unsampled else '')))

    sensing_calls = len(got.sensing) if SENSING_LOG_TOPIC in got.topics else sum(map(len, trigger_times.values()))
    if SENSING_LOG_TOPIC in got.topics:
        logged: dict[int, list[float]] = defaultdict(list)
        for agent, t in got.sensing:
            logged[agent].append(t)
        differing = [agent for agent in found.agent_ids if sorted(logged.get(agent, [])) != trigger_times[agent]]
        checks.append(Check(name='sensing log = triggers', ok=not differing, detail='every trigger sensed once at its time' if not differing else f'agents {differing} sensed at other times than they triggered'))
    if got.commands:
        differing = [agent for agent in found.agent_ids if got.commands.get(agent, 0) != len(trigger_times[agent])]
        checks.append(Check(name='one command per trigger', ok=not differing, detail='yes' if not differing else f'agents {differing}: commands {dict(got.commands)}'))
    extra: dict[str, Any] = {}
    if steps:
        extra['clock'] = 'realtime' if realtime else 'lockstep'
        if final and not realtime:
            extra['steps'] = final[-1].index  # lock-step: one Step per advance of the world
        extra['reached_time'] = times[-1]  # the simulator samples the world where it stops
        if final:
            extra['failure'] = None  # the final Step goes out only when the horizon is reached
    if got.statuses:
        sent: dict[int, int] = defaultdict(int)
        for (sender, _), receivers in got.infos.items():
            sent[sender] += len(receivers)
        # Counters only grow: the largest are the agent's final report.
        last = {agent: max(reports, key=lambda s: (s.info_sent, s.triggers)) for agent, reports in got.statuses.items()}
        wrong = [
            f'agent {agent}: status says {status.triggers} triggers / {status.info_sent} sent, bag has {len(trigger_times[agent])} / {sent[agent]}'
            for agent, status in last.items()
            if agent in trigger_times and (status.triggers != len(trigger_times[agent]) or status.info_sent != sent[agent])
        ]
        checks.append(Check(name='status counters = bag', ok=not wrong, detail='; '.join(wrong) or 'every agent\'s last Status counts what the bag holds'))
        if realtime:
            extra.update(_lateness(got.statuses, trigger_times))

    record = RunRecord(
        scenario=found,
        horizon=horizon,
        mode='distributed' if steps else 'recorded',
        trigger_times=trigger_times,
        sample_times=np.array(times),
        sample_positions=np.array(positions),
        sample_velocities=np.array(velocities) if velocities else None,
        messages_sent=got.info_total,
        sensing_calls=sensing_calls,
        wall_time=math.nan,  # not in a bag
        extra=extra,
    )
    return BagRun(bag=bag, record=record, scenario_source=source, topics=dict(got.topics), counts=dict(got.counts), checks=checks)


def _lateness(statuses: dict[int, list], trigger_times: dict[int, list[float]]) -> dict[str, Any]:
    """Wall clock: trigger time - planned time per new trigger (Status.last_planned), as the simulator computes it."""
    per_agent = {}
    for agent, reports in statuses.items():
        lateness, seen = [], 0
        for status in reports:
            if status.triggers > seen:
                seen = status.triggers
                if 0 < seen <= len(trigger_times.get(agent, [])):
                    lateness.append(trigger_times[agent][seen - 1] - status.last_planned)
        if lateness:
            per_agent[str(agent)] = {'max': max(lateness), 'mean': float(np.mean(lateness))}
    return {'lateness': per_agent, 'max_lateness': max((entry['max'] for entry in per_agent.values()), default=0.0)}


# ------------------------------------------------------------------------------------ time series


@dataclass(frozen=True, kw_only=True)
class Series:
    """The paper's quantities at every sample of a run (rows = samples, columns = scenario edges)."""

    times: np.ndarray  # (K,)
    edge_lengths: np.ndarray  # (K, m) ||x_i - x_j||, must stay < Δ (Theorem 1/2 (i))
    edge_errors: np.ndarray  # (K, m) ||x_i - x_j - d_ij|| = ||y_i - y_j||
    formation_error: np.ndarray  # (K,) max over edges
    tension: np.ndarray  # (K,) ν (single) or ν_d = k1 ν + ½ Σ||q_i||² (double)
    lyapunov: np.ndarray  # (K,) V = ½ δᵀδ or V_d (double)


def run_series(record: RunRecord, *, progress: ProgressCallback | None = None) -> Series:
    scenario = record.scenario
    heads, tails, d = scenario.edge_indices()
    x = record.sample_positions
    relative = x[:, heads] - x[:, tails]
    lengths = np.linalg.norm(relative, axis=2)
    errors = np.linalg.norm(relative - d, axis=2)
    tau = theory.formation_feasibility(scenario).tau
    double = scenario.dynamics == 'double'
    q = record.sample_velocities
    count = len(record.sample_times)
    tension = np.empty(count)
    lyapunov = np.empty(count)
    for k in range(count):
        if double:
            tension[k] = theory.tension_double(scenario, x[k], q[k])
            lyapunov[k] = theory.lyapunov_double(scenario, x[k], q[k], tau=tau)
        else:
            tension[k] = theory.tension(scenario, x[k])
            lyapunov[k] = theory.lyapunov(scenario, x[k], tau=tau)
        if progress is not None and k % 5000 == 0:
            progress(k, count)
    return Series(
        times=np.asarray(record.sample_times, dtype=float),
        edge_lengths=lengths,
        edge_errors=errors,
        formation_error=errors.max(axis=1),
        tension=tension,
        lyapunov=lyapunov,
    )


@dataclass(frozen=True, kw_only=True)
class TheoryBounds:
    """What Theorem 1 (single) or Theorem 2 (double, corrected chain) guarantees for a scenario."""

    theorem: int
    rate: float  # β (Theorem 1) or β_d (Theorem 2)
    k_nu: float  # ν(t) <= k_ν (kν), or ν_d(t) <= k^d_ν
    k_V: float | None  # V(t) < k_V e^{-2 rate t} (kV), or V_d < k^d_V e^{-2 β_d t} (kVd, corrected)
    error_gain: float | None  # ||y_i - y_j|| < error_gain e^{-rate t} (lengthysV) / (yiyj)
    edge_bounds: dict[tuple[int, int], float]  # ||x_i - x_j|| <= k_ij + ||d_ij|| < Δ
    xi: dict[int, float] | None  # (xi) / (xid): t_{k+1} - t_k >= ξ_i
    note: str
    # Theorem 2 only: k^d_V and the error gain of the chain as printed (rate (2-k4)ρ2(P)), drawn
    # for comparison; docs/THEOREM2.md shows where the paper's example leaves them.
    printed_k_V: float | None = None
    printed_error_gain: float | None = None


def theory_bounds(scenario: Scenario) -> TheoryBounds:
    """The proof constants as bounds; raises theory.TheoryError outside the theorems' hypotheses."""
    constants = theory.theorem_constants(scenario)
    norms = {edge.pair: float(np.linalg.norm(edge.d)) for edge in scenario.edges}
    edge_bounds = {pair: k + norms[pair] for pair, k in constants.k_edge.items()}
    if constants.theorem == 1:
        return TheoryBounds(
            theorem=1,
            rate=scenario.gains.beta,
            k_nu=constants.k_nu,
            k_V=constants.k_V,
            error_gain=2.0 * math.sqrt(constants.k_V),  # (lengthysV): ||y_i-y_j||² < 4 k_V e^{-2βt}
            edge_bounds=edge_bounds,
            xi=constants.xi,
            note='Theorem 1',
        )
    chain = constants.corrected_chain
    gain = None if chain.k_V is None else 2.0 * math.sqrt(chain.z_gain * chain.k_V)  # (yiyj), corrected
    printed = constants.paper_chain
    printed_gain = None if printed.k_V is None else 2.0 * math.sqrt(printed.z_gain * printed.k_V)
    return TheoryBounds(
        theorem=2,
        rate=scenario.gains.beta_d,
        k_nu=constants.k_nu,
        k_V=chain.k_V,
        error_gain=gain,
        edge_bounds=edge_bounds,
        xi=chain.xi,
        note='Theorem 2, corrected chain (docs/THEOREM2.md)' + ('' if chain.holds else ': β_d is not below (2-k4)/λmax(P), no decay bound'),
        printed_k_V=printed.k_V,
        printed_error_gain=printed_gain,
    )


def printed_chain_ratios(series: Series, bounds: TheoryBounds) -> dict[str, Any] | None:
    """Theorem 2: the largest V_d / (printed k^d_V e^{-2β_d t}) and the first time it reaches 1."""
    if bounds.printed_k_V is None:
        return None
    ratio = series.lyapunov / (bounds.printed_k_V * np.exp(-2.0 * bounds.rate * series.times))
    worst = int(np.argmax(ratio))
    above = np.flatnonzero(ratio >= 1.0)
    return {
        'max_ratio': float(ratio[worst]),
        'at_time': float(series.times[worst]),
        'first_time_above': float(series.times[above[0]]) if above.size else None,
    }


def theorem_checks(record: RunRecord, series: Series, bounds: TheoryBounds | None) -> list[Check]:
    """The theorems' guarantees checked at every sample (and every inter-event time)."""
    scenario = record.scenario
    delta = scenario.delta
    longest = float(series.edge_lengths.max())
    checks = [Check(name='connectivity: ||x_i - x_j|| < Δ', ok=longest < delta, detail=f'max edge length {longest!r} vs Δ = {delta!r}')]
    if bounds is None:
        return checks
    over = []
    for column, edge in enumerate(scenario.edges):
        top = float(series.edge_lengths[:, column].max())
        if not top <= bounds.edge_bounds[edge.pair]:
            over.append(f'{edge.i}-{edge.j}: {top!r} > {bounds.edge_bounds[edge.pair]!r}')
    checks.append(Check(name='edge lengths <= k_ij + ||d_ij|| (kij)', ok=not over, detail='; '.join(over) or 'every edge within its bound'))
    top_nu = float(series.tension.max())
    checks.append(Check(name='tension <= k_nu (knu)', ok=top_nu <= bounds.k_nu, detail=f'max {top_nu!r} vs k_nu = {bounds.k_nu!r}'))
    t = series.times
    if bounds.k_V is not None:
        ratio = series.lyapunov / (bounds.k_V * np.exp(-2.0 * bounds.rate * t))
        worst = int(np.argmax(ratio))
        checks.append(Check(name='V < k_V e^{-2 beta t} (kV)', ok=bool(ratio[worst] < 1.0), detail=f'largest V / bound {ratio[worst]:.3g} at t = {float(t[worst])!r}'))
    if bounds.error_gain is not None:
        ratio = series.formation_error / (bounds.error_gain * np.exp(-bounds.rate * t))
        worst = int(np.argmax(ratio))
        checks.append(Check(name='formation error < 2 sqrt(k_V) e^{-beta t}', ok=bool(ratio[worst] < 1.0), detail=f'largest error / bound {ratio[worst]:.3g} at t = {float(t[worst])!r}'))
    if bounds.xi is not None:
        below = []
        for agent, times in record.trigger_times.items():
            if len(times) > 1:
                gap = float(np.diff(times).min())
                if not gap >= bounds.xi[agent]:
                    below.append(f'agent {agent}: {gap!r} < {bounds.xi[agent]!r}')
        checks.append(Check(name='inter-event times >= xi_i (xi)', ok=not below, detail='; '.join(below) or 'every agent'))
    return checks


def inter_event_stats(record: RunRecord, xi: dict[int, float] | None) -> dict[str, dict[str, Any]]:
    result = {}
    for agent, times in record.trigger_times.items():
        gaps = np.diff(np.asarray(times, dtype=float))
        result[str(agent)] = {
            'events': len(times),
            'min': float(gaps.min()) if gaps.size else None,
            'median': float(np.median(gaps)) if gaps.size else None,
            'max': float(gaps.max()) if gaps.size else None,
            'xi': None if xi is None else xi.get(agent),
        }
    return result


# ------------------------------------------------------------------------------- summary vs bag


@dataclass(frozen=True, kw_only=True)
class Difference:
    key: str  # dotted path, list elements as [k]
    bag: Any
    summary: Any

    def to_dict(self) -> dict[str, Any]:
        return {'key': self.key, 'bag': self.bag, 'summary': self.summary}


_MISSING = object()


def diff_summaries(from_bag: dict, from_file: dict) -> tuple[list[Difference], list[str]]:
    """Every leaf where the bag's summary differs from summary.json (floats compared exactly).

    Returns (differences, keys of summary.json a bag cannot reproduce, see NOT_IN_BAG).
    """
    differences: list[Difference] = []
    skipped: list[str] = []

    def walk(a: Any, b: Any, key: str) -> None:
        if (key in NOT_IN_BAG and (a is _MISSING or a is None)) or (key.startswith('extra.') and a is _MISSING):
            skipped.append(key)
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for name in list(a) + [name for name in b if name not in a]:
                walk(a.get(name, _MISSING), b.get(name, _MISSING), f'{key}.{name}' if key else str(name))
            return
        if isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                differences.append(Difference(key=f'{key} (length)', bag=len(a), summary=len(b)))
            for k, (x, y) in enumerate(zip(a, b)):
                walk(x, y, f'{key}[{k}]')
            return
        if a is _MISSING or b is _MISSING or not _same(a, b):
            differences.append(Difference(key=key, bag=None if a is _MISSING else a, summary=None if b is _MISSING else b))

    walk(from_bag, from_file, '')
    return differences, skipped


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):  # True == 1 in Python, not in a summary
        return type(a) is type(b) and a == b
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def bag_summary(record: RunRecord) -> dict:
    """summary.json's schema computed from the rebuilt record (wall_time: not in a bag, null)."""
    summary = build_summary(record)
    summary['wall_time'] = None
    return summary


# ------------------------------------------------------------------------------------- report


def json_safe(value: Any) -> Any:
    """Replace non-finite floats by their names (JSON has none) and tuples/arrays by lists."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        return json_safe(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


def build_report(
    run: BagRun,
    *,
    series: Series,
    bounds: TheoryBounds | None,
    bounds_error: str | None = None,
    summary_path: Path | None = None,
    figures: dict[str, str] | None = None,
) -> dict[str, Any]:
    """The analysis as a JSON-ready dictionary (`render_markdown` prints it)."""
    record = run.record
    scenario = record.scenario
    summary = bag_summary(record)
    comparison = None
    if summary_path is not None:
        file_summary = json.loads(Path(summary_path).read_text(encoding='utf-8'))
        differences, skipped = diff_summaries(summary, file_summary)
        comparison = {
            'path': str(summary_path),
            'equal': not differences,
            'differences': [difference.to_dict() for difference in differences],
            'not_in_bag': skipped,
            'notes': _difference_notes(record) if differences else [],
        }
    t = series.times
    return json_safe(
        {
            'schema': 'formation-analysis/1',
            'bag': str(run.bag),
            'scenario_source': run.scenario_source,
            'run': {
                'scenario': scenario.name,
                'dynamics': scenario.dynamics,
                'mode': record.mode,
                'clock': record.extra.get('clock'),
                'horizon': record.horizon,
                'n_agents': scenario.n,
                'dimension': scenario.dimension,
                'delta': scenario.delta,
            },
            'topics': {name: {'type': run.topics[name], 'messages': run.counts[name]} for name in sorted(run.topics)},
            'bag_checks': [check.to_dict() for check in run.checks],
            'theorem_checks': [check.to_dict() for check in theorem_checks(record, series, bounds)],
            'theory': None
            if bounds is None
            else {
                'theorem': bounds.theorem,
                'note': bounds.note,
                'rate': bounds.rate,
                'k_nu': bounds.k_nu,
                'k_V': bounds.k_V,
                'error_gain': bounds.error_gain,
                'xi': bounds.xi,
                'printed_chain': None
                if bounds.printed_k_V is None
                else {'k_V': bounds.printed_k_V, 'error_gain': bounds.printed_error_gain, **printed_chain_ratios(series, bounds)},
            },
            'theory_error': bounds_error,
            'inter_event_times': inter_event_stats(record, None if bounds is None else bounds.xi),
            'series': {
                'samples': len(t),
                'formation_error': {'initial': float(series.formation_error[0]), 'final': float(series.formation_error[-1])},
                'tension': {'initial': float(series.tension[0]), 'max': float(series.tension.max()), 'final': float(series.tension[-1])},
                'lyapunov': {'initial': float(series.lyapunov[0]), 'final': float(series.lyapunov[-1])},
            },
            'summary': summary,
            'summary_json': comparison,
            'figures': figures or {},
        }
    )


def _difference_notes(record: RunRecord) -> list[str]:
    """Known reasons for a bag to differ from its summary.json."""
    notes = []
    if record.extra.get('clock') == 'realtime':
        at_end = [agent for agent, times in record.trigger_times.items() if times and times[-1] >= record.horizon]
        if at_end:
            notes.append(
                f'agents {at_end} triggered at the horizon t = {record.horizon!r} (wall clock): summary.json counts '
                'a trigger only once its command has acted on the world before the run ended, which a bag cannot show'
            )
    return notes


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.6g}'
    if value is None:
        return '—'
    return str(value)


def render_markdown(report: dict[str, Any]) -> str:
    run = report['run']
    summary = report['summary']
    lines = [
        f'# Analysis of `{report["bag"]}`',
        '',
        f'Scenario **{run["scenario"]}** ({run["dynamics"]} integrators, n = {run["n_agents"]}, p = {run["dimension"]}, '
        f'Δ = {_fmt(run["delta"])}), {run["mode"]} run, clock {run["clock"] or "—"}, horizon {_fmt(run["horizon"])} s. '
        f'Scenario from: {report["scenario_source"]}. Every number below is recomputed from the bag.',
        '',
        '## Events and messages',
        '',
        '| agent | events | min inter-event [s] | median | max | ξ_i (proof bound) |',
        '|---|---|---|---|---|---|',
    ]
    for agent, stats in report['inter_event_times'].items():
        lines.append(f'| {agent} | {stats["events"]} | {_fmt(stats["min"])} | {_fmt(stats["median"])} | {_fmt(stats["max"])} | {_fmt(stats["xi"])} |')
    lines += [
        '',
        f'Total events {summary["total_events"]}, triggering-information messages {summary["messages_sent"]}, '
        f'sensing calls {summary["sensing_calls"]}.',
        '',
        '| edge | max length | Δ − max length | final error ‖x_i − x_j − d_ij‖ |',
        '|---|---|---|---|',
    ]
    for edge in summary['edges']:
        lines.append(f'| {edge["i"]}-{edge["j"]} | {_fmt(edge["max_length"])} | {_fmt(edge["min_range_slack"])} | {_fmt(edge["final_error"])} |')
    series = report['series']
    lines += [
        '',
        f'Formation error: {_fmt(series["formation_error"]["initial"])} at t = 0, {_fmt(series["formation_error"]["final"])} at the horizon. '
        f'Tension: {_fmt(series["tension"]["initial"])} → max {_fmt(series["tension"]["max"])} → {_fmt(series["tension"]["final"])}. '
        f'Lyapunov: {_fmt(series["lyapunov"]["initial"])} → {_fmt(series["lyapunov"]["final"])} ({series["samples"]} samples).',
        '',
        '## Theorem checks (at every sample)',
        '',
    ]
    if report['theory']:
        theory_info = report['theory']
        lines.append(
            f'{theory_info["note"]}: rate {_fmt(theory_info["rate"])}, k_ν = {_fmt(theory_info["k_nu"])}, '
            f'k_V = {_fmt(theory_info["k_V"])}, error bound gain {_fmt(theory_info["error_gain"])}.'
        )
        printed = theory_info.get('printed_chain')
        if printed:
            above = printed['first_time_above']
            lines.append(
                f'For comparison, the chain as printed (rate (2-k4)ρ2(P)): k_V = {_fmt(printed["k_V"])}; '
                f'V_d reaches {_fmt(printed["max_ratio"])} × its bound k_V e^{{-2β_d t}} (at t = {_fmt(printed["at_time"])} s)'
                + (f', above it from t = {_fmt(above)} s on (docs/THEOREM2.md).' if above is not None else '; below it throughout.')
            )
        lines.append('')
    elif report['theory_error']:
        lines += [f'No proof constants: {report["theory_error"]}', '']
    lines += _check_table(report['theorem_checks'])
    lines += ['', '## Bag consistency', '']
    lines += _check_table(report['bag_checks'])
    lines += ['', '| topic | type | messages |', '|---|---|---|']
    for name, info in report['topics'].items():
        lines.append(f'| `{name}` | {info["type"]} | {info["messages"]} |')
    lines += ['', '## The bag against summary.json', '']
    comparison = report['summary_json']
    if comparison is None:
        lines.append('No summary.json next to the bag.')
    elif comparison['equal']:
        lines.append(
            f'`{comparison["path"]}`: every metric recomputed from the bag equals the file '
            f'(floats compared exactly). Not recomputed from the bag (wall-clock measurements, runtime '
            f'details): {", ".join(comparison["not_in_bag"]) or "—"}.'
        )
    else:
        differences = comparison['differences']
        lines += [
            f'`{comparison["path"]}` differs from the bag in {len(differences)} value(s) '
            f'(not recomputed from the bag, not compared: {", ".join(comparison["not_in_bag"]) or "—"}):',
            '',
            '| key | from the bag | summary.json |',
            '|---|---|---|',
        ]
        limit = 200
        for difference in differences[:limit]:
            lines.append(f'| `{difference["key"]}` | {_short(difference["bag"])} | {_short(difference["summary"])} |')
        if len(differences) > limit:
            lines.append(f'| … {len(differences) - limit} more (see the JSON report) | | |')
        for note in comparison.get('notes', []):
            lines += ['', f'Note: {note}.']
    if report['figures']:
        lines += ['', '## Figures', '']
        for title, name in report['figures'].items():
            if name.endswith('.gif') or name.endswith('.png'):
                lines.append(f'![{title}]({name})')
            else:
                lines.append(f'- {title}: `{name}`')
    return '\n'.join(lines) + '\n'


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 120 else text[:117] + '…'


def _check_table(checks: list[dict[str, Any]]) -> list[str]:
    lines = ['| check | holds | detail |', '|---|---|---|']
    for check in checks:
        lines.append(f'| {check["name"]} | {"yes" if check["ok"] else "**NO**"} | {check["detail"]} |')
    return lines


def write_report(report: dict[str, Any], out_dir: str | Path) -> tuple[Path, Path]:
    """`analysis.md` and `analysis.json` in `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    markdown = out / 'analysis.md'
    data = out / 'analysis.json'
    markdown.write_text(render_markdown(report), encoding='utf-8')
    data.write_text(json.dumps(report, indent=1, allow_nan=False) + '\n', encoding='utf-8')
    return markdown, data
