"""The physical world: true agent states, integrated exactly from event to event.

The world only moves forward when told to (`advance`), and only to event times, so the floating
point history of the state is the same whether or not anyone samples it in between: `state_at`
evaluates the closed form without changing anything.
"""

from __future__ import annotations

import numpy as np

from formation_agent.core import compiled, speed_scale
from formation_agent.core.closed_form import advance_double
from formation_msgs_py.types import SensedState
from formation_sim.sim.errors import WorldError


class World:
    """True states of all agents under piecewise-constant commands."""

    def __init__(
        self,
        *,
        agent_ids: tuple[int, ...],
        positions: np.ndarray,
        velocities: np.ndarray | None = None,
        damping: float | None = None,
        start_time: float = 0.0,
    ) -> None:
        """Single integrators when `velocities` is None, else double integrators with damping k3."""
        self.agent_ids = tuple(agent_ids)
        self._index = {agent: k for k, agent in enumerate(self.agent_ids)}
        self._x = np.array(positions, dtype=float)
        if self._x.shape[0] != len(self.agent_ids):
            raise WorldError(f'{self._x.shape[0]} positions for {len(self.agent_ids)} agents')
        self.double = velocities is not None
        if self.double:
            if damping is None or not damping > 0.0:
                raise WorldError(f'double integrators need damping k3 > 0, got {damping}')
            self._q = np.array(velocities, dtype=float)
            if self._q.shape != self._x.shape:
                raise WorldError(f'velocities {self._q.shape} do not match positions {self._x.shape}')
        else:
            self._q = None
        self.damping = damping
        self._u = np.zeros_like(self._x)
        self.time = float(start_time)

    @classmethod
    def from_scenario(cls, scenario) -> World:
        """The scenario's initial state; at a speed scale κ the damping is κ k3 and the velocities
        start at κ q(0), the scenario's being the paper's (`formation_agent.core.speed_scale`)."""
        kappa = scenario.gains.speed_scale
        damping = speed_scale.damping(scenario.gains.k3, kappa) if scenario.dynamics == 'double' else None
        return cls(
            agent_ids=scenario.agent_ids,
            positions=scenario.positions,
            velocities=speed_scale.initial_velocities(scenario.velocities, kappa),
            damping=damping,
        )

    @property
    def dimension(self) -> int:
        return self._x.shape[1]

    @property
    def positions(self) -> np.ndarray:
        return self._x.copy()

    @property
    def velocities(self) -> np.ndarray | None:
        return None if self._q is None else self._q.copy()

    def positions_of(self, rows: np.ndarray) -> np.ndarray:
        """The positions of the agents at these rows (a copy of those rows only)."""
        return self._x[rows]

    def arrays(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """The world's own (positions, velocities, commands), not copies: the compiled engine step
        (`_fastcore.Team`) senses from them and writes the commands of the agents it triggers."""
        return self._x, self._q, self._u

    @property
    def controls(self) -> np.ndarray:
        return self._u.copy()

    def index(self, agent: int) -> int:
        try:
            return self._index[agent]
        except KeyError:
            raise WorldError(f'unknown agent {agent}; agents are {list(self.agent_ids)}') from None

    def rows(self, agents) -> list[int]:
        """`index` of each of these agents (one lookup each: the sampler's edge watch at every event)."""
        try:
            return [self._index[agent] for agent in agents]
        except KeyError as error:
            raise WorldError(f'unknown agent {error.args[0]}; agents are {list(self.agent_ids)}') from None

    def set_control(self, agent: int, control) -> None:
        """Command of `agent` from now on: u_i (single) or the piecewise-constant u^d_i (double)."""
        value = np.asarray(control, dtype=float)
        if value.shape != (self.dimension,):
            raise WorldError(
                f'control of agent {agent} has shape {value.shape}, expected ({self.dimension},)'
            )
        if not np.isfinite(value).all():
            raise WorldError(f'control of agent {agent} is not finite: {value.tolist()}')
        self._u[self.index(agent)] = value

    def _propagate(self, t: float) -> tuple[np.ndarray, np.ndarray | None]:
        tau = t - self.time
        if tau < 0.0:
            raise WorldError(f'cannot go back in time from {self.time!r} to {t!r}')
        if tau == 0.0:
            return self._x.copy(), None if self._q is None else self._q.copy()
        step = compiled.world_step()
        if step is not None:  # the same floats in one compiled pass (docs/COMPILED_CORE.md)
            x = np.empty_like(self._x)
            q = None if self._q is None else np.empty_like(self._q)
            if step(self._x, self._q, self._u, x, q, self.damping or 0.0, tau):
                return x, q
        if self._q is None:
            return self._x + tau * self._u, None
        return advance_double(self._x, self._q, self._u, self.damping, tau)

    def advance(self, t: float) -> None:
        """Move the true state to time `t` (>= now) exactly."""
        self._x, q = self._propagate(t)
        if q is not None:
            self._q = q
        self.time = float(t)

    def state_at(self, t: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(positions, velocities) at `t` >= now, without changing the world."""
        return self._propagate(t)

    def sense(self, agent: int, neighbours) -> SensedState:
        """What `agent` senses now: x_i - x_j (and q_i - q_j, q_i) for each neighbour j."""
        i = self.index(agent)
        neighbours = tuple(neighbours)
        rows = [self.index(j) for j in neighbours]
        # One vectorised difference per quantity; rows of it are the exact x_i - x_j.
        rel_pos = dict(zip(neighbours, map(tuple, (self._x[i] - self._x[rows]).tolist())))
        if self._q is None:
            return SensedState(agent=agent, stamp=self.time, rel_positions=rel_pos)
        rel_vel = dict(zip(neighbours, map(tuple, (self._q[i] - self._q[rows]).tolist())))
        return SensedState(
            agent=agent,
            stamp=self.time,
            rel_positions=rel_pos,
            rel_velocities=rel_vel,
            velocity=tuple(self._q[i].tolist()),
        )

    def nearby(self, agent: int, radius: float, *, exclude=()) -> dict[int, tuple[float, ...]]:
        """x_i - x_j of every other agent j within `radius` of `agent` (not in `exclude`): what its
        range sensor sees (the safety layer, docs/SAFETY.md)."""
        i = self.index(agent)
        skip = {i, *(self.index(j) for j in exclude)}
        rel = (self._x[i] - self._x).tolist()
        return {
            self.agent_ids[k]: tuple(row)
            for k, row in enumerate(rel)
            if k not in skip and sum(v * v for v in row) <= radius * radius
        }
