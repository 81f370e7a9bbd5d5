"""Robot kinematics for the pose and command adapters (README, "Running on robots"), ROS-free.

The agent's state x_i is the position of the robot's *control point*: the robot's origin for a
holonomic robot, and for a differential-drive (unicycle) robot the point at distance l ahead of
the wheel axle on the robot's x axis,

    z = (x, y) + l (cos θ, sin θ),   dz/dt = [[cos θ, -l sin θ], [sin θ, l cos θ]] (v, ω).

The matrix has determinant l > 0, so any desired velocity u of the control point is met exactly
by the body-frame command

    v = cos θ u_x + sin θ u_y,   ω = (-sin θ u_x + cos θ u_y) / l.

This is the standard feedback linearisation of the unicycle about a point off the wheel axle
(the "hand position" of Lawton, Beard and Young, "A decentralized approach to formation
maneuvers", IEEE Trans. Robotics and Automation 19(6), 2003; the near-identity diffeomorphism as
l -> 0).  The control point then moves as the single (or double) integrator the theorems assume;
the heading is internal dynamics: for a constant u ≠ 0, dθ/dt = (|u|/l) sin(φ - θ) with φ the
direction of u, so θ turns to φ (tan((θ - φ)/2) decays as e^{-|u| t / l}).

Orientations are unit quaternions (x, y, z, w) as in geometry_msgs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def _cross(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float]:
    """a × b of two 3-vectors, in floats (np.cross on 3-vectors costs ~20 µs, most of a robot
    run's coordinator sampling every pose; the same products and differences)."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def rotate(orientation: Sequence[float], vector: Sequence[float] | np.ndarray) -> np.ndarray:
    """R(q) v: `vector` (3,) from the body frame into the world frame, q = (x, y, z, w) unit."""
    r = [float(c) for c in orientation[:3]]
    w = float(orientation[3])
    v = [float(c) for c in vector]
    t = [2.0 * c for c in _cross(r, v)]
    rt = _cross(r, t)
    return np.array([v[k] + w * t[k] + rt[k] for k in range(3)])


def yaw(orientation: Sequence[float]) -> float:
    """The heading θ (rotation about the world z axis) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(c) for c in orientation)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def control_point(
    position: Sequence[float], orientation: Sequence[float], offset: Sequence[float] | np.ndarray
) -> np.ndarray:
    """The world position of the point `offset` (body frame, (3,)) of a robot at this pose."""
    point: np.ndarray = np.asarray(position, dtype=float) + rotate(orientation, offset)
    return point


def control_point_velocity(
    orientation: Sequence[float],
    linear: Sequence[float],
    angular: Sequence[float],
    offset: Sequence[float] | np.ndarray,
) -> np.ndarray:
    """World velocity of the body point `offset` from the body-frame twist (REP 105 odometry):
    R (v + ω × offset)."""
    spin = _cross([float(c) for c in angular], [float(c) for c in offset])
    return rotate(orientation, [float(linear[k]) + spin[k] for k in range(3)])


def unicycle_velocity(
    u: Sequence[float] | np.ndarray, heading: float, distance: float
) -> tuple[float, float]:
    """(v, ω) that move the control point at `distance` l ahead of the axle with velocity u (2,)."""
    c, s = math.cos(heading), math.sin(heading)
    ux, uy = float(u[0]), float(u[1])
    return c * ux + s * uy, (-s * ux + c * uy) / distance


def control_point_rate(v: float, omega: float, heading: float, distance: float) -> np.ndarray:
    """dz/dt of the control point of a unicycle driving (v, ω) at heading θ (the forward map)."""
    c, s = math.cos(heading), math.sin(heading)
    return np.array([c * v - distance * s * omega, s * v + distance * c * omega])
