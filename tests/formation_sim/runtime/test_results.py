"""What `formation run` adds to a run's summary (no process of a run is started here)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from formation_sim.runtime.results import EXIT_INTERRUPTED, annotate, phases
from formation_sim.runtime.supervise import Child


def _child(name: str, returncode: int, tmp_path: Path, error: str = '') -> Child:
    process = subprocess.Popen(['true'])
    process.wait()
    process.returncode = returncode
    log = tmp_path / f'{name}.log'
    log.write_text(f'formation_agent: {error}\n' if error else '')
    return Child(name=name, process=process, log=log, expected_exit=name.startswith('agent'), exited_at=1.0)


@pytest.mark.parametrize(
    ('name', 'returncode', 'kind', 'agents'),
    [
        ('robot_2', -9, 'robot_lost', [2]),  # a simulated robot's process killed
        ('agent_3', -9, 'agent_lost', [3]),
        ('agent_3', 1, 'agent_failed', [3]),  # it named its error
        ('agents_1-4', -9, 'process_lost', []),  # a packed process: no one agent to name
        ('recorder', -9, 'process_lost', []),
    ],
)
def test_a_child_that_stopped_the_run_is_its_first_cause_by_kind_and_agent(
    tmp_path, name, returncode, kind, agents
):
    """formation run stops at once when a robot's or (on robots) an agent's process dies: the time
    keeper, stopped by the signal, says 'interrupted'; the summary names the child instead."""
    data = {
        'extra': {
            'failure': {
                'kind': 'interrupted',
                'message': 'stopped by a signal (SIGINT/SIGTERM)',
                'agents': [],
                'detected_by': 'coordinator',
            }
        }
    }
    child = _child(
        name, returncode, tmp_path, error='the pose of robot 2 is 0.6 s old' if returncode > 0 else ''
    )
    failure = annotate(data, child, EXIT_INTERRUPTED, '', launched=0.0)
    assert (failure['kind'], failure['agents']) == (kind, agents)
    assert failure['message'].startswith(f'{name} (pid {child.pid}) ') and failure['process']['name'] == name
    assert failure['detected_by'] == 'coordinator, orchestrator'


def test_the_commands_own_start_before_the_timeline_is_the_prepare_phase():
    marks = {'prepare': -1.5, 'run': 0.0, 'step0': 2.0, 'final_step': 5.0, 'checked': 6.0}
    assert phases(marks) == {'prepare': 1.5, 'start': 2.0, 'stepping': 3.0, 'end': 1.0}
    assert 'prepare' not in phases({'run': 0.0, 'step0': 2.0})
