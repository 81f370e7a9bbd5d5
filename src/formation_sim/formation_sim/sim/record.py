"""What a run produced: `RunRecord`, the one input of summaries, figures and analysis.

Every kind of run fills one: the in-process engine (`formation_sim.sim.engine`), the baselines
(`formation_sim.sim.baselines`), the simulator node of a distributed run, and a bag read back
(`formation_sim.analysis`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(kw_only=True)
class RunRecord:
    """Everything a run produced; the input of `formation_sim.sim.summary.write_summary`."""

    scenario: object
    horizon: float
    mode: str
    trigger_times: dict[int, list[float]]
    sample_times: np.ndarray
    sample_positions: np.ndarray
    sample_velocities: np.ndarray | None
    messages_sent: int
    sensing_calls: int
    wall_time: float
    extra: dict = field(default_factory=dict)

    @property
    def total_events(self) -> int:
        return sum(len(times) for times in self.trigger_times.values())
