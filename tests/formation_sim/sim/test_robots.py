"""Kinematic robots (ROS-free): exact motion under held commands, limits, noise, and how a robot
run's poses become samples."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from formation_agent.core import kinematics
from formation_agent.core.kinds import Geometry
from formation_sim.sim.errors import RobotError
from formation_sim.sim.robots import (
    Command,
    HolonomicRobot,
    Limits,
    PoseNoise,
    PoseTrack,
    RobotSample,
    UnicycleRobot,
    axle_position,
    control_point,
    make_robot,
    odometry_sample,
    pose_sample,
    quaternion_from_yaw,
    run_time,
    sample_times,
    trajectory_samples,
)


def _unicycle_ode(v: float, w: float):
    return lambda t, s: [v * math.cos(s[2]), v * math.sin(s[2]), w]


@pytest.mark.parametrize(
    ('v', 'w', 'duration'), [(0.22, 2.84, 1.7), (-0.1, 0.3, 5.0), (0.2, -1e-9, 3.0), (0.15, 0.0, 2.0)]
)
def test_the_unicycle_drives_the_exact_arc_of_a_held_command(v, w, duration):
    robot = UnicycleRobot(position=[0.3, -1.2], yaw=0.7)
    robot.set_command(Command(linear=(v,), angular=w))
    # In pieces of every length, the closed form composes to the same arc the ODE gives.
    for piece in (0.01, 0.2, duration - 0.21):
        robot.advance(piece)
    reference = solve_ivp(
        _unicycle_ode(v, w), (0.0, duration), [0.3, -1.2, 0.7], rtol=1e-12, atol=1e-12, method='DOP853'
    )
    x, y, yaw = reference.y[:, -1]
    assert np.allclose(robot.position, [x, y], atol=1e-10)
    assert math.isclose(math.remainder(robot.yaw - yaw, 2 * math.pi), 0.0, abs_tol=1e-10)


def test_a_straight_unicycle_line_has_no_cancellation():
    # ω = 0 exactly: the chord is v τ along the heading, to the last bit of a plain product.
    robot = UnicycleRobot(position=[0.0, 0.0], yaw=0.0)
    robot.set_command(Command(linear=(0.2,), angular=0.0))
    robot.advance(0.01)
    assert robot.position.tolist() == [0.2 * 0.01, 0.0]


def test_a_holonomic_robot_moves_on_the_straight_line_of_its_world_velocity():
    robot = HolonomicRobot(position=[1.0, 2.0, 0.5])
    robot.set_command(Command(linear=(0.1, -0.2, 0.05), angular=0.5))
    robot.advance(2.0)
    assert np.allclose(robot.position, [1.2, 1.6, 0.6], rtol=0, atol=1e-15)
    assert math.isclose(robot.yaw, 1.0)


def test_limits_clip_commands_as_a_base_does_and_count_them():
    holonomic = HolonomicRobot(position=[0.0, 0.0], limits=Limits(linear=0.22, angular=2.84))
    applied = holonomic.set_command(Command(linear=(0.3, 0.4), angular=0.0))  # 0.5 m/s, direction kept
    assert np.allclose(applied.linear, [0.132, 0.176]) and math.isclose(
        float(np.linalg.norm(applied.linear)), 0.22
    )
    holonomic.set_command(Command(linear=(0.1, 0.1), angular=0.0))
    assert holonomic.saturated == 1
    unicycle = UnicycleRobot(position=[0.0, 0.0], limits=Limits(linear=0.22, angular=2.84))
    assert unicycle.set_command(Command(linear=(-0.5,), angular=3.0)) == Command(
        linear=(-0.22,), angular=2.84
    )
    assert unicycle.set_command(Command(linear=(0.1,), angular=-9.0)).angular == -2.84
    assert unicycle.saturated == 2
    with pytest.raises(RobotError, match='must be > 0'):
        Limits(linear=0.0)


def test_a_unicycle_is_placed_by_its_control_point():
    robot = make_robot(
        'unicycle',
        scenario_position=[1.0, 1.0],
        yaw=math.pi / 2,
        geometry=Geometry(control_point_distance=0.1),
        limits=Limits(),
    )
    assert np.allclose(robot.position, [1.0, 0.9])
    assert np.allclose(robot.scenario_position(), [1.0, 1.0])
    assert np.allclose(axle_position(control_point([0.4, -0.3], 2.0, 0.25), 2.0, 0.25), [0.4, -0.3])
    with pytest.raises(RobotError, match='a unicycle moves in the plane: dimension p must be 2, got 3'):
        make_robot(
            'unicycle',
            scenario_position=[1.0, 1.0, 0.0],
            yaw=0.0,
            geometry=Geometry(control_point_distance=0.1),
            limits=Limits(),
        )


def test_noise_is_seeded_per_robot_and_has_the_asked_spread():
    first = PoseNoise(position_sigma=0.005, yaw_sigma=0.0, seed=3, robot_id=1)
    again = PoseNoise(position_sigma=0.005, yaw_sigma=0.0, seed=3, robot_id=1)
    other = PoseNoise(position_sigma=0.005, yaw_sigma=0.0, seed=3, robot_id=2)
    here = np.zeros(2)
    a = np.array([first.measure(here, 0.0)[0] for _ in range(4000)])
    b = np.array([again.measure(here, 0.0)[0] for _ in range(4000)])
    c = np.array([other.measure(here, 0.0)[0] for _ in range(4000)])
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert 0.0048 < a.std() < 0.0052  # 4000 draws: the standard error of σ is ~1 %
    assert first.measure(here, 0.3)[1] == 0.3  # no heading noise asked


def test_quaternions_and_stamps():
    for yaw in (-3.0, -0.5, 0.0, 1.2, 3.1):
        assert math.isclose(kinematics.yaw(quaternion_from_yaw(yaw)), yaw, abs_tol=1e-15)
    stamp = SimpleNamespace(sec=1_700_000_123, nanosec=250_000_000)
    assert run_time(stamp, 1_700_000_120.5) == 2.75


def _odometry(x, y, yaw, v, w, sec=100, nanosec=0):
    qx, qy, qz, qw = quaternion_from_yaw(yaw)
    pose = SimpleNamespace(
        position=SimpleNamespace(x=x, y=y, z=0.0), orientation=SimpleNamespace(x=qx, y=qy, z=qz, w=qw)
    )
    twist = SimpleNamespace(
        linear=SimpleNamespace(x=v, y=0.0, z=0.0), angular=SimpleNamespace(x=0.0, y=0.0, z=w)
    )
    return SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
        pose=SimpleNamespace(pose=pose),
        twist=SimpleNamespace(twist=twist),
    )


def test_a_unicycle_pose_is_read_as_its_control_point_and_its_velocity():
    msg = _odometry(1.0, 2.0, math.pi / 2, 0.2, 1.0)
    sample = odometry_sample(msg, model='unicycle', dimension=2, control_point_distance=0.1, epoch=99.0)
    assert sample.time == 1.0
    assert np.allclose(sample.position, [1.0, 2.1])
    # Axle (0, 0.2) plus l ω (−sin θ, cos θ) = (−0.1, 0).
    assert np.allclose(sample.velocity, [-0.1, 0.2])
    stamped = SimpleNamespace(header=msg.header, pose=msg.pose.pose)
    assert np.allclose(
        pose_sample(stamped, model='holonomic', dimension=2, control_point_distance=0.0, epoch=99.0).position,
        [1.0, 2.0],
    )


def test_tracks_are_sampled_by_interpolation_held_at_their_ends():
    samples = [RobotSample(time=t, position=np.array([t, 2 * t])) for t in (0.3, -0.01, 0.1, 0.1)]
    track = PoseTrack.from_samples(samples)
    assert track.times.tolist() == [-0.01, 0.1, 0.3] and track.velocities is None
    other = PoseTrack.from_samples([RobotSample(time=0.0, position=np.array([5.0, 5.0]))])
    positions, velocities = trajectory_samples({1: track, 2: other}, (1, 2), np.array([0.0, 0.2, 1.0]))
    assert np.allclose(velocities[:, 1], 0.0)  # from pose differences: robot 2 stands still
    # Within a track that moves at a constant velocity, the differences give that velocity.
    _, velocities = trajectory_samples({1: track}, (1,), np.array([0.0, 0.1, 0.25]))
    assert np.allclose(velocities[:, 0], [[1.0, 2.0]] * 3)
    assert np.allclose(positions[:, 0], [[0.0, 0.0], [0.2, 0.4], [0.3, 0.6]])
    assert np.allclose(positions[:, 1], [[5.0, 5.0]] * 3)
    with pytest.raises(RobotError, match='no pose'):
        PoseTrack.from_samples([])


def test_the_sample_grid_holds_the_horizon_and_every_event():
    times = sample_times(0.05, 0.02, events=[0.013, 0.04, 0.07])
    assert times.tolist() == [0.0, 0.013, 0.02, 0.04, 0.05]


def test_the_poses_sampled_at_a_runs_end_skip_a_robot_resumed_after_a_freeze_and_poses_long_past_it():
    from formation_sim.sim.robots import POSES_AFTER_END, RobotSample, poses_for_end

    def track(*times):
        return [RobotSample(time=t, position=np.array([t, 0.0]), velocity=None) for t in times]

    steady = track(3.98, 3.99, 4.0, 4.01, 4.0 + POSES_AFTER_END + 0.01)
    assert [p.time for p in poses_for_end(steady, 4.0, silence=0.5)] == [3.98, 3.99, 4.0, 4.01]
    # Frozen at t = 3.4, resumed at t = 4.7: the pose after the end comes 1.3 s after the last
    # before it, more than the silence: held at t = 3.4 (the coordinator may or may not have got it).
    frozen = track(3.39, 3.4, 4.7, 4.71)
    assert [p.time for p in poses_for_end(frozen, 4.0, silence=0.5)] == [3.39, 3.4]
    assert [p.time for p in poses_for_end(frozen, 4.0, silence=None)] == [
        3.39,
        3.4,
        4.7,
        4.71,
    ]  # a bag without it
