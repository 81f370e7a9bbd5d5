"""The registry of robot kinds: one `RobotKind` per kind of robot, everything that kind means (ROS-free).

A kind says, in one place, what the agents and the tools need to know of a robot:

- what the agent's state x_i is on it: the *control point*, at `control_offset` in the body
  frame (the origin of a holonomic robot, the point l ahead of the axle of a differential drive
  or a car), and in which dimensions it moves (`dimensions`);
- the command adapter: from the control point's velocity u to the robot's command within its
  limits, every clip counted (`command`, `formation_agent.core.limits`), and the zero command;
- the command's message: `command_type` (a ROS type name, resolved in the ros layer) and its
  convention, a world-frame TwistStamped (`world_frame_command`) or a body-frame Twist (v, ω);
- its shape parameters, each declared once (`shape`, `formation_agent.core.kinds.shape`), among
  them its footprint radius (`footprint_radius`); the limits it takes beyond the speed limit
  (`parameters`, names of the agent's parameter table); the rules they obey (`problems`);
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

import math
from collections.abc import Sequence
from typing import overload

import numpy as np

from formation_agent.core.errors import KindError
from formation_agent.core.kinds.shape import Geometry, ShapeParameter, declare, undeclare
from formation_agent.core.limits import Limits, SaturationLog

_KINDS: dict[str, RobotKind] = {}


FOOTPRINT_RADIUS = ShapeParameter(
    name='footprint_radius',
    symbol='r',
    help='radius r of its footprint, a disc about its origin (its pose) that holds the whole robot [m]',
    default=None,  # each kind's own `footprint_radius` (docs/ROBOTS.md, "Footprints")
    nodes=(),  # no node takes it yet: the safety layer on robots will (docs/SAFETY.md)
    metavar='R',
)
"""Every kind's footprint radius r, declared once for all kinds; its default is each kind's own."""

SEPARATION_MARGIN = 0.05
"""[m] the gap kept between two footprints by the default separation (`default_min_separation`):
a few centimetres of pose error (odometry over a run, motion capture's millimetres) and a base's
lag behind its command (0.22 m/s for 0.1 s is 2.2 cm); docs/ROBOTS.md, "Footprints"."""


class RobotKind:
    """One kind of robot (module docstring).  Subclasses set the class attributes and the methods."""

    name: str = ''
    summary: str = ''  # what it is and what it takes, one line, for help texts
    command_type: str = 'geometry_msgs/msg/Twist'
    world_frame_command: bool = (
        False  # TwistStamped in the world frame; else Twist (v = linear.x, ω = angular.z)
    )
    dimensions: tuple[int, ...] = (2,)  # the dimensions p its control point moves in
    steered: bool = (
        False  # its control point moves by turning, l ahead: a turn-rate limit W caps its speed at W l
    )
    parameters: tuple[str, ...] = ()  # its limits beyond max_linear_speed (the agent's parameter names)
    shape: tuple[ShapeParameter, ...] = (FOOTPRINT_RADIUS,)  # its shape parameters, declared once (shape.py)
    footprint_radius: float = 0.0  # r [m]: its footprint (FOOTPRINT_RADIUS), a kind's own default
    params_file: str | None = None  # formation_agent/config/<file>: an example robot's parameters

    def shape_value(self, geometry: Geometry, name: str) -> float:
        """The value of shape parameter `name` for a robot of this kind: the geometry's, or the
        kind's own where the parameter's default is each kind's (None)."""
        value = getattr(geometry, name)
        return float(getattr(self, name) if value is None else value)

    def footprint(self, geometry: Geometry) -> float:
        """r [m]: the radius of the disc about the robot's origin that holds the robot."""
        return self.shape_value(geometry, FOOTPRINT_RADIUS.name)

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
    """Add a kind to the registry and declare its shape parameters (KindError if its name is taken
    or empty, ShapeError if it declares a shape parameter differently, KindError if it lacks its
    own value of one whose default is each kind's); returns it."""
    if not kind.name or kind.name in _KINDS or kind.name in RESERVED:
        raise KindError(f'a robot kind needs a name that is new and not one of {RESERVED}, got {kind.name!r}')
    for parameter in kind.shape:
        own = getattr(kind, parameter.name, None)
        if parameter.default is None and not (isinstance(own, float) and parameter.holds(own)):
            raise KindError(
                f'a robot kind sets its own {parameter.name} {parameter.symbol} ({parameter.rule} [m]): '
                f'{kind.name} has {own!r}'
            )
    declare(kind.shape, kind=kind.name)
    _KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Remove a kind and the shape parameters only it took (tests register toy kinds and remove them)."""
    if _KINDS.pop(name, None) is not None:
        undeclare(name)


def control_point_separation(
    origin_separation: float,
    *,
    kind: RobotKind,
    geometry: Geometry,
    other_kind: RobotKind | None = None,
    other_geometry: Geometry | None = None,
) -> float:
    """D_s: the separation between two robots' control points that keeps their origins (their
    poses) at least D = `origin_separation` apart, whatever their headings.

    A control point sits c_i = ||control_offset|| from its robot's origin (l ahead of the axle of a
    unicycle or a car, 0 on a holonomic robot), so by the triangle inequality
    ||o_i - o_j|| >= ||x_i - x_j|| - c_i - c_j and D_s = D + c_i + c_j holds it; no less does, as
    two robots back to back (control points pointing away from each other) have ||o_i - o_j|| =
    ||x_i - x_j|| - c_i - c_j (docs/SAFETY.md: D + 2l for two unicycles).  The other robot: of the
    same kind and geometry unless given."""
    if not (math.isfinite(origin_separation) and origin_separation >= 0.0):
        raise KindError(f'origin_separation D must be a finite number >= 0 [m], got {origin_separation!r}')
    other_kind = kind if other_kind is None else other_kind
    other_geometry = geometry if other_geometry is None else other_geometry
    reach = math.hypot(*kind.control_offset(geometry))
    other_reach = math.hypot(*other_kind.control_offset(other_geometry))
    return origin_separation + reach + other_reach


def default_min_separation(
    *, kind: RobotKind, geometry: Geometry, margin: float = SEPARATION_MARGIN
) -> float:
    """The `--min-separation` a robot backend takes by default: D_s between control points for
    D = 2 r + margin between origins (two footprints of radius r kept `margin` apart)."""
    if not (math.isfinite(margin) and margin >= 0.0):
        raise KindError(f'margin must be a finite number >= 0 [m], got {margin!r}')
    footprint = kind.footprint(geometry)
    return control_point_separation(2.0 * footprint + margin, kind=kind, geometry=geometry)


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
