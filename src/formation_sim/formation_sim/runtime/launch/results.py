"""What a run leaves behind: the result of `FormationRun.run`, and the summary as the orchestrator
completes it (its view of a failure, a bag rebuilt when it was left unfinished, what the run
published against what its bag holds, a summary of what is known when the time keeper left none)."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.runtime.launch.backends import backend_kind
from formation_sim.runtime.launch.supervise import Child, describe_exit
from formation_sim.sim.summary import RunSummary, run_failure, summary_of, unstarted_summary

if TYPE_CHECKING:
    from formation_sim.analysis.accounting import RecordingCheck


@dataclass(frozen=True, kw_only=True)
class ChildExit:
    name: str
    pid: int
    returncode: int | None  # None: did not exit by itself and had to be stopped
    signal_used: str | None  # the last signal sent to stop it, if any
    left_with: int | None = None  # the status it left the run with, if its ROS teardown then hung (cut short)


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """What a run left behind and how it ended."""

    out_dir: Path
    summary: Path | None  # DIR/summary.json: complete, or partial when extra.failure is set
    bag: Path | None  # DIR/bag, None if not recorded or not readable
    # an ExitCode (formation_msgs_py.exit_codes): OK, FAILED, LOST (a process or agent lost), REFUSED
    # (the robots' start refused), STOPPED (an operator stopped the run: /formation/stop), INTERRUPTED
    exit_status: int
    domain_id: int
    wall_time: float
    children: tuple[ChildExit, ...] = ()
    message: str = ''
    failure: dict | None = None  # extra.failure of the summary (what failed, where, when)
    bag_recovered: bool = (
        False  # the bag was left unfinished and rebuilt by formation_sim.bag.recovery.reindex
    )
    phases: dict[str, float] = dataclasses.field(
        default_factory=dict
    )  # extra.phases: start, stepping, end [s]

    @property
    def ok(self) -> bool:
        return self.exit_status == 0


def lost_or_failed(child: Child) -> int:
    """ExitCode.FAILED for a child that left naming an error, ExitCode.LOST for one that died or vanished."""
    return ExitCode.FAILED if child.failed_itself else ExitCode.LOST


def first_lost(children: list[Child], keeper: Child) -> Child | None:
    """The first child besides the time keeper `keeper` whose exit (seen) stops the run: one that
    failed, or one that should have run until stopped."""
    return next(
        (
            c
            for c in children
            if c is not keeper
            and c.exited_at is not None
            and (c.process.returncode != 0 or not c.expected_exit)
        ),
        None,
    )


def detection_time(lost: Child, *, backend: str) -> float:
    """How long the time keeper may take to stop the run by itself after `lost` exited.

    Not an agent (a robot, the recorder): 0, everything stops now.  An agent that named its
    error: the time keeper stops the run as soon as the agent's final report comes
    (`backends.AGENT_REPORT_DETECTION`), naming the first cause (a robot whose poses stopped).  An agent
    killed on a robot run: 0, robots must not wait for a liveliness lease (the message names
    the dead agent's process).  Lock-step (`backend` exact): the keeper sees the lease lapse
    (`backends.LOST_DETECTION`).  Each kind of backend says its own (`backends.BackendKind`)."""
    if not lost.name.startswith('agent'):
        return 0.0
    kind = backend_kind(backend)
    return kind.agent_failed_detection if lost.failed_itself else kind.agent_killed_detection


def keeper_failed(code: int, keeper: Child, lost: Child | None) -> tuple[int, str]:
    """The time keeper exited with `code`, not 0: the run's exit status and message.  A status
    that names the first cause (failed, lost, refused) is the run's; else the child seen `lost`
    decides, or how the keeper ended (killed by a signal: lost)."""
    if code in (ExitCode.FAILED, ExitCode.LOST, ExitCode.REFUSED, ExitCode.STOPPED):
        status = code
    else:
        status = lost_or_failed(lost) if lost is not None else ExitCode.LOST if code < 0 else ExitCode.FAILED
    seen = '' if lost is None else f'{lost.describe()}; '
    return status, f'{seen}{keeper.name} (pid {keeper.pid}) {describe_exit(code)}; see {keeper.log}'


def recover_bag(bag: Path, *, recorder: Child | None) -> tuple[bool, str | None]:
    """A bag left unfinished (its recorder died, or could not write) is rebuilt from its MCAP file:
    (whether it was, what the run's message says of it)."""
    if not bag.is_dir():
        return False, None
    if recorder is not None and recorder.process.returncode == 0 and (bag / 'metadata.yaml').is_file():
        return False, None  # the recorder closed it and said so (it exits 0 only then)
    from formation_sim.bag.errors import BagError
    from formation_sim.bag.recovery import reindex

    died = recorder is not None and recorder.process.returncode not in (0, None)
    how = 'the recorder died: its bag' if died else 'the bag, left unfinished,'
    try:
        recovery = reindex(bag)
    except (BagError, OSError) as error:
        return False, f'{how} could not be recovered: {error}'
    if recovery.healthy:
        return False, None
    return True, f'{how} was recovered ({recovery.message_count} messages kept)'


def timeline(keeper: dict[str, float], marks: dict[str, float], *, started: float) -> dict[str, float]:
    """summary.json's extra.timeline: every mark of the run in seconds since `started` (the Unix
    time the run began), in order: the time keeper's (`keeper`, its extra.timestamps) and the
    orchestrator's (`marks`): prepare (negative: where the `formation` command began), spawned
    (every child started), keeper_exited, stopped (every child
    gone, the recorder last), checked (the bag checked against the summary)."""
    points = {name: at - started for name, at in {**keeper, **marks}.items() if isinstance(at, (int, float))}
    return dict(sorted(points.items(), key=lambda item: item[1]))


def phases(marks: dict[str, float]) -> dict[str, float]:
    """summary.json's extra.phases from its timeline: `prepare` (before the run's timeline begins
    at `run`: the `formation` command's imports, the scenario read and validated), `start` (spawn,
    imports, DDS participants, discovery: up to step 0), `stepping` (step 0 to the final step),
    `end` (final reports, acknowledgements, the summary, every process's exit, the bag closed and
    checked)."""
    spans = {
        'prepare': ('prepare', 'run'),
        'start': (None, 'step0'),
        'stepping': ('step0', 'final_step'),
        'end': ('final_step', 'checked'),
    }
    return {
        phase: marks[last] - (0.0 if first is None else marks[first])
        for phase, (first, last) in spans.items()
        if last in marks and (first is None or first in marks)
    }


def describe_phases(phases: dict[str, float]) -> str:
    """'start 1.2 s, stepping 0.9 s, end 0.5 s'."""
    return ', '.join(f'{phase} {seconds:.1f} s' for phase, seconds in phases.items())


def read_summary(path: Path) -> tuple[RunSummary | None, str | None]:
    """The time keeper's summary.json, or None (none, or unreadable: the note says why)."""
    if not path.is_file():
        return None, None
    try:
        return RunSummary.read(path), None
    except (OSError, ValueError) as error:
        return None, f'{path} could not be read ({error}): replaced by what the run knows'


def process_info(child: Child, *, launched: float) -> dict:
    """extra.failure.process: a child and how it ended (`launched`: the run's monotonic start)."""
    return {
        'name': child.name,
        'pid': child.pid,
        'returncode': child.process.returncode,
        'exit': describe_exit(child.process.returncode),
        'seconds_after_launch': (child.exited_at or time.monotonic()) - launched,
        'error': child.error_line(),
    }


def summary_of_what_is_known(
    keeper: Child,
    *,
    scenario,
    horizon: float,
    mode: str,
    bag: Path,
    run_dir: Path,
    status: int,
    last_progress: str,
    children: list[Child],
    launched: float,
) -> tuple[RunSummary, str | None]:
    """summary.json when the time keeper left none (killed hard, or it could not write): the
    failure, the last run time and step of its progress, the processes, and the run as far as
    the bag holds it (`formation_sim.analysis.load.load_bag_run`), or only the scenario without one;
    and a note when the bag could not be read."""
    progress = {
        key: float(value)
        for key, value in re.findall(r'\b(t|events|steps|wall)=([0-9.eE+-]+)', last_progress)
    }
    stopped_by_us = status == ExitCode.INTERRUPTED or keeper.signal_used is not None
    killed = keeper.process.returncode is None or keeper.process.returncode < 0
    failure = run_failure(
        'interrupted' if stopped_by_us else 'process_lost' if killed else 'process_failed',
        f'{keeper.name} (pid {keeper.pid}) {describe_exit(keeper.process.returncode)}',
        agents=[],
        time=progress.get('t'),  # its last progress line (once a second, 6 decimals)
        step=int(progress['steps']) if 'steps' in progress else None,
        wall_time=progress.get('wall'),
        detected_by='orchestrator',
        process=process_info(keeper, launched=launched),
    )
    data, note = None, None
    if (bag / 'metadata.yaml').is_file():
        from formation_sim.analysis.errors import AnalysisError
        from formation_sim.analysis.load import load_bag_run

        try:
            data = summary_of(load_bag_run(bag, run_dir=run_dir, scenario=scenario).record)
            data.wall_time = None
            source = f'orchestrator: the {keeper.name} left no summary; the run as far as its bag holds it'
        except (AnalysisError, ValueError) as error:
            note = f'the bag could not be read back: {error}'
    _latest_known(failure, progress, bag, reached=None if data is None else data.extra.get('reached_time'))
    if data is None:
        data = unstarted_summary(scenario, horizon=horizon, mode=mode, extra={})
        source = f'orchestrator: the {keeper.name} left no summary and there is no readable bag'
    data.extra.update(
        failure=failure,
        summary_source=source,
        processes={c.name: describe_exit(c.process.returncode) for c in children},
    )
    return data, note


def _latest_known(failure: dict, progress: dict, bag: Path, *, reached: float | None) -> None:
    """extra.failure's time and step: the latest the orchestrator knows (issue 28: a simulator
    killed past step 20 was recorded at t = 0.0, step null), from the time keeper's last progress
    line (once a second) and the bag (its last Step; `reached`: the run time its messages reach);
    None with `time_unknown` saying why when neither says."""
    times = [progress['t']] if 't' in progress else []
    steps = [int(progress['steps'])] if 'steps' in progress else []
    sources = ['its last progress line'] if times or steps else []
    last = _last_step(bag)
    if last is not None:
        times.append(last[1])
        steps.append(last[0])
        sources.append("the bag's last Step")
    if reached is not None and math.isfinite(reached):
        times.append(float(reached))
    failure['time'] = max(times) if times else None
    failure['step'] = max(steps) if steps else None
    if failure['time'] is None or failure['step'] is None:
        failure['time_unknown'] = (
            f'the {failure["message"].split(" ")[0]} printed no progress line and the bag holds no Step'
        )
    failure['time_from'] = ' and '.join(sources) or None


def _last_step(bag: Path) -> tuple[int, float] | None:
    """(index, time) of the last Step the bag holds, or None (no bag, no Step, unreadable)."""
    from formation_msgs_py.codec import decode_step
    from formation_msgs_py.errors import MessageError
    from formation_msgs_py.topics import STEP_TOPIC
    from formation_sim.bag.errors import BagError
    from formation_sim.bag.io import decode, read_bag

    last = None
    try:
        for message in read_bag(bag):
            if message.topic == STEP_TOPIC:
                with contextlib.suppress(MessageError, ValueError):
                    step = decode_step(decode(message.rawdata, message.msgtype))
                    if last is None or step.index >= last[0]:
                        last = (step.index, float(step.time))
    except BagError:
        return last
    return last


def annotate(
    data: RunSummary, lost: Child | None, status: int, message: str, *, launched: float
) -> dict | None:
    """Add the orchestrator's view of a failure to the summary's extra.failure; return it."""
    extra = data.extra
    failure = extra.get('failure')
    if failure is None and status == ExitCode.OK:
        return None
    if failure is None:  # the time keeper completed, but a child failed
        failure = run_failure('process_failed', message, agents=[], detected_by='orchestrator')
    if lost is not None:
        failure['process'] = process_info(lost, launched=launched)
        if failure['kind'] == 'interrupted':  # stopped by us because of that child: the first cause
            failure['kind'], failure['agents'] = _first_cause(lost)
            failure['message'] = lost.describe()
        elif failure['kind'] == 'agent_lost' and lost.failed_itself:
            failure['kind'] = 'agent_failed'
            failure['message'] = f'{lost.describe()}; {failure["message"]}'
        if 'orchestrator' not in failure['detected_by']:
            failure['detected_by'] += ', orchestrator'
    extra['failure'] = failure
    return failure


def excused_teardown(failed: list[Child]) -> tuple[list[Child], str]:
    """The children that left the run with status 0 and then hung in their ROS teardown (cut
    short: `Child.left_with`) are no failure of the run.  The others, and a note naming them."""
    excused = [c for c in failed if c.left_with() == 0]
    note = '; '.join(
        f'{c.name} left the run with status 0, then its ROS teardown hung in C code (rclpy) and '
        f'was cut short (stacks in {c.log})'
        for c in excused
    )
    return [c for c in failed if c not in excused], note


def excused_after_end(failed: list[Child], summary: Path) -> tuple[list[Child], str]:
    """After a run that reached its horizon: the agent processes that exited with an error the
    time keeper saw only after its final Step (summary.json `extra.after_end`: a pose gone stale
    past the end while the Step was on its way, the robot stopped by the agent's zero command) are
    no failure of the run.  The others, and a note naming the excused ones."""
    try:
        after_end = RunSummary.read(summary).extra.get('after_end') or {}
    except (OSError, ValueError):
        after_end = {}
    excused = [
        c for c in failed if c.name.startswith('agent_') and c.name.removeprefix('agent_') in after_end
    ]
    note = '; '.join(
        f'{c.name} stopped after the run reached its horizon (not a '
        f'failure of the run): {after_end[c.name.removeprefix("agent_")]}'
        for c in excused
    )
    return [c for c in failed if c not in excused], note


def _first_cause(child: Child) -> tuple[str, list[int]]:
    """extra.failure's kind and agents for a child that stopped the run: an agent's or a robot's
    own process (`agent_<i>`, `robot_<i>`) names the agent, any other a process."""
    kind, _, number = child.name.partition('_')
    if kind in ('agent', 'robot') and number.isdigit():
        if kind == 'robot':
            return 'robot_lost', [int(number)]
        return ('agent_failed' if child.failed_itself else 'agent_lost'), [int(number)]
    return ('process_failed' if child.failed_itself else 'process_lost'), []


def strangers(topics: dict[str, int], graph_file: Path, own_nodes: set[str], domain_id: int) -> str:
    """'; nodes outside the run wrote on them: /formation_replay (ROS domain 64)', as graph.json saw them."""
    try:
        graph = json.loads(graph_file.read_text(encoding='utf-8'))
    except (OSError, ValueError):
        graph = {}
    found = sorted(
        node
        for node, ends in graph.items()
        if node not in own_nodes and set(ends.get('publishers', ())) & set(topics)
    )
    return (
        f'; nodes outside the run wrote on them: {", ".join(found)} (ROS domain {domain_id})' if found else ''
    )


def check_recording(
    data: RunSummary, bag: Path, counted: set[str]
) -> tuple[RecordingCheck | None, str | None]:
    """What the run published on the `counted` topics (those its nodes count: not a robot's poses,
    nor the commands to it) against what its bag holds (extra.recording), None without a bag or
    counts; and what the run's message says of it (the bag not checked, messages uncounted)."""
    published = data.extra.get('published')
    if not published or not (bag / 'metadata.yaml').is_file():
        return None, None
    from formation_sim.analysis.accounting import check_recording as check

    published = {topic: n for topic, n in published.items() if topic in counted}
    try:
        result = check(published, bag)
    except Exception as error:  # noqa: BLE001 - rosbags raises several unrelated types
        return None, f'the bag could not be checked against what the run published: {error}'
    foreign = {topic: n for topic, n in result.foreign.items() if topic in counted}
    # An agent that died sent no final report: what it published is uncounted, not foreign (on
    # its own topics, and on the shared ones, where its messages cannot be told from others').
    missing = data.extra.get('reports_missing') or []
    note = None
    if missing:
        own = tuple(f'/agent_{agent}/' for agent in missing)
        uncounted = {
            topic: n
            for topic, n in foreign.items()
            if topic.startswith(own) or not topic.startswith('/agent_')
        }
        if uncounted:
            note = (
                f'{sum(uncounted.values())} messages in the bag are '
                f'uncounted: agents {missing} sent no final report '
                f'({", ".join(f"{topic} {n}" for topic, n in sorted(uncounted.items()))})'
            )
        foreign = {topic: n for topic, n in foreign.items() if topic not in uncounted}
    result = dataclasses.replace(result, foreign=foreign)
    data.extra['recording'] = result.to_dict()
    return result, note
