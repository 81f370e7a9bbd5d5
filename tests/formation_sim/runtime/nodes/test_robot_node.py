"""The simulated robot node in one process: it moves exactly as its command says between ticks,
takes only commands in its frame, and stops when commands stop coming."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros

DOMAIN_ID = 161


class _Probe:
    """A test node: publishes commands to robot i and keeps what the robot publishes."""

    def __init__(self, context, robot_id: int, *, holonomic: bool) -> None:
        from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.node import Node

        from formation_msgs_py.topics import (
            robot_command_topic,
            robot_odom_topic,
            robot_pose_topic,
            robot_true_odom_topic,
        )
        from formation_sim.runtime.nodes.robot_node import ROBOT_QOS

        self.node = Node(f'probe_{robot_id}', context=context, start_parameter_services=False)
        self.truth: list = []
        self.odom: list = []
        self.poses: list = []
        self.commands = self.node.create_publisher(
            TwistStamped if holonomic else Twist, robot_command_topic(robot_id), ROBOT_QOS
        )
        self.node.create_subscription(Odometry, robot_true_odom_topic(robot_id), self.truth.append, ROBOT_QOS)
        self.node.create_subscription(Odometry, robot_odom_topic(robot_id), self.odom.append, ROBOT_QOS)
        self.node.create_subscription(PoseStamped, robot_pose_topic(robot_id), self.poses.append, ROBOT_QOS)


def _robot(context, *, shared: bool = False, **parameters):
    """A robot ticked by its own timer, or (`shared`) by a `RobotTicker` as in a process of several."""
    from formation_agent.ros.parameters import as_overrides
    from formation_sim.runtime.nodes.robot_node import RobotTicker, SimulatedRobotNode

    robot = SimulatedRobotNode(
        namespace=f'/agent_{parameters["robot_id"]}',
        parameter_overrides=as_overrides(parameters),
        context=context,
        own_timer=not shared,
    )
    if shared:
        RobotTicker([robot])
    return robot


def _spin(executor, seconds: float, until=lambda: False) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not until():
        executor.spin_once(timeout_sec=0.01)


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _state(msg) -> tuple[float, float, float]:
    from formation_agent.core.kinematics import yaw

    pose = msg.pose.pose
    q = pose.orientation
    return pose.position.x, pose.position.y, yaw((q.x, q.y, q.z, q.w))


@pytest.fixture
def executor(ros):
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=ros)
    yield executor
    for node in list(executor.get_nodes()):
        executor.remove_node(node)
        node.destroy_node()


@pytest.mark.parametrize('shared', [False, True], ids=['own_timer', 'ticker'])
def test_a_unicycle_drives_exact_arcs_between_ticks_and_stops_when_commands_stop(ros, executor, shared):
    # The command timeout, 1 s: the test needs 5 ticks under the command; with 0.3 s (30 ticks at
    # 100 Hz) a loaded machine that ran the robot's timer less than every 60 ms failed it.
    timeout = 1.0
    from geometry_msgs.msg import Twist, Vector3

    robot = _robot(
        ros,
        shared=shared,
        robot_id=1,
        model='unicycle',
        position=[1.0, 0.5],
        yaw=0.3,
        control_point_distance=0.1,
        command_timeout=timeout,
    )
    probe = _Probe(ros, 1, holonomic=False)
    executor.add_node(robot)
    executor.add_node(probe.node)
    _spin(executor, 30.0, until=lambda: probe.commands.get_subscription_count() > 0 and len(probe.truth) > 2)
    assert probe.truth, 'the robot published no odometry'
    # Placed by its control point: the axle is l behind (1.0, 0.5) along θ = 0.3.
    x, y, yaw = _state(probe.truth[0])
    assert np.allclose([x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)], [1.0, 0.5]) and math.isclose(
        yaw, 0.3
    )

    v, w = 0.2, 1.5
    probe.commands.publish(Twist(linear=Vector3(x=v), angular=Vector3(z=w)))
    sent = time.time()
    # Until it stops on its command timeout: a loaded machine may take longer to get there.
    _spin(executor, 10.0, until=lambda: robot.timeouts >= 1)
    moving = [msg for msg in probe.truth if msg.twist.twist.angular.z == w]
    assert len(moving) >= 5, f'{len(moving)} ticks under the command'
    # Between two ticks under one command, the pose moved along the exact arc (closed form in
    # sim.robots, checked against an ODE solver in test_robots): here against the arc formula.
    for a, b in zip(moving, moving[1:]):
        (xa, ya, ta), (xb, yb, tb) = _state(a), _state(b)
        tau = _stamp(b) - _stamp(a)
        expected = (
            xa + v / w * (math.sin(ta + w * tau) - math.sin(ta)),
            ya - v / w * (math.cos(ta + w * tau) - math.cos(ta)),
        )
        assert np.allclose((xb, yb), expected, atol=1e-7), (tau, (xb, yb), expected)
        assert math.isclose(math.remainder(tb - ta - w * tau, 2 * math.pi), 0.0, abs_tol=1e-7)

    # No command for command_timeout: the robot stops, and stays where it stopped.
    _spin(executor, 0.8)
    stopped = [msg for msg in probe.truth if _stamp(msg) > sent + timeout and msg.twist.twist.linear.x == 0.0]
    assert stopped, 'the robot kept moving without commands'
    assert robot.timeouts == 1
    first_stop = _stamp(stopped[0])
    assert first_stop >= sent + timeout  # never before the timeout
    rests = {_state(msg)[:2] for msg in probe.truth if _stamp(msg) > first_stop}
    assert len(rests) == 1, 'it moved after stopping'
    # What the agent sees: the same poses on pose and odom, body-frame twist (v, 0) and ω.
    assert probe.poses and probe.odom and probe.odom[-1].child_frame_id == 'agent_1/base_link'


def test_robots_of_one_process_tick_on_one_timer_per_rate(ros):
    from formation_agent.ros.parameters import as_overrides
    from formation_sim.runtime.nodes.robot_node import RobotTicker, SimulatedRobotNode

    robots = [
        SimulatedRobotNode(
            namespace=f'/agent_{i}',
            parameter_overrides=as_overrides(
                {'robot_id': i, 'model': 'unicycle', 'position': [float(i), 0.0], 'rate': rate}
            ),
            context=ros,
            own_timer=False,
        )
        for i, rate in ((1, 100.0), (2, 50.0), (3, 100.0))
    ]
    try:
        assert [len(list(robot.timers)) for robot in robots] == [0, 0, 0]
        RobotTicker(robots)
        # Robots 1 and 3 (100 Hz) on robot 1's timer, robot 2 (50 Hz) on its own.
        timers = [[timer.timer_period_ns for timer in robot.timers] for robot in robots]
        assert timers == [[10_000_000], [20_000_000], []]
    finally:
        for robot in robots:
            robot.destroy_node()


def test_a_car_cannot_turn_in_place_and_steers_at_most_its_limit(ros, executor):
    from geometry_msgs.msg import Twist, Vector3

    robot = _robot(
        ros,
        robot_id=3,
        model='car',
        position=[0.0, 0.0],
        yaw=0.0,
        control_point_distance=0.33,
        wheelbase=0.33,
        max_steering_angle=0.42,
        command_timeout=5.0,
    )
    probe = _Probe(ros, 3, holonomic=False)
    executor.add_node(robot)
    executor.add_node(probe.node)
    _spin(executor, 30.0, until=lambda: probe.commands.get_subscription_count() > 0 and len(probe.truth) > 2)
    start = _state(probe.truth[-1])
    assert np.allclose(start, (-0.33, 0.0, 0.0))  # placed by its control point, on the front axle

    probe.commands.publish(Twist(angular=Vector3(z=1.0)))  # a turn in place: no car can
    _spin(executor, 10.0, until=lambda: robot.robot.saturated >= 1)
    _spin(executor, 0.1)
    assert robot.robot.saturated == 1 and robot.robot.command.angular == 0.0
    assert np.allclose(_state(probe.truth[-1]), start)  # it did not move

    v, turn = 0.2, 0.2 * math.tan(0.42) / 0.33  # the sharpest turn at v: |ω| = |v| tan φ_max / L
    probe.commands.publish(Twist(linear=Vector3(x=v), angular=Vector3(z=1.0)))

    def moving_ticks() -> int:
        return sum(msg.twist.twist.linear.x == v for msg in probe.truth)

    _spin(executor, 10.0, until=lambda: robot.robot.saturated >= 2 and moving_ticks() >= 5)
    assert robot.robot.saturated == 2
    moving = [msg for msg in probe.truth if msg.twist.twist.linear.x == v]
    assert len(moving) >= 5 and all(msg.twist.twist.angular.z == turn for msg in moving)
    for a, b in zip(moving, moving[1:]):  # the bicycle's arc at the steering limit
        (xa, ya, ta), (xb, yb, _) = _state(a), _state(b)
        tau = _stamp(b) - _stamp(a)
        expected = (
            xa + v / turn * (math.sin(ta + turn * tau) - math.sin(ta)),
            ya - v / turn * (math.cos(ta + turn * tau) - math.cos(ta)),
        )
        assert np.allclose((xb, yb), expected, atol=1e-7)


def test_a_holonomic_robot_takes_world_frame_commands_only_and_publishes_noisy_late_poses(ros, executor):
    from geometry_msgs.msg import TwistStamped

    robot = _robot(
        ros,
        robot_id=2,
        model='holonomic',
        position=[0.0, 0.0],
        pose_noise=0.01,
        pose_latency=0.05,
        seed=7,
        max_linear_speed=0.22,
    )
    probe = _Probe(ros, 2, holonomic=True)
    executor.add_node(robot)
    executor.add_node(probe.node)
    _spin(
        executor,
        30.0,
        until=lambda: probe.commands.get_subscription_count() > 0 and len(probe.truth) > 2 and probe.odom,
    )

    wrong = TwistStamped()
    wrong.header.frame_id = 'map'
    wrong.twist.linear.x = 0.1
    probe.commands.publish(wrong)
    _spin(executor, 10.0, until=lambda: robot.commands_refused >= 1)
    assert robot.commands_refused == 1 and robot.robot.command is None

    command = TwistStamped()
    command.header.frame_id = 'world'
    command.twist.linear.x, command.twist.linear.y = 0.3, 0.4  # 0.5 m/s: clipped to 0.22
    probe.commands.publish(command)

    def moving_ticks() -> int:
        return sum(msg.twist.twist.linear.x != 0.0 for msg in probe.truth)

    _spin(executor, 10.0, until=lambda: robot.robot.saturated >= 1 and moving_ticks() >= 20)
    assert robot.robot.saturated == 1
    moving = [msg for msg in probe.truth if msg.twist.twist.linear.x != 0.0]
    assert moving and math.isclose(
        math.hypot(moving[-1].twist.twist.linear.x, moving[-1].twist.twist.linear.y), 0.22
    )
    # Measured poses: stamped with the measurement, published pose_latency later, scattered
    # around the truth of the same instant.
    truth = {_stamp(msg): _state(msg)[:2] for msg in probe.truth}
    errors = np.array(
        [np.subtract(_state(msg)[:2], truth[_stamp(msg)]) for msg in probe.odom if _stamp(msg) in truth]
    )
    assert len(errors) > 10
    assert 0.004 < errors.std() < 0.02
    assert _stamp(probe.odom[-1]) <= _stamp(probe.truth[-1]) - 0.04  # the latency


class _Clocks:
    """The robot node's clocks (wall and monotonic), stopped: they move only by `offset`, so a
    process frozen (SIGSTOP) and resumed finds both clocks `offset` s further on than its last tick
    (both run on through a freeze), and a loaded test machine adds nothing between two ticks."""

    def __init__(self) -> None:
        self.offset = 0.0
        self._wall, self._monotonic = time.time(), time.monotonic()

    def time(self) -> float:
        return self._wall + self.offset

    def monotonic(self) -> float:
        return self._monotonic + self.offset


@pytest.mark.parametrize(
    ('gaps', 'moved'),
    [
        ((2.0,), 0.5),  # frozen 2 s right after its command: 0.5 s under it (the timeout), not 2 s
        ((0.3, 0.3), 0.5),  # two ticks 0.3 s apart: stopped 0.5 s after the command, inside the second
        ((0.3,), 0.3),  # within its timeout: it drives on
    ],
    ids=['frozen_2s', 'late_ticks', 'within_timeout'],
)
def test_a_robot_moves_under_its_last_command_for_its_timeout_at_most_however_late_its_next_tick(
    ros, monkeypatch, gaps, moved
):
    """A base's watchdog stops it `command_timeout` after its last command, wherever its ticks fall:
    a robot frozen 2 s (SIGSTOP) found, at its first tick after SIGCONT, that it had gone on under
    its last command for the whole freeze (0.60 m at 0.3 m/s, measured), then stopped."""
    from formation_agent.core.kinds import Geometry
    from formation_sim.runtime.nodes import robot_node
    from formation_sim.sim.robots import Command, Limits, make_robot

    clocks = _Clocks()
    monkeypatch.setattr(robot_node, 'time', clocks)
    robot = _robot(
        ros, shared=True, robot_id=5, model='unicycle', position=[0.0, 0.0], yaw=0.2, command_timeout=0.5
    )
    try:
        command = Command(linear=(0.3,), angular=0.8)
        robot._commands.append((clocks.monotonic(), command))  # as _on_command notes its arrival
        robot.tick()  # takes the command at its arrival (no command latency)
        start_position, start_yaw = robot.robot.position.copy(), robot.robot.yaw
        for gap in gaps:
            clocks.offset += gap
            robot.tick()
        exact = make_robot(
            'unicycle',
            scenario_position=[0.0, 0.0],
            yaw=0.2,
            geometry=Geometry(control_point_distance=0.1),
            limits=Limits(),
        )
        exact.position, exact.yaw = start_position, start_yaw
        exact.set_command(command)
        exact.advance(moved)
        # The clocks stand still between ticks: the robot moved under its command for `moved` s, to the
        # wall clock's resolution as a float (2.4e-7 s at 1.7e9 s, so 1e-7 m at 0.3 m/s).
        close = np.allclose(robot.robot.position, exact.position, rtol=0, atol=1e-6)
        assert close, (robot.robot.position, exact)
        stopped = moved < sum(gaps)
        assert robot.robot.command.is_zero == stopped and robot.timeouts == int(stopped)
    finally:
        robot.destroy_node()
