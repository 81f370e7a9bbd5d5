"""From the agent's command to a robot's velocity command, within the robot's limits (ROS-free).

The agent's command is the velocity its control point should have: u_i (ETA-1, eq. uxsingle),
or for ETA-2 the velocity reference q_i(t) driven by u^d_i (`velocity_reference`).  A holonomic
robot's kind (`formation_agent.core.kinds`) turns it into the robot's command: a holonomic robot
takes it as is (a world-frame velocity); a differential-drive robot gets (v, ω) from the
diffeomorphism of `kinematics`.

Limits (README, "Running on robots"): the theorems assume none, so every clip is counted per kind
(`formation_msgs_py.lockstep.SATURATION_KINDS`) with the largest value asked for, and reported.

- Speed and turn rate: the kind's adapter (`formation_agent.core.limits`): a holonomic velocity is
  scaled down to `linear_speed` keeping its direction; a differential drive's (v, ω) by one
  common factor until |v| <= `linear_speed` and |ω| <= `angular_speed`.  Both are linear in u,
  so this is the command for a scaled-down u: the control point keeps its direction of travel and
  only slows down (clipping v and ω apart would turn it off course).
- Acceleration (ETA-2): the velocity reference's acceleration is held to `linear_acceleration`
  (`velocity_reference`); counted once per trigger from which it acts.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from formation_agent.core.errors import KindError
from formation_agent.core.kinds import KIND_NAMES, Geometry, robot_kind
from formation_agent.core.limits import Limits, SaturationLog, limit_body_velocity, limit_world_velocity
from formation_agent.core.velocity_reference import VelocityReference
from formation_msgs_py.lockstep import SATURATION_LINEAR_ACCELERATION

if TYPE_CHECKING:
    from formation_agent.core.time_warp import TimeWarp

__all__ = [
    'DRIVES',
    'Limits',
    'RobotCommander',
    'SaturationLog',
    'limit_body_velocity',
    'limit_world_velocity',
]

DRIVES = KIND_NAMES  # the registered robot kinds (formation_agent.core.kinds), read at each use


class RobotCommander:
    """One robot's velocity commands from its agent's commands.

    `set_control(t, control, velocity)` at each trigger: control = u_i (ETA-1) or u^d_i (ETA-2,
    with `k3`); for ETA-2 the first call starts the velocity reference at the sensed velocity
    q_i(t), later calls re-anchor it at its own exact value (the reference is the double
    integrator's state; sensing noise never jumps into the command).  `command(t, heading)` then
    gives the command at any later t: a world-frame velocity (holonomic, (p,)) or (v, ω).
    """

    def __init__(
        self,
        *,
        drive: str,
        dimension: int,
        limits: Limits,
        geometry: Geometry | None = None,
        k3: float | None = None,
        time_warp: TimeWarp | None = None,
    ) -> None:
        """`time_warp` (ETA-1; `formation_agent.core.time_warp.TimeWarp`): the controls are the
        paper's u_p and the robot is sent κ(t) u_p at each command's real time t."""
        if drive not in DRIVES:
            raise KindError(f'drive must be one of {DRIVES}, got {drive!r}')
        self.kind = robot_kind(drive)
        self.geometry = Geometry() if geometry is None else geometry  # the declared defaults
        problems = self.kind.problems(dimension=dimension, geometry=self.geometry, limits=limits)
        if problems:
            raise KindError('; '.join(problems))
        self.drive = drive
        self.dimension = dimension
        self.limits = limits
        self.k3 = k3
        if time_warp is not None and k3 is not None:
            raise ValueError('time_warp: ETA-1 only (ETA-2 stays on a constant speed scale)')
        self.time_warp = time_warp
        self.saturation = SaturationLog()
        self.commands = 0  # commands computed (each published once)
        self._desired: np.ndarray | None = None  # ETA-1: u_i
        self._reference: VelocityReference | None = None  # ETA-2

    @property
    def started(self) -> bool:
        return self._desired is not None or self._reference is not None

    def set_control(
        self, t: float, control: Sequence[float], velocity: Sequence[float] | None = None
    ) -> None:
        if self.k3 is None:
            self._desired = np.array(control, dtype=float)
            return
        if self._reference is None:
            if velocity is None:
                raise ValueError(
                    'ETA-2: the first control needs the sensed velocity q_i to start the reference'
                )
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
        return self._desired if self.time_warp is None else self.time_warp.rate(t) * self._desired

    def command(self, t: float, heading: float | None = None) -> tuple[float, ...]:
        """The robot's command at t by its kind's adapter: (u_1..u_p) in the world frame (holonomic)
        or (v, ω) from the robot's heading (unicycle)."""
        u = self.desired(t)
        self.commands += 1
        return self.kind.command(
            u, heading=heading, geometry=self.geometry, limits=self.limits, log=self.saturation
        )
