"""The problem model: agents, graph, desired formation, gains; loading and dumping scenario files.

A scenario holds exactly the data of the paper's Theorems 1 and 2: the communication radius Δ,
the undirected graph with the desired displacements d_ij (Section 2.2), the initial states and the
gains. Structural soundness (shapes, ids, edges) is checked on construction and raises
`ScenarioError`; whether the paper's hypotheses hold is the job of `formation_sim.model.validate`.

The schema is documented in docs/SCENARIOS.md: a YAML file, or for large teams the same schema as
JSON (`.json`), which the json module parses ~100x faster than PyYAML and which has no aliases.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import re
import reprlib
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from formation_agent.core.errors import RuleError, SafetyError, ScaleError
from formation_agent.core.safety import SafetyConfig
from formation_agent.core.speed_scale import (
    DEFAULT_SPEED_SCALE,
    DEFAULT_THRESHOLD_FLOOR,
    check_speed_scale,
    check_threshold_floor,
)
from formation_agent.core.trigger import DEFAULT_RULE, rule_factory
from formation_msgs_py.types import MAX_AGENT_ID
from formation_sim.model.errors import ScenarioError
from formation_sim.model.gains import paper_k3, riccati_solution

DYNAMICS = ('single', 'double')
BUILTIN_PACKAGE = 'formation_sim.model.scenarios'

_TOP_REQUIRED = ('dynamics', 'communication_radius', 'horizon', 'agents', 'edges', 'gains')
_SINGLE_GAINS = ('alpha', 'beta')
_DOUBLE_GAINS = ('alpha_d', 'beta_d', 'beta1', 'k3')
_DOUBLE_OPTIONAL = ('k1', 'k2', 'k0')
# Both dynamics, optional (docs/SPEED_SCALE.md): the speed scale κ and the threshold floor c0.
SCALE_KEYS = {'speed_scale': DEFAULT_SPEED_SCALE, 'threshold_floor': DEFAULT_THRESHOLD_FLOOR}
NAME_LIMIT = 200  # characters of a scenario name (a label in reports, summaries and folder names)

# What a scenario file may hold. A team of 9 000 agents with 3 edges each (2-D) is ~300 000 YAML
# nodes and ~2.5 MB; the pure-Python parser takes ~25 µs a node, so these bound loading to
# seconds. Aliases count with everything they repeat: an "alias bomb" of a few hundred bytes
# expands to billions of nodes and is refused while it is read. Larger teams: a JSON file (C
# parser, no aliases, so its size bounds its cost: 32 MiB is ~130 000 agents, a few seconds), or
# Python (scenario_from_dict, formation_sim.generate).
MAX_FILE_BYTES = 4 * 1024 * 1024
MAX_YAML_NODES = 300_000
MAX_JSON_BYTES = 32 * 1024 * 1024
JSON_SUFFIX = '.json'


class _ShortRepr(reprlib.Repr):
    """repr() cut to a readable length: long strings, huge integers and deep or long containers end in
    '...'."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel, self.maxlist, self.maxtuple, self.maxdict, self.maxset = 3, 8, 8, 6, 6
        self.maxstring, self.maxother = 80, 80

    def repr_int(self, x: int, level: int) -> str:
        if abs(x) < 10**30:
            return repr(x)
        digits = (
            len(str(abs(x))) if x.bit_length() < 10_000 else f'about {int(x.bit_length() * math.log10(2))}'
        )
        return (
            f'{str(x)[:12] if x.bit_length() < 10_000 else "-" * (x < 0)}... (an integer of {digits} digits)'
        )


_SHORT_REPR = _ShortRepr()


def short_repr(value: Any) -> str:
    """repr(value), cut to a sensible length: what error messages quote of a user's value."""
    return _SHORT_REPR.repr(value)


def _readonly(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _finite_float(value: Any, where: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ScenarioError(f'{where}: expected a number, got {short_repr(value)}')
    try:
        result = float(value)
    except OverflowError:
        raise ScenarioError(
            f'{where}: {short_repr(value)} is too large for a double (|x| <= {_DOUBLE_MAX!r})'
        ) from None
    if not math.isfinite(result):
        raise ScenarioError(f'{where}: must be finite, got {short_repr(value)}')
    return result


_DOUBLE_MAX = float(np.finfo(float).max)


def _float_array(value: Any, where: str) -> np.ndarray:
    """np.array(value, dtype=float), refusing what cannot become one (too large, not numbers)."""
    try:
        return np.array(value, dtype=float)
    except OverflowError:
        raise ScenarioError(f'{where}: a value is too large for a double (|x| <= {_DOUBLE_MAX!r})') from None
    except (TypeError, ValueError) as error:
        raise ScenarioError(f'{where}: expected numbers, got {short_repr(value)} ({error})') from None


def _vector(value: Any, where: str, *, size: int | None = None) -> np.ndarray:
    """A finite float vector from a list of numbers (or an array), with an optional required size."""
    if (
        type(value) is np.ndarray
        and value.ndim == 1
        and value.size
        and value.dtype.kind in 'fiu'
        and (size is None or value.size == size)
    ):
        result = value.astype(float)  # fast path for generated scenarios: one copy, one check
        if np.all(np.isfinite(result)):
            return result
    if isinstance(value, np.ndarray):
        items = value.tolist() if value.ndim == 1 else None
    elif isinstance(value, (list, tuple)):
        items = list(value)
    else:
        items = None
    if items is None or not items:
        raise ScenarioError(f'{where}: expected a non-empty list of numbers, got {short_repr(value)}')
    numbers_ = [_finite_float(item, f'{where}[{k}]') for k, item in enumerate(items)]
    if size is not None and len(numbers_) != size:
        raise ScenarioError(
            f'{where}: has {len(numbers_)} components, expected {size} (the dimension p of the '
            f'scenario): {short_repr(value)}'
        )
    return np.array(numbers_, dtype=float)


def _agent_id(value: Any, where: str) -> int:
    if type(value) is int and 0 <= value <= MAX_AGENT_ID:
        return value
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, numbers.Integral)
        or not 0 <= value <= MAX_AGENT_ID
    ):
        raise ScenarioError(
            f'{where}: agent ids are integers in [0, {MAX_AGENT_ID}] (they name topics and travel in '
            f'messages and ROS parameters), got {short_repr(value)}'
        )
    return int(value)


def _name(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ScenarioError(f'name: expected a non-empty string, got {short_repr(value)}')
    if len(value) > NAME_LIMIT or not value.isprintable():
        raise ScenarioError(
            f'name: at most {NAME_LIMIT} printable characters (no line breaks or control characters), '
            f'got {short_repr(value)} ({len(value)} characters)'
        )
    return value


@dataclass(frozen=True, kw_only=True, eq=False)
class Edge:
    """An undirected edge (i, j), stored once, with d = d_ij = desired x_i - x_j (d_ji = -d_ij)."""

    i: int
    j: int
    d: np.ndarray

    def __post_init__(self) -> None:
        i = _agent_id(self.i, 'edge i')
        j = _agent_id(self.j, 'edge j')
        if i == j:
            raise ScenarioError(f'edge ({i}, {j}): i = j = {i} is a self-loop')
        object.__setattr__(self, 'i', i)
        object.__setattr__(self, 'j', j)
        object.__setattr__(self, 'd', _readonly(_vector(self.d, f'edge ({i}, {j}) d')))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Edge):
            return NotImplemented
        return self.i == other.i and self.j == other.j and np.array_equal(self.d, other.d)

    __hash__ = None

    @property
    def pair(self) -> tuple[int, int]:
        return (self.i, self.j)


@dataclass(frozen=True, kw_only=True)
class SingleGains:
    """ETA-1 gains: threshold α e^{-βt} of (triggersingle); the speed scale κ and the threshold
    floor c0 (docs/SPEED_SCALE.md; 1 and 0 are the paper's)."""

    alpha: float
    beta: float
    speed_scale: float = DEFAULT_SPEED_SCALE
    threshold_floor: float = DEFAULT_THRESHOLD_FLOOR

    def __post_init__(self) -> None:
        for key in _SINGLE_GAINS:
            object.__setattr__(self, key, _finite_float(getattr(self, key), f'gains.{key}'))
        _check_scale_keys(self)


def _check_scale_keys(gains) -> None:
    """κ and c0 of `gains` as floats within their rules (ScenarioError naming the rule and the value)."""
    try:
        object.__setattr__(gains, 'speed_scale', check_speed_scale(gains.speed_scale))
        object.__setattr__(gains, 'threshold_floor', check_threshold_floor(gains.threshold_floor))
    except ScaleError as error:
        raise ScenarioError(f'gains.{error}') from None


@dataclass(frozen=True, kw_only=True, eq=False)
class DoubleGains:
    """ETA-2 gains: threshold α_d e^{-β_d t} (triggerdouble), β1 and P of (riccatti), damping k3.

    P = [[k0, k1], [k1, k2]], so B^T P = [k1, k2] as the proof of Theorem 2 (ii) requires.
    """

    alpha_d: float
    beta_d: float
    beta1: float
    k3: float
    k1: float
    k2: float
    P: np.ndarray
    speed_scale: float = DEFAULT_SPEED_SCALE
    threshold_floor: float = DEFAULT_THRESHOLD_FLOOR

    def __post_init__(self) -> None:
        for key in ('alpha_d', 'beta_d', 'beta1', 'k3', 'k1', 'k2'):
            object.__setattr__(self, key, _finite_float(getattr(self, key), f'gains.{key}'))
        _check_scale_keys(self)
        matrix = _float_array(self.P, 'gains.P')
        if matrix.shape != (2, 2) or not np.all(np.isfinite(matrix)):
            raise ScenarioError(f'gains.P: expected a finite 2x2 matrix, got {short_repr(self.P)}')
        if matrix[0, 1] != matrix[1, 0]:
            raise ScenarioError(f'gains.P: must be symmetric, got {matrix.tolist()}')
        if matrix[0, 1] != self.k1 or matrix[1, 1] != self.k2:
            raise ScenarioError(
                f'gains: B^T P = [P01, P11] = {[matrix[0, 1], matrix[1, 1]]} must equal '
                f'[k1, k2] = {[self.k1, self.k2]}'
            )
        object.__setattr__(self, 'P', _readonly(matrix))

    @classmethod
    def from_riccati(
        cls,
        *,
        alpha_d: float,
        beta_d: float,
        beta1: float,
        k3: float | str,
        speed_scale: float = DEFAULT_SPEED_SCALE,
        threshold_floor: float = DEFAULT_THRESHOLD_FLOOR,
    ) -> DoubleGains:
        """P, k1, k2 solving (riccatti) with equality for this β1; k3='paper' is 2/(k2+sqrt(k1²+k2²))."""
        beta1 = _finite_float(beta1, 'gains.beta1')
        if not beta1 > 0.0:
            raise ScenarioError(
                f'gains.beta1: must be > 0 to determine P from (riccatti), got {short_repr(beta1)}'
            )
        matrix = riccati_solution(beta1)
        k1, k2 = float(matrix[0, 1]), float(matrix[1, 1])
        if isinstance(k3, str):
            if k3 != 'paper':
                raise ScenarioError(f"gains.k3: expected a number or 'paper', got {short_repr(k3)}")
            k3 = paper_k3(k1, k2)
        return cls(
            alpha_d=alpha_d,
            beta_d=beta_d,
            beta1=beta1,
            k3=k3,
            k1=k1,
            k2=k2,
            P=matrix,
            speed_scale=speed_scale,
            threshold_floor=threshold_floor,
        )

    @property
    def k0(self) -> float:
        return float(self.P[0, 0])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, DoubleGains):
            return NotImplemented
        return all(
            getattr(self, key) == getattr(other, key)
            for key in ('alpha_d', 'beta_d', 'beta1', 'k3', 'k1', 'k2', *SCALE_KEYS)
        ) and np.array_equal(self.P, other.P)

    __hash__ = None


@dataclass(frozen=True, kw_only=True, eq=False)
class Scenario:
    """One formation problem: Δ, graph with d_ij, initial states, gains, horizon."""

    name: str
    dynamics: str
    delta: float
    agent_ids: tuple[int, ...]
    positions: np.ndarray
    velocities: np.ndarray | None
    edges: tuple[Edge, ...]
    gains: SingleGains | DoubleGains
    horizon: float
    headings: np.ndarray | None = None  # (n,) [rad]: simulated robots' headings at t = 0, or None
    safety: SafetyConfig | None = None  # collision avoidance with connectivity (docs/SAFETY.md), or None
    trigger_rule: str = DEFAULT_RULE  # the threshold's family by name (formation_agent.core.trigger)

    def __post_init__(self) -> None:
        _name(self.name)
        try:
            rule_factory(self.trigger_rule)  # a registered name, or an import path that resolves
        except RuleError as error:
            raise ScenarioError(str(error)) from None
        if self.dynamics not in DYNAMICS:
            raise ScenarioError(f"dynamics: must be 'single' or 'double', got {short_repr(self.dynamics)}")
        delta = _finite_float(self.delta, 'communication_radius')
        if not delta > 0.0:
            raise ScenarioError(f'communication_radius: Δ must be > 0, got {short_repr(delta)}')
        horizon = _finite_float(self.horizon, 'horizon')
        if not horizon > 0.0:
            raise ScenarioError(f'horizon: must be > 0, got {short_repr(horizon)}')
        object.__setattr__(self, 'delta', delta)
        object.__setattr__(self, 'horizon', horizon)

        ids = tuple(_agent_id(agent, 'agent_ids') for agent in self.agent_ids)
        if len(ids) < 2:
            raise ScenarioError(f'agents: the formation problem needs at least 2 agents, got {list(ids)}')
        if any(a >= b for a, b in zip(ids, ids[1:])):
            raise ScenarioError(f'agent_ids: must be unique and sorted, got {list(ids)}')
        object.__setattr__(self, 'agent_ids', ids)
        index = {agent: k for k, agent in enumerate(ids)}

        positions = self._set_states(ids)

        expected = SingleGains if self.dynamics == 'single' else DoubleGains
        if not isinstance(self.gains, expected):
            raise ScenarioError(
                f'gains: dynamics {short_repr(self.dynamics)} needs {expected.__name__}, '
                f'got {type(self.gains).__name__}'
            )

        edges = _checked_edges(self.edges, ids=ids, index=index, p=positions.shape[1])
        object.__setattr__(self, 'edges', edges)
        if self.safety is not None:
            _check_safety(self.safety, dynamics=self.dynamics, ids=ids, positions=positions)
        object.__setattr__(self, '_index', index)
        object.__setattr__(self, '_neighbours', None)  # built on first use
        object.__setattr__(self, '_edge_indices', None)  # likewise

    def _set_states(self, ids: tuple[int, ...]) -> np.ndarray:
        """Positions, velocities (double) and headings (if any), checked against the agents `ids` and
        set read-only; the positions."""
        positions = _float_array(self.positions, 'positions')
        if positions.ndim != 2 or positions.shape[0] != len(ids) or positions.shape[1] < 1:
            raise ScenarioError(
                f'positions: expected shape ({len(ids)}, p) for agents {list(ids)}, got {positions.shape}'
            )
        self._check_finite(positions, 'position')
        object.__setattr__(self, 'positions', _readonly(positions))
        if self.dynamics == 'double':
            if self.velocities is None:
                raise ScenarioError("velocities: required for dynamics 'double'")
            velocities = _float_array(self.velocities, 'velocities')
            if velocities.shape != positions.shape:
                raise ScenarioError(
                    f'velocities: expected shape {positions.shape} like the positions, got {velocities.shape}'
                )
            self._check_finite(velocities, 'velocity')
            object.__setattr__(self, 'velocities', _readonly(velocities))
        elif self.velocities is not None:
            raise ScenarioError("velocities: must be absent for dynamics 'single'")

        if self.headings is not None:
            headings = _float_array(self.headings, 'headings')
            if headings.shape != (len(ids),):
                raise ScenarioError(
                    f'headings: expected one per agent, shape ({len(ids)},), got {headings.shape}'
                )
            self._check_finite(headings[:, None], 'heading')
            object.__setattr__(self, 'headings', _readonly(headings))
        return positions

    def _check_finite(self, array: np.ndarray, what: str) -> None:
        bad = np.flatnonzero(~np.all(np.isfinite(array), axis=1))
        if bad.size:
            agent = self.agent_ids[bad[0]]
            raise ScenarioError(f'agents.{agent}.{what}: must be finite, got {array[bad[0]].tolist()}')

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scenario):
            return NotImplemented
        return (
            self.name == other.name
            and self.dynamics == other.dynamics
            and self.delta == other.delta
            and self.agent_ids == other.agent_ids
            and np.array_equal(self.positions, other.positions)
            and (
                (self.velocities is None and other.velocities is None)
                or (
                    self.velocities is not None
                    and other.velocities is not None
                    and np.array_equal(self.velocities, other.velocities)
                )
            )
            and self.edges == other.edges
            and self.gains == other.gains
            and self.horizon == other.horizon
            and (
                (self.headings is None and other.headings is None)
                or (
                    self.headings is not None
                    and other.headings is not None
                    and np.array_equal(self.headings, other.headings)
                )
            )
            and self.safety == other.safety
            and self.trigger_rule == other.trigger_rule
        )

    __hash__ = None

    @property
    def n(self) -> int:
        return len(self.agent_ids)

    @property
    def dimension(self) -> int:
        return int(self.positions.shape[1])

    def index(self, agent_id: int) -> int:
        """Row of `agent_id` in positions/velocities."""
        try:
            return self._index[agent_id]
        except KeyError:
            raise ScenarioError(
                f'unknown agent {short_repr(agent_id)} (agents: {_id_list(self.agent_ids)})'
            ) from None

    def neighbours(self, agent_id: int) -> dict[int, np.ndarray]:
        """N_i with the desired displacement seen from agent i: j -> d_ij (d_ji = -d_ij)."""
        self.index(agent_id)
        if self._neighbours is None:
            table: dict[int, dict[int, np.ndarray]] = {agent: {} for agent in self.agent_ids}
            for edge in self.edges:
                table[edge.i][edge.j] = edge.d
                table[edge.j][edge.i] = _readonly(-edge.d)
            object.__setattr__(self, '_neighbours', table)
        return dict(self._neighbours[agent_id])

    def edge_indices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows of i, rows of j, d_ij stacked as (m, p)) over `edges`, for vectorised formulas."""
        if self._edge_indices is None:  # built once: per-sample formulas call it (run_series, theory)
            m = len(self.edges)
            heads = np.fromiter((self._index[e.i] for e in self.edges), dtype=np.intp, count=m)
            tails = np.fromiter((self._index[e.j] for e in self.edges), dtype=np.intp, count=m)
            d = np.array([e.d for e in self.edges], dtype=float).reshape(m, self.dimension)
            object.__setattr__(self, '_edge_indices', (heads, tails, d))
        return tuple(array.copy() for array in self._edge_indices)

    def replace(self, **changes: Any) -> Scenario:
        """A copy with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def with_scale(
        self, *, speed_scale: float | None = None, threshold_floor: float | None = None
    ) -> Scenario:
        """A copy with the speed scale κ and/or the threshold floor c0 replaced (None: kept)."""
        changes = {
            key: value
            for key, value in (('speed_scale', speed_scale), ('threshold_floor', threshold_floor))
            if value is not None
        }
        if not changes:
            return self
        return self.replace(gains=dataclasses.replace(self.gains, **changes))

    @property
    def speed_scale(self) -> float:
        """κ (docs/SPEED_SCALE.md): the run is the paper's in the time s = κt."""
        return self.gains.speed_scale


def _check_safety(safety, *, dynamics: str, ids: tuple[int, ...], positions: np.ndarray) -> None:
    """The safety layer's rules on the scenario: ETA-1, the plane, no two agents at one point (a pair
    closer than D starts in recovery, docs/SAFETY.md (S9))."""
    if not isinstance(safety, SafetyConfig):
        raise ScenarioError(f'safety: expected a SafetyConfig, got {short_repr(safety)}')
    if dynamics != 'single':
        raise ScenarioError(
            f"safety: the collision layer runs with dynamics 'single' (ETA-1), got {dynamics!r}"
        )
    if positions.shape[1] != 2:
        raise ScenarioError(
            f'safety: the collision layer is planar (dimension 2), got dimension {positions.shape[1]}'
        )
    from scipy.spatial import cKDTree  # the closest pair in O(n log n)

    gaps, rows = cKDTree(positions).query(positions, k=2)
    a = int(np.argmin(gaps[:, 1]))
    other = int(rows[a, 1]) if int(rows[a, 1]) != a else int(rows[a, 0])  # two at one point: either order
    a, b, gap = min(a, other), max(a, other), float(gaps[a, 1])
    if not gap > 0.0:  # closer than D is a start inside the margin, which the layer recovers from (S9)
        raise ScenarioError(
            f'safety: agents {ids[a]} and {ids[b]} start at the same point ({gap!r} m apart): the layer '
            'moves a pair apart along x_i - x_j, which two robots at one point do not have (S9)'
        )


def _checked_edges(edges, *, ids: tuple[int, ...], index: dict[int, int], p: int) -> tuple[Edge, ...]:
    """The scenario's edges as a tuple, each between two of its agents (`ids`; `index`: their
    places), with d in R^p, and listed once."""
    edges = tuple(edges)
    first_seen: dict[tuple[int, int], int] = {}
    for k, edge in enumerate(edges):
        if not isinstance(edge, Edge):
            raise ScenarioError(f'edges[{k}]: expected an Edge, got {short_repr(edge)}')
        i, j = edge.i, edge.j
        if i not in index or j not in index:
            role, agent = ('i', i) if i not in index else ('j', j)
            raise ScenarioError(
                f'edges[{k}] ({i}, {j}): {role}={agent} is not an agent (agents: {_id_list(ids)})'
            )
        if edge.d.shape != (p,):
            raise ScenarioError(
                f'edges[{k}] ({i}, {j}): d has {edge.d.size} components, expected {p} (the '
                f'dimension p of the positions): {edge.d.tolist()}'
            )
        key = (i, j) if i < j else (j, i)
        seen = first_seen.setdefault(key, k)
        if seen != k:
            other = edges[seen]
            # Seen from the first listing's orientation, the second one asks for this d.
            implied = edge.d if (other.i, other.j) == (i, j) else -edge.d
            agreement = (
                'they agree'
                if np.array_equal(implied, other.d)
                else f'and they disagree: d = {other.d.tolist()} there, {implied.tolist()} here'
            )
            raise ScenarioError(
                f'edges[{k}] ({i}, {j}): duplicates edges[{seen}] ({other.i}, {other.j}), {agreement} '
                f'(as d_{other.i}{other.j}); list each undirected edge once (d_ji = -d_ij is implied)'
            )
    return edges


def _id_list(ids: tuple[int, ...]) -> str:
    if len(ids) <= 12:
        return ', '.join(map(str, ids))
    return f'{ids[0]}, {ids[1]}, ..., {ids[-1]} ({len(ids)} agents)'


# --------------------------------------------------------------------------- dicts


def _mapping(value: Any, where: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise ScenarioError(f'{where}: expected a mapping, got {short_repr(value)}')
    return value


def _check_keys(data: Mapping, where: str, *, required: tuple, optional: tuple = ()) -> None:
    allowed = required + optional
    unknown = [key for key in data if key not in allowed]
    if unknown:
        raise ScenarioError(f'{where}: unknown key {short_repr(unknown[0])} (allowed: {", ".join(allowed)})')
    missing = [key for key in required if key not in data]
    if missing:
        raise ScenarioError(
            f'{where}: missing key {short_repr(missing[0])} (required: {", ".join(required)})'
        )


def _positive(value: Any, where: str, what: str) -> float:
    number = _finite_float(value, where)
    if not number > 0.0:
        raise ScenarioError(f'{where}: {what} must be > 0, got {short_repr(value)}')
    return number


def scenario_from_dict(data: Any, *, name: str | None = None) -> Scenario:
    """Build a scenario from the YAML schema (docs/SCENARIOS.md); `name` is used if data has none."""
    data = _mapping(data, 'scenario')
    _check_keys(data, 'scenario', required=_TOP_REQUIRED, optional=('name', 'safety', 'trigger_rule'))
    scenario_name = _name(data.get('name', name if name is not None else 'scenario'))

    dynamics = data['dynamics']
    if dynamics not in DYNAMICS:
        raise ScenarioError(f"dynamics: must be 'single' or 'double', got {short_repr(dynamics)}")
    delta = _positive(data['communication_radius'], 'communication_radius', 'Δ')
    horizon = _positive(data['horizon'], 'horizon', 'the horizon')

    entries, headings, dimension = _agents_from_dict(data['agents'], dynamics)
    ids = tuple(sorted(entries))
    if headings and len(headings) != len(ids):
        missing = [a for a in ids if a not in headings]
        raise ScenarioError(
            f'agents.{missing[0]}: heading missing, while agents {_id_list(tuple(sorted(headings)))} '
            'have one: give every agent a heading or none'
        )
    positions = np.array([entries[a][0] for a in ids])
    velocities = np.array([entries[a][1] for a in ids]) if dynamics == 'double' else None

    edges = _edges_from_dict(data['edges'], ids=ids, dimension=dimension)

    gains = _gains_from_dict(data['gains'], dynamics)
    safety = None
    if data.get('safety') is not None:
        try:
            safety = SafetyConfig.from_mapping(data['safety'])
        except SafetyError as error:
            raise ScenarioError(str(error)) from None
    return Scenario(
        name=scenario_name,
        dynamics=dynamics,
        delta=delta,
        agent_ids=ids,
        positions=positions,
        velocities=velocities,
        edges=tuple(edges),
        gains=gains,
        horizon=horizon,
        headings=np.array([headings[a] for a in ids]) if headings else None,
        safety=safety,
        trigger_rule=data.get('trigger_rule', DEFAULT_RULE),
    )


def _agents_from_dict(
    raw: Any, dynamics: str
) -> tuple[dict[int, tuple[np.ndarray, np.ndarray | None]], dict[int, float], int | None]:
    """The scenario's `agents` mapping: per agent its position and velocity (double), the headings
    given, and the dimension p."""
    agents = _mapping(raw, 'agents')
    if len(agents) < 2:
        raise ScenarioError(f'agents: the formation problem needs at least 2 agents, got {len(agents)}')
    velocity_keys = ('position', 'velocity') if dynamics == 'double' else ('position',)
    entries: dict[int, tuple[np.ndarray, np.ndarray | None]] = {}
    headings: dict[int, float] = {}
    dimension: int | None = None
    first_agent: int | None = None
    for raw_id, entry in agents.items():
        # JSON has only string keys: accept "12" for agent 12, so summary.json copies load too.
        json_id = isinstance(raw_id, str) and raw_id.isascii() and raw_id.isdigit() and len(raw_id) <= 20
        label = raw_id if isinstance(raw_id, str) and len(raw_id) <= 40 else short_repr(raw_id)
        agent = _agent_id(int(raw_id) if json_id else raw_id, f'agents.{label}')
        if agent in entries:
            raise ScenarioError(f'agents.{label}: agent {agent} is listed twice')
        where = f'agents.{agent}'
        entry = _mapping(entry, where)
        if dynamics == 'single' and 'velocity' in entry:
            raise ScenarioError(
                f"{where}.velocity: given, but dynamics is 'single' (single integrators have no "
                f'velocity state): {short_repr(entry["velocity"])}'
            )
        if dynamics == 'double' and 'velocity' not in entry and 'position' in entry:
            raise ScenarioError(f"{where}: velocity missing (dynamics is 'double')")
        if 'position' not in entry:
            raise ScenarioError(
                f'{where}: position missing (robots set down by hand: `formation measure` writes their '
                'positions from their poses)'
            )
        _check_keys(entry, where, required=velocity_keys, optional=('heading',))
        if 'heading' in entry:
            headings[agent] = _finite_float(entry['heading'], f'{where}.heading')
        position = _vector(entry['position'], f'{where}.position', size=dimension)
        if dimension is None:
            dimension, first_agent = position.size, agent
        elif position.size != dimension:  # pragma: no cover - _vector already enforces the size
            raise ScenarioError(f'{where}.position: dimension differs from agent {first_agent}')
        velocity = (
            _vector(entry['velocity'], f'{where}.velocity', size=dimension) if dynamics == 'double' else None
        )
        entries[agent] = (position, velocity)
    return entries, headings, dimension


def _edges_from_dict(raw_edges: Any, *, ids: tuple[int, ...], dimension: int | None) -> list[Edge]:
    """The scenario's `edges` list, each edge between two of the agents `ids`, with d in R^p."""
    if not isinstance(raw_edges, list):
        raise ScenarioError(f'edges: expected a list of {{i, j, d}}, got {short_repr(raw_edges)}')
    edges = []
    for k, raw in enumerate(raw_edges):
        where = f'edges[{k}]'
        raw = _mapping(raw, where)
        _check_keys(raw, where, required=('i', 'j', 'd'))
        i = _agent_id(raw['i'], f'{where}.i')
        j = _agent_id(raw['j'], f'{where}.j')
        where = f'edges[{k}] ({i}, {j})'
        for role, agent in (('i', i), ('j', j)):
            if agent not in ids:
                raise ScenarioError(f'{where}: {role}={agent} is not an agent (agents: {_id_list(ids)})')
        if i == j:
            raise ScenarioError(f'{where}: i = j = {i} is a self-loop')
        d = _vector(raw['d'], f'{where}.d', size=dimension)
        edges.append(Edge(i=i, j=j, d=d))
    return edges


def _gains_from_dict(raw: Any, dynamics: str) -> SingleGains | DoubleGains:
    raw = _mapping(raw, 'gains')
    scale = {key: raw[key] for key in SCALE_KEYS if key in raw}
    for key, value in scale.items():
        _finite_float(value, f'gains.{key}')
    if dynamics == 'single':
        unknown = [key for key in raw if key not in _SINGLE_GAINS + tuple(SCALE_KEYS)]
        if unknown:
            raise ScenarioError(
                f"gains: unknown key {short_repr(unknown[0])} for dynamics 'single' "
                f'(allowed: {", ".join(_SINGLE_GAINS + tuple(SCALE_KEYS))})'
            )
        _check_keys(raw, 'gains', required=_SINGLE_GAINS, optional=tuple(SCALE_KEYS))
        return SingleGains(alpha=raw['alpha'], beta=raw['beta'], **scale)
    optional = _DOUBLE_OPTIONAL + tuple(SCALE_KEYS)
    unknown = [key for key in raw if key not in _DOUBLE_GAINS + optional]
    if unknown:
        raise ScenarioError(
            f"gains: unknown key {short_repr(unknown[0])} for dynamics 'double' "
            f'(allowed: {", ".join(_DOUBLE_GAINS + optional)})'
        )
    _check_keys(raw, 'gains', required=_DOUBLE_GAINS, optional=optional)
    values = {key: raw[key] for key in ('alpha_d', 'beta_d', 'beta1')}
    for key, value in values.items():
        _finite_float(value, f'gains.{key}')
    k3 = raw['k3']
    if not isinstance(k3, str):
        k3 = _finite_float(k3, 'gains.k3')
    elif k3 != 'paper':
        raise ScenarioError(f"gains.k3: expected a number or 'paper', got {short_repr(k3)}")
    if 'k1' not in raw and 'k2' not in raw:
        if 'k0' in raw:
            raise ScenarioError(f'gains.k0: given ({short_repr(raw["k0"])}) without k1 and k2')
        return DoubleGains.from_riccati(k3=k3, **values, **scale)
    if 'k1' not in raw or 'k2' not in raw:
        given = 'k1' if 'k1' in raw else 'k2'
        raise ScenarioError(
            f'gains.{given}: given ({short_repr(raw[given])}) without its partner; give both k1 and k2 or '
            f'neither (then P, k1, k2 come from (riccatti))'
        )
    k1 = _finite_float(raw['k1'], 'gains.k1')
    k2 = _finite_float(raw['k2'], 'gains.k2')
    beta1 = float(values['beta1'])
    # k0 = 2 β1 k1 k2 zeroes the off-diagonal of (riccatti), the best choice for given k1, k2.
    k0 = _finite_float(raw['k0'], 'gains.k0') if 'k0' in raw else 2.0 * beta1 * k1 * k2
    if k3 == 'paper':
        k3 = paper_k3(k1, k2)
    return DoubleGains(k3=k3, k1=k1, k2=k2, P=np.array([[k0, k1], [k1, k2]]), **values, **scale)


def scenario_to_dict(scenario: Scenario) -> dict[str, Any]:
    """The YAML schema of `scenario`; scenario_from_dict(scenario_to_dict(s)) == s exactly."""
    double = scenario.dynamics == 'double'
    agents: dict[int, dict[str, list[float]]] = {}
    for k, agent in enumerate(scenario.agent_ids):
        entry = {'position': scenario.positions[k].tolist()}
        if double:
            entry['velocity'] = scenario.velocities[k].tolist()
        if scenario.headings is not None:
            entry['heading'] = float(scenario.headings[k])
        agents[agent] = entry
    gains = scenario.gains
    if double:
        gains_dict: dict[str, Any] = {
            'alpha_d': gains.alpha_d,
            'beta_d': gains.beta_d,
            'beta1': gains.beta1,
            'k3': gains.k3,
        }
        if not (gains.beta1 > 0.0 and np.array_equal(gains.P, riccati_solution(gains.beta1))):
            gains_dict.update(k1=gains.k1, k2=gains.k2, k0=gains.k0)
    else:
        gains_dict = {'alpha': gains.alpha, 'beta': gains.beta}
    for key, default in SCALE_KEYS.items():  # written only where not the paper's: older readers keep working
        if getattr(gains, key) != default:
            gains_dict[key] = getattr(gains, key)
    data = {
        'name': scenario.name,
        'dynamics': scenario.dynamics,
        'communication_radius': scenario.delta,
        'horizon': scenario.horizon,
        'agents': agents,
        'edges': [{'i': e.i, 'j': e.j, 'd': e.d.tolist()} for e in scenario.edges],
        'gains': gains_dict,
    }
    if scenario.safety is not None:  # written only when on: older readers keep working
        data['safety'] = scenario.safety.as_dict()
    if scenario.trigger_rule != DEFAULT_RULE:  # likewise: written only when not the paper's
        data['trigger_rule'] = scenario.trigger_rule
    return data


# --------------------------------------------------------------------------- YAML


class _TooManyNodes(yaml.YAMLError):
    """The document holds more than MAX_YAML_NODES nodes, aliases expanded."""

    def __init__(self, mark, alias: str | None) -> None:
        super().__init__()
        self.mark = mark
        self.alias = alias  # the alias being expanded when the count ran over, if any


class _TooDeep(yaml.YAMLError):
    """The document nests collections deeper than _YAML_DEPTH_LIMIT."""


# Nesting a YAML scenario file may have (a scenario nests 4 levels). libyaml composes and the
# constructor builds recursively: the limit keeps a file of 4 MB of '[' from reaching either.
_YAML_DEPTH_LIMIT = 100


class _Checks:
    """What both loaders add to PyYAML's safe constructor: duplicate keys refused, huge integers named."""

    def construct_mapping(self, node, deep=False):
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == 'tag:yaml.org,2002:merge':
                continue  # `<<: *base` merges keys the mapping itself may override (YAML merge keys)
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable: the base class names it
                break
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    'while constructing a mapping',
                    node.start_mark,
                    f'found duplicate key {short_repr(key)}',
                    key_node.start_mark,
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        try:
            return super().construct_yaml_int(node)
        except ValueError:  # beyond Python's 4300 digits for int(str): far beyond any double too
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f'an integer of {len(node.value)} characters is too large for a double',
                node.start_mark,
            ) from None


class _Loader(_Checks, yaml.SafeLoader):
    """The pure-Python SafeLoader with `_Checks`, counting nodes as it composes (see `_count_nodes`).

    It reads a document only after libyaml failed on it (`_load_yaml`): its error messages, with
    line and column, are the ones a user has always got.
    """

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._nodes = 0
        self._anchor_sizes: dict[str, int] = {}  # anchor -> nodes in the subtree it names

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            self._count(self._anchor_sizes.get(event.anchor, 1), event, alias=event.anchor)
            return super().compose_node(parent, index)
        before = self._nodes
        self._count(1, event, alias=None)
        node = super().compose_node(parent, index)
        if event.anchor is not None:
            self._anchor_sizes[event.anchor] = self._nodes - before
        return node

    def _count(self, nodes: int, event, *, alias: str | None) -> None:
        self._nodes += nodes
        if self._nodes > MAX_YAML_NODES:
            raise _TooManyNodes(event.start_mark, alias)


class _CLoader(_Checks, yaml.CSafeLoader):
    """libyaml's parser and composer (C) with the safe constructor and `_Checks` (Python)."""


_YAML_FLOAT = re.compile(r'^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$')
for _loader in (_Loader, _CLoader):
    _loader.add_constructor('tag:yaml.org,2002:int', _Checks.construct_yaml_int)
    _loader.add_implicit_resolver(
        'tag:yaml.org,2002:float', _YAML_FLOAT, list('-+0123456789.')
    )  # 1e-3 (YAML 1.2)


def _count_nodes(text: str) -> None:
    """Refuse `text` before anything is composed: more than MAX_YAML_NODES nodes, every alias counted
    as all the nodes it repeats (an alias bomb of a few hundred bytes expands to billions), or
    collections nested deeper than _YAML_DEPTH_LIMIT.

    libyaml (C) delivers the events; the count is `_Loader.compose_node`'s, event for event, so both
    refuse the same documents at the same place. A syntax error is raised as libyaml words it.
    """
    parser = yaml.CSafeLoader(text)
    scalar, alias, stream_end = yaml.ScalarEvent, yaml.AliasEvent, yaml.StreamEndEvent
    starts, ends = (
        (yaml.SequenceStartEvent, yaml.MappingStartEvent),
        (yaml.SequenceEndEvent, yaml.MappingEndEvent),
    )
    nodes = 0
    sizes: dict[str, int] = {}  # anchor -> nodes in the subtree it names
    opened: list[tuple[str | None, int]] = []  # the collections being read: (anchor, nodes before it)
    try:
        while True:
            event = parser.get_event()
            kind = type(event)
            if kind is scalar:
                nodes += 1
                if event.anchor is not None:
                    sizes[event.anchor] = 1
            elif kind in starts:
                opened.append((event.anchor, nodes))
                nodes += 1
                if len(opened) > _YAML_DEPTH_LIMIT:
                    raise _TooDeep
            elif kind in ends:
                anchor, before = opened.pop()
                if anchor is not None:
                    sizes[anchor] = nodes - before
            elif kind is alias:
                nodes += sizes.get(event.anchor, 1)  # 1 while the anchor is still open (a recursive alias)
                if nodes > MAX_YAML_NODES:
                    raise _TooManyNodes(event.start_mark, event.anchor)
            elif kind is stream_end:
                return
            if nodes > MAX_YAML_NODES:
                raise _TooManyNodes(event.start_mark, None)
    finally:
        parser.dispose()


class _NotPlain(Exception):
    """The document uses what `_read_plain` leaves to the full loader: an anchor or alias, an explicit
    tag, a merge key, a key that is not a scalar, a duplicate key, a second document."""


_PLAIN_TAGS = frozenset(f'tag:yaml.org,2002:{name}' for name in ('str', 'int', 'float', 'bool', 'null'))
_NO_KEY = object()


def _read_plain(text: str) -> Any:
    """The document in `text` built straight from libyaml's events, for documents of plain
    mappings, sequences and untagged scalars (every scenario file `dump_scenario` writes): each
    scalar resolved and constructed by the loader's own resolver and constructors, the nodes
    counted and the nesting bounded as `_count_nodes` does. Raises _NotPlain for anything else."""
    loader = _CLoader(text)
    try:
        return _build_plain(loader)
    finally:
        loader.dispose()


def _build_plain(loader: _CLoader) -> Any:
    get, resolve, constructors = loader.get_event, loader.resolve, loader.yaml_constructors
    scalar, stream_end, document_end = yaml.ScalarEvent, yaml.StreamEndEvent, yaml.DocumentEndEvent
    starts, ends = (
        (yaml.SequenceStartEvent, yaml.MappingStartEvent),
        (yaml.SequenceEndEvent, yaml.MappingEndEvent),
    )
    scalar_node, mapping_start = yaml.ScalarNode, yaml.MappingStartEvent
    cache: dict[tuple, Any] = {}  # (text, implicit) -> constructed value: keys repeat on every line
    first_error: yaml.YAMLError | None = None  # raised once the whole document is read, as PyYAML would
    opened: list[list] = []  # [container, pending key] of the collections being read
    root, nodes = None, 0
    get()  # StreamStartEvent
    if type(get()) is stream_end:
        return None  # an empty file
    while True:
        event = get()
        kind = type(event)
        if kind is document_end:
            break
        if kind in ends:
            opened.pop()
            continue
        if event.anchor is not None or event.tag is not None:
            raise _NotPlain
        nodes += 1
        if nodes > MAX_YAML_NODES:
            raise _TooManyNodes(event.start_mark, None)
        if kind is scalar:
            key = (event.value, event.implicit)
            value = cache.get(key, _NO_KEY)
            if value is _NO_KEY:
                tag = resolve(scalar_node, event.value, event.implicit)
                if tag not in _PLAIN_TAGS:
                    raise _NotPlain
                try:
                    value = constructors[tag](
                        loader, scalar_node(tag, event.value, event.start_mark, event.end_mark)
                    )
                except yaml.constructor.ConstructorError as error:
                    first_error, value = first_error or error, None
                cache[key] = value
        elif kind in starts:
            value = {} if kind is mapping_start else []
        else:
            raise _NotPlain
        if not opened:
            root = value
        else:
            parent = opened[-1]
            container = parent[0]
            if type(container) is list:
                container.append(value)
            elif parent[1] is not _NO_KEY:
                container[parent[1]] = value
                parent[1] = _NO_KEY
            elif kind is scalar and value not in container:
                parent[1] = value
            else:
                raise _NotPlain  # a collection as a key, or a duplicate key: the full loader names it
        if kind is not scalar:
            opened.append([value, _NO_KEY])
            if len(opened) > _YAML_DEPTH_LIMIT:
                raise _TooDeep
    if type(get()) is not stream_end:
        raise _NotPlain  # a second document
    if first_error is not None:
        raise first_error
    return root


def _load_yaml(text: str) -> Any:
    """The document in `text`, parsed by libyaml (C): plain documents in one pass over its events
    (`_read_plain`), others counted (`_count_nodes`), composed by libyaml and constructed with
    `_Checks`. A document libyaml cannot read is read again by the pure-Python `_Loader`, for the
    error message it has always given."""
    try:
        try:
            return _read_plain(text)
        except _NotPlain:
            pass
        _count_nodes(text)
        loader = _CLoader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except (_TooManyNodes, _TooDeep, yaml.constructor.ConstructorError):
        raise  # the constructor is the same Python code in both loaders, and so is its message
    except yaml.YAMLError:
        pass  # libyaml words syntax errors its own way
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader derives from SafeLoader


def _parse_yaml(text: str, source: str) -> Any:
    try:
        return _load_yaml(text)
    except _TooManyNodes as error:
        where = f'line {error.mark.line + 1}, column {error.mark.column + 1}'
        cause = (
            f'with its aliases expanded (at {where}, *{short_repr(error.alias)[1:-1]} repeats what it names; '
            f'an alias bomb?)'
            if error.alias is not None
            else f'(at {where})'
        )
        raise ScenarioError(
            f'{source}: the YAML document holds more than {MAX_YAML_NODES} nodes {cause}; a scenario file '
            f'holds at most {MAX_YAML_NODES} (about 9 000 agents): refused. Larger teams: {_LARGER_TEAMS}'
        ) from None
    except (_TooDeep, RecursionError):
        raise ScenarioError(
            f'{source}: malformed YAML: nested too deeply (a scenario nests 4 levels)'
        ) from None
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        where = f'line {mark.line + 1}, column {mark.column + 1}' if mark else 'unknown position'
        problem = error.problem or error.context or 'malformed YAML'
        context = ''
        if error.context and error.context_mark and error.context_mark is not mark:
            start = error.context_mark
            context = f' ({error.context} started at line {start.line + 1}, column {start.column + 1})'
        raise ScenarioError(f'{source}: malformed YAML at {where}: {problem}{context}') from None
    except yaml.YAMLError as error:
        raise ScenarioError(f'{source}: malformed YAML: {error}') from None


def builtin_scenarios() -> tuple[str, ...]:
    """Names accepted by `load_scenario` besides paths (the YAML files shipped in the package)."""
    folder = resources.files(BUILTIN_PACKAGE)
    return tuple(sorted(entry.name[:-5] for entry in folder.iterdir() if entry.name.endswith('.yaml')))


_LARGER_TEAMS = (
    'the same schema as JSON (.json, `formation generate`), or Python (scenario_from_dict, '
    'formation_sim.generate)'
)


def _size_limit(kind: str) -> int:
    return MAX_JSON_BYTES if kind == 'JSON' else MAX_FILE_BYTES


def _too_large(source: str, size: int, kind: str) -> ScenarioError:
    limit = _size_limit(kind)
    if kind == 'YAML':
        what, larger = 'a scenario file', f' (about 9 000 agents): refused. Larger teams: {_LARGER_TEAMS}'
    else:
        what, larger = f'a {kind} scenario file', ': refused'
    return ScenarioError(f'{source}: {size / 1e6:.1f} MB; {what} holds at most {limit / 1e6:.1f} MB{larger}')


def _read_text(path: Path, *, kind: str) -> str:
    """The UTF-8 text of a scenario file (a leading BOM dropped), refused above its size limit."""
    limit = _size_limit(kind)
    try:
        size = path.stat().st_size
        if size > limit:
            raise _too_large(str(path), size, kind)
        data = path.read_bytes()[: limit + 1]  # the file may have grown since stat
    except OSError as error:
        raise ScenarioError(f'{path}: cannot read: {error.strerror or error}') from None
    if len(data) > limit:
        raise ScenarioError(f'{path}: more than {limit / 1e6:.1f} MB; refused')
    try:
        return data.decode('utf-8-sig')
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b'\n') + 1
        raise ScenarioError(
            f'{path}: not UTF-8 text: byte 0x{data[error.start]:02x} at line {line} (offset {error.start}) '
            f'cannot be decoded; a scenario file is UTF-8 {kind}'
        ) from None


def file_kind(path: str | Path) -> str:
    """'JSON' for a name ending in .json, else 'YAML': how `load_scenario` and `dump_scenario` read and write
    it."""
    return 'JSON' if Path(path).suffix.lower() == JSON_SUFFIX else 'YAML'


def _parsed(text: str, *, kind: str, source: str) -> Any:
    """The data in `text` (size and syntax checked, the schema not yet)."""
    size = len(text.encode('utf-8'))
    if size > _size_limit(kind):
        raise _too_large(source, size, kind)
    return _parse_json(text, source) if kind == 'JSON' else _parse_yaml(text, source)


def scenario_from_text(text: str, *, kind: str, source: str, name: str) -> Scenario:
    """The scenario in `text` (a file's content, `kind` 'JSON' or 'YAML'), checked as `load_scenario`
    checks a file: size, syntax, schema; `name` if the text has none; errors name `source`."""
    data = _parsed(text, kind=kind, source=source)
    try:
        return scenario_from_dict(data, name=name)
    except ScenarioError as error:
        raise ScenarioError(f'{source}: {error}') from None


def _scenario_source(name_or_path: str | Path) -> tuple[str, str, str, str]:
    """(text, kind, source, name) of a built-in scenario or a file (ScenarioError if neither)."""
    if isinstance(name_or_path, str) and name_or_path in builtin_scenarios():
        resource = resources.files(BUILTIN_PACKAGE) / f'{name_or_path}.yaml'
        return (
            resource.read_text(encoding='utf-8'),
            'YAML',
            f'built-in scenario {short_repr(name_or_path)}',
            name_or_path,
        )
    named = bool(str(name_or_path).strip())  # Path('') would be the current folder
    path = Path(name_or_path)
    if named and path.is_dir():
        raise ScenarioError(f'{short_repr(str(name_or_path))}: is a folder, not a scenario file')
    if not (named and path.is_file()):
        raise ScenarioError(
            f'{short_repr(str(name_or_path))}: no such scenario file and not a built-in scenario '
            f'({", ".join(builtin_scenarios())})'
        )
    kind = file_kind(path)
    return _read_text(path, kind=kind), kind, str(path), path.stem


def load_scenario(name_or_path: str | Path) -> Scenario:
    """A built-in scenario by name (a str equal to one of `builtin_scenarios()`), else a file: JSON
    if its name ends in .json, YAML otherwise."""
    text, kind, source, name = _scenario_source(name_or_path)
    return scenario_from_text(text, kind=kind, source=source, name=name)


def load_scenario_data(name_or_path: str | Path) -> tuple[Any, str, str]:
    """A scenario's data as its file holds it, size and syntax checked but not its schema (so
    that agents may lack their positions: `formation measure` fills them in); with the name it
    gets when the data has none, and the source its errors name."""
    text, kind, source, name = _scenario_source(name_or_path)
    return _parsed(text, kind=kind, source=source), name, source


class _Dumper(yaml.SafeDumper):
    pass


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    # Vectors of numbers on one line, like the schema's examples.
    flow = all(isinstance(item, (int, float)) for item in data)
    return dumper.represent_sequence('tag:yaml.org,2002:seq', data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def dump_scenario_text(scenario: Scenario) -> str:
    """`scenario` as YAML text that reads back exactly (floats keep every bit)."""
    return yaml.dump(scenario_to_dict(scenario), Dumper=_Dumper, sort_keys=False, allow_unicode=True)


def dump_scenario_json_text(scenario: Scenario) -> str:
    """`scenario` as JSON text, one agent and one edge a line, that reads back exactly (floats keep every
    bit)."""
    data = scenario_to_dict(scenario)

    def text(value: Any) -> str:
        return json.dumps(value, allow_nan=False, ensure_ascii=False)

    head = ''.join(
        f'{text(key)}: {text(data[key])},\n'
        for key in ('name', 'dynamics', 'communication_radius', 'horizon')
    )
    agents = ',\n'.join(f'  {text(str(agent))}: {text(entry)}' for agent, entry in data['agents'].items())
    edges = ',\n'.join(f'  {text(edge)}' for edge in data['edges'])
    return (
        f'{{\n{head}"agents": {{\n{agents}\n}},\n"edges": [\n{edges}\n],\n"gains": '
        f'{text(data["gains"])}\n}}\n'
    )


def dump_scenario_as(scenario: Scenario, kind: str) -> str:
    """`scenario` as the text of a 'JSON' or 'YAML' file."""
    return dump_scenario_json_text(scenario) if kind == 'JSON' else dump_scenario_text(scenario)


def dump_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write `scenario` as JSON if `path` ends in .json, else YAML; load_scenario(path) == scenario
    exactly (floats keep every bit)."""
    Path(path).write_text(dump_scenario_as(scenario, file_kind(path)), encoding='utf-8')


# --------------------------------------------------------------------------- JSON


class _DuplicateJsonKey(ValueError):
    def __init__(self, key: str, keys: list[str]) -> None:
        super().__init__(key)
        self.key, self.keys = key, keys


class _HugeJsonInteger(ValueError):
    def __init__(self, digits: int) -> None:
        super().__init__(digits)
        self.digits = digits


def _json_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object as a dict; a key given twice is refused (json.loads would keep the last silently)."""
    result = dict(pairs)
    if len(result) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise _DuplicateJsonKey(key, [name for name, _ in pairs])
            seen.add(key)
    return result


def _json_int(text: str) -> int:
    try:
        return int(text)
    except ValueError:  # beyond Python's 4300 digits for int(str): far beyond any double too
        raise _HugeJsonInteger(len(text.lstrip('-'))) from None


def _parse_json(text: str, source: str) -> Any:
    """The JSON document of a scenario file; any fault as a ScenarioError naming the file and where.

    NaN and Infinity, which json reads, reach scenario_from_dict as numbers and are refused there
    by name, as in YAML files.
    """
    try:
        return json.loads(text, object_pairs_hook=_json_object, parse_int=_json_int)
    except json.JSONDecodeError as error:
        raise ScenarioError(
            f'{source}: malformed JSON at line {error.lineno}, column {error.colno}: {error.msg}'
        ) from None
    except _DuplicateJsonKey as error:
        keys = short_repr(error.keys)
        raise ScenarioError(
            f'{source}: malformed JSON: duplicate key {short_repr(error.key)} in the object with keys {keys}'
        ) from None
    except _HugeJsonInteger as error:
        raise ScenarioError(
            f'{source}: an integer of {error.digits} digits is too large for a double'
        ) from None
    except RecursionError:
        raise ScenarioError(
            f'{source}: malformed JSON: nested too deeply (a scenario nests 4 levels)'
        ) from None
