"""The holonomic kind: an omnidirectional base or a quadrotor in velocity mode (ROS-free).

Its control point is its own position; it takes the control point's velocity as is, a world-frame
`geometry_msgs/TwistStamped`, scaled down to `max_linear_speed` keeping its direction.  Simulated:
ẋ = v in the world frame, θ̇ = ω; over a hold of length τ, x ← x + τ v, θ ← θ + τ ω.
"""

from __future__ import annotations

import math

import numpy as np

from formation_agent.core.kinds.registry import RobotKind
from formation_agent.core.kinds.shape import Geometry
from formation_agent.core.limits import Limits, SaturationLog, limit_world_velocity


class Holonomic(RobotKind):
    name = 'holonomic'
    summary = 'world-frame TwistStamped: omnidirectional base, quadrotor'
    command_type = 'geometry_msgs/msg/TwistStamped'
    world_frame_command = True
    dimensions = (1, 2, 3)
    parameters = ()
    params_file = 'crazyflie.params.yaml'
    # A Crazyflie 2.x (crazyflie.params.yaml): motors 33 mm from the centre along each axis (46.7 mm
    # out), 47 mm propellers: 0.0467 + 0.0235 = 0.070 m.  In the plane only: one flying under
    # another needs more height (its downwash), which a disc does not say.
    footprint_radius = 0.07

    def command(
        self, u: np.ndarray, *, heading: float | None, geometry: Geometry, limits: Limits, log: SaturationLog
    ) -> tuple[float, ...]:
        return tuple(float(c) for c in limit_world_velocity(u, limits, log))

    def clip(
        self, linear: tuple[float, ...], angular: float, *, geometry: Geometry, limits: Limits
    ) -> tuple[tuple[float, ...], float, bool]:
        """The speed scaled down to the limit keeping its direction, |ω| clipped."""
        velocity = np.array(linear, dtype=float)
        speed = float(np.linalg.norm(velocity))
        clipped = speed > limits.linear_speed or abs(angular) > limits.angular_speed
        if speed > limits.linear_speed:
            velocity = velocity * (limits.linear_speed / speed)
        angular = max(-limits.angular_speed, min(limits.angular_speed, float(angular)))
        return tuple(velocity.tolist()), angular, clipped

    def move(
        self, position: np.ndarray, yaw: float, linear: tuple[float, ...], angular: float, duration: float
    ) -> tuple[np.ndarray, float]:
        return position + duration * np.array(linear), yaw + duration * angular

    def body_twist(self, linear: tuple[float, ...], angular: float, yaw: float) -> tuple[np.ndarray, float]:
        world = np.zeros(3)
        world[: len(linear)] = linear
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c * world[0] + s * world[1], -s * world[0] + c * world[1], world[2]]), angular
