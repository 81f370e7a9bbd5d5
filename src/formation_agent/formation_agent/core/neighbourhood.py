"""An agent's neighbourhood, ROS-free: who its neighbours are, the desired displacements d_ij and
the edges' capacities Δ - ||d_ij|| (Assumption 1), and the checks of what the agent is handed
about them.

Whatever reaches an agent (`formation_agent.core.eta`) — what it senses at a trigger, a
neighbour's triggering information — is checked here before anything changes: vectors of the
agent's dimension p with finite components, finite times, exactly its neighbours, information
addressed to it by one of them, sensed edges within their capacity.  Each refusal is an
`AgentError` that names the agent, the rule and the value.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from formation_agent.core.errors import AgentError
from formation_agent.core.tension import edge_capacity
from formation_msgs_py.types import TriggerInfo

PADDED = 3
"""The plain-float path's vectors have three components (`offset_rows3`: d_ij padded with zeros)."""


def positive(name: str, value: float) -> float:
    """`value` as a float, finite and > 0 (AgentError naming `name` otherwise)."""
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise AgentError(f'{name} must be a finite number > 0, got {value!r}')
    return value


class Neighbourhood:
    """Agent `agent_id`'s neighbours (`neighbours`: j -> d_ij) within radius Δ = `delta`, checked:
    at least one neighbour, no self-loop, d_ij finite vectors of one dimension p >= 1, and
    ||d_ij|| < Δ (Assumption 1)."""

    def __init__(self, *, agent_id: int, neighbours: Mapping[int, object], delta: float) -> None:
        if not neighbours:
            raise AgentError(f'agent {agent_id} has no neighbours: the graph must be connected')
        if agent_id in neighbours:
            raise AgentError(f'agent {agent_id} lists itself as a neighbour (self-loop)')
        self.agent_id = int(agent_id)
        self.delta = positive('delta (communication radius Δ)', delta)
        self.ids = tuple(map(int, neighbours))
        try:  # one numpy call for all rows (built once per agent: a 1000-agent team builds 1000)
            offsets = np.array([neighbours[j] for j in self.ids], dtype=float)
        except (TypeError, ValueError):  # not numbers, or vectors of different lengths
            offsets = None
        if offsets is None or offsets.ndim != 2 or offsets.shape[1] < 1:
            raise AgentError(
                f'agent {agent_id}: desired displacements must be vectors of one dimension p >= 1'
            )
        if not np.isfinite(offsets).all():
            raise AgentError(f'agent {agent_id}: desired displacements are not finite')
        self.offsets = offsets  # d_ij, one row per neighbour
        self.capacity = edge_capacity(self.delta, offsets)  # Δ - ||d_ij||
        self._capacity = self.capacity.tolist()
        for j, c in zip(self.ids, self._capacity):
            if c <= 0.0:
                raise AgentError(
                    f'edge ({agent_id},{j}): ||d_ij|| = {float(self.delta - c)!r} is not below '
                    f'Δ = {self.delta!r} (Assumption 1)'
                )
        self.dimension = offsets.shape[1]
        # d_ij as tuples of floats, and padded with zeros to three components (the plain-float path's)
        self.offset_rows = list(map(tuple, offsets.tolist()))
        padding = (0.0,) * (PADDED - self.dimension)
        self.offset_rows3 = [row + padding for row in self.offset_rows]

    @classmethod
    def team(
        cls, *, neighbours: Mapping[int, Mapping[int, object]], delta: float
    ) -> dict[int, Neighbourhood] | None:
        """Every agent's neighbourhood of a team at once (`neighbours`: agent i -> its j -> d_ij), the
        same as one `Neighbourhood(agent_id=i, ...)` per agent: the d_ij of all agents in one `np.array`,
        their capacities in one `edge_capacity` (a row's reduction does not depend on the rows around
        it), each agent's `offsets` and `capacity` a view of its slice of the team's arrays (the same
        bytes as the constructor's: tests/formation_agent/core/test_neighbourhood.py). None where one of
        them would be refused (no neighbour, a self-loop, Δ not a positive number, vectors of different
        lengths, not finite or not below Δ) or an id is not an int: built one by one, that agent raises
        its error naming the rule (or makes ints of its ids)."""
        try:
            delta = positive('delta', delta)
        except (AgentError, TypeError, ValueError):
            return None
        ids = {}
        for i, table in neighbours.items():
            if not table or i in table:
                return None
            ids[i] = tuple(table)
        kinds = {type(i) for i in neighbours} | set(map(type, itertools.chain.from_iterable(ids.values())))
        if kinds != {int}:
            return None
        try:
            offsets = np.array([d for table in neighbours.values() for d in table.values()], dtype=float)
        except (TypeError, ValueError):
            return None
        if offsets.ndim != 2 or offsets.shape[1] < 1 or not np.isfinite(offsets).all():
            return None
        capacity = edge_capacity(delta, offsets)
        if not (capacity > 0.0).all():
            return None
        p = offsets.shape[1]
        columns = offsets.T.tolist()  # the rows' tuples from p lists (not one list per row)
        rows, rows3 = list(zip(*columns)), list(zip(*columns, *[[0.0] * len(offsets)] * (PADDED - p)))
        capacities, hoods, start = capacity.tolist(), {}, 0
        for i, own in ids.items():
            end = start + len(own)
            hood = hoods[i] = cls.__new__(cls)
            hood.agent_id, hood.delta, hood.ids, hood.dimension = i, delta, own, p
            hood.offsets, hood.capacity = offsets[start:end], capacity[start:end]  # views of the team's
            hood._capacity, hood.offset_rows = capacities[start:end], rows[start:end]
            hood.offset_rows3 = rows3[start:end]
            start = end
        return hoods

    @functools.cached_property
    def slot(self) -> dict[int, int]:
        """neighbour -> its row (made when first read: the compiled engine never reads it)."""
        return {j: k for k, j in enumerate(self.ids)}

    @functools.cached_property
    def _ids(self) -> set[int]:
        return set(self.ids)

    def vector(self, value: object, what: str) -> np.ndarray:
        """`value` (named `what`) as an array of p finite floats."""
        array = np.asarray(value, dtype=float)
        if array.shape != (self.dimension,):
            raise AgentError(
                f'agent {self.agent_id}: {what} has shape {array.shape}, expected ({self.dimension},)'
            )
        if not np.all(np.isfinite(array)):
            raise AgentError(f'agent {self.agent_id}: {what} is not finite: {array.tolist()}')
        return array

    def floats(self, value: Any, what: str, *args: object) -> tuple[float, ...]:  # a message's: checked
        """`value` as a tuple of p finite floats (the checks of `vector`, without numpy).

        `what` names the value, as a format template filled with `args` only on error (this runs
        for every message).
        """
        try:
            floats = tuple(map(float, value))
        except (TypeError, ValueError):
            floats = None
        if floats is not None and len(floats) == self.dimension and all(map(math.isfinite, floats)):
            return floats
        return tuple(self.vector(value, what.format(*args)).tolist())  # raises the error naming the rule

    def time(self, stamp: float, what: str, *args: object) -> float:
        """`stamp` as a finite float (`what`, a template filled with `args`, names it on error)."""
        stamp = float(stamp)
        if not math.isfinite(stamp):
            raise AgentError(f'agent {self.agent_id}: {what.format(*args)} has a non-finite time {stamp!r}')
        return stamp

    def rows(self, values: Mapping[int, object] | None, what: str) -> list[tuple[float, ...]]:
        """One vector of p finite floats per neighbour, in neighbour order, from `values` (named
        `what`), which must cover exactly the neighbours."""
        if values is None or values.keys() != self._ids:
            got = None if values is None else sorted(values)
            raise AgentError(
                f'agent {self.agent_id}: {what} must cover exactly its neighbours {sorted(self.ids)}, '
                f'got {got}'
            )
        template = what + '[{}]'
        return [self.floats(values[j], template, j) for j in self.ids]

    def sender_slot(self, info: TriggerInfo) -> int:
        """The row of the neighbour that sent `info`, which must be addressed to this agent."""
        if info.receiver != self.agent_id:
            raise AgentError(f'agent {self.agent_id} got information addressed to agent {info.receiver}')
        k = self.slot.get(info.sender)
        if k is None:
            raise AgentError(
                f'agent {self.agent_id} got information from agent {info.sender}, '
                f'which is not a neighbour {sorted(self.ids)}'
            )
        return k

    def check_sensed_range(self, length: list[float]) -> None:
        """Every sensed edge k within its range: ||x_i - x_j - d_ij|| = length[k] < Δ - ||d_ij||."""
        for k, (r, c) in enumerate(zip(length, self._capacity)):
            if r >= c:
                raise AgentError(
                    f'agent {self.agent_id}: edge to agent {self.ids[k]} is out of its range: '
                    f'||x_i-x_j-d_ij|| = {r!r} >= Δ-||d_ij|| = {c!r}'
                )

    def out_of_range(self, k: int, r: float, c: float) -> AgentError:
        """The error of a predicted edge k that left its range (||y_ij|| = r >= Δ - ||d_ij|| = c)."""
        return AgentError(
            f'agent {self.agent_id}: predicted edge to agent {self.ids[k]} left its range '
            f'(||y_ij|| = {r!r} >= Δ-||d_ij|| = {c!r})'
        )
