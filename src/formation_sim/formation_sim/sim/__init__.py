"""Exact simulation, ROS-free: the true dynamics in closed form and whole runs in one process.

- `world`: `World`, the true state, advanced exactly from event to event ((single), (double)).
- `engine`: `simulate`, the team's event-driven run with the agents' own core objects.
- `record`: `RunRecord`, what any run produced; `samples`: its sample store, in memory or a
  run folder's `trajectory/` (streamed, memory-mapped); `summary`: summary.json;
  `files`: result files written whole or not at all.
- `baselines`: the continuous-time controller (`simulate_continuous`) for comparison.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'world': ('World',),
        'engine': ('simulate',),
        'record': ('RunRecord',),
        'samples': ('Samples', 'load_trajectory'),
        'summary': ('build_summary', 'load_record', 'load_summary', 'write_summary'),
        'baselines': ('simulate_continuous',),
        'errors': ('BaselineError', 'EngineError', 'TrajectoryError', 'WorldError'),
    },
)
