"""Scenarios, exact simulation, distributed runs and their analysis for the formation agents.

Layers, each a sub-package; a layer imports only those before it (docs/DESIGN.md, tested):

1. `model` — the problem (no ROS): scenarios, Theorem 2's gains, the theorems' constants,
   validation of every hypothesis, random teams.
2. `sim` — exact simulation (no ROS): the true world in closed form, the in-process engine, the
   run record and summary.json, the periodic and continuous baselines.
3. `bag` — rosbag2 bags without ROS: write, read, decode, recover.
4. `analysis` — runs rebuilt from bags, the paper's quantities and bounds, reports, comparisons,
   figures and 3D markers (no ROS).
5. `runtime` — ROS 2 processes: the simulator node, the recorder node, replay, graph inspection,
   and `FormationRun`, which starts and watches them.
6. `commands` — the `formation` command line (`cli.main`).

The names below are the most used ones; each is imported on first use.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'model.scenario': ('Scenario', 'builtin_scenarios', 'dump_scenario', 'load_scenario'),
        'model.validate': ('ValidationError', 'require_valid', 'validate_scenario'),
        'model.generate': ('random_scenario',),
        'model.theory': ('theorem_constants',),
        'sim.engine': ('simulate',),
        'sim.record': ('RunRecord',),
        'sim.summary': ('load_record', 'load_summary', 'write_summary'),
        'bag.io': ('read_bag',),
        'analysis.load': ('load_bag_run',),
        'runtime.launch.orchestrate': ('FormationRun', 'RunResult'),
        'model.errors': ('ScenarioError',),
    },
)
