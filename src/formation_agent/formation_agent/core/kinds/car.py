"""The car kind: a car-like robot (kinematic bicycle), steered at a control point ahead of its
rear axle (ROS-free).

Model: rear axle (x, y), heading θ, wheelbase L, front wheels steered by φ with |φ| <= φ_max < π/2:

    ẋ = v cos θ,   ẏ = v sin θ,   θ̇ = ω = v tan φ / L,

a unicycle whose turn rate is tied to its speed: |ω| <= |v| κ with κ = tan φ_max / L (1 / the
smallest turning radius).  It cannot turn in place.  Its command is the body-frame
`geometry_msgs/Twist` (v = linear.x, ω = angular.z) that car-like ROS drivers accept (they
steer φ = atan(L ω / v)); a base clips |v|, then |ω| to min(max_angular_speed, |v| κ).  Under a
held (v, φ) it drives the unicycle's arc of (v, ω = v tan φ / L), in closed form
(`unicycle.arc`).

Steering: the agent's x_i is the point l ahead of the rear axle, as for a unicycle; the same
near-identity diffeomorphism gives v = u·(cos θ, sin θ) and ω = u·(-sin θ, cos θ) / l.  So
|ω| <= |v| κ holds exactly when u lies in the double cone of half-angle ψ_max = atan(l κ)
about ±(cos θ, sin θ): there the car follows u exactly, as the theorems assume.  Outside it no
command moves the control point with velocity u — the theorems' assumption that every agent is
a fully actuated integrator (ẋ_i = u_i for any u_i in R^p, Theorems 1 and 2) breaks, and with
it the proofs' V̇ <= 0 and connectivity preservation.  The adapter then sends the command for the
nearest velocity it can follow: u projected orthogonally onto the nearest edge of the cone (the
least-squares choice, ||u' - u|| smallest), driving forward (or backward, for u behind) at the
full turn the steering allows; the control point's heading turns towards u, which re-enters the
cone after a finite turn, and from then on it is followed exactly.  Each such command is counted
as saturation 'steering' (the steering angle atan(L |ω| / |v|) asked for, π/2 for a turn in
place, against φ_max) in the AgentReport (docs/MESSAGES.md).  The speed limits then scale
(v, ω) by one common factor (`limits.limit_body_velocity`), which keeps |ω| / |v|.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from formation_agent.core.kinds.shape import Geometry, ShapeParameter
from formation_agent.core.kinds.unicycle import Unicycle
from formation_agent.core.kinematics import unicycle_velocity
from formation_agent.core.limits import Limits, SaturationLog, limit_body_velocity
from formation_msgs_py.lockstep import SATURATION_STEERING

if TYPE_CHECKING:
    import numpy as np

WHEELBASE = ShapeParameter(
    name='wheelbase',
    symbol='L',
    help='the wheelbase L from the rear axle to the steered front axle [m]',
    default=0.0,  # not given: a car needs its own (drive_problems); the other kinds take none
    positive=False,
    nodes=('agent', 'robot'),
    metavar='L',
)
"""L: a physical property of each car, with no default a car could assume (a wrong L is a wrong
steering limit |ω| <= |v| tan φ_max / L): 0 stands for not given and a car refuses it."""

ROUNDING = 1e-12  # a base counts as clipped only a turn rate beyond |v| κ by more than this, relative


def curvature(geometry: Geometry, limits: Limits) -> float:
    """κ = tan φ_max / L: the largest |ω| / |v| [1/m]."""
    return math.tan(limits.steering_angle) / geometry.wheelbase


def steer(v: float, omega: float, *, distance: float, kappa: float) -> tuple[float, float]:
    """(v, ω) for u = (v, l ω) in the body frame, or for u projected onto the nearest edge of the
    cone |ω| <= |v| κ when it lies outside (module docstring); on the edge, |ω| = |v| κ exactly."""
    if abs(omega) <= abs(v) * kappa:
        return v, omega
    psi = math.atan(distance * kappa)  # the cone's half-angle about ±heading
    along = abs(v) * math.cos(psi) + abs(distance * omega) * math.sin(psi)  # u · (the nearest edge) > 0
    v_edge = (
        math.copysign(along * math.cos(psi), v) if v != 0.0 else along * math.cos(psi)
    )  # sideways: forwards
    return v_edge, math.copysign(abs(v_edge) * kappa, omega)


def steering_angle(v: float, omega: float, wheelbase: float) -> float:
    """The steering angle φ a car of this wheelbase needs for (v, ω): atan(L |ω| / |v|), π/2 at v = 0."""
    return math.atan2(wheelbase * abs(omega), abs(v))


class Car(Unicycle):
    name = 'car'
    summary = (
        'body-frame Twist (v, ω), car-like (kinematic bicycle) steered l ahead of its rear axle, '
        '|ω| <= |v| tan φ_max / L'
    )
    parameters = ('max_angular_speed', 'max_steering_angle')  # its shape parameters: `shape`
    params_file = 'car.params.yaml'
    shape = (*Unicycle.shape, WHEELBASE)
    # An F1TENTH car (car.params.yaml: L = 0.33 m, φ_max = 0.42 rad): body 0.58 m x 0.31 m
    # centred 0.171 m ahead of the rear axle (f1tenth_gym's length, width, lr); the disc about the
    # rear axle that holds it reaches the front corners, hypot(0.171 + 0.29, 0.155) = 0.487 m.
    footprint_radius = 0.49

    def drive_problems(self, *, geometry: Geometry, limits: Limits) -> list[str]:
        problems = []
        if not geometry.wheelbase > 0.0:
            problems.append(
                f'a car needs its wheelbase L > 0 [m] (rear to front axle), got {geometry.wheelbase!r}'
            )
        if not 0.0 < limits.steering_angle < math.pi / 2:
            problems.append(
                'a car needs its steering limit max_steering_angle φ_max in (0, π/2) [rad] '
                '(it cannot turn in place), '
                f'got {limits.steering_angle!r}'
            )
        return problems

    def command(
        self, u: np.ndarray, *, heading: float | None, geometry: Geometry, limits: Limits, log: SaturationLog
    ) -> tuple[float, ...]:
        if heading is None:
            raise ValueError('a car command needs the robot heading')
        v, omega = unicycle_velocity(u, heading, geometry.control_point_distance)
        kappa = curvature(geometry, limits)
        steered = steer(v, omega, distance=geometry.control_point_distance, kappa=kappa)
        if steered != (v, omega):
            log.note(SATURATION_STEERING, steering_angle(v, omega, geometry.wheelbase), limits.steering_angle)
        return limit_body_velocity(*steered, limits, log)

    def clip(
        self, linear: tuple[float, ...], angular: float, *, geometry: Geometry, limits: Limits
    ) -> tuple[tuple[float, ...], float, bool]:
        """|v| clipped, then |ω| to min(max_angular_speed, |v| κ): the steering limit, as a car's base."""
        (v,), w, clipped = super().clip(linear, angular, geometry=geometry, limits=limits)
        turn = abs(v) * curvature(geometry, limits)
        if abs(w) > turn:
            clipped = clipped or abs(w) > turn * (1.0 + ROUNDING)
            w = math.copysign(turn, w)
        return (v,), w, clipped
