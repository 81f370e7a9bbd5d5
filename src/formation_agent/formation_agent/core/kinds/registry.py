"""The registry of robot kinds: one `RobotKind` per kind of robot, everything that kind means (ROS-free).

A kind says, in one place, what the agents and the tools need to know of a robot:

- what the agent's state x_i is on it: the *control point*, at `control_offset` in the body
  frame (the origin of a holonomic robot, the point l ahead of the axle of a differential drive
  or a car), and in which dimensions it moves (`dimensions`);
- the command adapter: from the control point's velocity u to the robot's command within its
  limits, every clip counted (`command`, `formation_agent.core.limits`), and the zero command;
- the command's message: `command_type` (a ROS type name, resolved in the ros layer) and its
  convention, a world-frame TwistStamped (`world_frame_command`) or a body-frame Twist (v, ω);
- its parameters beyond the speed limits (`parameters`, names of the agent's parameter table) and
  the rules they obey (`problems`);
- the simulated model: how a base clips what it is sent (`clip`) and the exact motion under a
  held command (`move`, closed form; `formation_sim.sim.robots` moves its robots with it), the
  odometry twist (`body_twist`) and where the robot stands for a scenario position (`origin`);
- its example parameter file in formation_agent's config/ (`params_file`).

Everything that lists or branches on kinds reads this registry: the `formation` command's
choices, the launch plan, the simulated robots, the agent's parameter `robot`, the command
adapters, the analysis (docs/DESIGN.md, "Robot kinds").  `register` adds a kind; `KindNames` is a
live view of the names (with fixed names before and after: the agent's 'none', the backends'
'exact' and 'external'), so a kind registered later is among every choice.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np

from formation_agent.core.errors import KindError
from formation_agent.core.limits import Limits, SaturationLog

_KINDS: dict[str, RobotKind] = {}


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """A robot's shape as its kind needs it; 0: not given."""

    control_point_distance: float = 0.0  # l [m]: the control point ahead of the (rear) axle
    wheelbase: float = 0.0  # L [m]: from the rear axle to the steered front axle (car)


class RobotKind:
    """One kind of robot (module docstring).  Subclasses set the class attributes and the methods."""

    name: str = ''
    summary: str = ''  # what it is and what it takes, one line, for help texts
    command_type: str = 'geometry_msgs/msg/Twist'
    world_frame_command: bool = (
        False  # TwistStamped in the world frame; else Twist (v = linear.x, ω = angular.z)
    )
    dimensions: tuple[int, ...] = (2,)  # the dimensions p its control point moves in
    parameters: tuple[str, ...] = ()  # its parameters beyond max_linear_speed (the agent's parameter names)
    params_file: str | None = None  # formation_agent/config/<file>: an example robot's parameters

    # -- what a robot of this kind must be ----------------------------------------------------

    def problems(self, *, dimension: int | None, geometry: Geometry, limits: Limits) -> list[str]:
        """Why a robot of this kind cannot have these values (each rule broken, with its value)."""
        return self.placement_problems(dimension=dimension, geometry=geometry) + self.drive_problems(
            geometry=geometry, limits=limits
        )

    def placement_problems(self, *, dimension: int | None, geometry: Geometry) -> list[str]:
        """Why the scenario's points cannot be this kind's control points: its dimensions (None: not
        known, not checked), its control point."""
        if dimension is not None and dimension not in self.dimensions:
            where = (
                'in the plane'
                if self.dimensions == (2,)
                else f'in {" or ".join(map(str, self.dimensions))} dimensions'
            )
            return [
                f'a {self.name} moves {where}: dimension p must be '
                f'{" or ".join(map(str, self.dimensions))}, got {dimension}'
            ]
        return []

    def drive_problems(self, *, geometry: Geometry, limits: Limits) -> list[str]:
        """Why a robot of this kind cannot be driven with this geometry and these limits (none by default)."""
        return []

    def control_offset(self, geometry: Geometry) -> tuple[float, float, float]:
        """Where the control point (the scenario's position, the agent's x_i) sits in the body frame."""
        return (0.0, 0.0, 0.0)

    # -- the command adapter -------------------------------------------------------------------

    def command(
        self, u: np.ndarray, *, heading: float | None, geometry: Geometry, limits: Limits, log: SaturationLog
    ) -> tuple[float, ...]:
        """The robot's command that moves the control point with velocity u, within `limits`;
        every clip noted in `log`.  A world velocity (p values) or (v, ω)."""
        raise NotImplementedError

    def zero_command(self, dimension: int) -> tuple[float, ...]:
        return (0.0,) * dimension if self.world_frame_command else (0.0, 0.0)

    # -- the simulated model -------------------------------------------------------------------

    def clip(
        self, linear: tuple[float, ...], angular: float, *, geometry: Geometry, limits: Limits
    ) -> tuple[tuple[float, ...], float, bool]:
        """What a base of this kind applies of the command (linear, ω), and whether it clipped it."""
        raise NotImplementedError

    def move(
        self, position: np.ndarray, yaw: float, linear: tuple[float, ...], angular: float, duration: float
    ) -> tuple[np.ndarray, float]:
        """The pose after `duration` s under the held command (exact, closed form); yaw unwrapped."""
        raise NotImplementedError

    def body_twist(self, linear: tuple[float, ...], angular: float, yaw: float) -> tuple[np.ndarray, float]:
        """The velocity (3,) in the body frame and ω, as odometry reports them (REP 105)."""
        raise NotImplementedError

    def world_offset(self, yaw: float, geometry: Geometry, dimension: int) -> np.ndarray:
        """The control point's offset from the robot's position in the world frame (p,), heading `yaw`."""
        offset = np.array(self.control_offset(geometry)[:dimension], dtype=float)
        if dimension >= 2:
            c, s = np.cos(yaw), np.sin(yaw)
            offset[:2] = (c * offset[0] - s * offset[1], s * offset[0] + c * offset[1])
        return offset

    def origin(self, point: np.ndarray, yaw: float, geometry: Geometry) -> np.ndarray:
        """The robot's own position (its pose) whose control point, heading `yaw`, is `point`."""
        origin: np.ndarray = point - self.world_offset(yaw, geometry, point.size)
        return origin


def register(kind: RobotKind) -> RobotKind:
    """Add a kind to the registry (KindError if its name is taken or empty); returns it."""
    if not kind.name or kind.name in _KINDS or kind.name in RESERVED:
        raise KindError(f'a robot kind needs a name that is new and not one of {RESERVED}, got {kind.name!r}')
    _KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Remove a kind (tests register toy kinds and remove them again)."""
    _KINDS.pop(name, None)


def robot_kind(name: str) -> RobotKind:
    """The kind called `name` (KindError naming the registered kinds otherwise)."""
    try:
        return _KINDS[name]
    except (KeyError, TypeError):
        raise KindError(f'robot kind must be one of {tuple(_KINDS)}, got {name!r}') from None


class KindNames(Sequence[str]):
    """The registered kinds' names, read at every use, between fixed names `before` and `after`:
    a choice that never goes stale (argparse choices, a parameter's choices, a backend list)."""

    def __init__(self, *, before: tuple[str, ...] = (), after: tuple[str, ...] = ()) -> None:
        self.before, self.after = tuple(before), tuple(after)

    def _names(self) -> tuple[str, ...]:
        return (*self.before, *_KINDS, *self.after)

    @overload
    def __getitem__(self, index: int) -> str: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[str, ...]: ...

    def __getitem__(self, index: int | slice) -> str | tuple[str, ...]:
        return self._names()[index]

    def __len__(self) -> int:
        return len(self._names())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and not isinstance(other, str) and tuple(self) == tuple(other)

    __hash__ = None  # type: ignore[assignment]  # equal to tuples, so not hashable

    def __repr__(self) -> str:
        return repr(self._names())


RESERVED = ('none', 'exact', 'external')  # the agent's plant ('none') and the non-robot backends
KIND_NAMES = KindNames()
