"""What a run produced: `RunRecord`, the one input of summaries, figures and analysis.

Every kind of run fills one: the in-process engine (`formation_sim.sim.engine`), the baselines
(`formation_sim.sim.baselines`), the simulator node of a distributed run, and a bag read back
(`formation_sim.analysis`). Its samples (`formation_sim.sim.samples.Samples`) are in memory, or,
for `formation simulate` and run folders read back, memory-mapped from the run's trajectory folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from formation_sim.sim.samples import Samples

if TYPE_CHECKING:
    from formation_sim.model.scenario import Scenario


@dataclass(kw_only=True)
class RunRecord:
    """Everything a run produced; the input of `formation_sim.sim.summary.write_summary`."""

    scenario: Scenario
    horizon: float
    mode: str
    trigger_times: dict[int, list[float]]
    samples: Samples
    messages_sent: int
    sensing_calls: int
    wall_time: float | None  # None: not measured (a run rebuilt from its bag or its summary)
    extra: dict = field(default_factory=dict)

    @property
    def total_events(self) -> int:
        return sum(len(times) for times in self.trigger_times.values())

    @property
    def sample_times(self) -> np.ndarray:
        """(K,) increasing: every event time and a grid, or what the run's sample policy kept."""
        return self.samples.times

    @property
    def sample_positions(self) -> np.ndarray:
        """(K, n, p), in memory or memory-mapped."""
        return self.samples.positions

    @property
    def sample_velocities(self) -> np.ndarray | None:
        """(K, n, p) for double integrators, else None."""
        return self.samples.velocities
