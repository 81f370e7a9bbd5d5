"""A robot kind's shape parameters, each declared once, in its kind (ROS-free).

A `ShapeParameter` says everything of one number of a robot's shape: its name (the agent's,
the coordinator's and the simulated robot's parameter, a key of `Geometry`, the `formation`
command's flag `--name-with-dashes`), its symbol, its default, its rule and its help.  A kind
lists the ones it takes in `RobotKind.shape`; `registry.register` declares them here, and what
offers shape parameters is generated from the declarations (docs/DESIGN.md, "Robot kinds"):

- `Geometry`, a robot's shape: any declared name, its declared default unless given;
- the nodes' parameter tables (`formation_agent.ros.kind_parameters.shape_specs`), each node
  taking the parameters whose `nodes` name it;
- the `formation` command's flags (`formation_sim.commands.common.add_shape_arguments`) and
  `formation_sim.runtime.launch.plan.RobotOptions.geometry`.

So adding a shape parameter is one `ShapeParameter` in its kind's module and its name in that
kind's `shape`.  Two kinds may share a parameter (the car takes the unicycle's l) only by
declaring the same one: a second, different declaration under a name is refused (`ShapeError`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from formation_agent.core.errors import ShapeError

NODES = ('agent', 'coordinator', 'robot')
"""The nodes that may take a shape parameter: the agent (`formation_agent`), the coordinator of
robot runs, the simulated robot (`formation_sim.runtime.nodes.robot_node`)."""


@dataclass(frozen=True, kw_only=True)
class ShapeParameter:
    """One number of a robot's shape [m] (module docstring)."""

    name: str  # the nodes' parameter, Geometry's key; the flag is --name-with-dashes
    symbol: str  # in formulas and messages: 'l', 'L', 'r'
    help: str  # what it is, with its unit [m], without the kinds that take it
    default: float | None  # None: each kind's own, its class attribute of this name
    positive: bool = True  # the rule: a finite number > 0; False: >= 0 (0: not given)
    nodes: tuple[str, ...] = NODES  # the nodes that take it as a parameter
    metavar: str = 'M'  # the flag's metavar

    def __post_init__(self) -> None:
        if not self.name.isidentifier() or not set(self.nodes) <= set(NODES):
            raise ShapeError(
                f'a shape parameter needs a name that is an identifier and nodes among {NODES}, '
                f'got {self.name!r} with nodes {self.nodes!r}'
            )

    @property
    def flag(self) -> str:
        return '--' + self.name.replace('_', '-')

    @property
    def rule(self) -> str:
        """The rule in words: 'a finite number > 0' or '>= 0'."""
        return f'a finite number {">" if self.positive else ">="} 0'

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and (value > 0.0 if self.positive else value >= 0.0)

    def problem(self, value: float) -> str | None:
        """Why `value` breaks the rule (named with the rule and the value), or None."""
        if self.holds(value):
            return None
        return f'{self.name} {self.symbol} must be {self.rule} [m], got {value!r}'


_DECLARED: dict[str, ShapeParameter] = {}
_OWNERS: dict[str, dict[str, None]] = {}  # name -> the kinds that take it, in registration order


def declare(parameters: tuple[ShapeParameter, ...], *, kind: str) -> None:
    """Declare `kind`'s shape parameters, all or none (ShapeError if a name holds another declaration)."""
    for parameter in parameters:
        known = _DECLARED.get(parameter.name)
        if known is not None and known != parameter:
            raise ShapeError(
                f'shape parameter {parameter.name!r} is declared once: kind {kind!r} declares it '
                f'differently from {owners(parameter.name)} ({parameter} != {known})'
            )
    for parameter in parameters:
        _DECLARED.setdefault(parameter.name, parameter)
        _OWNERS.setdefault(parameter.name, {})[kind] = None


def undeclare(kind: str) -> None:
    """Forget `kind`'s parameters that no other kind takes (a kind unregistered)."""
    for name in [name for name, owners in _OWNERS.items() if kind in owners]:
        del _OWNERS[name][kind]
        if not _OWNERS[name]:
            del _OWNERS[name], _DECLARED[name]


def declared(*, node: str | None = None) -> tuple[ShapeParameter, ...]:
    """Every declared shape parameter in the order of declaration; with `node`, those it takes."""
    return tuple(p for p in _DECLARED.values() if node is None or node in p.nodes)


def shape_parameter(name: str) -> ShapeParameter:
    try:
        return _DECLARED[name]
    except KeyError:
        raise ShapeError(f'shape parameter must be one of {tuple(_DECLARED)}, got {name!r}') from None


def owners(name: str) -> tuple[str, ...]:
    """The kinds that take shape parameter `name`, in registration order."""
    return tuple(_OWNERS.get(name, ()))


class Geometry:
    """A robot's shape: a value per declared shape parameter, its declared default unless given
    (None for a parameter whose default is each kind's own: `RobotKind.shape_value`).  Immutable;
    equal when every value is."""

    __slots__ = ('_given',)
    _given: dict[str, float]
    if TYPE_CHECKING:  # for the type checker: the built-in kinds' shape parameters (any other: getattr)
        control_point_distance: float
        wheelbase: float
        footprint_radius: float | None

    def __init__(self, **values: float) -> None:
        for name in values:
            shape_parameter(name)  # ShapeError naming the declared ones
        object.__setattr__(self, '_given', {name: float(value) for name, value in values.items()})

    def __getattr__(self, name: str) -> float | None:
        if name.startswith('_') or name not in _DECLARED:
            raise AttributeError(f'Geometry has no shape parameter {name!r} (declared: {tuple(_DECLARED)})')
        return self._given.get(name, _DECLARED[name].default)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError('a Geometry is immutable: use replace(...)')

    def given(self) -> dict[str, float]:
        """The values given (not the defaults)."""
        return dict(self._given)

    def values(self) -> dict[str, float | None]:
        """Every declared parameter's value (given or default)."""
        return {name: getattr(self, name) for name in _DECLARED}

    def replace(self, **values: float) -> Geometry:
        return Geometry(**{**self._given, **values})

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Geometry) and self.values() == other.values()

    def __hash__(self) -> int:
        return hash(tuple(sorted(self.values().items())))

    def __repr__(self) -> str:
        return 'Geometry(' + ', '.join(f'{name}={value!r}' for name, value in self._given.items()) + ')'

    def __reduce__(self) -> tuple[Callable[[dict[str, float]], Geometry], tuple[dict[str, float]]]:
        return (_geometry, (self._given,))


def _geometry(given: dict[str, float]) -> Geometry:
    """A pickled Geometry, rebuilt (its values as given)."""
    return Geometry(**given)
