"""What `formation run` adds to a run's summary (no process of a run is started here)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.runtime.launch.results import annotate, phases
from formation_sim.runtime.launch.supervise import Child


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
    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.summary import unstarted_summary

    keeper_failure = {
        'kind': 'interrupted',
        'message': 'stopped by a signal (SIGINT/SIGTERM)',
        'agents': [],
        'detected_by': 'coordinator',
    }
    data = unstarted_summary(
        load_scenario('paper_single'), horizon=10.0, mode='robots', extra={'failure': keeper_failure}
    )
    child = _child(
        name, returncode, tmp_path, error='the pose of robot 2 is 0.6 s old' if returncode > 0 else ''
    )
    failure = annotate(data, child, ExitCode.INTERRUPTED, '', launched=0.0)
    assert (failure['kind'], failure['agents']) == (kind, agents)
    assert failure['message'].startswith(f'{name} (pid {child.pid}) ') and failure['process']['name'] == name
    assert failure['detected_by'] == 'coordinator, orchestrator' and data.failure is failure


def test_the_commands_own_start_before_the_timeline_is_the_prepare_phase():
    marks = {'prepare': -1.5, 'run': 0.0, 'step0': 2.0, 'final_step': 5.0, 'checked': 6.0}
    assert phases(marks) == {'prepare': 1.5, 'start': 2.0, 'stepping': 3.0, 'end': 1.0}
    assert 'prepare' not in phases({'run': 0.0, 'step0': 2.0})


def test_the_child_that_stops_the_run_is_the_first_besides_the_keeper_that_failed_or_should_not_have_left(
    tmp_path,
):
    from formation_sim.runtime.launch.results import first_lost

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
    from formation_sim.runtime.launch import backends, results

    expected = getattr(backends, wait) if isinstance(wait, str) else wait
    assert results.detection_time(_child(name, returncode, tmp_path), backend=backend) == expected


def test_a_time_keeper_that_failed_gives_its_status_or_the_lost_childs(tmp_path):
    from formation_sim.runtime.launch.results import keeper_failed

    keeper = _child('coordinator', 4, tmp_path)
    status, message = keeper_failed(4, keeper, None)  # refused: the robots' start (nothing was sent)
    assert status == 4 and message == f'coordinator (pid {keeper.pid}) exited with status 4; see {keeper.log}'
    lost = _child('agent_2', 1, tmp_path, error='the pose of robot 2 is 0.6 s old')
    status, message = keeper_failed(130, keeper, lost)  # stopped with the rest: the lost child decides
    assert status == ExitCode.FAILED and message.startswith(
        f'agent_2 (pid {lost.pid}) exited with status 1: the pose of robot 2 is 0.6 s old; coordinator'
    )
    assert (
        keeper_failed(-9, keeper, None)[0] == ExitCode.LOST
        and keeper_failed(7, keeper, None)[0] == ExitCode.FAILED
    )
    # An operator's stop (/formation/stop) is the run's status whatever child went meanwhile.
    assert keeper_failed(5, keeper, lost)[0] == 5 and keeper_failed(5, keeper, None)[0] == 5


def _killed_keeper():
    from types import SimpleNamespace

    return SimpleNamespace(
        name='simulator',
        pid=4242,
        process=SimpleNamespace(returncode=-9),
        signal_used=None,
        exited_at=None,
        error_line=lambda: None,
    )


@pytest.mark.ros  # the Steps are serialized by rclpy
def test_a_killed_simulators_failure_is_at_the_latest_step_and_time_the_orchestrator_knows(tmp_path):
    """Issue 28: a killed simulator's summary recorded the failure at t = 0.0 and step null though
    the run was past step 20: the time and step are now the latest of its last progress line (once
    a second) and the bag's last Step, or null with the reason."""
    from rclpy.serialization import serialize_message

    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import Step
    from formation_sim.bag.io import BagWriter
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.launch.results import summary_of_what_is_known

    scenario = load_scenario('paper_single')
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/formation/step', 'std_msgs/msg/Float64MultiArray')
        for index in range(24):
            step = Step(index=index, time=index * 0.01, due=(1,))
            writer.write('/formation/step', round(step.time * 1e9), serialize_message(encode_step(step)))

    def failure(progress_line: str, bag_dir: Path) -> dict:
        keeper = _killed_keeper()
        data, note = summary_of_what_is_known(
            keeper,
            scenario=scenario,
            horizon=10.0,
            mode='distributed',
            bag=bag_dir,
            run_dir=tmp_path,
            status=3,
            last_progress=progress_line,
            children=[keeper],
            launched=0.0,
        )
        # A bag of Steps only: nothing to rebuild the run from, and the note says why.
        assert not data.started and (note is None) == (not (bag_dir / 'metadata.yaml').is_file())
        assert note is None or note.startswith('the bag could not be read back: ')
        return data.extra['failure']

    # The last progress line (a second old) said step 4; the bag holds Steps up to 23 at t = 0.23.
    got = failure('t=0.000001 horizon=10 events=7 steps=4 wall=1.0s', bag)
    assert (got['time'], got['step']) == (0.23, 23) and 'time_unknown' not in got
    assert got['time_from'] == "its last progress line and the bag's last Step"
    # A later progress line than the bag: the progress line's.
    got = failure('t=0.5 horizon=10 events=70 steps=50 wall=2.0s', bag)
    assert (got['time'], got['step']) == (0.5, 50)
    # Neither: null, and why.
    got = failure('', tmp_path / 'no_bag')
    assert got['time'] is None and got['step'] is None
    assert got['time_unknown'] == 'the simulator printed no progress line and the bag holds no Step'
