"""Start, watch and stop a formation run: its time keeper, agents, recorder and simulated robots.

```python
from formation_sim.runtime.launch.orchestrate import FormationRun
from formation_sim.runtime.launch.plan import RobotOptions

result = FormationRun('paper_single', out_dir='runs/demo', horizon=10.0).run()
turtlebots = RobotOptions(model='unicycle', max_linear_speed=0.22, max_angular_speed=2.84)
robots = FormationRun('robots_square', out_dir='runs/u', horizon=30.0, backend='unicycle',
                      robots=turtlebots).run()
print(result.summary, result.bag)
```

The pieces: `launch` (the backend's plan: domain, environment, inputs, processes), `supervise`
(children in their own process groups, stopped by PID; `fastdds_shm` for the shared-memory files
of the dead), `results` (what a run leaves).  The run ends when the time keeper (the simulator,
or the coordinator of a robot backend) reaches the horizon, when any child dies, or on
Ctrl-C/SIGTERM.  Children are then stopped (SIGINT, then SIGTERM, then SIGKILL after timeouts; the
recorder last) and the Fast DDS shared-memory files whose owners died are removed.  If the
orchestrator itself is killed, the kernel sends every child SIGTERM (PR_SET_PDEATHSIG), so nothing
is left running.

Fault policy (README, "Reliability"): a scenario that breaks the theorems' hypotheses starts
nothing (`formation_sim.model.validate.ValidationError`).  A child that dies stops the run: the
time keeper detects a lost agent or recorder itself within the DDS liveliness lease and stops
with a partial summary; this process sees any child exit within `POLL_PERIOD`, gives the time
keeper `backends.LOST_DETECTION` s to do so, then stops the rest (the recorder last).  The summary's
`extra.failure` names what failed and when (this process writes the summary itself if the time
keeper could not); a bag left unfinished is recovered (`formation_sim.bag.recovery.reindex`);
and the bag is checked against what the run published (`formation_sim.analysis.accounting`): a
run that lost messages fails, however it ended.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from formation_agent.ros.process import SignalFlag
from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.topics import (
    AGENT_NODE,
    COORDINATOR_NODE,
    RECORDER_NODE,
    ROBOT_NODE,
    SIMULATOR_NODE,
    agent_namespace,
)
from formation_sim.model.scenario import Scenario, load_scenario
from formation_sim.model.validate import require_valid
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.backends import BACKENDS, backend_kind
from formation_sim.runtime.launch.plan import (
    BAG_DIR,
    LOG_DIR,
    LaunchPlan,
    RobotOptions,
    free_udp_port,
    reserve_domain,
)
from formation_sim.runtime.launch.results import (
    ChildExit,
    RunResult,
    annotate,
    check_recording,
    describe_phases,
    detection_time,
    excused_after_end,
    excused_teardown,
    first_lost,
    keeper_failed,
    lost_or_failed,
    phases,
    read_summary,
    recover_bag,
    strangers,
    summary_of_what_is_known,
    timeline,
)
from formation_sim.runtime.launch.run_options import RunOptions
from formation_sim.runtime.launch.supervise import POLL_PERIOD, Child, Supervisor
from formation_sim.sim.errors import RunFolderError
from formation_sim.sim.run_folder import check_out_dir, claim_out_dir
from formation_sim.sim.summary import SUMMARY_FILE, RunSummary, run_failure

if TYPE_CHECKING:
    from formation_sim.analysis.accounting import RecordingCheck

__all__ = [
    'BACKENDS',
    'ChildExit',
    'FormationRun',
    'RobotOptions',
    'RunError',
    'RunOptions',
    'RunResult',
    'reserve_domain',
]

# What the last line of `formation run` says of a run that ended with these statuses besides 0.
OUTCOMES = {ExitCode.INTERRUPTED: 'stopped', ExitCode.STOPPED: 'stopped by the operator'}

# Where the children's Fast DDS files are looked for while they live (a look at /dev/shm; their
# memory maps only when it changed: supervise.Supervisor.note_shm_files), every this long [s].
SHM_SNAPSHOT_PERIOD = 0.2


def _process_started() -> float:
    """The Unix time the `formation` command's process started (its imports and checks before
    `FormationRun.run` belong to the run's start-up); for any other caller, now."""
    main = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else ''
    if main != 'formation' and not sys.argv[0].endswith(('formation_sim/cli.py', 'formation_sim.cli')):
        return time.time()
    try:
        fields = Path('/proc/self/stat').read_text().rsplit(')', 1)[1].split()
        boot = next(
            float(line.split()[1])
            for line in Path('/proc/stat').read_text().splitlines()
            if line.startswith('btime ')
        )
        return boot + int(fields[19]) / os.sysconf(
            'SC_CLK_TCK'
        )  # field 22, starttime, in clock ticks since boot
    except (OSError, ValueError, IndexError, StopIteration):
        return time.time()


class FormationRun:
    """One distributed run of a scenario: time keeper, agent processes, recorder (and robots)."""

    def __init__(
        self,
        scenario: Scenario | str | Path,
        *,
        out_dir: str | Path | None = None,
        force: bool = False,
        validate: bool = True,
        options: RunOptions | None = None,
        **fields,
    ) -> None:
        """Check everything that can be checked before any process starts or anything on disk changes.

        `out_dir`: a folder that is new or empty (`formation_sim.sim.run_folder`); None: a new
        folder under runs/ named after the scenario.  `force`: replace the earlier run in `out_dir`
        (its files are removed when the run starts).  `validate`: refuse a scenario that breaks the
        theorems' hypotheses (ValidationError); False only for experiments on purpose outside them.
        How it runs: `options` (`RunOptions`), and any of its fields as keywords over them
        (`FormationRun('paper_single', horizon=5.0)`); a name that is no option is a TypeError.
        """
        self._prepared_from = _process_started()  # the `formation` command's start, else now (extra.timeline)
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        if validate:
            require_valid(self.scenario)  # ValidationError names the rule, the edge or agent, the values
        self.options = dataclasses.replace(options or RunOptions(), **fields).check(self.scenario)
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.force = force
        if self.out_dir is not None:  # last: every other argument is refused before the folder is looked at
            try:
                check_out_dir(self.out_dir, force=force)
            except RunFolderError as error:
                raise RunError(str(error)) from None
        o = self.options
        self.plan = LaunchPlan(
            scenario=self.scenario,
            backend=o.backend,
            out_dir=self.out_dir,
            horizon=o.horizon,
            clock=o.clock,
            record=o.record,
            agents_per_process=o.agents_per_process,
            sample_period=o.sample_period,
            executor=o.executor,
            step_listeners=o.step_listeners,
            inject=o.inject,
            robots=o.robots,
            discovery=o.discovery,
            localhost_only=o.localhost_only,
        )
        self._supervisor: Supervisor | None = None
        self.removed_shm_files: list[str] = []
        self.marks: dict[str, float] = {}
        self._interrupted = SignalFlag()  # set in a signal handler: no lock (process.SignalFlag)
        self._started_at = 0.0

    def _environment(self, domain_id: int, processes: int | None = None) -> dict[str, str]:
        """The children's environment (launch.LaunchPlan.environment)."""
        return self.plan.environment(domain_id, extra_env=self.options.extra_env)

    @property
    def _children(self) -> list[Child]:
        return [] if self._supervisor is None else self._supervisor.children

    # -- running -------------------------------------------------------------------------------

    def run(self) -> RunResult:
        started = self._started_at = time.monotonic()
        # The orchestrator's marks of the run (Unix times; extra.timeline): 'prepare' is where the
        # command began (before run(): its imports, the scenario read and validated).
        self.marks = {'prepare': self._prepared_from, 'run': time.time()}
        lost: Child | None = None
        with reserve_domain(self.options.domain_id) as domain_id, signals_trapped(self._interrupted):
            try:  # the domain is ours: only now may the run folder change
                self.out_dir = claim_out_dir(
                    self.out_dir, scenario_name=self.scenario.name, kind='run', force=self.force
                )
            except RunFolderError as error:
                raise RunError(str(error)) from None
            port = free_udp_port(domain_id) if self.plan.discovery == 'server' else None
            self.plan = dataclasses.replace(self.plan, out_dir=self.out_dir, discovery_port=port)
            paths = self.plan.write_inputs()
            (self.out_dir / LOG_DIR).mkdir(exist_ok=True)
            self._supervisor = Supervisor(
                log_dir=self.out_dir / LOG_DIR,
                env=self._environment(domain_id),
                launch_prefix=self.options.launch_prefix,
            )
            watch = RunWatch(
                supervisor=self._supervisor,
                plan=self.plan,
                options=self.options,
                marks=self.marks,
                interrupted=self._interrupted,
            )
            try:
                status, message, lost = watch.until_end(paths)
            finally:
                self.removed_shm_files = self._supervisor.stop(
                    self.options.stop_timeouts,
                    domain_id=domain_id,
                    robots_after=robots_after(self.plan, lost),
                )
                self.marks['stopped'] = time.time()
        summary = self.out_dir / SUMMARY_FILE
        bag = self.out_dir / BAG_DIR
        recorder = next((c for c in self._children if c.name == 'recorder'), None)
        recovered, recovery = recover_bag(bag, recorder=recorder) if self.options.record else (False, None)
        status, failure, run_phases, notes = self._write_summary(status, message, lost, domain_id=domain_id)
        notes = [note for note in (recovery, *notes) if note]  # what the message adds after the failure
        if status == ExitCode.OK and not summary.is_file():
            status = ExitCode.FAILED
            message = message or f'the {self.plan.keeper} exited without writing {summary}'
        if failure is not None and status != ExitCode.INTERRUPTED and failure['message'] not in message:
            message = failure['message'] + (f'; {message}' if message else '')
        message = '; '.join([message, *notes] if message else notes)
        result = RunResult(
            out_dir=self.out_dir,
            summary=summary if summary.is_file() else None,
            bag=bag if (bag / 'metadata.yaml').is_file() else None,
            exit_status=status,
            domain_id=domain_id,
            wall_time=time.monotonic() - started,
            children=tuple(
                ChildExit(
                    name=c.name,
                    pid=c.pid,
                    returncode=c.process.returncode,
                    signal_used=c.signal_used,
                    left_with=c.left_with(),
                )
                for c in self._children
            ),
            message=message,
            failure=failure,
            bag_recovered=recovered,
            phases=run_phases,
        )
        if self.options.progress:
            outcome = 'done' if result.ok else OUTCOMES.get(status, 'FAILED')
            spent = f' ({describe_phases(run_phases)})' if run_phases else ''
            say(f'{outcome} in {result.wall_time:.1f} s{spent}: {message or self.last_progress}', end=True)
        return result

    def _write_summary(
        self, status: int, message: str, lost: Child | None, *, domain_id: int
    ) -> tuple[int, dict | None, dict[str, float], list[str]]:
        """summary.json as the run ended (the time keeper's, or what is known), with the failure, the
        recording's check, the timeline and `summary_extra`: (exit status, extra.failure, phases,
        what the message should add)."""
        summary = self.out_dir / SUMMARY_FILE
        bag = self.out_dir / BAG_DIR
        data, note = read_summary(summary)
        notes = [note] if note else []
        if data is None and 't=' in self.last_progress:  # it ran, and the time keeper left no summary
            keeper = next(c for c in self._children if c.name == self.plan.keeper)
            data, note = summary_of_what_is_known(
                keeper,
                scenario=self.scenario,
                horizon=self.options.horizon,
                mode=backend_kind(self.options.backend).mode,
                bag=bag,
                run_dir=self.out_dir,
                status=status,
                last_progress=self.last_progress,
                children=self._children,
                launched=self._started_at,
            )
            notes += [note] if note else []
        failure = None
        run_phases: dict[str, float] = {}
        if data is not None:
            failure = annotate(data, lost, status, message, launched=self._started_at)
            check, note = self._check_recording(data, bag)
            notes += [note] if note else []
            if check is not None and not check.complete:
                if failure is None:
                    failure = data.extra['failure'] = run_failure(
                        'recording_incomplete',
                        check.describe_missing(),
                        agents=[],
                        time=data.extra.get('reached_time'),
                        step=data.extra.get('steps'),
                        detected_by='orchestrator',
                    )
                    status = ExitCode.FAILED if status == ExitCode.OK else status
                elif status != ExitCode.INTERRUPTED:
                    notes.append(check.describe_missing())
            if check is not None and check.foreign and status != ExitCode.INTERRUPTED:
                notes.append(check.describe_foreign() + self._strangers(check.foreign, domain_id))
            self.marks['checked'] = time.time()
            extra = data.extra
            extra['timeline'] = timeline(extra.get('timestamps') or {}, self.marks, started=self.marks['run'])
            extra['phases'] = run_phases = phases(extra['timeline'])
            _add_extra(extra, self.options.summary_extra)
            try:
                data.write(summary)
            except OSError as error:
                summary.unlink(missing_ok=True)  # the time keeper's, without the failure: not to be believed
                notes.append(f'summary.json could not be written: {error}')
        return status, failure, run_phases, notes

    def _check_recording(self, data: RunSummary, bag: Path) -> tuple[RecordingCheck | None, str | None]:
        """What the run published against what its bag holds (extra.recording), None without a bag;
        and what the message says of it."""
        if not self.options.record:
            return None, None
        return check_recording(data, bag, self.plan.counted_topics())

    def _strangers(self, topics: dict[str, int], domain_id: int) -> str:
        """'; nodes outside the run wrote on them: …', as graph.json saw them."""
        from formation_sim.runtime.contract import GRAPH_FILE

        return strangers(topics, self.out_dir / GRAPH_FILE, own_nodes(self.scenario), domain_id)

    @property
    def last_progress(self) -> str:
        """The time keeper's latest progress line ('' before the first step)."""
        return '' if self._supervisor is None else self._supervisor.last_progress

    def interrupt(self) -> None:
        """Stop the run as Ctrl-C would (for callers on another thread)."""
        self._interrupted.set()


class RunWatch:
    """A run's processes, started in the plan's order and watched until the time keeper leaves:
    its exit status, a child lost, the timeout (the children's stacks asked for first) and Ctrl-C
    (`interrupted`).  `marks`: the orchestrator's marks, to which it adds when the children were
    spawned and when the keeper exited."""

    def __init__(
        self,
        *,
        supervisor: Supervisor,
        plan: LaunchPlan,
        options: RunOptions,
        marks: dict[str, float],
        interrupted: SignalFlag,
    ) -> None:
        self.supervisor, self.plan, self.options = supervisor, plan, options
        self.marks, self._interrupted = marks, interrupted

    def start(self, paths: dict[str, Path]) -> Child:
        """Every process of the plan, in its order; the time keeper's child."""
        supervisor = self.supervisor
        keeper = None
        for spec in self.plan.processes(paths):
            child = supervisor.start(spec)
            if spec.keeper:
                keeper = child
        self.marks['spawned'] = time.time()
        if self.options.progress:
            groups = len(self.plan.agent_groups())
            robots = sum(1 for c in supervisor.children if c.name.startswith('robot'))
            robots_text = f', {robots} robot process(es)' if robots else ''
            recorder = ', recorder' if self.options.record else ''
            server = (
                f', discovery server on port {self.plan.discovery_port}'
                if self.plan.discovery == 'server'
                else ''
            )
            say(
                f'ROS domain {supervisor.env["ROS_DOMAIN_ID"]}: {self.plan.keeper}, {groups} agent '
                f'process(es){robots_text}{recorder}{server} started; waiting for discovery'
            )
        if keeper is None:  # LaunchPlan.processes always starts one
            raise RunError(f'the launch plan started no time keeper: {[c.name for c in supervisor.children]}')
        return keeper

    def timed_out(self) -> str:
        """The timeout's message, once the children still running wrote their stacks to their logs
        (where each was stuck), before they are stopped."""
        running = [c for c in self.supervisor.children if c.alive() and c.name != 'discovery_server']
        asked = self.supervisor.ask_for_stacks()
        if not running:
            return f'timed out after {self.options.timeout} s'
        return f'timed out after {self.options.timeout} s; still running: ' + ', '.join(
            f'{c.name} (stacks in {c.log})' if c in asked else f'{c.name} (still starting: no stacks yet)'
            for c in running
        )

    def until_end(self, paths: dict[str, Path]) -> tuple[int, str, Child | None]:
        """Start the children and watch them: (exit status, message, the child that was lost)."""
        supervisor = self.supervisor
        keeper = self.start(paths)
        deadline = None if self.options.timeout is None else time.monotonic() + self.options.timeout
        shown = ''
        lost: Child | None = None
        next_snapshot = time.monotonic()  # the children's Fast DDS files, noted while they live
        while True:
            if self._interrupted.is_set():
                return ExitCode.INTERRUPTED, 'interrupted', lost
            now = time.monotonic()
            if deadline is not None and now > deadline:
                return ExitCode.FAILED, self.timed_out(), lost
            if self.options.progress and supervisor.last_progress != shown:
                shown = supervisor.last_progress
                say(shown)
            supervisor.note_exits(now)
            if now >= next_snapshot:
                supervisor.note_shm_files(now)
                next_snapshot = now + SHM_SNAPSHOT_PERIOD
            code = keeper.process.poll()
            if code is not None:
                self.marks['keeper_exited'] = time.time()
                if code == 0 or keeper.left_with() == 0:  # its ROS teardown may hang after the end
                    failed = supervisor.wait_for_expected(self.options.stop_timeouts[0], besides=keeper)
                    failed, hung = excused_teardown(failed + ([keeper] if code else []))
                    failed, after_end = excused_after_end(failed, self.plan.out_dir / SUMMARY_FILE)
                    after_end = '; '.join(note for note in (after_end, hung) if note)
                    if not failed:
                        return ExitCode.OK, after_end, lost
                    # The time keeper reached the end, but a process that should have left
                    # cleanly did not (an agent that stopped on an error near the horizon).
                    return ExitCode.FAILED, '; '.join(child.describe() for child in failed), lost or failed[0]
                return (*keeper_failed(code, keeper, lost), lost)
            if lost is None:
                lost = first_lost(supervisor.children, keeper)
                if lost is not None and self.options.progress:
                    say(f'{lost.describe()}; stopping the run')
            if lost is not None and now - lost.exited_at > detection_time(lost, backend=self.options.backend):
                # The time keeper has had the time to detect it and stop by itself.
                return lost_or_failed(lost), f'{lost.describe()}; see {lost.log}', lost
            time.sleep(POLL_PERIOD)


def robots_after(plan: LaunchPlan, lost: Child | None) -> float:
    """How long the simulated robots run on after the stop began: a robot whose agent died
    without its zero command stops on its command timeout, and the bag shows it."""
    if lost is None or not lost.name.startswith('agent') or not plan.simulated_robots:
        return 0.0
    return plan.robots.command_timeout + 0.3  # and a few of its ticks


def own_nodes(scenario: Scenario) -> set[str]:
    """The names of every node a run of `scenario` may have (graph.json's keys)."""
    own = {f'/{SIMULATOR_NODE}', f'/{COORDINATOR_NODE}', f'/{RECORDER_NODE}'}
    for i in scenario.agent_ids:
        own |= {f'{agent_namespace(i)}/{AGENT_NODE}', f'{agent_namespace(i)}/{ROBOT_NODE}'}
    return own


@contextlib.contextmanager
def signals_trapped(flag: SignalFlag) -> Iterator[None]:
    """Ctrl-C and SIGTERM set `flag`: the run stops cleanly (only possible from the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {
        sig: signal.signal(sig, lambda signum, frame: flag.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def say(text: str, *, end: bool = False) -> None:
    """A progress line of `formation run` on stderr (on a terminal, over the previous one)."""
    stream = sys.stderr
    if stream.isatty():
        stream.write(f'\r\033[K[formation run] {text}' + ('\n' if end else ''))
    else:
        stream.write(f'[formation run] {text}\n')
    stream.flush()


def _add_extra(extra: dict, more) -> None:
    """summary.json's extra with `more` (the command's: the speed's choice, the safety layer's
    origins): a dict adds to the run's own entry of that name (extra.safety), anything else replaces it."""
    for key, value in more.items():
        mine = extra.get(key)
        extra[key] = {**mine, **value} if isinstance(mine, dict) and isinstance(value, dict) else value
