"""Studies at scale, ROS-free: many cases (random teams, gains, algorithms) on Dask distributed.

- `spec`: a SPEC (YAML: grids and random draws) expanded into `Case`s (`load_study`, `build_study`).
- `case`: one case's team, validation and run through the exact engine, as a row (`run_case`).
- `audit`: the guarantees of Theorems 1 and 2 checked event by event on one run.
- `store`: the study folder, `rows.csv` appended row by row (`read_rows`).
- `runner`: `run_study` on a LocalCluster or an existing scheduler, resumable.
- `report`: figures and a Markdown table from the rows (`write_report`).
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'spec': ('Case', 'Study', 'build_study', 'load_study'),
        'case': ('COLUMNS', 'check_case', 'run_case', 'scenario_of'),
        'audit': ('EdgeWatch', 'theorem_audit'),
        'store': ('read_rows',),
        'runner': ('StudySummary', 'run_study'),
        'report': ('write_report',),
        'errors': ('StudyError',),
    },
)
