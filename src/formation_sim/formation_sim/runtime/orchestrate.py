"""Start, watch and stop a distributed formation run: simulator, agents and recorder processes.

```python
from formation_sim.runtime.orchestrate import FormationRun

result = FormationRun('paper_single', out_dir='runs/demo', horizon=10.0).run()
print(result.summary, result.bag)
```

Every child runs in its own process group and session, in a private ROS domain limited to this
machine (unless `localhost_only=False`); the run ends when the simulator reaches the horizon, when
any child dies, or on Ctrl-C/SIGTERM.  Children are then stopped by PID (SIGINT, then SIGTERM,
then SIGKILL after timeouts), and the Fast DDS shared-memory files of any child killed hard are
removed.  If the orchestrator itself is killed, the kernel sends every child SIGTERM
(PR_SET_PDEATHSIG), so nothing is left running.

Fault policy (README, "Reliability"): a scenario that breaks the theorems' hypotheses starts
nothing (`formation_sim.model.validate.ValidationError`).  A child that dies stops the run: the
simulator detects a lost agent or recorder itself within the DDS liveliness lease and stops with
a partial summary; this process sees any child exit within `POLL_PERIOD`, gives the simulator
`LOST_DETECTION` s to do so, then stops the rest (the recorder last).  The summary's
`extra.failure` names what failed and when (this process writes the summary itself if the
simulator could not); a bag left unfinished is recovered (`formation_sim.bag.recovery.reindex`);
and the bag is checked against what the run published (`formation_sim.analysis.accounting`): a
run that lost messages fails, however it ended.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import importlib.util
import json
import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from formation_sim.model.scenario import Scenario, dump_scenario, load_scenario
from formation_sim.model.validate import require_valid
from formation_sim.sim.engine import EngineError, check_sample_dt
from formation_sim.sim.run_folder import RunFolderError, check_out_dir, claim_out_dir
from formation_sim.runtime.fastdds_shm import domain_port_files, held_files, remove_orphans

DOMAIN_RANGE = (100, 232)  # ids whose Fast DDS ports all fit below 65536
MANY_PROCESSES = 30  # beyond this, shared-memory transport segments cost more than they bring
SCENARIO_FILE = 'scenario.yaml'
SUMMARY_FILE = 'summary.json'
BAG_DIR = 'bag'
LOG_DIR = 'logs'
PROGRESS_PREFIX = 'progress '
POLL_PERIOD = 0.05  # how often the orchestrator looks at its children [s]
FASTDDS_PROFILE = Path(__file__).with_name('fastdds_profile.xml')  # the children's Fast DDS settings

# Exit statuses of a run (and of `formation run`; 2 is bad input, refused before anything starts).
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_LOST = 3  # a process of the run died or an agent was lost
EXIT_INTERRUPTED = 130

INJECT_KEYS = ('loss', 'delay_ms', 'jitter_ms', 'seed')

# How long the simulator may take to notice a lost agent by itself: the DDS liveliness lease, its
# grace, one 0.1 s tick, and margin for a loaded machine (formation_agent.ros.node.LIVELINESS_LEASE).
LOST_DETECTION = 1.0 + 0.5 + 0.1 + 2.0


class RunError(RuntimeError):
    """The run could not be set up (bad arguments, no free ROS domain, an output folder in use)."""


@dataclass(frozen=True, kw_only=True)
class ChildExit:
    name: str
    pid: int
    returncode: int | None  # None: did not exit by itself and had to be stopped
    signal_used: str | None  # the last signal sent to stop it, if any


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """What a run left behind and how it ended."""

    out_dir: Path
    summary: Path | None  # DIR/summary.json: complete, or partial when extra.failure is set
    bag: Path | None  # DIR/bag, None if not recorded or not readable
    exit_status: int  # EXIT_OK 0; EXIT_FAILED 1; EXIT_LOST 3 a process or agent lost; 130 interrupted
    domain_id: int
    wall_time: float
    children: tuple[ChildExit, ...] = ()
    message: str = ''
    failure: dict | None = None  # extra.failure of the summary (what failed, where, when)
    bag_recovered: bool = False  # the bag was left unfinished and rebuilt by formation_sim.bag.recovery.reindex

    @property
    def ok(self) -> bool:
        return self.exit_status == 0


# -- ROS domain -------------------------------------------------------------------------------


def _domain_ports(domain_id: int) -> tuple[int, int]:
    """Fast DDS unicast ports of participant 0 in `domain_id` (RTPS port mapping)."""
    base = 7400 + 250 * domain_id
    return base + 10, base + 11


def _ports_free(domain_id: int) -> bool:
    for port in _domain_ports(domain_id):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(('', port))
            except OSError:
                return False
    return True


@contextlib.contextmanager
def reserve_domain(domain_id: int | None = None, *, lock_dir: Path | None = None) -> Iterator[int]:
    """Hold a ROS domain id for the duration of the block (a lock file; the ports unused).

    With `domain_id` the caller pins the id; it is still locked against other runs.
    """
    lock_dir = lock_dir or Path('/tmp/formation_domains')
    lock_dir.mkdir(parents=True, exist_ok=True)
    low, high = DOMAIN_RANGE
    if domain_id is not None:
        if not 0 <= domain_id <= high:
            raise RunError(f'domain id must lie in [0, {high}], got {domain_id}')
        candidates = [domain_id]
    else:
        candidates = list(range(low, high + 1))
        start = random.randrange(len(candidates))
        candidates = candidates[start:] + candidates[:start]
    for candidate in candidates:
        handle = open(lock_dir / f'{candidate}.lock', 'w')  # noqa: SIM115 - held while running
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        if domain_id is None and not _ports_free(candidate):
            handle.close()
            continue
        try:
            yield candidate
        finally:
            handle.close()
        return
    if domain_id is not None:
        raise RunError(f'ROS domain {domain_id} is held by another formation run')
    raise RunError(f'no free ROS domain in {low}-{high}')


# -- processes --------------------------------------------------------------------------------


try:  # looked up here, not in the forked child (a child before exec must take no lock)
    _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # pragma: no cover - not Linux
    _PRCTL = None
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the orchestrator dies, even by SIGKILL (Linux)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


def describe_exit(returncode: int | None) -> str:
    if returncode is None:
        return 'still running'
    if returncode < 0:
        with contextlib.suppress(ValueError):
            return f'killed by {signal.Signals(-returncode).name}'
    return f'exited with status {returncode}'


def _lost_or_failed(child: _Child) -> int:
    """EXIT_FAILED for a child that left naming an error, EXIT_LOST for one that died or vanished."""
    return EXIT_FAILED if (child.process.returncode or 0) > 0 else EXIT_LOST


@dataclass
class _Child:
    name: str
    process: subprocess.Popen
    log: Path
    expected_exit: bool  # leaves by itself when the run completes
    signal_used: str | None = None
    shm_files: set[str] = field(default_factory=set)
    exited_at: float | None = None  # monotonic time its exit was seen

    @property
    def pid(self) -> int:
        return self.process.pid

    def alive(self) -> bool:
        return self.process.poll() is None

    def error_line(self) -> str:
        """The error the child named on its way out (its last 'formation_...: ' line), or ''."""
        try:
            with self.log.open('rb') as handle:
                handle.seek(max(0, self.log.stat().st_size - 65536))
                lines = handle.read().decode(errors='replace').splitlines()
        except OSError:
            return ''
        named = [line for line in lines if line.startswith(('formation_agent: ', 'formation_sim: ', 'formation_recorder: '))]
        return named[-1].split(': ', 1)[1] if named else ''

    def describe(self) -> str:
        """'agent_2 (pid 123) killed by SIGKILL', with the error it named if it gave one."""
        text = f'{self.name} (pid {self.pid}) {describe_exit(self.process.returncode)}'
        error = self.error_line() if self.process.returncode not in (None, 0) else ''
        return f'{text}: {error}' if error else text


class FormationRun:
    """One distributed run of a scenario: simulator, agent processes and recorder."""

    def __init__(
        self,
        scenario: Scenario | str | Path,
        *,
        out_dir: str | Path | None = None,
        force: bool = False,
        horizon: float | None = None,
        domain_id: int | None = None,
        agents_per_process: int = 1,
        record: bool = True,
        localhost_only: bool = True,
        progress: bool = True,
        sample_period: float = 0.01,
        timeout: float | None = None,
        clock: str = 'lockstep',
        executor: str = 'events',
        stop_timeouts: tuple[float, float] = (5.0, 3.0),
        validate: bool = True,
        inject: dict[str, float] | None = None,
        launch_prefix: Callable[[str], Sequence[str]] | None = None,
        extra_env: dict[str, str] | None = None,
        step_listeners: int = 0,
    ) -> None:
        """Check everything that can be checked before any process starts or anything on disk changes.

        `out_dir`: a folder that is new or empty (`formation_sim.sim.run_folder`); None: a new folder
        under runs/ named after the scenario.  `force`: replace the earlier run in `out_dir` (its
        files are removed when the run starts).  `validate`: refuse a scenario that breaks the theorems' hypotheses (ValidationError);
        False only for experiments on purpose outside them.  `inject`: fault injection on the
        agents' arriving triggering information, keys `loss` (probability), `delay_ms`,
        `jitter_ms`, `seed` (a test facility; loss needs clock='realtime').  `launch_prefix`:
        child name ('simulator', 'recorder', 'agent_<i>' or 'agents_<i>-<j>') -> command put
        before its python, e.g. ['ip', 'netns', 'exec', 'host1'] to run it on another network
        stack.  `extra_env`: variables set for every child (e.g. FASTDDS_BUILTIN_TRANSPORTS).
        `executor`: the rclpy executor of the simulator and agent processes, 'events'
        (rclpy.experimental.EventsExecutor) or 'single' (SingleThreadedExecutor).
        `step_listeners`: nodes outside the run (a live monitor, a test's fault injector) that
        must hear every Step: step 0 waits until that many more readers of it are matched.
        """
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        if validate:
            require_valid(self.scenario)  # ValidationError names the rule, the edge or agent, the values
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.force = force
        self.horizon = float(self.scenario.horizon if horizon is None else horizon)
        if not (math.isfinite(self.horizon) and self.horizon >= sys.float_info.min):
            # (the smallest normal double: a ROS parameter file cannot carry a subnormal one)
            raise RunError(f'horizon must be a finite number > 0, got {self.horizon!r}')
        if domain_id is not None and not (isinstance(domain_id, int) and 0 <= domain_id <= DOMAIN_RANGE[1]):
            raise RunError(f'domain id must lie in [0, {DOMAIN_RANGE[1]}], got {domain_id!r}')
        try:
            check_sample_dt(sample_period, horizon=self.horizon, scenario=self.scenario)
        except EngineError as error:
            raise RunError(f'sample_period: {error}') from None
        if timeout is not None and not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0.0):
            raise RunError(f'timeout must be a finite number of seconds > 0, got {timeout!r}')
        if agents_per_process < 1:
            raise RunError(f'agents_per_process must be >= 1, got {agents_per_process}')
        if self.scenario.dimension > 3:
            raise RunError(f'distributed runs need p <= 3 (geometry_msgs commands), got p = {self.scenario.dimension}')
        if clock not in ('lockstep', 'realtime'):
            raise RunError(f"clock must be 'lockstep' (sim time, exact) or 'realtime' (wall clock), got {clock!r}")
        self.clock = clock
        from formation_agent.ros.process import EXECUTORS

        if executor not in EXECUTORS:
            raise RunError(f'executor must be one of {EXECUTORS}, got {executor!r}')
        self.executor = executor
        self.inject = dict(inject or {})
        if unknown := set(self.inject) - set(INJECT_KEYS):
            raise RunError(f'inject: unknown keys {sorted(unknown)} (known: {list(INJECT_KEYS)})')
        for key, value in self.inject.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise RunError(f'inject: {key} must be a finite number >= 0, got {value!r}')
        if self.inject.get('loss', 0.0) > 1.0:
            raise RunError(f'inject: loss is a probability in [0, 1], got {self.inject["loss"]!r}')
        if self.inject.get('loss', 0.0) > 0.0 and clock != 'realtime':
            raise RunError(
                'inject: loss needs the wall clock (clock=realtime, --real-time): lock-step waits for '
                'every message sent, so a dropped one stalls the run'
            )
        if step_listeners < 0:
            raise RunError(f'step_listeners must be >= 0, got {step_listeners}')
        self.step_listeners = step_listeners
        if self.out_dir is not None:  # last: every other argument is refused before the folder is looked at
            try:
                check_out_dir(self.out_dir, force=force)
            except RunFolderError as error:
                raise RunError(str(error)) from None
        self.launch_prefix = launch_prefix
        self.extra_env = dict(extra_env or {})
        self.domain_id = domain_id
        self.agents_per_process = agents_per_process
        self.record = record
        self.localhost_only = localhost_only
        self.progress = progress
        self.sample_period = sample_period
        self.timeout = timeout
        self.stop_timeouts = stop_timeouts
        self._children: list[_Child] = []
        self.removed_shm_files: list[str] = []
        self._interrupted = threading.Event()
        self._last_progress = ''
        self._started_at = 0.0

    # -- files ---------------------------------------------------------------------------------

    def _agent_groups(self) -> list[list[int]]:
        ids = list(self.scenario.agent_ids)
        k = self.agents_per_process
        return [ids[start : start + k] for start in range(0, len(ids), k)]

    def _write_inputs(self) -> dict[str, Path]:
        from formation_agent.ros.node import NODE_NAME
        from formation_msgs_py.topics import agent_namespace
        from formation_sim.runtime.sim_node import agent_parameters, formation_topics

        out = self.out_dir
        (out / LOG_DIR).mkdir(parents=True, exist_ok=True)
        scenario_path = out / SCENARIO_FILE
        dump_scenario(self.scenario, scenario_path)  # every float kept bit for bit
        extra = 1 if self.record else 0
        injected = {
            f'inject_{key}': (int(value) if key == 'seed' else float(value)) for key, value in self.inject.items()
        }
        agents = {
            f'{agent_namespace(i)}/{NODE_NAME}': {
                'ros__parameters': {
                    **agent_parameters(self.scenario, i, horizon=self.horizon, extra_subscribers=extra),
                    **injected,
                }
            }
            for i in self.scenario.agent_ids
        }
        agents_path = out / 'agents.params.yaml'
        agents_path.write_text(yaml.safe_dump(agents, sort_keys=False), encoding='utf-8')
        paths = {'scenario': scenario_path, 'agents': agents_path}
        if self.record:
            recorder = {
                '/formation_recorder': {
                    'ros__parameters': {
                        'output': str((out / BAG_DIR).resolve()),
                        'topics': [f'{name}:{msgtype}' for name, msgtype in formation_topics(self.scenario)],
                    }
                }
            }
            paths['recorder'] = out / 'recorder.params.yaml'
            paths['recorder'].write_text(yaml.safe_dump(recorder, sort_keys=False), encoding='utf-8')
        return paths

    def _environment(self, domain_id: int, processes: int) -> dict[str, str]:
        env = dict(os.environ)
        env['ROS_DOMAIN_ID'] = str(domain_id)
        env['ROS_LOG_DIR'] = str((self.out_dir / LOG_DIR / 'ros').resolve())
        env['RMW_IMPLEMENTATION'] = 'rmw_fastrtps_cpp'
        env['PYTHONUNBUFFERED'] = '1'
        if self.localhost_only:
            env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        else:
            env.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)  # Jazzy's default: SUBNET
        if processes > MANY_PROCESSES:
            env['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
        env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(FASTDDS_PROFILE))  # a user's own file wins
        env.update(self.extra_env)
        # Children find these packages the way this process did.
        here = [
            str(Path(next(iter(importlib.util.find_spec(name).submodule_search_locations))).resolve().parent)
            for name in ('formation_msgs_py', 'formation_agent', 'formation_sim')
        ]
        env['PYTHONPATH'] = os.pathsep.join(dict.fromkeys(here + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p]))
        return env

    def _start(self, name: str, args: list[str], env: dict[str, str], *, expected_exit: bool, pipe: bool = False) -> _Child:
        log = self.out_dir / LOG_DIR / f'{name}.log'
        handle = open(log, 'w', encoding='utf-8')  # noqa: SIM115 - owned by the child
        prefix = list(self.launch_prefix(name)) if self.launch_prefix is not None else []
        process = subprocess.Popen(
            [*prefix, sys.executable, *args],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE if pipe else handle,
            stderr=handle,
            start_new_session=True,  # own process group: a terminal's Ctrl-C reaches only us
            preexec_fn=_die_with_parent,  # noqa: PLW1509 - only prctl, no locks taken
            text=True,
        )
        child = _Child(name=name, process=process, log=log, expected_exit=expected_exit)
        if pipe:
            threading.Thread(target=self._pump, args=(child, handle), daemon=True).start()
        self._children.append(child)
        return child

    def _pump(self, child: _Child, handle) -> None:
        """Copy the simulator's stdout into its log; keep its progress lines for the terminal."""
        for line in child.process.stdout:
            with contextlib.suppress(OSError):  # a full disk: keep reading, or the child blocks on the pipe
                handle.write(line)
                handle.flush()
            if line.startswith(PROGRESS_PREFIX):
                self._last_progress = line[len(PROGRESS_PREFIX) :].strip()

    # -- running -------------------------------------------------------------------------------

    def run(self) -> RunResult:
        started = self._started_at = time.monotonic()
        lost: _Child | None = None
        with reserve_domain(self.domain_id) as domain_id, self._signals_trapped():
            try:  # the domain is ours: only now may the run folder change
                self.out_dir = claim_out_dir(self.out_dir, scenario_name=self.scenario.name, kind='run', force=self.force)
            except RunFolderError as error:
                raise RunError(str(error)) from None
            paths = self._write_inputs()
            groups = self._agent_groups()
            env = self._environment(domain_id, len(groups) + 1 + int(self.record))
            try:
                status, message, lost = self._launch_and_watch(paths, groups, env)
            finally:
                self._stop_all(domain_id)
        summary = self.out_dir / SUMMARY_FILE
        bag = self.out_dir / BAG_DIR
        notes: list[str] = []  # what the message adds after the failure
        recovered = self._recover_bag(bag, notes) if self.record else False
        data = self._read_summary(summary, notes)
        if data is None and 't=' in self._last_progress:  # it ran, and the simulator left no summary
            data = self._summary_of_what_is_known(bag, status, notes)
        failure = None
        if data is not None:
            failure = self._annotate(data, lost, status, message)
            check = self._check_recording(data, bag, notes)
            if check is not None and not check.complete:
                if failure is None:
                    failure = data['extra']['failure'] = {
                        'kind': 'recording_incomplete',
                        'message': check.describe_missing(),
                        'agents': [],
                        'time': data['extra'].get('reached_time'),
                        'step': data['extra'].get('steps'),
                        'detected_by': 'orchestrator',
                    }
                    status = EXIT_FAILED if status == EXIT_OK else status
                elif status != EXIT_INTERRUPTED:
                    notes.append(check.describe_missing())
            if check is not None and check.foreign and status != EXIT_INTERRUPTED:
                notes.append(check.describe_foreign() + self._strangers(check.foreign, domain_id))
            from formation_sim.sim.summary import write_summary_file

            try:
                write_summary_file(data, summary)
            except OSError as error:
                summary.unlink(missing_ok=True)  # the simulator's, without the failure: not to be believed
                notes.append(f'summary.json could not be written: {error}')
        if status == EXIT_OK and not summary.is_file():
            status = EXIT_FAILED
            message = message or f'the simulator exited without writing {summary}'
        if failure is not None and status != EXIT_INTERRUPTED and failure['message'] not in message:
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
                ChildExit(name=c.name, pid=c.pid, returncode=c.process.returncode, signal_used=c.signal_used)
                for c in self._children
            ),
            message=message,
            failure=failure,
            bag_recovered=recovered,
        )
        if self.progress:
            outcome = 'done' if result.ok else 'stopped' if status == EXIT_INTERRUPTED else 'FAILED'
            self._say(f'{outcome} in {result.wall_time:.1f} s: {message or self._last_progress}', end=True)
        return result

    def _recover_bag(self, bag: Path, notes: list[str]) -> bool:
        """A bag left unfinished (its recorder died, or could not write) is rebuilt from its MCAP file."""
        if not bag.is_dir():
            return False
        from formation_sim.bag.io import BagError
        from formation_sim.bag.recovery import reindex

        recorder = next((c for c in self._children if c.name == 'recorder'), None)
        died = recorder is not None and recorder.process.returncode not in (0, None)
        how = 'the recorder died: its bag' if died else 'the bag, left unfinished,'
        try:
            recovery = reindex(bag)
        except (BagError, OSError) as error:
            notes.append(f'{how} could not be recovered: {error}')
            return False
        if recovery.healthy:
            return False
        notes.append(f'{how} was recovered ({recovery.message_count} messages kept)')
        return True

    def _read_summary(self, path: Path, notes: list[str]) -> dict | None:
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError) as error:
            notes.append(f'{path} could not be read ({error}): replaced by what the run knows')
            return None

    def _process_info(self, child: _Child) -> dict:
        return {
            'name': child.name,
            'pid': child.pid,
            'returncode': child.process.returncode,
            'exit': describe_exit(child.process.returncode),
            'seconds_after_launch': (child.exited_at or time.monotonic()) - self._started_at,
            'error': child.error_line(),
        }

    def _summary_of_what_is_known(self, bag: Path, status: int, notes: list[str]) -> dict:
        """summary.json when the simulator left none (killed hard, or it could not write): the
        failure, the last sim time and step of its progress, the processes, and the run as far as
        the bag holds it (`formation_sim.analysis.load.load_bag_run`), or only the scenario without one."""
        from formation_sim.sim.summary import SCHEMA, build_summary

        simulator = next(c for c in self._children if c.name == 'simulator')
        progress = {key: float(value) for key, value in re.findall(r'\b(t|events|steps|wall)=([0-9.eE+-]+)', self._last_progress)}
        stopped_by_us = status == EXIT_INTERRUPTED or simulator.signal_used is not None
        killed = simulator.process.returncode is None or simulator.process.returncode < 0
        failure = {
            'kind': 'interrupted' if stopped_by_us else 'process_lost' if killed else 'process_failed',
            'message': f'simulator (pid {simulator.pid}) {describe_exit(simulator.process.returncode)}',
            'agents': [],
            'time': progress.get('t'),  # its last progress line (once a second, 6 decimals)
            'step': int(progress['steps']) if 'steps' in progress else None,
            'wall_time': progress.get('wall'),
            'detected_by': 'orchestrator',
            'process': self._process_info(simulator),
        }
        scenario = self.scenario
        data = None
        if (bag / 'metadata.yaml').is_file():
            from formation_sim.analysis.load import AnalysisError, load_bag_run

            try:
                data = build_summary(load_bag_run(bag, run_dir=self.out_dir, scenario=scenario).record)
                data['wall_time'] = None
                source = 'orchestrator: the simulator left no summary; the run as far as its bag holds it'
            except (AnalysisError, ValueError) as error:
                notes.append(f'the bag could not be read back: {error}')
        if data is None:
            data = {
                'schema': SCHEMA,
                'scenario': scenario.name,
                'dynamics': scenario.dynamics,
                'mode': 'distributed',
                'horizon': self.horizon,
                'n_agents': len(scenario.agent_ids),
                'dimension': scenario.dimension,
                'delta': scenario.delta,
                'wall_time': None,
                'extra': {},
            }
            source = 'orchestrator: the simulator left no summary and there is no readable bag'
        data['extra'].update(
            failure=failure,
            summary_source=source,
            processes={c.name: describe_exit(c.process.returncode) for c in self._children},
        )
        return data

    def _annotate(self, data: dict, lost: _Child | None, status: int, message: str) -> dict | None:
        """Add the orchestrator's view of a failure to the summary's extra.failure; return it."""
        extra = data.setdefault('extra', {})
        failure = extra.get('failure')
        if failure is None and status == EXIT_OK:
            return None
        if failure is None:  # the simulator completed, but a child failed
            failure = {'kind': 'process_failed', 'message': message, 'agents': [], 'detected_by': 'orchestrator'}
        if lost is not None:
            failure['process'] = self._process_info(lost)
            failed_itself = (lost.process.returncode or 0) > 0  # it named an error and left
            if failure['kind'] == 'interrupted':  # stopped by us because of that child
                failure['kind'] = 'process_failed' if failed_itself else 'process_lost'
                failure['message'] = lost.describe()
            elif failure['kind'] == 'agent_lost' and failed_itself:
                failure['kind'] = 'agent_failed'
                failure['message'] = f'{lost.describe()}; {failure["message"]}'
            if 'orchestrator' not in failure['detected_by']:
                failure['detected_by'] += ', orchestrator'
        extra['failure'] = failure
        return failure

    def _strangers(self, topics: dict[str, int], domain_id: int) -> str:
        """'; nodes outside the run wrote on them: /formation_replay (ROS domain 64)', as graph.json saw them."""
        from formation_agent.ros.node import NODE_NAME
        from formation_msgs_py.topics import agent_namespace
        from formation_sim.runtime.sim_node import GRAPH_FILE

        own = {'/formation_simulator', '/formation_recorder', *(f'{agent_namespace(i)}/{NODE_NAME}' for i in self.scenario.agent_ids)}
        try:
            graph = json.loads((self.out_dir / GRAPH_FILE).read_text(encoding='utf-8'))
        except (OSError, ValueError):
            graph = {}
        strangers = sorted(node for node, ends in graph.items() if node not in own and set(ends.get('publishers', ())) & set(topics))
        return f'; nodes outside the run wrote on them: {", ".join(strangers)} (ROS domain {domain_id})' if strangers else ''

    def _check_recording(self, data: dict, bag: Path, notes: list[str]):
        """What the run published against what its bag holds (extra.recording); None without a bag."""
        published = data.get('extra', {}).get('published')
        if not self.record or not published or not (bag / 'metadata.yaml').is_file():
            return None
        from formation_sim.analysis.accounting import check_recording
        from formation_sim.runtime.sim_node import formation_topics

        recorded = {name for name, _ in formation_topics(self.scenario)}  # not, e.g., a robot's own topics
        published = {topic: n for topic, n in published.items() if topic in recorded}
        try:
            check = check_recording(published, bag)
        except Exception as error:  # noqa: BLE001 - rosbags raises several unrelated types
            notes.append(f'the bag could not be checked against what the run published: {error}')
            return None
        data['extra']['recording'] = check.to_dict()
        return check

    @contextlib.contextmanager
    def _signals_trapped(self) -> Iterator[None]:
        """Ctrl-C and SIGTERM ask the run to stop cleanly (only possible from the main thread)."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {
            sig: signal.signal(sig, lambda signum, frame: self._interrupted.set())
            for sig in (signal.SIGINT, signal.SIGTERM)
        }
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    @property
    def last_progress(self) -> str:
        """The simulator's latest progress line ('' before the first step)."""
        return self._last_progress

    def interrupt(self) -> None:
        """Stop the run as Ctrl-C would (for callers on another thread)."""
        self._interrupted.set()

    def _launch_and_watch(
        self, paths: dict[str, Path], groups: list[list[int]], env: dict[str, str]
    ) -> tuple[int, str, _Child | None]:
        """Start the children and watch them: (exit status, message, the child that was lost)."""
        if self.record:
            self._start('recorder', ['-m', 'formation_sim.runtime.recorder', '--ros-args', '--params-file', str(paths['recorder'])], env, expected_exit=False)
        sim_args = [
            '-m', 'formation_sim.runtime.sim_node', '--ros-args',
            '-p', f'scenario:={paths["scenario"].resolve()}',
            '-p', f'horizon:={self.horizon!r}',
            '-p', f'out_dir:={self.out_dir.resolve()}',
            '-p', f'sample_period:={float(self.sample_period)!r}',
            '-p', f'extra_subscribers:={1 if self.record else 0}',
            '-p', f'step_listeners:={self.step_listeners}',
            '-p', f'clock_mode:={self.clock}',
            '-p', f'executor:={self.executor}',
            # Discovery of a large team on a small machine takes long (300 agents here: ~1 min).
            '-p', f'discovery_timeout:={max(120.0, float(len(self.scenario.agent_ids)))!r}',
        ]  # fmt: skip
        simulator = self._start('simulator', sim_args, env, expected_exit=True, pipe=True)
        for group in groups:
            ids = ','.join(map(str, group))
            name = f'agent_{group[0]}' if len(group) == 1 else f'agents_{group[0]}-{group[-1]}'
            self._start(name, ['-m', 'formation_agent.ros.main', '--agents', ids, '--executor', self.executor, '--ros-args', '--params-file', str(paths['agents'])], env, expected_exit=True)
        if self.progress:
            self._say(
                f'ROS domain {env["ROS_DOMAIN_ID"]}: simulator, {len(groups)} agent process(es)'
                f'{", recorder" if self.record else ""} started; waiting for discovery'
            )
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        shown = ''
        lost: _Child | None = None
        # Fast DDS maps a peer's shared-memory port file when it first sends to it: look often
        # (each look costs ~0.6 ms per child), but spend at most ~1 % of a core on it.
        snapshot_period = max(0.25, 0.06 * len(self._children))
        next_snapshot = time.monotonic()
        while True:
            if self._interrupted.is_set():
                return EXIT_INTERRUPTED, 'interrupted', lost
            now = time.monotonic()
            if deadline is not None and now > deadline:
                return EXIT_FAILED, f'timed out after {self.timeout} s', lost
            if self.progress and self._last_progress != shown:
                shown = self._last_progress
                self._say(shown)
            for child in self._children:
                if child.exited_at is None and not child.alive():
                    child.exited_at = now
            if now >= next_snapshot:
                # A child killed by a signal cannot remove its Fast DDS shared-memory files, and
                # once it is gone nobody can tell which were its own: note them while it lives.
                for child in self._children:
                    if child.exited_at is None:
                        child.shm_files |= held_files(child.pid)
                next_snapshot = now + snapshot_period
            code = simulator.process.poll()
            if code is not None:
                if code == 0:
                    return self._finish(), '', lost
                status = _lost_or_failed(lost) if lost is not None else EXIT_LOST if code == EXIT_LOST or code < 0 else EXIT_FAILED
                seen = '' if lost is None else f'{lost.describe()}; '
                return status, f'{seen}simulator (pid {simulator.pid}) {describe_exit(code)}; see {simulator.log}', lost
            if lost is None:
                lost = next(
                    (
                        c
                        for c in self._children
                        if c is not simulator and c.exited_at is not None
                        and (c.process.returncode != 0 or not c.expected_exit)
                    ),
                    None,
                )
                if lost is not None and self.progress:
                    self._say(f'{lost.describe()}; stopping the run')
            if lost is not None and (lost.name == 'recorder' or now - lost.exited_at > LOST_DETECTION):
                # An agent: the simulator has had the time to detect it and stop by itself.
                return _lost_or_failed(lost), f'{lost.describe()}; see {lost.log}', lost
            time.sleep(POLL_PERIOD)

    def _finish(self) -> int:
        """After the simulator's success: let the agents leave, then close the bag."""
        limit = time.monotonic() + self.stop_timeouts[0]
        agents = [c for c in self._children if c.expected_exit and c.name != 'simulator']
        while any(c.alive() for c in agents) and time.monotonic() < limit:
            time.sleep(POLL_PERIOD)
        failed = [c for c in agents if not c.alive() and c.process.returncode != 0]
        return EXIT_FAILED if failed else EXIT_OK

    def _stop_all(self, domain_id: int) -> None:
        """Stop the children still alive, the recorder last; then remove their shm files.

        Each gets SIGINT, then SIGTERM, then SIGKILL (`stop_timeouts`).  The simulator and the agents
        go first: they flush what they published to the recorder before they exit (a message
        dropped on the way is only repaired at a writer's next heartbeat, after up to 3 s), and the
        recorder, still recording meanwhile, then drains and closes its bag.

        A child that dies by a signal cannot remove its Fast DDS shared-memory files, and a peer
        that mapped one of its ports keeps the port's reference (the file outlives both).  Once
        every child is gone, the files any of them held (noted while they ran, `held_files`) go
        if their owner is dead (`fastdds_shm.remove_orphans`); after a death by a signal, so do
        the dead port files of the run's own domain (a port mapped after the last look).
        """
        self._stop([c for c in self._children if c.name != 'recorder'])
        self._stop([c for c in self._children if c.name == 'recorder'])
        for child in self._children:
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.process.wait(timeout=1.0)
        held = set().union(*(c.shm_files for c in self._children))
        if any((c.process.returncode or 0) < 0 for c in self._children):
            held |= domain_port_files(domain_id)
        self.removed_shm_files = remove_orphans(held)

    def _stop(self, children: list[_Child]) -> None:
        """SIGINT, then SIGTERM, then SIGKILL, each to those of `children` still alive."""
        first, second = self.stop_timeouts
        for sig, wait in ((signal.SIGINT, first), (signal.SIGTERM, second), (signal.SIGKILL, 2.0)):
            alive = [c for c in children if c.alive()]
            if not alive:
                break
            for child in alive:
                child.shm_files |= held_files(child.pid)
                child.signal_used = sig.name
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(child.pid, sig)  # the group we created for it, nothing else
                    if sig == signal.SIGINT:
                        os.killpg(child.pid, signal.SIGCONT)  # a stopped child (SIGSTOP) must hear it
            limit = time.monotonic() + wait
            while any(c.alive() for c in alive) and time.monotonic() < limit:
                time.sleep(0.05)

    def _say(self, text: str, *, end: bool = False) -> None:
        stream = sys.stderr
        if stream.isatty():
            stream.write(f'\r\033[K[formation run] {text}' + ('\n' if end else ''))
        else:
            stream.write(f'[formation run] {text}\n')
        stream.flush()
