"""Runs analysed from their bags alone, ROS-free.

- `load`: `load_bag_run` rebuilds a run's `RunRecord` from its bag, with consistency checks.
- `checks`: the paper's quantities along the run and the theorems' bounds they must respect.
- `report`: analysis.md/analysis.json, and where a bag differs from its summary.json.
- `accounting`: what a run published per topic against what its bag holds.
- `compare`: two runs side by side (events, triggering times, trajectories).
- `figures` (matplotlib): the paper's Fig. 1/2 panels and the analysis figures; `plots`: the
  figure of `formation simulate/run`; `markers`: a 3D view as visualization_msgs/MarkerArray.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'load': ('BagRun', 'load_bag_run', 'locate'),
        'checks': ('Check', 'Series', 'TheoryBounds', 'run_series', 'theorem_checks', 'theory_bounds'),
        'report': ('bag_summary', 'build_report', 'diff_summaries', 'write_report'),
        'compare': ('compare_runs', 'load_run'),
        'markers': ('FormationMarkers', 'write_bag_with_markers'),
        'errors': ('AnalysisError', 'CompareError', 'MarkerError'),
    },
)
