"""The simulator's world without ROS (`sim_node`): the exact `World` of a scenario, sampled as the
in-process engine samples it, moved as the engine moves it, stopped where the engine stops.

`advance(t)` is the engine's move from one event to the next: the grid samples before `t` (pure
evaluations, `sim.engine.Sampler`), the world's closed form to `t`, the event sample at `t`.  At
each lock-step event `floor_problem` says whether the triggering threshold has fallen to the
rounding level of the states (`sim.engine.rounding_floor`, with the agents' own threshold: the
very same floats), where the engine stops with the same message.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from formation_sim.model.scenario import Scenario
from formation_sim.sim.engine import FloorEdges, Sampler, build_agent, rounding_floor
from formation_sim.sim.world import World


class ExactWorld:
    """A scenario's exact world, its samples, and the engine's stopping rule."""

    def __init__(
        self,
        scenario: Scenario,
        *,
        sample_period: float,
        on_sample: Callable[[float, np.ndarray, np.ndarray | None], None] | None = None,
    ) -> None:
        self.world = World.from_scenario(scenario)
        self.sampler = Sampler(self.world, sample_period, on_sample=on_sample)
        # The agents' threshold (any agent's: they share it) and the edges of the rounding floor.
        self.threshold_model = build_agent(scenario, scenario.agent_ids[0])
        self.floor_edges = FloorEdges.of(scenario)

    @property
    def time(self) -> float:
        return self.world.time

    def advance(self, t: float) -> None:
        """Move to `t` (an event): the grid samples before it, the world, the sample at `t`."""
        self.sampler.grid_until(t)
        self.world.advance(t)
        self.sampler.event()

    def floor_problem(self) -> str | None:
        """Why the event chain can no longer be trusted now (`rounding_floor`), or None."""
        return rounding_floor(self.threshold_model, self.world, self.floor_edges)
