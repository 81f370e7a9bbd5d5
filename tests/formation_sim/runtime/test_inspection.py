"""Inspecting a robot run never hurts it (issue 19, part 4).

While `formation run robots_square --backend unicycle` runs, a node outside the run does what
`ros2 node list`, `ros2 topic echo --once`, `ros2 topic hz` and `ros2 param describe` do: graph
queries, new readers with ROS's default QoS (reliable, volatile, keep last 10) on a
triggering-information, Step, cmd_vel, odom and Status topic, and parameter service calls on an
agent node.  The run must complete as any robot run does (exit 0, every message it published in
its bag and nothing else) and the agent's parameter services must answer within 2 s.  Real
processes on the wall clock in private ROS domain 37 (this module's own).
"""

from __future__ import annotations

import json
import threading
import time

import pytest

from formation_sim.cli import main

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]

DOMAIN_ID = 37
HORIZON = 8.0
ANSWER_WITHIN = 2.0  # [s] a parameter service call, as `ros2 param describe` waits for it


def _wait(executor, done, *, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < deadline, f'no {what} within {timeout} s'
        executor.spin_once(timeout_sec=0.05)


def _call(executor, client, request) -> tuple[object, float]:
    """The answer of a service call and the seconds it took."""
    began = time.monotonic()
    future = client.call_async(request)
    _wait(executor, future.done, timeout=10.0, what=f'answer from {client.srv_name}')
    return future.result(), time.monotonic() - began


@pytest.mark.alone  # a wall-clock bound: no other ROS test beside it (tests/conftest.py)
@pytest.mark.timeout(300)
def test_a_robot_run_inspected_from_outside_completes_and_its_agents_answer_parameter_calls(ros, tmp_path):
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rcl_interfaces.srv import DescribeParameters, GetParameters
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from std_msgs.msg import Float64MultiArray

    from formation_sim.runtime.launch.orchestrate import FormationRun
    from formation_sim.runtime.launch.plan import RobotOptions

    run = FormationRun(
        'robots_square',
        out_dir=tmp_path / 'run',
        horizon=HORIZON,
        domain_id=DOMAIN_ID,
        progress=False,
        timeout=240.0,
        backend='unicycle',
        robots=RobotOptions(model='unicycle'),
    )
    results = []
    worker = threading.Thread(target=lambda: results.append(run.run()))
    node = Node('inspector', context=ros)
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    worker.start()
    try:
        # `ros2 node list`, `ros2 topic list`: the graph, until the run's agents are in it.
        def agent_listed() -> bool:
            node.get_topic_names_and_types()
            return ('formation_agent', '/agent_1') in node.get_node_names_and_namespaces()

        _wait(executor, agent_listed, timeout=120.0, what='agent node /agent_1/formation_agent in the graph')
        _wait(executor, lambda: 't=' in run.last_progress, timeout=120.0, what='step 0 (the run stepping)')

        # `ros2 topic echo --once` on five topics (default QoS), `ros2 topic hz` on odom (kept).
        default = QoSProfile(depth=10)
        topics = {
            '/agent_1/trigger_info/to_2': Float64MultiArray,
            '/formation/step': Float64MultiArray,
            '/agent_1/robot/cmd_vel': Twist,
            '/agent_1/robot/odom': Odometry,
            '/formation/status': Float64MultiArray,
        }
        heard: dict[str, list] = {topic: [] for topic in topics}
        readers = {
            topic: node.create_subscription(kind, topic, heard[topic].append, default)
            for topic, kind in topics.items()
        }

        # `ros2 param describe /agent_1/formation_agent pose_timeout`, and `ros2 param get`.
        describe = node.create_client(DescribeParameters, '/agent_1/formation_agent/describe_parameters')
        get = node.create_client(GetParameters, '/agent_1/formation_agent/get_parameters')
        _wait(
            executor,
            lambda: describe.service_is_ready() and get.service_is_ready(),
            timeout=10.0,
            what='parameter services',
        )
        described, took_describe = _call(
            executor, describe, DescribeParameters.Request(names=['pose_timeout'])
        )
        got, took_get = _call(executor, get, GetParameters.Request(names=['pose_timeout', 'agent_id']))
        assert took_describe < ANSWER_WITHIN and took_get < ANSWER_WITHIN, (took_describe, took_get)
        (descriptor,) = described.descriptors
        assert descriptor.name == 'pose_timeout' and 'stops the agent' in descriptor.description
        assert [value.double_value for value in got.values[:1]] == [RobotOptions().pose_timeout]
        assert got.values[1].integer_value == 1

        stepping = [
            topic for topic in topics if topic != '/formation/step'
        ]  # Steps: 0 (before we joined) and the final one
        _wait(
            executor,
            lambda: all(heard[topic] for topic in stepping),
            timeout=HORIZON,
            what=f'message on each of {stepping}',
        )
        for topic in stepping[:-1]:  # echo --once: gone after its first message; odom stays, as hz does
            node.destroy_subscription(readers[topic])
        _wait(
            executor,
            lambda: bool(heard['/formation/step']) or not worker.is_alive(),
            timeout=240.0,
            what='final Step',
        )
    finally:
        worker.join(timeout=240.0)
        executor.shutdown()
        node.destroy_node()
    (result,) = results
    assert result.exit_status == 0, result.message
    assert heard['/formation/step'], 'the final Step never reached a default-QoS reader'
    summary = json.loads(result.summary.read_text())
    assert summary['extra']['failure'] is None and summary['max_edge_length'] < summary['delta']
    recording = summary['extra']['recording']  # every message the run published, in its bag, and nothing else
    assert (
        recording['complete']
        and not recording['foreign']
        and recording['recorded'] == recording['published'] > 0
    )
    assert main(['analyze', str(tmp_path / 'run'), '--no-figures', '--quiet']) == 0
