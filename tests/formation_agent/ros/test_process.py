"""formation_agent.ros.process: the stop signals' handler."""

from __future__ import annotations

import os
import signal
import sys

import pytest

from formation_agent.ros.process import SignalFlag, StopSignals, teardown_status


def _acquisitions_during(call) -> list[str]:
    """The names of the C-level lock operations `call` makes (acquire, __enter__ of a lock)."""
    seen: list[str] = []

    def profile(frame, event, arg) -> None:
        if event == 'c_call' and getattr(arg, '__name__', '') in ('acquire', '__enter__'):
            seen.append(f'{type(getattr(arg, "__self__", None)).__name__}.{arg.__name__}')

    sys.setprofile(profile)
    try:
        call()
    finally:
        sys.setprofile(None)
    return seen


def test_the_stop_handler_takes_no_lock_so_a_second_signal_inside_it_cannot_deadlock() -> None:
    # A handler runs in the main thread between two bytecodes, also inside another handler: one
    # that takes a lock (threading.Event.set) waits forever for itself when a second SIGTERM comes
    # while the first holds it.  An agent of a SIGKILLed `formation run` lived on that way.
    with StopSignals() as stop:
        handler = signal.getsignal(signal.SIGTERM)
        assert _acquisitions_during(lambda: handler(signal.SIGTERM, None)) == []
        assert stop.received.is_set()


def test_two_signals_in_a_row_stop_the_loop_once() -> None:
    with StopSignals() as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGINT)
        try:
            stop.check()
        except KeyboardInterrupt:
            pass
        else:
            raise AssertionError('check() did not raise after two stop signals')
    assert signal.getsignal(signal.SIGTERM) is not stop._on_signal  # the previous handlers are back


def test_a_flag_is_clear_until_set() -> None:
    flag = SignalFlag()
    assert not flag.is_set()
    flag.set()
    assert flag.is_set()


_HANGING_SHUTDOWN = """
import time
from formation_agent.ros.process import shutdown_guard
status = 7
with shutdown_guard('formation_test', lambda: status, bound=0.5):
    time.sleep(60)  # a shutdown that never returns
"""


def test_a_shutdown_that_hangs_leaves_within_the_bound_with_the_status_and_says_so() -> None:
    import subprocess

    # (without the guard the block sleeps 60 s, and the run below times out)
    done = subprocess.run(
        [sys.executable, '-c', _HANGING_SHUTDOWN], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 7, done.stderr
    mark, first, *stacks = done.stderr.splitlines()
    assert mark == 'shutting ROS down, exit status 7'
    assert (
        first == 'formation_test: shutting rclpy down took more than 0.5 s; leaving without it (stacks below)'
    )
    assert any('line 6' in line for line in stacks), done.stderr  # the main thread's stack: where it hung


def test_a_shutdown_that_ends_in_time_leaves_no_watchdog_behind() -> None:
    import threading

    from formation_agent.ros.process import shutdown_guard

    with shutdown_guard('formation_test', lambda: 7, bound=0.05):
        pass
    assert not any(thread.name == 'shutdown_guard' for thread in threading.enumerate())


_GIL_HELD = """
import atexit, ctypes
from formation_agent.ros import process
process.GIL_FREE_MARGIN = 0.3
process.EXIT_BOUND = 0.5
held = ctypes.PyDLL(None).sleep  # PyDLL keeps the GIL through the C call
{body}
"""

_SHUTDOWN_HOLDING_THE_GIL = """with process.shutdown_guard('formation_test', lambda: 7, bound=0.3):
    held(60)  # a shutdown blocked in C code that holds the GIL: the guard's thread never runs"""

_EXIT_HOLDING_THE_GIL = """atexit.register(held, 60)  # an exit handler blocked in C code, the GIL held
process.exit_process(0)"""


@pytest.mark.parametrize('body', [_SHUTDOWN_HOLDING_THE_GIL, _EXIT_HOLDING_THE_GIL], ids=['shutdown', 'exit'])
def test_a_process_blocked_in_c_code_that_holds_the_gil_still_leaves_with_its_stacks(body: str) -> None:
    import subprocess

    # (without faulthandler's thread the child sleeps 60 s, and the run below times out)
    done = subprocess.run(
        [sys.executable, '-c', _GIL_HELD.format(body=body)], capture_output=True, text=True, timeout=30
    )
    assert done.returncode == 1, done.stderr
    assert 'Timeout (0:00:00' in done.stderr, done.stderr  # faulthandler's dump, then _exit(1)
    assert 'File "<string>", line 8 in <module>' in done.stderr, done.stderr  # where it was held
    # The status the process meant to leave with, when it was its teardown that hung.
    assert teardown_status(done.stderr.splitlines()) == (7 if body is _SHUTDOWN_HOLDING_THE_GIL else None)


def test_the_status_a_process_left_its_run_with_is_read_only_from_a_teardown_cut_short() -> None:
    assert teardown_status(['shutting ROS down, exit status 0', 'Timeout (0:00:12)!', '  File "x"']) == 0
    assert teardown_status(['shutting ROS down, exit status 3', 'Timeout (0:00:12)!']) == 3
    assert teardown_status(['shutting ROS down, exit status 0']) is None  # it left: no dump after it
    assert teardown_status(['Timeout (0:00:05)!', 'shutting ROS down, exit status 0']) is None
    assert (
        teardown_status(['formation_agent: the pose of robot 1 is 0.6 s old', 'Timeout (0:00:12)!']) is None
    )


_STUCK_NODE = """
import sys, time
from formation_agent.ros.process import StopSignals
with StopSignals():
    print('ready', flush=True)
    while True:
        time.sleep(0.05)  # stuck here
"""


def test_a_stuck_node_asked_for_its_stacks_writes_them_and_lives_on(tmp_path) -> None:
    import subprocess
    import time

    from formation_agent.ros.process import STACKS_SIGNAL

    log = tmp_path / 'stuck.err'
    with open(log, 'w') as err:
        child = subprocess.Popen(
            [sys.executable, '-c', _STUCK_NODE], stdout=subprocess.PIPE, stderr=err, text=True
        )
    try:
        assert child.stdout.readline().strip() == 'ready'
        os.kill(child.pid, STACKS_SIGNAL)
        # Until the stacks are written (it was a fixed 0.5 s, after which the child was killed: on a
        # loaded machine the stacks could still be to come); 20 s for a loaded machine.
        deadline = time.monotonic() + 20.0
        while 'File "<string>"' not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)  # the signal had its time to end the process, had it done so
        assert child.poll() is None, 'the signal ended the process'
    finally:
        child.terminate()  # SIGTERM: StopSignals takes it; the loop above does not look, so kill
        child.kill()
        child.communicate(timeout=10)
    stderr = log.read_text()
    # Its main thread's stack, wherever the signal found it (still leaving print, or in the loop).
    assert 'most recent call first' in stderr and 'File "<string>"' in stderr, stderr
