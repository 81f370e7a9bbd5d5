"""Robot kinematics: rotations, control points, and the unicycle's near-identity diffeomorphism.

The diffeomorphism is checked against the unicycle itself, integrated with scipy to 1e-12: under
continuous feedback the control point follows a constant desired velocity exactly, and the
heading turns to the direction of travel as tan((θ - φ)/2) e^{-|u| t / l}.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from formation_agent.core.kinematics import (
    control_point,
    control_point_rate,
    control_point_velocity,
    rotate,
    unicycle_velocity,
    yaw,
)


def _matrix(q):
    """The rotation matrix of a unit quaternion (x, y, z, w), from the textbook formula."""
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _heading(theta):
    return (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))


def test_rotation_and_yaw_agree_with_the_rotation_matrix():
    rng = np.random.default_rng(5)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        v = rng.normal(size=3)
        assert np.allclose(rotate(q, v), _matrix(q) @ v, rtol=0, atol=1e-14)
    for theta in (-3.0, -1.0, 0.0, 0.5, 2.0, 3.1):
        assert yaw(_heading(theta)) == pytest.approx(theta, abs=1e-15)
        assert np.allclose(
            rotate(_heading(theta), (1.0, 0.0, 0.0)), (math.cos(theta), math.sin(theta), 0.0), atol=1e-15
        )


def test_the_diffeomorphism_inverts_the_control_point_map():
    rng = np.random.default_rng(11)
    for _ in range(200):
        u = rng.normal(size=2)
        theta = rng.uniform(-math.pi, math.pi)
        distance = rng.uniform(0.01, 1.0)
        v, omega = unicycle_velocity(u, theta, distance)
        assert np.allclose(control_point_rate(v, omega, theta, distance), u, rtol=0, atol=1e-13)


def test_odometry_twist_gives_the_control_point_velocity():
    """R (v + ω × offset) from the body twist equals the planar formula of the unicycle."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        theta, v, omega, distance = rng.uniform(-3, 3), rng.normal(), rng.normal(), rng.uniform(0.05, 0.5)
        velocity = control_point_velocity(
            _heading(theta), (v, 0.0, 0.0), (0.0, 0.0, omega), (distance, 0.0, 0.0)
        )
        assert (
            np.allclose(velocity[:2], control_point_rate(v, omega, theta, distance), atol=1e-14)
            and velocity[2] == 0.0
        )
    point = control_point((1.0, 2.0, 0.0), _heading(math.pi / 2), (0.1, 0.0, 0.0))
    assert np.allclose(point, (1.0, 2.1, 0.0), atol=1e-15)


def _drive(u, theta0, distance, horizon):
    """A unicycle (x, y, θ) whose (v, ω) come from the diffeomorphism at every instant."""

    def rate(_t, state):
        v, omega = unicycle_velocity(u, state[2], distance)
        return [v * math.cos(state[2]), v * math.sin(state[2]), omega]

    times = np.linspace(0.0, horizon, 201)
    solution = solve_ivp(
        rate, (0.0, horizon), [0.3, -0.2, theta0], method='DOP853', rtol=1e-12, atol=1e-12, t_eval=times
    )
    assert solution.success
    return times, solution.y


@pytest.mark.parametrize('theta0', [0.0, 1.0, -2.5, 3.0])
def test_for_a_constant_desired_velocity_the_control_point_follows_it_exactly(theta0):
    u, distance = np.array([0.15, -0.08]), 0.1
    times, (x, y, theta) = _drive(u, theta0, distance, horizon=20.0)
    start = np.array([0.3 + distance * math.cos(theta0), -0.2 + distance * math.sin(theta0)])
    points = np.stack([x + distance * np.cos(theta), y + distance * np.sin(theta)], axis=1)
    assert np.abs(points - (start + np.outer(times, u))).max() < 1e-9


@pytest.mark.parametrize('theta0', [0.0, 1.0, -2.5, 3.0])
def test_for_straight_motion_the_heading_converges_to_the_direction_of_travel(theta0):
    u, distance = np.array([0.15, -0.08]), 0.1
    speed, phi = float(np.linalg.norm(u)), math.atan2(u[1], u[0])
    times, (_, _, theta) = _drive(u, theta0, distance, horizon=20.0)
    # dθ/dt = (|u|/l) sin(φ - θ): tan((θ - φ)/2) decays as e^{-|u| t / l}.
    expected = phi + 2.0 * np.arctan(math.tan((theta0 - phi) / 2.0) * np.exp(-speed * times / distance))
    assert np.abs(_wrapped(theta - expected)).max() < 1e-8
    assert abs(_wrapped(theta[-1] - phi)) < 1e-9  # 20 s = 34 time constants l / |u|


def _wrapped(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))
