"""formation_sim.runtime.supervise: a child that does not stop when asked says where it is stuck."""

from __future__ import annotations

import os
import time
from pathlib import Path

from formation_sim.runtime.launch import ProcessSpec
from formation_sim.runtime.supervise import Supervisor

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


def test_a_child_deaf_to_sigint_writes_its_stacks_to_its_log_before_it_is_terminated(tmp_path) -> None:
    supervisor = Supervisor(log_dir=tmp_path, env=dict(os.environ))
    child = supervisor.start(ProcessSpec(name='agent_1', args=('-c', _DEAF_NODE), expected_exit=True))
    _wait_for_line(child.log, 'ready')

    assert supervisor.wait_for_expected(0.2, besides=None) == []  # it did not leave: asked, not failed
    supervisor.stop((0.3, 0.3), domain_id=232)

    # SIGINT and SIGTERM set StopSignals' flag, which this node never reads: SIGKILL ended it.
    assert child.process.returncode == -9 and child.signal_used == 'SIGKILL'
    log = child.log.read_text()
    # Asked three times: before its wait to leave by itself ends, and before SIGTERM and SIGKILL.
    assert log.count('File "<string>", line 7 in <module>') == 3, log
