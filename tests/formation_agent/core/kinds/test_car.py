"""The car kind: exact where its steering constraint is not active, the nearest followable velocity
where it is (counted as saturation 'steering'), a base that cannot turn in place, the bicycle's arc."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from formation_agent.core.commander import RobotCommander
from formation_agent.core.errors import KindError
from formation_agent.core.kinds import Geometry, robot_kind
from formation_agent.core.kinds.car import curvature, steer, steering_angle
from formation_agent.core.kinematics import control_point_rate
from formation_agent.core.limits import Limits, SaturationLog
from formation_msgs_py.lockstep import SATURATION_KINDS

CAR = robot_kind('car')
GEOMETRY = Geometry(control_point_distance=0.33, wheelbase=0.33)
LIMITS = Limits(steering_angle=0.42)
KAPPA = math.tan(0.42) / 0.33


def _angle_to_heading_axis(u, heading):
    """The angle between u and the nearer of ±(cos θ, sin θ), in [0, π/2]."""
    along = abs(u[0] * math.cos(heading) + u[1] * math.sin(heading))
    across = abs(-u[0] * math.sin(heading) + u[1] * math.cos(heading))
    return math.atan2(across, along)


def test_where_the_steering_constraint_is_not_active_the_car_follows_u_exactly():
    """Inside the cone of half-angle atan(l κ) about ±heading the adapter is the unicycle's
    diffeomorphism: the control point moves with u (to rounding), nothing is counted."""
    rng = np.random.default_rng(11)
    psi = math.atan(GEOMETRY.control_point_distance * KAPPA)
    followed = 0
    for _ in range(2000):
        u = rng.normal(size=2)
        heading = rng.uniform(-math.pi, math.pi)
        if _angle_to_heading_axis(u, heading) >= psi * (1 - 1e-9):
            continue
        log = SaturationLog()
        v, omega = CAR.command(u, heading=heading, geometry=GEOMETRY, limits=LIMITS, log=log)
        assert np.allclose(
            control_point_rate(v, omega, heading, GEOMETRY.control_point_distance), u, rtol=0, atol=1e-14
        )
        assert abs(omega) <= abs(v) * KAPPA and log.records == {}
        assert (v, omega) == robot_kind('unicycle').command(
            u, heading=heading, geometry=GEOMETRY, limits=Limits(), log=log
        )
        followed += 1
    assert followed > 300  # ψ = 0.42 rad: about 2ψ/π = 27 % of directions


def test_a_u_the_car_cannot_follow_becomes_the_nearest_it_can_and_is_counted():
    rng = np.random.default_rng(12)
    log = SaturationLog()
    outside = 0
    for _ in range(500):
        u = rng.normal(size=2)
        heading = rng.uniform(-math.pi, math.pi)
        v, omega = CAR.command(u, heading=heading, geometry=GEOMETRY, limits=LIMITS, log=log)
        assert abs(omega) <= abs(v) * KAPPA * (1 + 1e-15)  # a car can drive it
        moved = control_point_rate(v, omega, heading, GEOMETRY.control_point_distance)
        if np.allclose(moved, u, atol=1e-12):
            continue
        outside += 1
        assert math.isclose(abs(omega), abs(v) * KAPPA, rel_tol=1e-15)  # on the cone's edge
        # The orthogonal projection onto that edge: the remainder is perpendicular to what is driven,
        # and no velocity the car can drive is nearer to u (checked against a fan of edge velocities).
        assert abs(np.dot(u - moved, moved)) <= 1e-12 * np.dot(u, u) and np.dot(u, moved) > 0.0
        for sign_v in (1.0, -1.0):
            for sign_w in (1.0, -1.0):
                for speed in np.linspace(0.0, 3.0, 31):
                    edge = control_point_rate(
                        sign_v * speed, sign_w * speed * KAPPA, heading, GEOMETRY.control_point_distance
                    )
                    assert np.linalg.norm(u - moved) <= np.linalg.norm(u - edge) + 1e-12
    record = log.records['steering']
    assert record.count == outside > 300 and record.allowed == 0.42
    assert 0.42 < record.largest_requested <= math.pi / 2
    assert 'steering' in SATURATION_KINDS


def test_a_sideways_u_drives_forwards_at_the_full_steering_angle():
    log = SaturationLog()
    v, omega = CAR.command(np.array([0.0, 0.2]), heading=0.0, geometry=GEOMETRY, limits=LIMITS, log=log)
    assert (
        v > 0.0
        and omega > 0.0
        and math.isclose(math.atan(GEOMETRY.wheelbase * omega / v), 0.42, rel_tol=1e-14)
    )
    assert log.records['steering'].largest_requested == math.pi / 2  # a turn in place
    assert steer(0.0, 0.0, distance=0.33, kappa=KAPPA) == (0.0, 0.0)  # standing still is followed


def test_speed_limits_scale_a_steered_command_keeping_its_curvature():
    limits = Limits(linear_speed=0.1, angular_speed=0.05, steering_angle=0.42)
    log = SaturationLog()
    v, omega = CAR.command(np.array([1.0, 1.0]), heading=0.0, geometry=GEOMETRY, limits=limits, log=log)
    assert abs(v) <= 0.1 and abs(omega) <= 0.05 * (1 + 1e-15)
    assert math.isclose(abs(omega), abs(v) * KAPPA, rel_tol=1e-14)
    assert set(log.records) == {'steering', 'linear_speed', 'angular_speed'}


def test_a_car_base_cannot_turn_in_place_and_counts_what_it_clips():
    limits = Limits(linear_speed=1.0, angular_speed=2.0, steering_angle=0.42)
    assert CAR.clip((0.0,), 0.5, geometry=GEOMETRY, limits=limits) == ((0.0,), 0.0, True)
    (v,), w, clipped = CAR.clip((0.5,), -1.0, geometry=GEOMETRY, limits=limits)
    assert v == 0.5 and w == -0.5 * curvature(GEOMETRY, limits) and clipped
    assert CAR.clip((-0.5,), 0.3, geometry=GEOMETRY, limits=limits) == ((-0.5,), 0.3, False)
    (v,), w, clipped = CAR.clip((3.0,), 3.0, geometry=GEOMETRY, limits=limits)
    assert (v, w, clipped) == (1.0, 1.0 * curvature(GEOMETRY, limits), True)
    assert steering_angle(0.5, 0.5 * curvature(GEOMETRY, limits), 0.33) == pytest.approx(0.42, rel=1e-15)


def _bicycle(v: float, phi: float, wheelbase: float):
    return lambda t, s: [v * math.cos(s[2]), v * math.sin(s[2]), v * math.tan(phi) / wheelbase]


@pytest.mark.parametrize(('v', 'phi', 'duration'), [(0.5, 0.42, 3.0), (-0.3, -0.2, 4.0), (0.2, 1e-10, 2.0)])
def test_the_car_drives_the_bicycles_exact_arc_under_a_held_speed_and_steering(v, phi, duration):
    from formation_sim.sim.robots import Command, make_robot
    from formation_sim.sim.robots import Limits as BaseLimits

    robot = make_robot(
        'car',
        scenario_position=[0.4, -1.0],
        yaw=0.9,
        geometry=Geometry(control_point_distance=0.33, wheelbase=0.33),
        limits=BaseLimits(steering=0.42),
    )
    start = robot.position.copy()
    robot.set_command(Command(linear=(v,), angular=v * math.tan(phi) / 0.33))  # what a driver steering φ does
    assert robot.saturated == 0
    for piece in (0.01, 0.5, duration - 0.51):
        robot.advance(piece)
    reference = solve_ivp(
        _bicycle(v, phi, 0.33), (0.0, duration), [*start, 0.9], rtol=1e-12, atol=1e-12, method='DOP853'
    )
    x, y, yaw = reference.y[:, -1]
    assert np.allclose(robot.position, [x, y], atol=1e-10)
    assert math.isclose(math.remainder(robot.yaw - yaw, 2 * math.pi), 0.0, abs_tol=1e-10)


@pytest.mark.parametrize(
    ('geometry', 'limits', 'complaint'),
    [
        (
            Geometry(control_point_distance=0.33),
            LIMITS,
            'a car needs its wheelbase L > 0 [m] (rear to front axle), got 0.0',
        ),
        (
            GEOMETRY,
            Limits(),
            'a car needs its steering limit max_steering_angle φ_max in (0, π/2) [rad] '
            '(it cannot turn in place), got inf',
        ),
        (GEOMETRY, Limits(steering_angle=1.6), 'got 1.6'),
        (
            Geometry(control_point_distance=0.0, wheelbase=0.33),
            LIMITS,
            'control_point_distance l must be > 0, got 0.0',
        ),
    ],
)
def test_a_car_that_cannot_be_driven_is_refused_with_the_rule(geometry, limits, complaint):
    assert any(
        complaint in problem for problem in CAR.problems(dimension=2, geometry=geometry, limits=limits)
    )
    with pytest.raises(
        KindError,
        match=complaint.replace('(', r'\(').replace(')', r'\)').replace('[', r'\[').replace(']', r'\]'),
    ):
        RobotCommander(drive='car', dimension=2, limits=limits, geometry=geometry)
