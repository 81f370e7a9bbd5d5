"""formation_agent.ros.process: the stop signals' handler."""

from __future__ import annotations

import os
import signal
import sys

from formation_agent.ros.process import SignalFlag, StopSignals


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
