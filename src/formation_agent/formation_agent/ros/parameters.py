"""Declared parameters: one table per node, each entry with its type, description and range.

Every node of the project declares its parameters from a tuple of `ParameterSpec` through
`declare_parameters`, which

- gives each a `ParameterDescriptor` (description, type, range, choices), so that
  `ros2 param describe` explains it on a ROS 2 install and `parameter_help` prints the same table
  for `--help`;
- reads them all and checks them all before it fails: one `ParameterError` lists every missing
  parameter, every value of the wrong type, out of its range or not among its choices.

```python
SPECS = (
    ParameterSpec(name='agent_id', type=INTEGER, description='this agent's id i', low=0),
    ParameterSpec(
        name='delta', type=DOUBLE, description='communication radius Δ [m]', low=0.0, low_open=True
    ),
    ParameterSpec(
        name='robot', type=STRING, default='none', description='command adapter', choices=('none', 'unicycle')
    ),
)
values = declare_parameters(node, SPECS)   # {'agent_id': 2, 'delta': 4.0, 'robot': 'none'}
```
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.parameter import Parameter

from formation_agent.ros.errors import ParameterError

BOOL = Parameter.Type.BOOL
INTEGER = Parameter.Type.INTEGER
DOUBLE = Parameter.Type.DOUBLE
STRING = Parameter.Type.STRING
INTEGER_ARRAY = Parameter.Type.INTEGER_ARRAY
DOUBLE_ARRAY = Parameter.Type.DOUBLE_ARRAY
STRING_ARRAY = Parameter.Type.STRING_ARRAY

REQUIRED = object()
"""The default of a parameter that has none: it must be given."""

_TYPE_NAMES = {
    BOOL: 'bool',
    INTEGER: 'int',
    DOUBLE: 'double',
    STRING: 'string',
    INTEGER_ARRAY: 'int[]',
    DOUBLE_ARRAY: 'double[]',
    STRING_ARRAY: 'string[]',
}
_QUOTE_LIMIT = 80  # characters of a bad value quoted in an error


@dataclass(frozen=True, kw_only=True)
class ParameterSpec:
    """One parameter of a node. `low`/`high` bound numbers (and each element of number arrays);
    `low_open`/`high_open` make a bound strict (the descriptor's range, inclusive by ROS's
    definition, then only documents it); `choices` lists the values a string may take."""

    name: str
    type: Parameter.Type
    description: str
    default: Any = REQUIRED
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def constraint_text(self) -> str:
        """The range or choices in words ('> 0', 'in [0, 1]', "one of 'a', 'b'"), '' if none."""
        if self.choices:
            return 'one of ' + ', '.join(repr(choice) for choice in self.choices)
        # high = inf, open: a finite number (rclpy accepts inf and nan for a double).
        finite = self.high == math.inf and self.high_open
        low = None if self.low is None else f'{"(" if self.low_open else "["}{_number(self.low)}'
        high = (
            None if self.high is None or finite else f'{_number(self.high)}{")" if self.high_open else "]"}'
        )
        if low and high:
            return f'in {low}, {high}'
        if low:
            return f'{">" if self.low_open else ">="} {_number(self.low)}{", finite" if finite else ""}'
        if high:
            return f'{"<" if self.high_open else "<="} {_number(self.high)}'
        return 'finite' if finite else ''

    def descriptor(self) -> ParameterDescriptor:
        descriptor = ParameterDescriptor(
            name=self.name,
            type=self.type.value,
            description=self.description,
            additional_constraints=self.constraint_text(),
            read_only=True,  # read once at start: a change later would not be seen
        )
        # ROS ranges are inclusive; a strict bound is checked here and only written in words.
        closed = not (self.low_open or self.high_open) and self.low is not None and self.high is not None
        if self.type in (DOUBLE, DOUBLE_ARRAY) and closed:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(self.low), to_value=float(self.high), step=0.0)
            ]
        if self.type in (INTEGER, INTEGER_ARRAY) and closed:
            descriptor.integer_range = [
                IntegerRange(from_value=int(self.low), to_value=int(self.high), step=0)
            ]
        return descriptor

    def problem(self, value: Any) -> str | None:
        """Why `value` breaks this spec's range or choices, or None."""
        if self.choices:
            return None if value in self.choices else f'must be {self.constraint_text()}, got {_quote(value)}'
        if self.low is None and self.high is None:
            return None
        is_array = hasattr(value, '__len__') and not isinstance(value, str)
        for number in value if is_array else (value,):
            too_low = self.low is not None and (number <= self.low if self.low_open else number < self.low)
            too_high = self.high is not None and (
                number >= self.high if self.high_open else number > self.high
            )
            if too_low or too_high or (isinstance(number, float) and math.isnan(number)):
                every = ' (every element)' if is_array else ''
                return f'must be {self.constraint_text()}{every}, got {_quote(number)}'
        return None


def _number(value: float) -> str:
    """A bound as written: integers whole, other numbers exactly (repr)."""
    if isinstance(value, int) or (math.isfinite(value) and value == int(value) and abs(value) < 1e15):
        return str(int(value))
    return repr(float(value))


def _quote(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= _QUOTE_LIMIT else text[: _QUOTE_LIMIT - 1] + '…'


def declare_parameters(node, specs: Sequence[ParameterSpec]) -> dict[str, Any]:
    """Declare every spec on `node` (idempotent), read and check all; raise one ParameterError."""
    values, problems = read_parameters(node, specs)
    if problems:
        raise ParameterError(node.get_fully_qualified_name(), problems)
    return values


def read_parameters(node, specs: Sequence[ParameterSpec]) -> tuple[dict[str, Any], list[str]]:
    """Declare every spec on `node` (idempotent) and read it: the good values, and a problem per bad one.

    For nodes whose later parameters depend on earlier ones (which gains an algorithm takes): they
    gather the problems of every stage and raise one ParameterError at the end.
    """
    values: dict[str, Any] = {}
    problems: list[str] = []
    for spec in specs:
        label = f'parameter {spec.name!r} ({_TYPE_NAMES.get(spec.type, spec.type.name.lower())})'
        # An empty array says nothing of its element type (rclpy would take it for bytes):
        # declared by type, it stays unset unless given, and then reads as the default.
        by_type = spec.required or (isinstance(spec.default, (list, tuple)) and not spec.default)
        try:
            if not node.has_parameter(spec.name):
                node.declare_parameter(spec.name, spec.type if by_type else spec.default, spec.descriptor())
            value = node.get_parameter(spec.name).value
        except ParameterUninitializedException:
            if not spec.required:
                values[spec.name] = list(spec.default)
                continue
            problems.append(f'{label} is required: {spec.description}')
            continue
        except ParameterException as error:  # the wrong type, or outside the descriptor's range
            problems.append(f'{label}: {str(error).removesuffix(f": {spec.name}")}')
            continue
        if (problem := spec.problem(value)) is not None:
            problems.append(f'{label} {problem}')
            continue
        values[spec.name] = value
    return values, problems


def _rows(specs: Sequence[ParameterSpec]) -> list[tuple[str, str, str, str, str]]:
    """name, type, default (or 'required'), range or choices, description: one row per spec."""
    return [
        (
            spec.name,
            _TYPE_NAMES.get(spec.type, spec.type.name.lower()),
            'required' if spec.required else _quote(spec.default),
            spec.constraint_text(),
            spec.description,
        )
        for spec in specs
    ]


def parameter_table(specs: Sequence[ParameterSpec]) -> str:
    """The same table in Markdown (docs/PARAMETERS.md)."""
    lines = ['| parameter | type | default | range | meaning |', '|---|---|---|---|---|']
    for row in _rows(specs):
        name, kind, default, constraint, description = (cell.replace('|', '\\|') for cell in row)
        shown = default if default == 'required' else f'`{default}`'
        lines.append(f'| `{name}` | {kind} | {shown} | {constraint} | {description} |')
    return '\n'.join(lines)


def parameter_help(specs: Sequence[ParameterSpec], *, title: str = 'parameters') -> str:
    """The table `--help` prints: name, type, default (or 'required'), range, description."""
    rows = _rows(specs)
    widths = [max(len(row[k]) for row in rows) for k in range(4)]
    lines = [f'{title} (--ros-args -p name:=value, or --params-file FILE):']
    for row in rows:
        lines.append('  ' + '  '.join(cell.ljust(width) for cell, width in zip(row, widths)) + '  ' + row[4])
    return '\n'.join(lines)


def as_overrides(values: Mapping[str, Any]) -> list[Parameter]:
    """`values` as rclpy parameter overrides (for nodes built in a test or in one process)."""
    return [Parameter(name, value=value) for name, value in values.items()]
