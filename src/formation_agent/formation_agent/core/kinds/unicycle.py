"""The unicycle kind: a differential-drive robot steered at a control point ahead of its axle (ROS-free).

The agent's x_i is the point z = (x, y) + l (cos θ, sin θ), l ahead of the wheel axle; the
near-identity diffeomorphism (`formation_agent.core.kinematics.unicycle_velocity`) meets any u
exactly with a body-frame `geometry_msgs/Twist` (v, ω), which is scaled by one common factor to
`max_linear_speed` and `max_angular_speed` (the control point keeps its course).

Simulated (ẋ = v cos θ, ẏ = v sin θ, θ̇ = ω): over a hold of length τ it drives the arc

    x ← x + v τ sinc(ωτ/2) cos(θ + ωτ/2),   y ← y + v τ sinc(ωτ/2) sin(θ + ωτ/2),   θ ← θ + ωτ

(sin(θ+ωτ) − sin θ = 2 cos(θ + ωτ/2) sin(ωτ/2), so ω → 0 gives the straight line with no
cancellation; sinc(u) = sin(u)/u); a base clips |v| and |ω| each on its own, as a TurtleBot3 does.
"""

from __future__ import annotations

import math

import numpy as np

from formation_agent.core.kinds.registry import RobotKind
from formation_agent.core.kinds.shape import Geometry, ShapeParameter
from formation_agent.core.kinematics import unicycle_velocity
from formation_agent.core.limits import Limits, SaturationLog, limit_body_velocity

CONTROL_POINT_DISTANCE = ShapeParameter(
    name='control_point_distance',
    symbol='l',
    help="the control point l ahead of the axle [m]; the scenario's positions are the control points'",
    default=0.1,
    metavar='L',
)
"""l: where a unicycle (and a car) is steered; > 0, as the near-identity diffeomorphism needs
(|ω| = |u⊥| / l).  0.1 m: a TurtleBot3 Burger's (turtlebot3.params.yaml), the value every robot
node, coordinator and command line took by default (docs/ROBOTS.md)."""


_EPS = float(np.finfo(float).eps)


def sinc(u: float) -> float:
    """`np.sinc(u)` = sin(πu)/(πu) of one float, the same bits (its steps: πu, eps for 0, numpy's
    sin) without its arrays: a simulated robot's tick takes one (100 Hz), and `np.sinc` of a
    scalar was a tenth of the robots' main thread (issue 19)."""
    y = math.pi * u
    if not y:
        y = _EPS
    ratio: float = np.sin(y) / y
    return ratio


def arc(
    position: np.ndarray, yaw: float, v: float, omega: float, duration: float
) -> tuple[np.ndarray, float]:
    """The exact arc of (v, ω) held for `duration` from (position, yaw) (module docstring)."""
    half = 0.5 * omega * duration
    chord = v * duration * sinc(half / math.pi)
    middle = yaw + half
    return position + chord * np.array([math.cos(middle), math.sin(middle)]), yaw + omega * duration


class Unicycle(RobotKind):
    name = 'unicycle'
    summary = 'body-frame Twist (v, ω), differential drive steered l ahead of its axle'
    command_type = 'geometry_msgs/msg/Twist'
    world_frame_command = False
    dimensions = (2,)
    steered = True
    parameters: tuple[str, ...] = ('max_angular_speed',)  # its shape parameters: `shape`
    params_file = 'turtlebot3.params.yaml'
    shape = (*RobotKind.shape, CONTROL_POINT_DISTANCE)
    # TurtleBot3 Burger: robot_radius 0.105 m in turtlebot3_navigation2's param/burger.yaml (the
    # example's limits 0.22 m/s, 2.84 rad/s are the Burger's); a Waffle takes 0.22 m.
    footprint_radius = 0.105

    def placement_problems(self, *, dimension: int | None, geometry: Geometry) -> list[str]:
        problems = super().placement_problems(dimension=dimension, geometry=geometry)
        if not geometry.control_point_distance > 0.0:
            problems.append(
                f'a {self.name} is steered at a control point ahead of its axle: '
                'control_point_distance l must be > 0, '
                f'got {geometry.control_point_distance!r}'
            )
        return problems

    def control_offset(self, geometry: Geometry) -> tuple[float, float, float]:
        return (float(geometry.control_point_distance), 0.0, 0.0)

    def command(
        self, u: np.ndarray, *, heading: float | None, geometry: Geometry, limits: Limits, log: SaturationLog
    ) -> tuple[float, ...]:
        if heading is None:
            raise ValueError(f'a {self.name} command needs the robot heading')
        v, omega = unicycle_velocity(u, heading, geometry.control_point_distance)
        return limit_body_velocity(v, omega, limits, log)

    def clip(
        self, linear: tuple[float, ...], angular: float, *, geometry: Geometry, limits: Limits
    ) -> tuple[tuple[float, ...], float, bool]:
        """|v| and |ω| clipped each on its own."""
        v, w = float(linear[0]), float(angular)
        clipped = abs(v) > limits.linear_speed or abs(w) > limits.angular_speed
        v = max(-limits.linear_speed, min(limits.linear_speed, v))
        w = max(-limits.angular_speed, min(limits.angular_speed, w))
        return (v,), w, clipped

    def move(
        self, position: np.ndarray, yaw: float, linear: tuple[float, ...], angular: float, duration: float
    ) -> tuple[np.ndarray, float]:
        return arc(position, yaw, linear[0], angular, duration)

    def body_twist(self, linear: tuple[float, ...], angular: float, yaw: float) -> tuple[np.ndarray, float]:
        return np.array([linear[0], 0.0, 0.0]), angular
