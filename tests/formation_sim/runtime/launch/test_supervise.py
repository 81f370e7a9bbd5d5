"""formation_sim.runtime.launch.supervise: a child that does not stop when asked says where it is stuck."""

from __future__ import annotations

import os
import time
from pathlib import Path

from formation_sim.runtime.launch.plan import ProcessSpec
from formation_sim.runtime.launch.supervise import Supervisor

# A node that takes SIGINT and SIGTERM (StopSignals) but never looks at them again.
_DEAF_NODE = """
import time
from formation_agent.ros.process import StopSignals
with StopSignals():
    print('ready', flush=True)
    while True:
        time.sleep(0.05)  # deaf here
"""


def _wait_for_line(log: Path, line: str, *, timeout: float = 20.0) -> None:
    limit = time.monotonic() + timeout
    while time.monotonic() < limit:
        if log.exists() and line in log.read_text().splitlines():
            return
        time.sleep(0.05)
    raise AssertionError(f'{log} never said {line!r}')


def test_a_child_deaf_to_sigint_writes_its_stacks_to_its_log_before_it_is_terminated(
    tmp_path, monkeypatch
) -> None:
    from formation_sim.runtime.launch import supervise

    # Each wait asks for the stacks at once and gives the child all of it to write them: 1.5 s,
    # for a loaded machine (0.5 s in a run).
    monkeypatch.setattr(supervise, 'STACKS_WAIT', 1.5)
    supervisor = Supervisor(log_dir=tmp_path, env=dict(os.environ))
    child = supervisor.start(ProcessSpec(name='agent_1', args=('-c', _DEAF_NODE), expected_exit=True))
    _wait_for_line(child.log, 'ready')

    assert supervisor.wait_for_expected(1.5, besides=None) == []  # it did not leave: asked, not failed
    supervisor.stop((1.5, 1.5), domain_id=232)

    # SIGINT and SIGTERM set StopSignals' flag, which this node never reads: SIGKILL ended it.
    assert child.process.returncode == -9 and child.signal_used == 'SIGKILL'
    log = child.log.read_text()
    # Asked three times: before its wait to leave by itself ends, and before SIGTERM and SIGKILL.
    assert log.count('File "<string>", line 7 in <module>') == 3, log


# A time keeper whose output holds a byte that is not UTF-8, then more than a pipe holds.
_STRAY_BYTE_KEEPER = r"""
import sys
sys.stdout.buffer.write(b'\xff fast dds said this\n')
for i in range(5000):
    sys.stdout.buffer.write(b'progress t=%d, a line of some length to fill a pipe quickly\n' % i)
sys.stdout.flush()
"""


def test_a_time_keeper_writing_a_stray_byte_is_still_read_to_its_end(tmp_path) -> None:
    supervisor = Supervisor(log_dir=tmp_path, env=dict(os.environ))
    keeper = supervisor.start(
        ProcessSpec(name='simulator', args=('-c', _STRAY_BYTE_KEEPER), expected_exit=True, keeper=True)
    )
    # Its 5000 lines (~330 kB) pass through the pipe only while the supervisor reads them.
    assert keeper.process.wait(timeout=30) == 0
    _wait_for_line(keeper.log, 'progress t=4999, a line of some length to fill a pipe quickly')
    assert supervisor.last_progress == 't=4999, a line of some length to fill a pipe quickly'
    assert keeper.log.read_text().startswith('\ufffd fast dds said this\n')


# An agent that names its error on its way out, as formation_agent does.
_NAMED_FAILURE = ProcessSpec(
    name='agent_1',
    args=('-c', 'import sys; print("formation_agent: a stale pose", file=sys.stderr); sys.exit(1)'),
    expected_exit=True,
)


def test_a_child_that_failed_without_naming_its_error_is_described_by_its_logs_last_line(tmp_path) -> None:
    supervisor = Supervisor(log_dir=tmp_path, env=dict(os.environ))
    crashed = supervisor.start(
        ProcessSpec(name='simulator', args=('-c', 'raise RuntimeError("no context")'), expected_exit=True)
    )
    named = supervisor.start(_NAMED_FAILURE)
    assert crashed.process.wait(timeout=30) == 1 and named.process.wait(timeout=30) == 1
    assert crashed.describe() == (
        f"simulator (pid {crashed.pid}) exited with status 1 (its log ends: 'RuntimeError: no context')"
    )
    assert named.describe() == f'agent_1 (pid {named.pid}) exited with status 1: a stale pose'


def test_a_child_whose_ros_teardown_hung_after_a_clean_run_is_no_failure_and_said_so(tmp_path) -> None:
    from formation_sim.runtime.launch.results import excused_teardown

    supervisor = Supervisor(log_dir=tmp_path, env=dict(os.environ))
    # As rclpy's destroy_node blocked in C code with the GIL held, cut short by faulthandler.
    hung = supervisor.start(ProcessSpec(name='agent_3', args=('-c', _GIL_HELD_TEARDOWN), expected_exit=True))
    failed_itself = supervisor.start(_NAMED_FAILURE)
    assert hung.process.wait(timeout=30) == 1 and failed_itself.process.wait(timeout=30) == 1
    assert hung.left_with() == 0 and failed_itself.left_with() is None
    failed, note = excused_teardown([hung, failed_itself])
    assert failed == [failed_itself]
    assert note == (
        'agent_3 left the run with status 0, then its ROS teardown hung in C code (rclpy) and was cut '
        f'short (stacks in {hung.log})'
    )


_GIL_HELD_TEARDOWN = """
import ctypes
from formation_agent.ros import process
process.GIL_FREE_MARGIN = 0.3
with process.shutdown_guard('formation_agent', lambda: 0, bound=0.3):
    ctypes.PyDLL(None).sleep(60)
"""
