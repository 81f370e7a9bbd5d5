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


def test_the_child_that_stops_the_run_is_the_first_besides_the_keeper_that_failed_or_should_not_have_left(
    tmp_path,
):
    from formation_sim.runtime.results import first_lost

    keeper = _child('simulator', -9, tmp_path)
    done = _child('agent_1', 0, tmp_path)  # an agent leaves by itself: no loss
    recorder = _child('recorder', 0, tmp_path)  # the recorder runs until stopped: its exit is one
    unseen = _child('agent_2', 1, tmp_path)
    unseen.exited_at = None  # its exit not seen yet
    assert first_lost([keeper, done, unseen], keeper) is None
    assert first_lost([keeper, done, unseen, recorder], keeper) is recorder
    assert first_lost([_child('agent_3', 1, tmp_path), recorder], keeper).name == 'agent_3'


@pytest.mark.parametrize(
    ('name', 'returncode', 'backend', 'wait'),
    [
        ('robot_2', -9, 'unicycle', 0.0),  # not an agent: everything stops now
        ('recorder', -9, 'exact', 0.0),
        ('agent_3', 1, 'unicycle', 'AGENT_REPORT_DETECTION'),  # its final report names its error
        ('agent_3', 1, 'exact', 'LOST_DETECTION'),
        ('agent_3', -9, 'unicycle', 0.0),  # killed on robots: no waiting for a lease
        ('agent_3', -9, 'exact', 'LOST_DETECTION'),  # lock-step: the keeper sees the lease lapse
    ],
)
def test_the_time_keeper_gets_its_time_to_name_a_lost_child_itself(tmp_path, name, returncode, backend, wait):
    from formation_sim.runtime import results

    expected = getattr(results, wait) if isinstance(wait, str) else wait
    assert results.detection_time(_child(name, returncode, tmp_path), backend=backend) == expected


def test_a_time_keeper_that_failed_gives_its_status_or_the_lost_childs(tmp_path):
    from formation_sim.runtime.results import EXIT_FAILED, EXIT_LOST, keeper_failed

    keeper = _child('coordinator', 4, tmp_path)
    status, message = keeper_failed(4, keeper, None)  # refused: the robots' start (nothing was sent)
    assert status == 4 and message == f'coordinator (pid {keeper.pid}) exited with status 4; see {keeper.log}'
    lost = _child('agent_2', 1, tmp_path, error='the pose of robot 2 is 0.6 s old')
    status, message = keeper_failed(130, keeper, lost)  # stopped with the rest: the lost child decides
    assert status == EXIT_FAILED and message.startswith(
        f'agent_2 (pid {lost.pid}) exited with status 1: the pose of robot 2 is 0.6 s old; coordinator'
    )
    assert (
        keeper_failed(-9, keeper, None)[0] == EXIT_LOST and keeper_failed(7, keeper, None)[0] == EXIT_FAILED
    )
    # An operator's stop (/formation/stop) is the run's status whatever child went meanwhile.
    assert keeper_failed(5, keeper, lost)[0] == 5 and keeper_failed(5, keeper, None)[0] == 5
