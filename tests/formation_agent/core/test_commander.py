"""A robot's velocity commands within its limits: clipped values, counts, largest values asked for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.commander import (
    Limits,
    RobotCommander,
    SaturationLog,
    limit_body_velocity,
    limit_world_velocity,
)
from formation_agent.core.kinds import Geometry
from formation_agent.core.kinematics import control_point_rate
from formation_msgs_py.lockstep import Saturation


def test_a_holonomic_speed_is_scaled_to_the_limit_keeping_its_direction():
    log = SaturationLog()
    limits = Limits(linear_speed=0.22)
    assert np.array_equal(limit_world_velocity([0.1, -0.15], limits, log), [0.1, -0.15])  # 0.18 m/s: below
    clipped = limit_world_velocity([0.3, 0.4], limits, log)
    assert np.allclose(clipped, [0.132, 0.176], rtol=1e-15) and np.linalg.norm(clipped) == pytest.approx(
        0.22, rel=1e-15
    )
    limit_world_velocity([0.0, -7.5], limits, log)
    limit_world_velocity([0.0, 0.22], limits, log)  # at the limit: not clipped
    assert log.records == {'linear_speed': Saturation(count=2, largest_requested=7.5, allowed=0.22)}


def test_a_differential_drive_command_is_scaled_by_one_factor():
    log = SaturationLog()
    limits = Limits(linear_speed=0.22, angular_speed=2.84)
    assert limit_body_velocity(0.5, 1.0, limits, log) == pytest.approx((0.22, 0.44), rel=1e-15)
    assert limit_body_velocity(0.1, -5.68, limits, log) == pytest.approx((0.05, -2.84), rel=1e-15)
    v, omega = limit_body_velocity(-0.44, 11.36, limits, log)  # both over: the stricter factor, 1/4
    assert (v, omega) == pytest.approx((-0.11, 2.84), rel=1e-15)
    assert limit_body_velocity(0.22, -2.84, limits, log) == (0.22, -2.84)
    assert log.records == {
        'linear_speed': Saturation(count=2, largest_requested=0.5, allowed=0.22),
        'angular_speed': Saturation(count=2, largest_requested=11.36, allowed=2.84),
    }


def test_a_clipped_unicycle_keeps_its_control_point_on_course():
    rng = np.random.default_rng(2)
    limits = Limits(linear_speed=0.22, angular_speed=2.84)
    commander = RobotCommander(
        drive='unicycle', dimension=2, limits=limits, geometry=Geometry(control_point_distance=0.1)
    )
    for _ in range(100):
        u = rng.normal(scale=1.0, size=2)
        theta = rng.uniform(-math.pi, math.pi)
        commander.set_control(0.0, u)
        v, omega = commander.command(0.0, theta)
        assert abs(v) <= 0.22 * (1 + 1e-15) and abs(omega) <= 2.84 * (1 + 1e-15)
        moved = control_point_rate(v, omega, theta, 0.1)
        scale = np.linalg.norm(moved) / np.linalg.norm(u)
        assert 0.0 < scale <= 1.0 + 1e-12 and np.allclose(moved, scale * u, atol=1e-12)
    assert commander.commands == 100
    records = commander.saturation.records
    assert (
        records['linear_speed'].count + records['angular_speed'].count >= 100 - 5
    )  # almost all asked too much


def test_eta1_commands_are_the_agents_and_eta2_follows_its_reference():
    holonomic = RobotCommander(drive='holonomic', dimension=3, limits=Limits())
    with pytest.raises(ValueError, match='the agent has not triggered'):
        holonomic.command(0.0)
    holonomic.set_control(0.0, (0.1, 0.2, -0.3))
    assert holonomic.command(5.0) == (0.1, 0.2, -0.3) and holonomic.saturation.records == {}
    double = RobotCommander(drive='holonomic', dimension=2, limits=Limits(linear_acceleration=0.5), k3=0.6)
    with pytest.raises(ValueError, match='needs the sensed velocity'):
        double.set_control(0.0, (1.0, 0.0))
    double.set_control(0.0, (4.0, 0.0), velocity=(1.0, -2.0))  # asks ||(3.4, 1.2)|| = 3.606 m/s²
    double.set_control(1.0, (0.0, 0.0), velocity=(9.0, 9.0))  # later sensed velocities do not reset it
    start = np.array([1.0, -2.0]) + 0.5 * np.array([3.4, 1.2]) / math.hypot(3.4, 1.2)
    assert np.allclose(double.command(1.0), start, atol=1e-15)
    # Both triggers asked for more than 0.5 m/s²: 3.606, then k3 ||q(1)|| = 1.41 (u^d = 0).
    assert double.saturation.records['linear_acceleration'] == Saturation(
        count=2, largest_requested=math.hypot(3.4, 1.2), allowed=0.5
    )


@pytest.mark.parametrize(
    ('options', 'complaint'),
    [
        ({'drive': 'tank', 'dimension': 2}, "drive must be one of ('holonomic', 'unicycle'"),
        (
            {'drive': 'unicycle', 'dimension': 3},
            'a unicycle moves in the plane: dimension p must be 2, got 3',
        ),
        (
            {'drive': 'unicycle', 'dimension': 2, 'geometry': Geometry(control_point_distance=0.0)},
            'control_point_distance l must be > 0, got 0.0',
        ),
    ],
)
def test_a_commander_that_cannot_drive_is_refused(options, complaint):
    with pytest.raises(ValueError) as error:
        RobotCommander(limits=Limits(), **options)
    assert complaint in str(error.value)
    with pytest.raises(ValueError, match=r'limit angular_speed must be > 0 \(inf: none\), got nan'):
        Limits(angular_speed=math.nan)


def test_a_warped_eta1_command_is_the_paper_command_times_the_rate_at_its_time():
    from formation_agent.core.time_warp import TimeWarp

    warp = TimeWarp(paper_starts=(0.0, 0.5), rates=(0.25, 1.0))  # κ = 1 from t = 2 on
    commander = RobotCommander(
        drive='holonomic', dimension=2, limits=Limits(linear_speed=0.3), time_warp=warp
    )
    commander.set_control(0.0, (0.8, -0.6))  # the paper's u_p: 1 m/s
    assert commander.command(1.999) == pytest.approx((0.2, -0.15))  # 0.25 u_p, within the limit
    assert commander.saturation.records == {}
    assert commander.command(2.0) == pytest.approx((0.24, -0.18))  # u_p clipped to 0.3 m/s, counted
    assert len(commander.saturation.records) == 1
    with pytest.raises(ValueError, match='time_warp: ETA-1 only'):
        RobotCommander(drive='holonomic', dimension=2, limits=Limits(), k3=0.6, time_warp=warp)
