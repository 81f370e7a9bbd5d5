"""Tests of formation_sim.runtime.nodes.operator_stop: the run's emergency stop (issue 27, part 3).

Without ROS, on a stand-in time keeper: what a call does in which order, what it answers, who it
names.  With ROS (real `formation run` processes in private domains 53-56, on the wall clock): a
simulated robot team stopped mid-run by `formation stop` and by a plain rclpy Trigger client, a
run stopped before its Step 0, and a lock-step exact run; each ends with exit status 5,
`extra.failure.kind = stopped_by_operator`, every robot's last command a zero within 1 s of the
call (read from the bag), and `formation analyze` agreeing.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from std_srvs.srv import Trigger

from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.topics import STOP_SERVICE
from formation_sim.runtime.errors import OperatorStopError
from formation_sim.runtime.nodes.operator_stop import CALLER_LOOK, CALLER_WAIT, OperatorStop
from formation_sim.runtime.nodes.run_book import failure_extra

BOUND = 1.0  # [s] issue 27: every robot's zero within this long of the call
TEST_POSE_TIMEOUT = 2.0  # as tests/formation_sim/runtime/launch/test_orchestrate.py: a loaded machine


class _Step:
    def __init__(self, index: int) -> None:
        self.index = index


class _Keeper:
    """What OperatorStop asks of a time keeper, and what it did, in order (`calls`)."""

    def __init__(self, *, step: int | None, finished: bool = False, graph: dict | None = None) -> None:
        self.step = None if step is None else _Step(step)
        self.finished = finished
        self.reached_time = 0.0 if step is None else 1.5
        self.failure = None
        self.failure_info = None
        self.calls: list[str] = []
        self.graph = graph or {}
        self.service = None
        self.world = self  # the world it holds: its robots' zeros recorded here

    def create_service(self, kind, name: str, callback):
        self.service = (kind, name, callback)
        return self.service

    def end_now(self) -> None:
        self.calls.append('final Step')
        self.finished = True

    def stop_robots(self, *, why: str) -> list[int]:
        self.calls.append(f'zeros: {why}')
        return [1, 2, 3, 4]

    def fail(self, error: BaseException) -> None:
        self.calls.append('fail')
        self.failure_info = failure_extra(
            error, interrupted=False, time=self.reached_time, step=None, wall_time=0.0, detected_by='keeper'
        )

    def get_node_names_and_namespaces(self):
        self.calls.append('graph')
        return list(self.graph)

    def get_client_names_and_types_by_node(self, name: str, namespace: str):
        return [(service, ['std_srvs/srv/Trigger']) for service in self.graph[(name, namespace)]]


def _call(keeper: _Keeper) -> Trigger.Response:
    kind, name, callback = keeper.service
    assert kind is Trigger and name == STOP_SERVICE == '/formation/stop'
    return callback(Trigger.Request(), Trigger.Response())


def test_a_call_sends_the_final_step_and_the_zeros_before_it_looks_who_asked_and_a_second_call_is_told():
    graph = {
        ('formation_coordinator', '/'): [],
        ('formation_agent', '/agent_1'): [STOP_SERVICE],  # the run's own nodes are never who asked
        ('formation_recorder', '/'): [STOP_SERVICE],
        ('formation_stop_lab_42', '/'): [STOP_SERVICE],
        ('_ros2cli_123', '/'): ['/other/service'],
    }
    keeper = _Keeper(step=3, graph=graph)
    stop = OperatorStop(keeper)
    response = _call(keeper)
    assert response.success
    assert response.message == (
        'stopping the run at t=1.5 (step 3): every robot is sent a zero command (4 robots)'
    )
    assert keeper.calls == ['final Step', 'zeros: an operator stopped the run', 'graph', 'fail']
    assert isinstance(keeper.failure, OperatorStopError)
    assert keeper.failure_info['kind'] == 'stopped_by_operator'
    assert keeper.failure_info['asked_by'] == ['/formation_stop_lab_42']
    assert keeper.failure_info['message'] == (
        'stopped by /formation_stop_lab_42 at t=1.5 (step 3) (the emergency stop, /formation/stop)'
    )
    assert stop.requested and stop.asked['step'] == 3

    again = _call(keeper)
    assert again.success
    assert again.message == 'the run is already stopping (asked by /formation_stop_lab_42 at t=1.5 (step 3))'
    assert keeper.calls == [
        'final Step',
        'zeros: an operator stopped the run',
        'graph',
        'fail',
    ]  # nothing more


class _StoppedTime:
    """operator_stop's `time`, stopped: sleep(s) moves it by exactly s, and nothing else does (on
    the wall clock a loaded machine's late wake-ups from time.sleep made fewer looks)."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def time(self) -> float:
        return 1.7e9 + self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def test_a_call_before_step_0_sends_no_step_and_names_an_operator_when_the_graph_shows_none(monkeypatch):
    from formation_sim.runtime.nodes import operator_stop

    clock = _StoppedTime()
    monkeypatch.setattr(operator_stop, 'time', clock)
    keeper = _Keeper(step=None)
    OperatorStop(keeper)
    response = _call(keeper)
    assert response.success
    assert response.message == (
        'stopping the run before it started (no Step 0: no robot has moved): every robot is sent a zero '
        'command (4 robots)'
    )
    # The graph looked at for CALLER_WAIT (a caller's node name may come after its request).
    looks = keeper.calls.count('graph')
    assert keeper.calls == ['zeros: an operator stopped the run'] + ['graph'] * looks + ['fail']
    # One look at once, then one every CALLER_LOOK until CALLER_WAIT has passed (one more if the
    # sum of the sleeps rounds below it).
    assert CALLER_WAIT / CALLER_LOOK + 1 <= looks <= CALLER_WAIT / CALLER_LOOK + 2, looks
    assert CALLER_WAIT <= clock.now - 1000.0 < CALLER_WAIT + CALLER_LOOK + 1e-9
    assert keeper.failure_info['message'] == (
        'stopped by an operator before step 0 (the emergency stop, /formation/stop)'
    )
    assert keeper.failure_info['asked_by'] == [] and keeper.failure_info['kind'] == 'stopped_by_operator'


def test_a_caller_whose_node_name_comes_after_its_request_is_still_named():
    keeper = _Keeper(step=2, graph={('formation_simulator', '/'): []})
    looked = keeper.get_node_names_and_namespaces

    def later():  # the third look finds the caller
        if keeper.calls.count('graph') == 2:
            keeper.graph[('formation_stop_lab_7', '/')] = [STOP_SERVICE]
        return looked()

    keeper.get_node_names_and_namespaces = later
    OperatorStop(keeper)
    _call(keeper)
    assert keeper.calls.count('graph') == 3 and keeper.failure_info['asked_by'] == ['/formation_stop_lab_7']


def test_a_call_after_the_end_stops_the_robots_again_and_is_no_failure():
    keeper = _Keeper(step=1, finished=True)
    stop = OperatorStop(keeper)
    response = _call(keeper)
    assert response.success
    assert response.message == (
        'the run already ended at t=1.5 (its final Step is out): every robot is sent a zero command again '
        '(4 robots)'
    )
    assert keeper.calls == ['zeros: an operator asked to stop the run after its end']
    assert keeper.failure is None and not stop.requested


def test_the_simulator_has_no_robots_and_says_what_stops():
    keeper = _Keeper(step=7)
    keeper.stop_robots = lambda why: []  # the exact world: it stops with the final Step
    OperatorStop(keeper)
    assert _call(keeper).message == (
        'stopping the run at t=1.5 (step 7): the final Step is out, every agent stops and leaves'
    )


# -- live runs (ROS) ------------------------------------------------------------------------------


def _zero_ends(bag: Path, agents) -> dict[int, float]:
    """Per robot, when (Unix time) the recorder received the zero command that ends its command
    stream: the first zero after its last non-zero command (a wall-clock bag is stamped with the
    time since Step 0's epoch)."""
    from formation_msgs_py.codec import decode_step
    from formation_sim.bag.io import decode, read_bag

    stream: dict[int, list[tuple[float, bool]]] = {agent: [] for agent in agents}
    epoch = None
    for message in read_bag(bag):
        if message.topic == '/formation/step' and epoch is None:
            epoch = decode_step(decode(message.rawdata, message.msgtype)).epoch
        if message.topic.endswith('/robot/cmd_vel'):
            agent = int(message.topic.split('/')[1].removeprefix('agent_'))
            msg = decode(message.rawdata, message.msgtype)
            twist = msg.twist if message.msgtype.endswith('TwistStamped') else msg
            values = (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y)
            stream[agent].append((message.timestamp_ns * 1e-9, not any((*values, twist.angular.z))))
    ends = {}
    for agent, commands in stream.items():
        if commands and commands[-1][1]:
            last_moving = max((n for n, (_, zero) in enumerate(commands) if not zero), default=-1)
            ends[agent] = epoch + commands[last_moving + 1][0]
    return ends


def _robot_run(tmp_path: Path, *, model: str, domain: int, backend: str | None = None):
    from formation_sim.runtime.launch.orchestrate import FormationRun
    from formation_sim.runtime.launch.plan import RobotOptions

    return FormationRun(
        'robots_square',
        out_dir=tmp_path / 'run',
        horizon=60.0,
        domain_id=domain,
        progress=False,
        timeout=240.0,
        backend=backend or model,
        robots=RobotOptions(model=model, pose_timeout=TEST_POSE_TIMEOUT, robots_per_process=4),
    )


def _assert_stopped_by_the_operator(result, *, asked_by: str, called_at: float, capsys) -> dict:
    """Exit 5, the summary's failure, every robot's last command a zero within BOUND of the call,
    `formation analyze` agreeing: the latencies per robot."""
    from formation_sim.cli import main

    assert result.exit_status == ExitCode.STOPPED == 5, result.message
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'stopped_by_operator' and result.failure == failure, failure
    assert failure['asked_by'] == [asked_by] and f'stopped by {asked_by} at t=' in failure['message']
    assert 0.0 < failure['time'] == summary['extra']['reached_time'] < 60.0 and failure['step'] == 0
    assert result.message.startswith(failure['message'])
    ends = _zero_ends(result.bag, (1, 2, 3, 4))
    assert set(ends) == {1, 2, 3, 4}, ends
    latencies = {agent: end - called_at for agent, end in ends.items()}
    assert all(0.0 < latency < BOUND for latency in latencies.values()), latencies
    capsys.readouterr()
    assert main(['analyze', str(result.out_dir), '--no-figures', '--no-animation']) == 0, capsys.readouterr()
    err = capsys.readouterr().err
    assert 'the run stopped early at t = ' in err and 'stopped_by_operator: stopped by' in err, err
    report = json.loads((result.out_dir / 'analysis' / 'analysis.json').read_text())
    last = next(c for c in report['bag_checks'] if c['name'] == "every robot's last command is a stop")
    assert last['ok'], last
    slowest = max(latencies.values())
    print(f'{result.out_dir.name}: every robot stopped {slowest:.3f} s after the call {latencies}')
    return latencies


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.alone  # a wall-clock bound: no other ROS test beside it (tests/conftest.py)
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_formation_stop_stops_a_holonomic_team_mid_run(tmp_path, stepping_run, capsys):
    """`formation stop --domain-id 53` from another process, as an operator's terminal: the run
    ends (exit 5, stopped_by_operator naming the command's node), every robot's zero within 1 s of
    the time keeper taking the call, `formation analyze` passes and names the stop."""
    env = {**os.environ, 'ROS_LOG_DIR': str(tmp_path / 'ros_log')}
    env.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)  # the command's own default: LOCALHOST, as the run's
    stepping = stepping_run(_robot_run(tmp_path, model='holonomic', domain=53))
    time.sleep(1.0)  # well into the run
    done = subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', 'stop', '--domain-id', '53'],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith('formation stop: stopping the run at t='), done.stdout
    assert done.stdout.rstrip().endswith('(step 0): every robot is sent a zero command (4 robots)')
    result = stepping.result(timeout=120.0)
    summary = json.loads(result.summary.read_text())
    caller = summary['extra']['failure']['asked_by'][0]
    assert re.fullmatch(r'/formation_stop_\w+_[0-9]+', caller), caller  # formation_stop_<host>_<pid>
    # When the coordinator took the call: its final Step (extra.timestamps, Unix time).
    taken_at = summary['extra']['timestamps']['final_step']
    _assert_stopped_by_the_operator(result, asked_by=caller, called_at=taken_at, capsys=capsys)


class _Operator:
    """A plain rclpy Trigger client of the stop service, as an operator panel's program would be."""

    NAME = 'operator_panel'

    def __init__(self, domain: int) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node(self.NAME, context=self.context)
        self.client = self.node.create_client(Trigger, STOP_SERVICE)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def wait_for_service(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not self.client.service_is_ready():
            assert time.monotonic() < deadline, f'no {STOP_SERVICE} within {timeout} s'
            time.sleep(0.01)

    def call(self, *, times: int = 1) -> tuple[float, list[Trigger.Response]]:
        """(the Unix time of the first call, the answers): `times` requests sent back to back, so
        that a later one reaches the service while the run is still alive (on a loaded machine the
        first answer can come back after the stopped run has ended)."""
        called_at = time.time()
        futures = [self.client.call_async(Trigger.Request()) for _ in range(times)]
        deadline = time.monotonic() + 30.0
        while not all(future.done() for future in futures) and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.1)
        assert all(future.done() for future in futures), 'the run did not answer within 30 s'
        return called_at, [future.result() for future in futures]

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.alone  # a wall-clock bound: no other ROS test beside it (tests/conftest.py)
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_trigger_client_stops_a_unicycle_team_mid_run(tmp_path, stepping_run, capsys):
    """A plain rclpy client calls /formation/stop (std_srvs/srv/Trigger): the answer says the run
    stops and every robot is sent a zero; every robot's zero within 1 s of the call; exit 5, and
    `formation analyze` agrees.  (A second call is answered only while the stopped run is still
    ending: two fresh-clone runs found it gone, even with both requests sent at once; the answer to
    a second call is tested on a stand-in keeper above.)"""
    operator = _Operator(54)
    try:
        stepping = stepping_run(_robot_run(tmp_path, model='unicycle', domain=54))
        time.sleep(1.0)
        operator.wait_for_service(30.0)
        called_at, (answer,) = operator.call()
        assert answer.success and answer.message.startswith('stopping the run at t='), answer.message
        assert answer.message.endswith('(step 0): every robot is sent a zero command (4 robots)')
        result = stepping.result(timeout=120.0)
    finally:
        operator.close()
    _assert_stopped_by_the_operator(result, asked_by=f'/{_Operator.NAME}', called_at=called_at, capsys=capsys)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_call_before_step_0_stops_the_run_before_it_starts(tmp_path, capsys):
    """External robots that never come: discovery waits for their poses.  A call then ends the run
    before its Step 0 (exit 5, summary.json started false, stopped_by_operator); the bag holds no
    Step and no robot command but zeros; `formation analyze` says there is no run to analyse."""
    from formation_sim.bag.io import decode, read_bag
    from formation_sim.cli import main

    operator = _Operator(55)
    results = []
    try:
        run = _robot_run(tmp_path, model='unicycle', domain=55, backend='external')
        worker = threading.Thread(target=lambda: results.append(run.run()), daemon=True)
        worker.start()
        operator.wait_for_service(120.0)
        _, (answer,) = operator.call()
        worker.join(timeout=120.0)
    finally:
        operator.close()
    assert answer.success and answer.message == (
        'stopping the run before it started (no Step 0: no robot has moved): every robot is sent a zero '
        'command (4 robots)'
    )
    (result,) = results
    assert result.exit_status == ExitCode.STOPPED, result.message
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'stopped_by_operator' and failure['step'] is None, failure
    assert failure['message'] == (
        f'stopped by /{_Operator.NAME} before step 0 (the emergency stop, /formation/stop)'
    )
    assert summary['extra']['started'] is False and summary['extra']['steps'] == 0
    steps, commands = 0, []
    for message in read_bag(result.bag):
        if message.topic == '/formation/step':
            steps += 1
        elif message.topic.endswith('/robot/cmd_vel'):
            twist = decode(message.rawdata, message.msgtype)
            commands.append((twist.linear.x, twist.linear.y, twist.angular.z))
    assert steps == 0 and not any(any(c) for c in commands), commands
    capsys.readouterr()
    assert main(['analyze', str(result.out_dir), '--no-figures']) == 2
    assert 'the run did not start (no Step 0; extra.failure stopped_by_operator: stopped by' in (
        capsys.readouterr().err
    )


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_lock_step_exact_run_is_stopped_too(tmp_path, stepping_run, long_run_scenario, capsys):
    """The simulator serves the stop as well: a lock-step run of the exact world ends at the step
    it was in (exit 5), and `formation analyze` finds the bag as summary.json says."""
    from formation_sim.cli import main
    from formation_sim.runtime.launch.orchestrate import FormationRun

    operator = _Operator(56)
    try:
        run = FormationRun(
            long_run_scenario, out_dir=tmp_path / 'run', domain_id=56, progress=False, timeout=240.0
        )
        stepping = stepping_run(run)
        operator.wait_for_service(30.0)
        _, (answer,) = operator.call()
        result = stepping.result(timeout=120.0)
    finally:
        operator.close()
    assert answer.success and answer.message.startswith('stopping the run at t='), answer.message
    assert answer.message.endswith(': the final Step is out, every agent stops and leaves')
    assert result.exit_status == ExitCode.STOPPED, result.message
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'stopped_by_operator' and failure['asked_by'] == [f'/{_Operator.NAME}']
    assert 0.0 < failure['time'] == summary['extra']['reached_time'] < 600.0 and failure['step'] > 0
    capsys.readouterr()
    assert main(['analyze', str(result.out_dir), '--no-figures']) == 0, capsys.readouterr()
    assert 'stopped_by_operator: stopped by' in capsys.readouterr().err
