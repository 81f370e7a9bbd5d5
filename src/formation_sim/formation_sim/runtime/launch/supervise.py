"""Process supervision of a run: start each child in its own group, watch it, stop it by PID.

Every child runs in its own process group and session (a terminal's Ctrl-C reaches only the
orchestrator) and gets SIGTERM from the kernel if the orchestrator dies, even by SIGKILL
(PR_SET_PDEATHSIG).  `stop` sends SIGINT, then SIGTERM, then SIGKILL after timeouts, each to the
children still alive and to nothing else, the recorder last; then the Fast DDS shared-memory files
the children held go if their owners are dead (`fastdds_shm`).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from formation_agent.ros.process import STACKS_SIGNAL, teardown_status
from formation_sim.runtime.launch.fastdds_shm import (
    domain_port_files,
    fastdds_names,
    held_files,
    remove_orphans,
)
from formation_sim.runtime.launch.plan import ProcessSpec

POLL_PERIOD = 0.05  # how often the orchestrator looks at its children [s]
SHM_LOOK_PERIOD = (
    2.0  # children's shared-memory files are looked at when /dev/shm changes, or after this long [s]
)
PROGRESS_PREFIX = 'progress '
STACKS_WAIT = 0.5  # [s] for the children asked for their stacks to write them (`ask_for_stacks`)

try:  # looked up here, not in the forked child (a child before exec must take no lock)
    _PRCTL = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # pragma: no cover - not Linux
    _PRCTL = None
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the orchestrator dies, even by SIGKILL (Linux)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


def catches(pid: int, sig: int) -> bool:
    """Whether process `pid` has its own handler for signal `sig` (Linux: /proc/<pid>/status,
    SigCgt).  A child still starting (importing rclpy takes seconds on a loaded machine) has no
    stack handler yet, and STACKS_SIGNAL's default would end it without a word: a fresh-clone run
    under load named a simulator 'stacks in' a log it never wrote."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('SigCgt:'):
                return bool(int(line.split()[1], 16) >> (int(sig) - 1) & 1)
    return False


def describe_exit(returncode: int | None) -> str:
    if returncode is None:
        return 'still running'
    if returncode < 0:
        with contextlib.suppress(ValueError):
            return f'killed by {signal.Signals(-returncode).name}'
    return f'exited with status {returncode}'


@dataclass
class Child:
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

    def _log_tail(self) -> list[str]:
        """The last 64 kB of its log, as lines."""
        try:
            with self.log.open('rb') as handle:
                handle.seek(max(0, self.log.stat().st_size - 65536))
                return handle.read().decode(errors='replace').splitlines()
        except OSError:
            return []

    def left_with(self) -> int | None:
        """The status it left its run with, if its ROS teardown then hung and was cut short (exit
        1, `formation_agent.ros.process.teardown_status`); None otherwise."""
        if self.process.returncode in (None, 0):
            return None
        return teardown_status(self._log_tail())

    def error_line(self, lines: list[str] | None = None) -> str:
        """The error the child named on its way out (its last 'formation_...: ' line), or ''
        (`lines`: its log's tail, read here when not given)."""
        named = [
            line
            for line in (self._log_tail() if lines is None else lines)
            if line.startswith(('formation_agent: ', 'formation_sim: ', 'formation_recorder: '))
        ]
        return named[-1].split(': ', 1)[1] if named else ''

    def describe(self) -> str:
        """'agent_2 (pid 123) killed by SIGKILL', with the error it named if it gave one, else, for
        one that failed without naming it (a traceback, a stuck end cut short), its log's last line."""
        text = f'{self.name} (pid {self.pid}) {describe_exit(self.process.returncode)}'
        if self.process.returncode in (None, 0):
            return text
        lines = self._log_tail()
        error = self.error_line(lines)
        if error:
            return f'{text}: {error}'
        last = next((line.strip() for line in reversed(lines) if line.strip()), '')
        return f'{text} (its log ends: {last[:200]!r})' if last and self.process.returncode > 0 else text

    @property
    def failed_itself(self) -> bool:
        """It named an error and left (else it died, was killed, or vanished)."""
        return (self.process.returncode or 0) > 0


class Supervisor:
    """The children of one run."""

    def __init__(
        self,
        *,
        log_dir: Path,
        env: dict[str, str],
        launch_prefix: Callable[[str], Sequence[str]] | None = None,
    ) -> None:
        self.log_dir = log_dir
        self.env = env
        self.launch_prefix = launch_prefix
        self.children: list[Child] = []
        self.last_progress = ''  # the time keeper's latest progress line
        self._shm_seen: set[str] = set()  # the Fast DDS files in /dev/shm at the last look
        self._next_shm_look = 0.0

    def start(self, spec: ProcessSpec) -> Child:
        log = self.log_dir / f'{spec.name}.log'
        handle = open(log, 'w', encoding='utf-8')  # noqa: SIM115 - owned by the child
        prefix = list(self.launch_prefix(spec.name)) if self.launch_prefix is not None else []
        process = subprocess.Popen(
            [*prefix, spec.program or sys.executable, *spec.args],
            env={**self.env, **dict(spec.env)},
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE if spec.keeper else handle,
            stderr=handle,
            start_new_session=True,  # own process group: a terminal's Ctrl-C reaches only us
            preexec_fn=_die_with_parent,  # noqa: PLW1509 - only prctl, no locks taken
            text=True,
            errors='replace',  # a stray byte in the time keeper's output must not end _pump
        )
        child = Child(name=spec.name, process=process, log=log, expected_exit=spec.expected_exit)
        if spec.keeper:
            threading.Thread(target=self._pump, args=(child, handle), daemon=True).start()
        self.children.append(child)
        return child

    def _pump(self, child: Child, handle) -> None:
        """Copy the time keeper's stdout into its log; keep its progress lines for the terminal."""
        for line in child.process.stdout:
            with contextlib.suppress(OSError):  # a full disk: keep reading, or the child blocks on the pipe
                handle.write(line)
                handle.flush()
            if line.startswith(PROGRESS_PREFIX):
                self.last_progress = line[len(PROGRESS_PREFIX) :].strip()

    def ask_for_stacks(self, children: Sequence[Child] | None = None, *, wait: bool = True) -> list[Child]:
        """Each of `children` (default: the run's) still running writes every thread's stack to its
        log (STACKS_SIGNAL, `formation_agent.ros.process.stacks_on_signal`), given STACKS_WAIT to do
        it (`wait`; else the caller waits); the discovery server is not ours and is left alone, and
        a child still starting (no handler yet, `catches`) is not asked.  The children asked.

        faulthandler writes from its C signal handler: a process whose main thread is blocked in C
        code, holding the GIL or not, still says where it is."""
        asked = [
            child
            for child in (self.children if children is None else children)
            if child.alive() and child.name != 'discovery_server' and catches(child.pid, STACKS_SIGNAL)
        ]
        for child in asked:
            with contextlib.suppress(OSError):
                os.kill(child.pid, STACKS_SIGNAL)
        if asked and wait:
            time.sleep(STACKS_WAIT)
        return asked

    def _wait(self, children: Sequence[Child], limit: float, *, ask_for_stacks: bool = True) -> None:
        """Until `children` have left or time.monotonic() reaches `limit`; those still running
        STACKS_WAIT before it are asked for their stacks (`ask_for_stacks`), so that they are
        written before the next signal.  The wait is never longer for it: a shorter one asks at
        once, a zero one asks nothing."""
        asked = not ask_for_stacks
        while any(c.alive() for c in children) and time.monotonic() < limit:
            if not asked and limit - time.monotonic() <= STACKS_WAIT:
                self.ask_for_stacks([c for c in children if c.alive()], wait=False)
                asked = True
            time.sleep(POLL_PERIOD)

    def note_exits(self, now: float) -> None:
        for child in self.children:
            if child.exited_at is None and not child.alive():
                child.exited_at = now

    def note_shm_files(self, now: float) -> None:
        """A child killed by a signal cannot remove its Fast DDS shared-memory files, and once it
        is gone nobody can tell which were its own: note them while it lives.

        A file is noted with the child that creates it (its owner maps it and holds its lock), so
        the children are looked at when /dev/shm holds new Fast DDS files, and otherwise only
        every SHM_LOOK_PERIOD: reading a process's memory map costs milliseconds, which a
        2-core machine starting a run needs for the run."""
        names = fastdds_names()
        if names <= self._shm_seen and now < self._next_shm_look:
            self._shm_seen = names
            return
        self._shm_seen = names
        self._next_shm_look = now + SHM_LOOK_PERIOD
        for child in self.children:
            if child.exited_at is None:
                child.shm_files |= held_files(child.pid)

    def wait_for_expected(self, timeout: float, *, besides: Child) -> list[Child]:
        """After the time keeper's success: let the others that leave by themselves leave; those
        that left with a non-zero status."""
        limit = time.monotonic() + timeout
        leaving = [c for c in self.children if c.expected_exit and c is not besides]
        # One that should have left says where it is before it is stopped.
        self._wait(leaving, limit)
        return [c for c in leaving if not c.alive() and c.process.returncode != 0]

    def stop(self, timeouts: tuple[float, float], *, domain_id: int, robots_after: float = 0.0) -> list[str]:
        """Stop the children still alive, the recorder last; then remove their shm files (the list).

        Each gets SIGINT, then SIGTERM, then SIGKILL (`timeouts`).  The time keeper and the agents
        go first, then the simulated robots (which take the agents' zero commands and publish
        their poses up to the end of the run): they flush what they published to the recorder before they exit
        (a message dropped on the way is only repaired at a writer's next heartbeat, after up to
        3 s), and the recorder, still recording meanwhile, then drains and closes its bag.

        `robots_after`: the simulated robots run at least this long after the stop began (a robot
        whose agent was killed gets its zero command from the coordinator only after
        `run_end.UNREPORTED_STOP_AFTER`: the bag shows it stopping on its own command timeout).

        A child that dies by a signal cannot remove its Fast DDS shared-memory files, and a peer
        that mapped one of its ports keeps the port's reference (the file outlives both).  Once
        every child is gone, the files any of them held (noted while they ran, `held_files`) go
        if their owner is dead (`fastdds_shm.remove_orphans`); after a death by a signal, so do
        the dead port files of the run's own domain (a port mapped after the last look).
        """
        robots = [c for c in self.children if c.name.startswith('robot')]
        began = time.monotonic()
        self._stop([c for c in self.children if c.name != 'recorder' and c not in robots], timeouts)
        while (
            robots and time.monotonic() < began + robots_after
        ):  # a robot left without commands stops by itself first
            time.sleep(POLL_PERIOD)
        self._stop(
            robots, timeouts
        )  # after their agents: they take the zero commands, their poses end the bag
        self._stop([c for c in self.children if c.name == 'recorder'], timeouts)
        for child in self.children:
            with contextlib.suppress(subprocess.TimeoutExpired):
                child.process.wait(timeout=1.0)
        held = set().union(*(c.shm_files for c in self.children))
        if any((c.process.returncode or 0) < 0 for c in self.children):
            held |= domain_port_files(domain_id)
        return remove_orphans(held)

    def _stop(self, children: list[Child], timeouts: tuple[float, float]) -> None:
        """SIGINT, then SIGTERM, then SIGKILL, each to those of `children` still alive."""
        first, second = timeouts
        for sig, wait in ((signal.SIGINT, first), (signal.SIGTERM, second), (signal.SIGKILL, 2.0)):
            alive = [c for c in children if c.alive()]
            if not alive:
                break
            for child in alive:  # what it maps now: a child that stops unmaps what its dead peers left
                child.shm_files |= held_files(child.pid)
                child.signal_used = sig.name
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(child.pid, sig)  # the group we created for it, nothing else
                    if sig == signal.SIGINT:
                        os.killpg(child.pid, signal.SIGCONT)  # a stopped child (SIGSTOP) must hear it
            # One that does not stop when asked says where it is stuck.
            self._wait(alive, time.monotonic() + wait, ask_for_stacks=sig != signal.SIGKILL)
