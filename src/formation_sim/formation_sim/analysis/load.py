"""A run rebuilt from its rosbag2 bag alone: every metric recomputed, checked and reported.

`load_bag_run(bag)` reads the bag once and rebuilds the `RunRecord` the simulator had:

- triggering times from the TriggerInfo messages (`/agent_<i>/trigger_info/to_<j>`): one message
  per neighbour per trigger, so agent i triggered at t iff some message from i is stamped t;
  messages are grouped by (sender, stamp) and each group must reach every neighbour once;
- the trajectories from `/formation/state` (WorldState: exact positions and velocities at every
  event time and on the sample grid), the horizon and the clock mode from `/formation/step`;
- messages sent = TriggerInfo messages recorded, sensing calls = `/formation/sensing_log` entries;
- robot runs (`formation run --backend <robot kind> | external`, no `/formation/state`):
  the trajectories from the robots' pose topics (`/formation/robots` names which: a simulated
  robot's noise-free `true_odom`, else the measured `odom` or `pose`), run time from their header
  stamps and the epoch of Step 0, sampled as the coordinator samples them
  (`formation_sim.sim.robots.trajectory_samples`); every robot's last command must be a stop;
- the scenario from `/formation/scenario` (std_msgs/String holding the scenario YAML) when the
  bag has it, else from `scenario.yaml` of the run folder holding the bag, else from the
  `scenario` the caller gives (`formation analyze --scenario`). Whatever its source, it must
  agree with the bag: same agents, the first state equal to its initial state, every
  TriggerInfo topic an edge of its graph.

Every cross-check the bag allows (Status counters, sensing log, commands, a state sample at
every event) becomes a `Check` in the report rather than an error: a bag with a lost message is
still worth analysing, and the report says what is wrong.

The checks and bounds: `formation_sim.analysis.checks`; the report: `formation_sim.analysis.report`.
"""

from __future__ import annotations

import json
import math
import struct
import tempfile
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from formation_agent.core.pose_sensing import pose_refusal
from formation_agent.core.speed_scale import initial_velocities
from formation_msgs_py.cdr import odometry_fields, pose_stamped_fields
from formation_msgs_py.codec import (
    decode_agent_report,
    decode_status,
    decode_step,
    decode_trigger_info,
    decode_world_state,
)
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME
from formation_msgs_py.topic_table import match_topic
from formation_msgs_py.topics import ROBOTS_TOPIC, SCENARIO_TOPIC, SENSING_LOG_TOPIC, STATE_TOPIC, STEP_TOPIC
from formation_sim.analysis.checks import Check, ProgressCallback
from formation_sim.analysis.errors import AnalysisError
from formation_sim.bag.errors import BagError
from formation_sim.bag.io import decode, read_bag
from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import Scenario, load_scenario
from formation_sim.sim.record import RunRecord
from formation_sim.sim.robots import (
    PoseTrack,
    poses_for_end,
    sample_from_fields,
    sample_times,
    trajectory_samples,
)
from formation_sim.sim.samples import Samples
from formation_sim.sim.summary import SUMMARY_FILE, lateness_extra, saturation_extra

SCENARIO_FILE = 'scenario.yaml'


BAG_DIR = 'bag'


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
            raise AnalysisError(
                f'{path}: expected a run folder, a bag folder, a .mcap file or a summary.json'
            )
    elif _is_bag(path):
        bag = path
    elif _is_bag(path / BAG_DIR):
        bag = path / BAG_DIR
    else:
        summary = path / SUMMARY_FILE
        if summary.is_file():
            return RunLocation(bag=None, run_dir=path, summary=summary)
        raise AnalysisError(
            f'{path}: neither a bag (metadata.yaml or .mcap), nor a run folder with bag/ or {SUMMARY_FILE}'
        )
    run_dir = (
        bag.parent
        if (bag.parent / SUMMARY_FILE).is_file() or (bag.parent / SCENARIO_FILE).is_file()
        else None
    )
    summary = run_dir / SUMMARY_FILE if run_dir is not None and (run_dir / SUMMARY_FILE).is_file() else None
    return RunLocation(bag=bag, run_dir=run_dir, summary=summary)


def _is_bag(path: Path) -> bool:
    return path.is_dir() and ((path / 'metadata.yaml').is_file() or any(path.glob('*.mcap')))


@dataclass(kw_only=True)
class BagRun:
    """A run as rebuilt from its bag."""

    bag: Path
    record: RunRecord
    scenario_source: str
    topics: dict[str, str]  # name -> type
    counts: dict[str, int]  # name -> messages
    checks: list[Check] = field(default_factory=list)
    horizon: float | None = None  # the horizon the run was asked for (from /formation/scenario), if known
    stop: dict[str, Any] | None = (
        None  # {time, step, horizon, final_step}: where a run that stopped early ended
    )

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
    last_command_zero: dict[int, bool] = field(default_factory=dict)  # agent -> its last command is all 0
    robots: dict | None = None  # /formation/robots: what the robots of a robot run are
    # (agent, robot topic) -> (msgtype, CDR, bag time [ns]: when the recorder got it, run time)
    robot_messages: dict[tuple[int, str], list[tuple[str, bytes, int]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    reports: dict[int, Any] = field(default_factory=dict)  # agent -> its latest report (the final one kept)


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
                _dispatch(got, topic, msgtype, message.rawdata, stamp_ns=message.timestamp_ns)
            except MessageError as error:
                got.problems.append(f'{topic} message {got.counts[topic]}: {error}')
            except Exception as error:  # CDR that does not decode as its type: the message is damaged
                if not type(error).__module__.startswith('rosbags') and not isinstance(
                    error, (struct.error, IndexError, ValueError)
                ):
                    raise
                got.problems.append(
                    f'{topic} message {got.counts[topic]}: does not decode as {msgtype}: {error}'
                )
        if progress is not None:
            progress(number, total)
    except BagError as error:
        raise AnalysisError(str(error) if str(error).startswith(str(bag)) else f'{bag}: {error}') from None
    return got


def _on_trigger_info(
    got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int
) -> None:
    info = decode_trigger_info(decode(rawdata, msgtype))
    sender, receiver = ids
    if (info.sender, info.receiver) != (sender, receiver):
        raise MessageError(
            f'carries sender {info.sender} and receiver {info.receiver}, '
            f"not the topic's {sender} -> {receiver}"
        )
    got.infos[(info.sender, info.stamp)].append(info.receiver)
    got.info_total += 1


def _on_status(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
    status = decode_status(decode(rawdata, msgtype))
    got.statuses[status.agent].append(status)


def _on_sensing_log(
    got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int
) -> None:
    try:
        entry = json.loads(decode(rawdata, msgtype).data)
        got.sensing.append((int(entry['agent']), float(entry['time'])))
    except (ValueError, KeyError, TypeError) as error:
        raise MessageError(f'sensing log entry is not {{"agent", "time", ...}} JSON: {error}') from None


def _on_scenario(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
    got.scenario_text = decode(rawdata, msgtype).data


def _on_command(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
    got.commands[ids[0]] += 1
    got.last_command_zero[ids[0]] = _is_zero_command(rawdata, msgtype)


def _on_robot(kind: str):
    """Robot topics are decoded once the run is known (which topic is the trajectory, the epoch,
    the model): kept as they came."""

    def keep(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
        got.robot_messages[(ids[0], kind)].append((msgtype, rawdata, stamp_ns))

    return keep


def _on_robots(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
    try:
        got.robots = json.loads(decode(rawdata, msgtype).data)
    except ValueError as error:
        raise MessageError(f'not JSON: {error}') from None


def _on_report(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
    report = decode_agent_report(decode(rawdata, msgtype))
    if report.agent not in got.reports or not got.reports[report.agent].final:
        got.reports[report.agent] = report


def _append(field: str, decoder):
    def on(got: _Collected, rawdata: bytes, msgtype: str, ids: tuple[int, ...], stamp_ns: int) -> None:
        getattr(got, field).append(decoder(decode(rawdata, msgtype)))

    return on


HANDLERS: dict[str, tuple[bool, Any]] = {
    'step': (True, _append('steps', decode_step)),
    'status': (True, _on_status),
    'state': (True, _append('states', decode_world_state)),
    'ground_truth': (False, None),  # for tools: the analysis rebuilds the formation from the states
    'sensing_log': (True, _on_sensing_log),
    'clock': (False, None),
    'report': (True, _on_report),
    'scenario': (True, _on_scenario),
    'markers': (False, None),
    'robots': (True, _on_robots),
    'cmd_vel': (False, _on_command),
    'cmd_accel': (False, _on_command),
    'robot/pose': (False, _on_robot('pose')),
    'robot/odom': (False, _on_robot('odom')),
    'robot/true_odom': (False, _on_robot('true_odom')),
    'robot/cmd_vel': (False, _on_robot('cmd_vel')),
    'trigger_info': (True, _on_trigger_info),
}
"""What the analysis does with each recorded row of the topic table (`formation_msgs_py.topic_table`;
a test checks that every recorded row has an entry): (read only if of the row's type, the handler;
None: not read)."""


def _dispatch(got: _Collected, topic: str, msgtype: str, rawdata: bytes, *, stamp_ns: int = 0) -> None:
    if (found := match_topic(topic)) is None or found[0].key not in HANDLERS:
        return
    row, ids = found
    typed, handler = HANDLERS[row.key]
    if handler is not None and (not typed or msgtype == row.msgtype):
        handler(got, rawdata, msgtype, ids, stamp_ns)


def _is_zero_command(rawdata: bytes, msgtype: str) -> bool:
    """Whether a plant command (Twist, Accel) is all zeros."""
    msg = decode(rawdata, msgtype)
    return not any(
        getattr(getattr(msg, part), axis) for part in ('linear', 'angular') for axis in ('x', 'y', 'z')
    )


def _resolve_scenario(
    got: _Collected, run_dir: Path | None, fallback: Scenario | str | Path | None
) -> tuple[Scenario, str]:
    if got.scenario_text is not None:
        return scenario_from_yaml(
            got.scenario_text, source=f"the bag's {SCENARIO_TOPIC}"
        ), f'bag topic {SCENARIO_TOPIC}'
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
        raise AnalysisError(
            f"the bag's agents {list(first.agent_ids)} are not the scenario's {list(scenario.agent_ids)}"
        )
    if first.positions.shape[1] != scenario.dimension:
        raise AnalysisError(
            f"the bag's states have dimension {first.positions.shape[1]}, the scenario {scenario.dimension}"
        )
    if (first.velocities is None) != (scenario.dynamics == 'single'):
        raise AnalysisError(
            f"the bag's states {'lack' if first.velocities is None else 'carry'} velocities; the "
            f'scenario is {scenario.dynamics!r}'
        )
    if first.time == 0.0:
        start_velocities = initial_velocities(scenario.velocities, scenario.speed_scale)  # κ q(0)
        for k, agent in enumerate(scenario.agent_ids):
            if not np.array_equal(first.positions[k], scenario.positions[k]):
                raise AnalysisError(
                    f'agent {agent} starts at {first.positions[k].tolist()} in the bag but at '
                    f'{scenario.positions[k].tolist()} in the scenario {scenario.name!r}'
                )
            if start_velocities is not None and not np.array_equal(first.velocities[k], start_velocities[k]):
                raise AnalysisError(
                    f'agent {agent} starts with velocity {first.velocities[k].tolist()} in the bag but '
                    f'{start_velocities[k].tolist()} in the scenario {scenario.name!r} (at its speed scale)'
                )
    for sender, _ in got.infos:
        if sender not in scenario.agent_ids:
            raise AnalysisError(
                f'the bag has triggering information from agent {sender}, not an agent of {scenario.name!r}'
            )
    for (sender, _), receivers in got.infos.items():
        stray = set(receivers) - set(scenario.neighbours(sender))
        if stray:
            raise AnalysisError(
                f'the bag has messages {sender} -> {sorted(stray)}, which are not edges of {scenario.name!r}'
            )


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
    run_dir = None if run_dir is None else Path(run_dir)
    if not got.states and got.robots is not None:
        found, source = _resolve_scenario(got, run_dir, scenario)
        return _robot_run(bag, got, found, source)
    if not got.states:
        raise AnalysisError(
            f'{bag}: no {STATE_TOPIC} messages and no {ROBOTS_TOPIC} (a robot run): the trajectories '
            f'cannot be rebuilt (topics: {sorted(got.topics)})'
        )
    found, source = _resolve_scenario(got, run_dir, scenario)
    states = sorted(got.states, key=lambda state: state.time)  # stable: ties keep bag order
    _check_scenario_matches(found, got, states)
    checks = [_decoding_check(got)]
    times, positions, velocities, samples_check = _state_samples(states)
    checks.append(samples_check)
    trigger_times, triggers_check = _trigger_times(got, found)
    checks.append(triggers_check)

    steps = got.steps
    final = [step for step in steps if step.flags & STEP_FLAG_FINAL]
    realtime = any(step.flags & STEP_FLAG_REALTIME for step in steps)
    # The run ends at its final Step: at the horizon, or where it stopped early (the simulator
    # sends one then too); a bag without one ends where its recording did.
    horizon = final[-1].time if final else times[-1]
    asked = found.horizon if got.scenario_text is not None else None  # the run publishes its own horizon
    finished, stop = _ending(final, end=horizon, asked=asked)
    checks += _sampling_checks(times, trigger_times, horizon=horizon)
    checks += _message_checks(
        got, found, trigger_times, stopped=stop is not None, horizon=horizon, realtime=realtime
    )
    extra = _clock_extra(final, realtime=realtime, finished=finished, reached=times[-1]) if steps else {}
    if got.statuses and realtime:
        extra.update(_lateness(got.statuses, trigger_times))
    record = RunRecord(
        scenario=found,
        horizon=horizon,
        mode='distributed' if steps else 'recorded',
        trigger_times=trigger_times,
        samples=Samples.from_rows(times, positions, velocities or None),
        messages_sent=got.info_total,
        sensing_calls=(
            len(got.sensing) if SENSING_LOG_TOPIC in got.topics else sum(map(len, trigger_times.values()))
        ),
        wall_time=math.nan,  # not in a bag
        extra=extra,
    )
    return _bag_run(bag, got, record, source=source, checks=checks, asked=asked, stop=stop)


def _decoding_check(got: _Collected) -> Check:
    """Every formation message decoded as its layout says (the first ten problems named)."""
    return Check(
        name='decoding',
        ok=not got.problems,
        detail='; '.join(got.problems[:10]) or 'every formation message follows its layout',
    )


def _ending(final: list, *, end: float, asked: float | None) -> tuple[bool, dict[str, Any] | None]:
    """Whether a run that ended at `end` finished (a final Step at the horizon it was `asked`, if
    known), and else where it stopped: {time, step, horizon, final_step}."""
    finished = bool(final) and (asked is None or end == asked)
    stop = (
        None
        if finished
        else {
            'time': end,
            'step': final[-1].index if final else None,
            'horizon': asked,
            'final_step': bool(final),
        }
    )
    return finished, stop


def _sampling_checks(
    times: list[float], trigger_times: dict[int, list[float]], *, horizon: float
) -> list[Check]:
    """A state sample where the run ended (when it is not there) and one at every event time."""
    checks = []
    if times[-1] != horizon:
        checks.append(
            Check(
                name='final state',
                ok=False,
                detail=f'the last state is at t={times[-1]!r}, the run ended at t={horizon!r}',
            )
        )
    events = sorted({t for agent_times in trigger_times.values() for t in agent_times})
    sampled = set(times)
    unsampled = [t for t in events if t not in sampled]
    checks.append(
        Check(
            name='a state sample at every event',
            ok=not unsampled,
            detail=f'{len(events)} distinct event times'
            + (f'; without a sample: {unsampled[:5]}' if unsampled else ''),
        )
    )
    return checks


def _message_checks(
    got: _Collected,
    found: Scenario,
    trigger_times: dict[int, list[float]],
    *,
    stopped: bool,
    horizon: float,
    realtime: bool = False,
) -> list[Check]:
    """The sensing log, the commands and the agents' Status counters against the triggers, for
    whichever of them the bag holds.  On the wall clock an agent's last command may be its zero
    command as it leaves (`PlantOutput.stop`: every plant stops; issue 28: a clean --real-time run
    failed this check), one more than its triggers."""
    checks = []
    if SENSING_LOG_TOPIC in got.topics:
        checks.append(_sensing_check(got, found, trigger_times, stopped=stopped, horizon=horizon))
    if got.commands:
        differing = [
            agent
            for agent in found.agent_ids
            if got.commands.get(agent, 0) - len(trigger_times[agent])
            not in ((0, 1) if realtime and got.last_command_zero.get(agent, False) else (0,))
        ]
        checks.append(
            Check(
                name='one command per trigger',
                ok=not differing,
                detail='yes' if not differing else f'agents {differing}: commands {dict(got.commands)}',
            )
        )
    if got.statuses:
        checks.append(_status_check(got, {agent: len(times) for agent, times in trigger_times.items()}))
    return checks


def _bag_run(
    bag: Path,
    got: _Collected,
    record: RunRecord,
    *,
    source: str,
    checks: list[Check],
    asked: float | None,
    stop: dict[str, Any] | None,
) -> BagRun:
    return BagRun(
        bag=bag,
        record=record,
        scenario_source=source,
        topics=dict(got.topics),
        counts=dict(got.counts),
        checks=checks,
        horizon=asked,
        stop=stop,
    )


def _state_samples(states: list) -> tuple[list[float], list[np.ndarray], list[np.ndarray], Check]:
    """Samples: one per distinct time (a repeat of a time must repeat the state); that check."""
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
    check = Check(
        name='state samples',
        ok=not repeats,
        detail=f'{len(times)} samples'
        + (f'; different states at the same time {repeats[:5]}' if repeats else ''),
    )
    return times, positions, velocities, check


def _sensing_check(
    got, found: Scenario, trigger_times: dict[int, list[float]], *, stopped: bool, horizon: float
) -> Check:
    """The sensing log against the triggers: every trigger sensed once, at its time."""
    logged: dict[int, list[float]] = defaultdict(list)
    for agent, t in got.sensing:
        logged[agent].append(t)
    # A run that stopped early may have answered a sensing whose trigger the stop cut short.
    cut = {agent: sorted(logged.get(agent, [])) for agent in found.agent_ids}
    if stopped:
        cut = {
            agent: times[:-1]
            if times and times[-1] == horizon and times[:-1] == trigger_times[agent]
            else times
            for agent, times in cut.items()
        }
    differing = [agent for agent in found.agent_ids if cut[agent] != trigger_times[agent]]
    return Check(
        name='sensing log = triggers',
        ok=not differing,
        detail='every trigger sensed once at its time'
        if not differing
        else f'agents {differing} sensed at other times than they triggered',
    )


def _clock_extra(final: list, *, realtime: bool, finished: bool, reached: float) -> dict[str, Any]:
    """What a run with Steps says of its clock (RunRecord.extra)."""
    extra: dict[str, Any] = {'clock': 'realtime' if realtime else 'lockstep'}
    if finished and not realtime:
        extra['steps'] = final[-1].index  # lock-step: one Step per advance of the world
    extra['reached_time'] = reached  # the simulator samples the world where it stops
    if finished:
        extra['failure'] = None  # the run reached its horizon (why one stopped is not in a bag)
    return extra


def _lateness(statuses: dict[int, list], trigger_times: dict[int, list[float]]) -> dict[str, Any]:
    """Wall clock: trigger time - planned time per new trigger (Status.last_planned), as the coordinator
    computes it."""
    planned: dict[int, dict[int, float]] = {}
    for agent, reports in statuses.items():
        plans, seen = planned.setdefault(agent, {}), 0
        for status in reports:
            if status.triggers > seen:
                seen = status.triggers
                plans[seen] = status.last_planned
    return lateness_extra(planned, trigger_times)


def _trigger_times(got: _Collected, scenario: Scenario) -> tuple[dict[int, list[float]], Check]:
    """Triggering times from the TriggerInfo messages, and the check that each reached every neighbour
    once."""
    trigger_times: dict[int, list[float]] = {agent: [] for agent in scenario.agent_ids}
    missing, duplicated = [], []
    for (sender, stamp), receivers in got.infos.items():
        trigger_times[sender].append(stamp)
        expected = set(scenario.neighbours(sender))
        if len(receivers) != len(set(receivers)):
            duplicated.append(f'{sender} @ {stamp!r}')
        if set(receivers) != expected:
            missing.append(f'{sender} @ {stamp!r} -> {sorted(expected - set(receivers))}')
    for times in trigger_times.values():
        times.sort()
    check = Check(
        name='one TriggerInfo per neighbour per trigger',
        ok=not missing and not duplicated,
        detail=f'{got.info_total} messages for {sum(map(len, trigger_times.values()))} triggers'
        + (f'; missing: {missing[:5]}' if missing else '')
        + (f'; duplicated: {duplicated[:5]}' if duplicated else ''),
    )
    return trigger_times, check


def _status_check(got: _Collected, triggers: dict[int, int]) -> Check:
    """Every agent's last Status counts the triggers (`triggers`: per agent) and messages the bag holds."""
    sent: dict[int, int] = defaultdict(int)
    for (sender, _), receivers in got.infos.items():
        sent[sender] += len(receivers)
    # Counters only grow: the largest are the agent's final report.
    last = {
        agent: max(reports, key=lambda s: (s.info_sent, s.triggers))
        for agent, reports in got.statuses.items()
    }
    wrong = [
        f'agent {agent}: status says {status.triggers} triggers / {status.info_sent} sent, bag has '
        f'{triggers[agent]} / {sent[agent]}'
        for agent, status in last.items()
        if agent in triggers and (status.triggers != triggers[agent] or status.info_sent != sent[agent])
    ]
    return Check(
        name='status counters = bag',
        ok=not wrong,
        detail='; '.join(wrong) or "every agent's last Status counts what the bag holds",
    )


def _robot_poses(
    bag: Path,
    got: _Collected,
    scenario: Scenario,
    *,
    trajectory: str,
    model: str,
    distance: float,
    epoch: float,
) -> tuple[dict, Check]:
    """Every robot's samples (`RobotSample`) from its `trajectory` topic, in the bag's order, the
    poses the coordinator refuses left out as it leaves them out (`pose_sensing.pose_refusal`:
    not finite, stamped backwards, ahead of when the recorder got it, or a jump beyond the speed
    limit), and the check that counts them."""
    robots = got.robots or {}
    rules = {
        'ahead': float(robots.get('pose_ahead_tolerance', 0.1)),
        'max_speed': float(robots.get('max_linear_speed') or math.inf),
        'slack': float(robots.get('pose_jump_slack', 0.05)),
    }
    poses, refused = {}, Counter()
    for agent in scenario.agent_ids:
        poses[agent], latest = [], None
        for msgtype, rawdata, received in got.robot_messages.get((agent, trajectory), []):
            odometry = msgtype == 'nav_msgs/msg/Odometry'
            try:
                fields = (odometry_fields if odometry else pose_stamped_fields)(rawdata)
            except (MessageError, struct.error) as error:
                refused[getattr(error, 'reason', 'length')] += 1
                continue
            stamp = fields[0] + fields[1] * 1e-9
            twist = fields[3] if odometry else None
            now = epoch + received * 1e-9
            if refusal := pose_refusal(
                agent, stamp=stamp, pose=fields[2], twist=twist, now=now, latest=latest, **rules
            ):
                refused[refusal[0]] += 1
                continue
            latest = (stamp, tuple(fields[2][:3]))
            poses[agent].append(
                sample_from_fields(
                    *fields,
                    model=model,
                    dimension=scenario.dimension,
                    control_point_distance=distance,
                    epoch=epoch,
                )
            )
    missing = [agent for agent, samples in poses.items() if not samples]
    if missing:
        raise AnalysisError(
            f'{bag}: robots {missing} have no /agent_<i>/robot/{trajectory} messages the coordinator '
            f'would take (refused: {dict(refused)}): their trajectories cannot be rebuilt'
        )
    detail = (
        f'{sum(refused.values())} poses on /agent_<i>/robot/{trajectory} refused as the coordinator and '
        f'the agents refuse them, not sampled: {dict(sorted(refused.items()))}'
        if refused
        else 'every pose taken'
    )
    return poses, Check(name='robot poses', ok=True, detail=detail)


def _robot_run(bag: Path, got: _Collected, scenario: Scenario, source: str) -> BagRun:
    """A robot run rebuilt from its bag: trajectories from the pose topics (module docstring)."""
    robots = got.robots
    model, trajectory, distance, period = _robots_description(bag, robots)
    epoch = _robot_epoch(bag, got.steps)
    final = [step for step in got.steps if step.flags & STEP_FLAG_FINAL]
    checks = [_decoding_check(got)]
    poses, poses_check = _robot_poses(
        bag, got, scenario, trajectory=trajectory, model=model, distance=distance, epoch=epoch
    )
    checks.append(poses_check)
    if final:
        end = final[-1].time
    else:
        end = min(max(sample.time for sample in samples) for samples in poses.values())
        checks.append(
            Check(
                name='final step',
                ok=False,
                detail=f'no final {STEP_TOPIC} message: the run did not finish; taken to end at the last '
                f'pose, t={end!r}',
            )
        )
    # As the coordinator: no pose stamped long past the end, nor one of a robot silent at the end
    # (frozen, resumed later: held at its last pose before the end in both).
    silence = robots.get('pose_silence')
    tracks = {
        agent: PoseTrack.from_samples(poses_for_end(samples, end, silence=silence))
        for agent, samples in poses.items()
    }
    trigger_times, triggers_check = _trigger_times(got, scenario)
    all_counts = {agent: len(times) for agent, times in trigger_times.items()}
    # The coordinator counts the triggers up to where the run ended (and samples them).
    trigger_times = {agent: [t for t in times if t <= end] for agent, times in trigger_times.items()}
    checks.append(triggers_check)
    # A run that stopped early because a robot's poses stopped has none of it at its end: named,
    # not binding (summary.json holds its last pose there too); poses missing at t = 0 always are.
    stopped_early = bool(final) and got.scenario_text is not None and end != scenario.horizon
    checks.append(_coverage_check(tracks, trajectory=trajectory, end=end, stopped_early=stopped_early))
    checks.append(_last_commands_check(got, scenario))
    if got.statuses:
        checks.append(_status_check(got, all_counts))
    times = sample_times(end, period, [t for ts in trigger_times.values() for t in ts])
    positions, velocities = trajectory_samples(tracks, scenario.agent_ids, times)
    extra: dict[str, Any] = {'clock': 'realtime', 'reached_time': float(times[-1])}
    # As for the exact backend: the run publishes its own horizon, and a final Step before it
    # marks a run that stopped early (why it stopped is summary.json's).
    asked = scenario.horizon if got.scenario_text is not None else None
    finished, stop = _ending(final, end=end, asked=asked)
    if finished:
        extra['failure'] = None
    if got.statuses:
        extra.update(_lateness(got.statuses, trigger_times))
    extra.update(
        robots=robots, saturation=saturation_extra(got.reports.get(agent) for agent in scenario.agent_ids)
    )
    record = RunRecord(
        scenario=scenario,
        horizon=end,
        mode='robots',
        trigger_times=trigger_times,
        samples=Samples(
            times=times, positions=positions, velocities=velocities if scenario.dynamics == 'double' else None
        ),
        messages_sent=got.info_total,
        sensing_calls=sum(map(len, trigger_times.values())),
        wall_time=math.nan,
        extra=extra,
    )
    return _bag_run(bag, got, record, source=source, checks=checks, asked=asked, stop=stop)


def _robots_description(bag: Path, robots: Any) -> tuple[str, str, float, float]:
    """The robots' model, trajectory topic, control point distance and sample period, from the
    run's /formation/robots."""
    try:
        model, trajectory = robots['model'], robots['trajectory']
        distance, period = float(robots['control_point_distance']), float(robots['sample_period'])
    except (KeyError, TypeError, ValueError) as error:
        raise AnalysisError(
            f'{bag}: {ROBOTS_TOPIC} lacks {error} (model, trajectory, control_point_distance, sample_period)'
        ) from None
    return model, trajectory, distance, period


def _robot_epoch(bag: Path, steps: list) -> float:
    """The run's epoch, from its wall-clock Step 0."""
    start = [step for step in steps if step.index == 0 and step.flags & STEP_FLAG_REALTIME]
    if not start:
        raise AnalysisError(
            f'{bag}: no wall-clock Step 0 on {STEP_TOPIC}: the run never started, or its epoch is missing'
        )
    return start[0].epoch


def _coverage_check(
    tracks: dict[int, PoseTrack], *, trajectory: str, end: float, stopped_early: bool
) -> Check:
    """Every robot has poses from t = 0 to the end; a robot silent only at the end of a run that
    stopped early is named, not binding."""
    uncovered = [
        agent for agent, track in tracks.items() if not (track.times[0] <= 0.0 and track.times[-1] >= end)
    ]
    silent_at_end = [agent for agent in uncovered if tracks[agent].times[0] <= 0.0]
    return Check(
        name='poses cover the run',
        ok=not uncovered,
        detail=f'every robot has {trajectory} poses from before t = 0 to after t = {end!r}'
        if not uncovered
        else f'robots {uncovered} lack poses at the start or the end (their first or last pose is held '
        'there)',
        binding=not (stopped_early and uncovered == silent_at_end),
    )


def _last_commands_check(got: _Collected, scenario: Scenario) -> Check:
    """Every robot's last velocity command is a stop (what the agents send when they leave)."""
    moving, silent = [], []
    for agent in scenario.agent_ids:
        commands = got.robot_messages.get((agent, 'cmd_vel'))
        if not commands:
            silent.append(agent)
            continue
        msgtype, rawdata, _ = commands[-1]
        msg = decode(rawdata, msgtype)
        twist = msg.twist if msgtype == 'geometry_msgs/msg/TwistStamped' else msg
        values = [
            twist.linear.x,
            twist.linear.y,
            twist.linear.z,
            twist.angular.x,
            twist.angular.y,
            twist.angular.z,
        ]
        if any(values):
            moving.append(f'{agent}: {values}')
    detail = f'{len(scenario.agent_ids) - len(silent) - len(moving)} robots stopped by their last command'
    if moving:
        detail += f'; still moving: {moving[:5]}'
    if silent:
        detail += f'; no command recorded for robots {silent}'
    return Check(name="every robot's last command is a stop", ok=not moving and not silent, detail=detail)
