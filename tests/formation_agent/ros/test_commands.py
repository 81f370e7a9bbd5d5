"""Command adapters of a real agent process: what a robot receives, against the math done by hand.

The bench (conftest.py) holds the robots still, so the agent's command stays the one of its first
trigger; it is computed here from the poses with the ETA core alone and the robot's command
from it with the formulas written out (diffeomorphism, scaling, (stateqiqj)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.eta import Eta1Agent, Eta2Agent
from formation_msgs_py.types import SensedState

# Each test on a ROS domain of its own (conftest.py, robot_domain).
pytestmark = [pytest.mark.ros, pytest.mark.slow]

DISTANCE = 0.1  # control point ahead of the axle [m]


def _eta1_control(rel_position) -> np.ndarray:
    agent = Eta1Agent(agent_id=1, neighbours={2: (-1.0, 0.0)}, delta=4.0, alpha=10.0, beta=1.0)
    sensed = SensedState(agent=1, stamp=0.0, rel_positions={2: tuple(rel_position)})
    return np.array(agent.trigger(0.0, sensed).control)


def _before_stop(rig) -> list:
    """Every command before the stop: the agent sends the zero command DEFAULT_READER_DEPTH times
    (a frozen robot's reader then holds only zeros when it resumes)."""
    from formation_msgs_py.qos import DEFAULT_READER_DEPTH

    messages = [msg for _, msg in rig.commands]
    before, stop = messages[:-DEFAULT_READER_DEPTH], messages[-DEFAULT_READER_DEPTH:]
    twists = [msg.twist if hasattr(msg, 'twist') else msg for msg in stop]
    assert all((t.linear.x, t.linear.y, t.angular.z) == (0.0, 0.0, 0.0) for t in twists), stop
    return before


def _commands(rig):
    """(v, ω) of every command before the stop."""
    return [(msg.linear.x, msg.angular.z) for msg in _before_stop(rig)]


def _drive(bench, agent_process, **parameters):
    rig = bench(robot='unicycle')
    theta1, theta2 = 0.7, -0.4
    rig.robots[1]['theta'], rig.robots[2]['theta'] = theta1, theta2
    agent = agent_process(robot='unicycle', control_point_distance=DISTANCE, **parameters)
    rig.start()
    rig.spin_until(lambda: len(rig.commands) >= 5, timeout=15.0, what='five commands')
    rig.finish()
    assert rig.wait_for_exit(agent) == 0, agent.stderr
    # Control points: 0.1 m ahead of each axle.
    z1 = np.array([0.0, 0.0]) + DISTANCE * np.array([math.cos(theta1), math.sin(theta1)])
    z2 = np.array([0.5, 0.3]) + DISTANCE * np.array([math.cos(theta2), math.sin(theta2)])
    u = _eta1_control(z1 - z2)
    v = math.cos(theta1) * u[0] + math.sin(theta1) * u[1]
    omega = (-math.sin(theta1) * u[0] + math.cos(theta1) * u[1]) / DISTANCE
    return rig, (v, omega)


def test_a_unicycle_gets_the_diffeomorphisms_body_velocity(bench, agent_process):
    rig, (v, omega) = _drive(bench, agent_process)
    commands = _commands(rig)
    assert len(commands) >= 5 and abs(v) > 0.05 and abs(omega) > 0.5
    assert all(command == pytest.approx((v, omega), rel=1e-12, abs=1e-15) for command in commands), (
        commands[0],
        (v, omega),
    )
    (_, last), (final,) = rig.commands[-1], [report for report in rig.reports if report.final]
    assert (last.linear.x, last.linear.y, last.angular.z) == (0.0, 0.0, 0.0)
    assert final.saturation == {} and final.robot_commands == len(commands)


def test_a_unicycle_beyond_its_limits_is_scaled_down_and_the_clips_reported(bench, agent_process):
    rig, (v, omega) = _drive(bench, agent_process, max_linear_speed=0.05, max_angular_speed=0.5)
    scale = min(0.05 / abs(v), 0.5 / abs(omega))
    assert scale < 1.0
    commands = _commands(rig)
    assert all(command == pytest.approx((v * scale, omega * scale), rel=1e-12) for command in commands)
    (final,) = [report for report in rig.reports if report.final]
    assert final.robot_commands == len(commands)
    for kind, requested, allowed in (('linear_speed', abs(v), 0.05), ('angular_speed', abs(omega), 0.5)):
        if requested > allowed:
            clipped = final.saturation[kind]
            assert clipped.count == len(commands)
            assert (
                clipped.largest_requested == pytest.approx(requested, rel=1e-12)
                and clipped.allowed == allowed
            )
        else:
            assert kind not in final.saturation


def test_eta2_on_a_holonomic_robot_follows_its_velocity_reference_from_odometry(bench, agent_process):
    k3 = 0.6
    rig = bench(robot='holonomic', pose_type='odom')
    rig.robots[1].update(theta=0.3, twist=(0.1, 0.2))  # body twist: 0.1 m/s forward, turning
    rig.robots[2].update(theta=-1.2, twist=(0.05, 0.0))
    agent = agent_process(algorithm='eta2', pose_type='odom', alpha_d=10.0, beta_d=1.0, k1=1.0, k2=1.0, k3=k3)
    rig.start()
    rig.spin_until(lambda: len(rig.commands) >= 20, timeout=15.0, what='twenty commands')
    rig.finish()
    assert rig.wait_for_exit(agent) == 0, agent.stderr
    # What agent 1 senses: the twists rotated into the world frame (holonomic: the origin is the
    # control point).
    q1 = 0.1 * np.array([math.cos(0.3), math.sin(0.3)])
    q2 = 0.05 * np.array([math.cos(-1.2), math.sin(-1.2)])
    agent_core = Eta2Agent(
        agent_id=1, neighbours={2: (-1.0, 0.0)}, delta=4.0, alpha_d=10.0, beta_d=1.0, k1=1.0, k2=1.0, k3=k3
    )
    sensed = SensedState(
        agent=1,
        stamp=0.0,
        rel_positions={2: (-0.5, -0.3)},
        rel_velocities={2: tuple(q1 - q2)},
        velocity=tuple(q1),
    )
    rest = np.array(agent_core.trigger(0.0, sensed).control) / k3  # where (stateqiqj) goes: u^d / k3
    samples = [
        (
            msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9,
            np.array([msg.twist.linear.x, msg.twist.linear.y]),
        )
        for msg in _before_stop(rig)
    ]
    # From any command to any later one: q(b) - u^d/k3 = (q(a) - u^d/k3) e^{-k3 (b - a)} (stamps to the ns).
    (a, qa), *later = samples
    for b, qb in later:
        assert np.allclose(qb - rest, (qa - rest) * math.exp(-k3 * (b - a)), rtol=0, atol=1e-9)
    # It starts at the sensed velocity: the first command is on the same curve from q1 at the trigger,
    # qa - u^d/k3 = (q1 - u^d/k3) e^{-k3 Δ}, Δ its delay after the trigger.  Δ < 1 s: a loaded machine
    # may hold the agent between sensing and sending (this said |qa - q1| < 1 % of |u^d/k3 - q1|,
    # which left it 17 ms).
    ratio = float(np.dot(qa - rest, q1 - rest) / np.dot(q1 - rest, q1 - rest))
    assert np.allclose(qa - rest, ratio * (q1 - rest), rtol=0, atol=1e-9), (qa, q1, rest)
    assert math.exp(-k3 * 1.0) < ratio <= 1.0 + 1e-12, -math.log(ratio) / k3
    assert samples[-1][0] - a > 0.2  # the reference did move over the commands compared
    assert [msg.twist.linear.x for _, msg in rig.commands[-1:]] == [0.0]
