"""From the agent's command to a robot's velocity command, within the robot's limits (ROS-free).

The agent's command is the velocity its control point should have: u_i (ETA-1, eq. uxsingle),
or for ETA-2 the velocity reference q_i(t) driven by u^d_i (`velocity_reference`).  A holonomic
robot takes it as is (a world-frame velocity); a differential-drive robot gets (v, ω) from the
diffeomorphism of `kinematics`.

Limits (README, "Running on robots"): the theorems assume none, so every clip is counted per kind
(`formation_msgs_py.lockstep.SATURATION_KINDS`) with the largest value asked for, and reported.

- Speed of a holonomic robot: the velocity is scaled down to `linear_speed`, keeping its direction.
- Differential drive: (v, ω) are scaled down by one common factor until |v| <= `linear_speed`
  and |ω| <= `angular_speed`.  Both are linear in u, so this is the command for a scaled-down u:
  the control point keeps its direction of travel and only slows down (clipping v and ω apart
  would turn it off course).
- Acceleration (ETA-2): the velocity reference's acceleration is held to `linear_acceleration`
  (`velocity_reference`); counted once per trigger from which it acts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from formation_agent.core.kinematics import unicycle_velocity
from formation_agent.core.velocity_reference import VelocityReference
from formation_msgs_py.lockstep import (
    SATURATION_ANGULAR_SPEED,
    SATURATION_LINEAR_ACCELERATION,
    SATURATION_LINEAR_SPEED,
    Saturation,
)

DRIVES = ('holonomic', 'unicycle')


@dataclass(frozen=True, kw_only=True)
class Limits:
    """A robot's limits; inf: none."""

    linear_speed: float = math.inf  # m/s
    angular_speed: float = math.inf  # rad/s (differential drive)
    linear_acceleration: float = math.inf  # m/s² (ETA-2's velocity reference)

    def __post_init__(self) -> None:
        for name in ('linear_speed', 'angular_speed', 'linear_acceleration'):
            value = getattr(self, name)
            if not value > 0.0:  # also refuses NaN
                raise ValueError(f'limit {name} must be > 0 (inf: none), got {value!r}')


class SaturationLog:
    """Clipped commands per kind: how many, the largest value asked for, the limit."""

    def __init__(self) -> None:
        self._records: dict[str, Saturation] = {}

    def note(self, kind: str, requested: float, allowed: float) -> None:
        previous = self._records.get(kind)
        count = 1 if previous is None else previous.count + 1
        largest = requested if previous is None else max(previous.largest_requested, requested)
        self._records[kind] = Saturation(count=count, largest_requested=float(largest), allowed=float(allowed))

    @property
    def records(self) -> dict[str, Saturation]:
        return dict(self._records)


def limit_world_velocity(u: Sequence[float], limits: Limits, log: SaturationLog) -> np.ndarray:
    """u scaled down to the speed limit (direction kept); a clip is noted in `log`."""
    u = np.asarray(u, dtype=float)
    speed = float(np.linalg.norm(u))
    if speed > limits.linear_speed:
        log.note(SATURATION_LINEAR_SPEED, speed, limits.linear_speed)
        return u * (limits.linear_speed / speed)
    return u


def limit_body_velocity(v: float, omega: float, limits: Limits, log: SaturationLog) -> tuple[float, float]:
    """(v, ω) scaled down by one factor to both limits (README: the control point keeps its course)."""
    scale = 1.0
    if abs(v) > limits.linear_speed:
        log.note(SATURATION_LINEAR_SPEED, abs(v), limits.linear_speed)
        scale = limits.linear_speed / abs(v)
    if abs(omega) > limits.angular_speed:
        log.note(SATURATION_ANGULAR_SPEED, abs(omega), limits.angular_speed)
        scale = min(scale, limits.angular_speed / abs(omega))
    return v * scale, omega * scale


class RobotCommander:
    """One robot's velocity commands from its agent's commands.

    `set_control(t, control, velocity)` at each trigger: control = u_i (ETA-1) or u^d_i (ETA-2,
    with `k3`); for ETA-2 the first call starts the velocity reference at the sensed velocity
    q_i(t), later calls re-anchor it at its own exact value (the reference is the double
    integrator's state; sensing noise never jumps into the command).  `command(t, heading)` then
    gives the command at any later t: a world-frame velocity (holonomic, (p,)) or (v, ω).
    """

    def __init__(
        self, *, drive: str, dimension: int, limits: Limits, distance: float = 0.0, k3: float | None = None
    ) -> None:
        if drive not in DRIVES:
            raise ValueError(f'drive must be one of {DRIVES}, got {drive!r}')
        if drive == 'unicycle' and (dimension != 2 or not distance > 0.0):
            raise ValueError(
                f'a unicycle drives in the plane about a control point ahead of its axle: it needs dimension 2 '
                f'and a distance l > 0, got dimension {dimension} and l = {distance!r}'
            )
        self.drive = drive
        self.dimension = dimension
        self.limits = limits
        self.distance = float(distance)
        self.k3 = k3
        self.saturation = SaturationLog()
        self.commands = 0  # commands computed (each published once)
        self._desired: np.ndarray | None = None  # ETA-1: u_i
        self._reference: VelocityReference | None = None  # ETA-2

    @property
    def started(self) -> bool:
        return self._desired is not None or self._reference is not None

    def set_control(self, t: float, control: Sequence[float], velocity: Sequence[float] | None = None) -> None:
        if self.k3 is None:
            self._desired = np.array(control, dtype=float)
            return
        if self._reference is None:
            if velocity is None:
                raise ValueError('ETA-2: the first control needs the sensed velocity q_i to start the reference')
            self._reference = VelocityReference(
                k3=self.k3, velocity=velocity, time=t, max_acceleration=self.limits.linear_acceleration
            )
        requested = self._reference.update(t, control)
        if requested > self.limits.linear_acceleration:
            self.saturation.note(SATURATION_LINEAR_ACCELERATION, requested, self.limits.linear_acceleration)

    def desired(self, t: float) -> np.ndarray:
        """The control point's velocity the agent asks for at t (before limits)."""
        if self._reference is not None:
            return self._reference.velocity(t)
        if self._desired is None:
            raise ValueError('no control yet: the agent has not triggered')
        return self._desired

    def command(self, t: float, heading: float | None = None) -> tuple[float, ...]:
        """The robot's command at t: (u_1..u_p) world frame (holonomic) or (v, ω) (unicycle)."""
        u = self.desired(t)
        self.commands += 1
        if self.drive == 'holonomic':
            return tuple(float(c) for c in limit_world_velocity(u, self.limits, self.saturation))
        if heading is None:
            raise ValueError('a unicycle command needs the robot heading')
        v, omega = unicycle_velocity(u, heading, self.distance)
        return limit_body_velocity(v, omega, self.limits, self.saturation)
