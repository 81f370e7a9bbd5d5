"""Node processes: which executor spins them, how SIGINT/SIGTERM stop them, how they exit.

Imports no rclpy at module level: the orchestrator (`formation run`, `formation robots`) uses its
exit statuses and SignalFlag without loading ROS."""

from __future__ import annotations

import atexit
import contextlib
import faulthandler
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import NoReturn

from formation_msgs_py.middleware import EXECUTORS

SHUTDOWN_BOUND = 10.0
"""How long a node process may take to destroy its nodes and shut rclpy down [s] before it leaves
without them (`shutdown_guard`): every command has gone out by then, a process must still end."""

GIL_FREE_MARGIN = 2.0
"""How much longer than its bound a guard waits before faulthandler's own thread, which needs no
GIL, writes the stacks and leaves with status 1 (`shutdown_guard`, `exit_process`): a main thread
blocked in C code while it holds the GIL starves the guard's Python thread."""

TEARDOWN_MARK = 'shutting ROS down, exit status '
"""The line a node process writes before its ROS teardown (`shutdown_guard`), with the status it
leaves with: a teardown that then hangs in C code and is cut short (status 1, 'Timeout (' and the
stacks after this line) left the run with that status (`teardown_status`)."""

EXIT_BOUND = 5.0
"""How long `exit_process` may take (exit handlers, flushing) [s] before faulthandler's thread
writes the stacks and leaves with status 1."""

# EXECUTORS (formation_msgs_py.middleware): rclpy's EventsExecutor (default) or the
# SingleThreadedExecutor. The SingleThreadedExecutor rebuilds its wait set in Python on every spin;
# on a 2-core machine that was most of the simulator's time per lock-step step (BENCHMARKS.md).
# The EventsExecutor (rclpy.experimental, C++) dispatches each message as it comes. It has no
# guard conditions, so the nodes use none.


def make_executor(kind: str, *, context=None):
    """The executor `kind` (one of EXECUTORS)."""
    if kind == 'events':
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == 'single':
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    raise ValueError(f'executor must be one of {EXECUTORS}, got {kind!r}')


class SignalFlag:
    """A flag a signal handler may set: an assignment, no lock.

    `threading.Event.set()` takes a lock; a second signal whose handler runs while the first
    handler is inside it (SIGTERM from the kernel on the orchestrator's death, then another) waits
    for that lock forever in the main thread: an agent of a killed run lived on, deadlocked.
    """

    __slots__ = ('_set',)

    def __init__(self) -> None:
        self._set = False

    def set(self) -> None:
        self._set = True

    def is_set(self) -> bool:
        return self._set


STACKS_SIGNAL = signal.SIGUSR1  # `formation run` asks a child that outlived its timeout for its stacks


def stacks_on_signal() -> None:
    """Every thread's stack on stderr (the run's log) when STACKS_SIGNAL comes: a run that timed
    out says where each of its children still was (`FormationRun`, before it stops them)."""
    with contextlib.suppress(Exception):  # stderr may be closed; the signal is then the default's
        faulthandler.register(STACKS_SIGNAL, file=sys.stderr, all_threads=True)


class StopSignals:
    """SIGINT and SIGTERM as a flag that the spin loop turns into KeyboardInterrupt between spins.

    rclpy's own handlers (or Python's) raise KeyboardInterrupt wherever the main thread is; inside
    the EventsExecutor's C++ dispatch it comes out as a pybind11 RuntimeError ("Unable to convert
    call argument"), and an interrupted run would look like a failed one.  Use with
    `rclpy.init(..., signal_handler_options=SignalHandlerOptions.NO)`.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.received = SignalFlag()
        self.received_at: float | None = None  # time.monotonic() of the first stop signal
        self._previous: dict = {}

    def __enter__(self) -> StopSignals:
        self._previous = {sig: signal.signal(sig, self._on_signal) for sig in self.SIGNALS}
        stacks_on_signal()
        return self

    def __exit__(self, *exc_info) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _on_signal(self, signum, frame) -> None:
        if self.received_at is None:  # assignments only: no lock in a handler
            self.received_at = time.monotonic()
        self.received.set()

    def check(self) -> None:
        """Raise KeyboardInterrupt once a stop signal has come."""
        if self.received.is_set():
            raise KeyboardInterrupt


def exit_process(status: int) -> NoReturn:
    """Leave a node process with `status` once its nodes are destroyed and rclpy is shut down.

    Python's exit handlers run and its streams are flushed, but the C++ static destructors are
    skipped: Fast DDS's DomainParticipantFactory destructor sleeps a fixed 100 ms at every process
    exit (the participant itself is gone with rclpy's shutdown), and a run waits for its
    simulator, its agents and its recorder to exit one after the other.  After EXIT_BOUND it leaves
    with status 1 and the stacks on stderr, whatever holds it.
    """
    with contextlib.suppress(Exception):
        faulthandler.dump_traceback_later(EXIT_BOUND, exit=True, file=sys.stderr)
    with contextlib.suppress(Exception):
        atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


def teardown_status(log_lines: list[str]) -> int | None:
    """The status a node process left its run with if its ROS teardown hung and faulthandler's
    thread cut it short (its log: TEARDOWN_MARK with the status, then faulthandler's 'Timeout ('
    dump); None otherwise.

    rclpy's `destroy_node` can block in C code while it holds the GIL (seen in rclpy 7.1.6 with
    Fast DDS, about once in a thousand node teardowns on a loaded machine): the guard's Python
    thread cannot run, and faulthandler leaves with status 1 whatever the run's was."""
    marks = [k for k, line in enumerate(log_lines) if line.startswith(TEARDOWN_MARK)]
    if not marks:
        return None
    after = log_lines[marks[-1] + 1 :]
    if not any(line.startswith('Timeout (') for line in after):
        return None
    text = log_lines[marks[-1]].removeprefix(TEARDOWN_MARK).strip()
    return int(text) if text.lstrip('-').isdigit() else None


def release_ros(executor, nodes) -> None:
    """The end of a node process, in ros2/examples' order: the executor stops dispatching and lets
    go of every entity (`shutdown`), the nodes are destroyed, rclpy is shut down.

    Call it under `shutdown_guard`, inside StopSignals, and drop the executor there too
    (`executor = None`): its C++ teardown then runs under the guard and with the stop signals
    taken, not after `main` returns, where SIGTERM is fatal and nothing bounds it."""
    import rclpy

    if executor is not None:
        executor.shutdown(timeout_sec=1.0)
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()


@contextlib.contextmanager
def shutdown_guard(
    command: str, status: Callable[[], int], *, bound: float = SHUTDOWN_BOUND, announce: bool = True
) -> Iterator[None]:
    """Leave the process with `status()` if the block (destroying the nodes, rclpy's shutdown)
    has not ended within `bound` seconds, after one line naming it and every thread's stack on
    stderr (the run's log).

    Fast DDS can block in a participant's shutdown (a peer killed while it held a shared-memory
    port's lock): a node that has sent its last command and said why it stopped must still exit,
    or the run that started it waits for it.  The block's first line on stderr is TEARDOWN_MARK
    with `status()` (`announce`: a process refused before it made a node says only why); a
    block stuck in C code with the GIL held is cut short `GIL_FREE_MARGIN` later by
    faulthandler's thread (status 1: `teardown_status` tells the status it meant).
    """
    done = threading.Event()

    def leave() -> None:
        if done.wait(bound):
            return
        with contextlib.suppress(Exception):
            sys.stderr.write(
                f'{command}: shutting rclpy down took more than {bound:g} s; '
                'leaving without it (stacks below)\n'
            )
            sys.stderr.flush()
            faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
        os._exit(status())

    if announce:
        with contextlib.suppress(Exception):
            sys.stderr.write(f'{TEARDOWN_MARK}{status()}\n')
            sys.stderr.flush()
    watchdog = threading.Thread(target=leave, name='shutdown_guard', daemon=True)
    watchdog.start()
    with contextlib.suppress(Exception):  # stderr closed: the Python guard alone
        faulthandler.dump_traceback_later(bound + GIL_FREE_MARGIN, exit=True, file=sys.stderr)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        done.set()
        watchdog.join()
