"""Where the robots are before step 0, against the hypotheses of the theorems.

On robots the run starts from the measured poses, not from the scenario's positions: before step 0
the coordinator reads each robot's latest pose, takes its control point (a unicycle's or car's: l
ahead along its heading; `formation_agent.core.kinds`), and checks the initial condition
(initial) of Theorem 1 (ETA-1) / Theorem 2 (ETA-2) on every edge:

    ||x_i(0) - x_j(0) - d_ij|| < Δ - ||d_ij||

A run whose measured start breaks it does not start: no Step 0, no command (README, "Running on
robots").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formation_sim.model import theory
from formation_sim.model.scenario import Scenario

SHOWN_BREACHES = 5  # edges named in the message; `breaches` holds them all


def _apart(a: float, b: float) -> tuple[str, str]:
    """a and b to 3 significant digits, or as many more as it takes to print them differently."""
    for digits in range(3, 18):
        left, right = f'{a:.{digits}g}', f'{b:.{digits}g}'
        if left != right or a == b:
            return left, right
    return repr(a), repr(b)  # pragma: no cover - 17 digits tell any two doubles apart


def _pair(i: int, j: int) -> str:
    return f'{i}{j}' if i < 10 and j < 10 else f'{i},{j}'


@dataclass(frozen=True, kw_only=True)
class InitialBreach:
    """An edge whose measured start breaks (initial)."""

    i: int
    j: int
    error: float  # ||x_i(0) - x_j(0) - d_ij||, measured
    capacity: float  # Δ - ||d_ij||
    theorem: int  # 1 (ETA-1) or 2 (ETA-2)

    def message(self) -> str:
        error, capacity = _apart(self.error, self.capacity)
        ij = _pair(self.i, self.j)
        return (
            f'edge ({self.i},{self.j}): the measured ‖x_{self.i} − x_{self.j} − d_{ij}‖ = {error} m is '
            f'not below Δ − ‖d_{ij}‖ = {capacity} m (initial condition of Theorem {self.theorem})'
        )

    def to_dict(self) -> dict:
        return {'edge': [self.i, self.j], 'error': self.error, 'capacity': self.capacity}


@dataclass(frozen=True, kw_only=True)
class MeasuredStart:
    """The measured control points before step 0, their distances from the scenario's positions,
    and the edges on which they break (initial)."""

    agent_ids: tuple[int, ...]
    positions: np.ndarray  # (n, p) measured control points, in agent order
    distances: np.ndarray  # (n,) ||measured - scenario position||
    breaches: tuple[InitialBreach, ...]

    @property
    def ok(self) -> bool:
        return not self.breaches

    @property
    def largest(self) -> tuple[int, float]:
        """(agent, distance) of the robot measured farthest from its scenario position."""
        k = int(np.argmax(self.distances))
        return self.agent_ids[k], float(self.distances[k])

    def message(self) -> str:
        """Every broken edge (the first SHOWN_BREACHES named), and that the run does not start."""
        shown = '; '.join(breach.message() for breach in self.breaches[:SHOWN_BREACHES])
        more = len(self.breaches) - SHOWN_BREACHES
        tail = f'; and {more} more edge(s)' if more > 0 else ''
        return f'{shown}{tail}: the run does not start'

    def to_dict(self) -> dict:
        """summary.json's extra.measured_start."""
        agent, largest = self.largest
        return {
            'agents': {
                str(i): {
                    'position': [float(v) for v in self.positions[k]],
                    'distance': float(self.distances[k]),
                }
                for k, i in enumerate(self.agent_ids)
            },
            'largest_distance': largest,
            'largest_agent': agent,
            'breaches': [breach.to_dict() for breach in self.breaches],
        }


def check_measured_start(scenario: Scenario, positions) -> MeasuredStart:
    """The initial condition (initial) on every edge for the measured control points `positions`
    ((n, p), in `scenario.agent_ids` order)."""
    x = np.asarray(positions, dtype=float).reshape(scenario.n, scenario.dimension)
    errors = theory.edge_errors(scenario, x)
    capacities = theory.edge_capacities(scenario)
    theorem = 2 if scenario.dynamics == 'double' else 1
    breaches = tuple(
        InitialBreach(
            i=edge.i, j=edge.j, error=float(errors[k]), capacity=float(capacities[k]), theorem=theorem
        )
        for k, edge in enumerate(scenario.edges)
        if not errors[k] < capacities[k]  # (initial), strict; NaN breaks it too
    )
    distances = np.linalg.norm(x - np.asarray(scenario.positions, dtype=float), axis=1)
    return MeasuredStart(
        agent_ids=tuple(scenario.agent_ids), positions=x, distances=distances, breaches=breaches
    )
