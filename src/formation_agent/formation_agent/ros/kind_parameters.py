"""The robot parameters every node declares alike: generated from the kinds' declarations.

- `shape_specs(node)`: the `ParameterSpec` of each shape parameter the registered kinds declare
  for `node` (`formation_agent.core.kinds.shape`): its name, its default, its rule (> 0 or >= 0,
  finite) and its help, prefixed with the kinds that take it.  The agent's, the coordinator's
  and the simulated robot's tables hold these, so a shape parameter is declared once, in its kind.
- `limit_spec(name, use)`: a robot limit (speed, turn rate, steering angle), declared once here
  with its default (inf: none) and rule (> 0); each node adds what it does with it (`use`).

The tables are live (`SpecTable`): a kind registered later (a test's toy kind) brings its shape
parameters into every node's table, as `KindNames` brings its name into every choice.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from formation_agent.core.kinds.shape import ShapeParameter, declared, owners
from formation_agent.ros.parameters import DOUBLE, ParameterSpec


def shape_spec(parameter: ShapeParameter) -> ParameterSpec:
    """The node parameter of a shape parameter: '<kinds>: <help>', its default and rule.  A default
    that is each kind's own is 0 in a node (ROS parameters need a value): '0: the kind's'."""
    kinds = ', '.join(owners(parameter.name))
    own = parameter.default is None
    return ParameterSpec(
        name=parameter.name,
        type=DOUBLE,
        default=0.0 if parameter.default is None else float(parameter.default),
        low=0.0,
        low_open=parameter.positive and not own,
        high=math.inf,
        high_open=True,
        description=f'{kinds}: {parameter.help}' + (" (0: the kind's own)" if own else ''),
    )


def shape_specs(node: str) -> tuple[ParameterSpec, ...]:
    """The shape parameters `node` ('agent', 'coordinator', 'robot') takes, as its table's specs."""
    return tuple(shape_spec(parameter) for parameter in declared(node=node))


LIMITS = ('max_linear_speed', 'max_angular_speed', 'max_steering_angle', 'max_linear_acceleration')


def limit_spec(name: str, description: str) -> ParameterSpec:
    """A robot limit: a double > 0, inf (the default) for none; `description` says what it limits
    for the node that declares it, with its unit."""
    if name not in LIMITS:
        raise ValueError(f'limit must be one of {LIMITS}, got {name!r}')
    return ParameterSpec(
        name=name, type=DOUBLE, default=math.inf, low=0.0, low_open=True, description=description
    )


class SpecTable(Sequence):
    """A node's parameter table, built at each use from `build` (the kinds registered now)."""

    def __init__(self, build: Callable[[], tuple[ParameterSpec, ...]]) -> None:
        self._build = build

    def __getitem__(self, index):
        return self._build()[index]

    def __len__(self) -> int:
        return len(self._build())

    def __iter__(self):
        return iter(self._build())

    def __repr__(self) -> str:
        return f'SpecTable({self._build()!r})'
