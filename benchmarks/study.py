"""`formation study` on a LocalCluster: wall time of a 500-case study against its single runs.

    python benchmarks/study.py                 # 500 cases, LocalCluster of 2 workers
    python benchmarks/study.py --cases 100 --workers 1 2

For each worker count, a fresh study folder: the run phase's wall time (first submitted run to
last row; the cluster's start and the validation are reported apart), the sum of the rows' own
wall times (each case timed on its worker), speed-up = sum / wall and efficiency per worker =
speed-up / workers. As a baseline measured in the same run, a sample of the cases is also run
one after the other in this process (no Dask): the sum of the single runs extrapolated from it
shows what the workers' own timings lose to sharing the machine. The load average before and
after is printed: the machine is shared.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
# This folder holds benchmarks/distributed.py, which would shadow the `distributed` package.
sys.path[:] = [entry for entry in sys.path if Path(entry or '.').resolve() != HERE]

from formation_sim.study.case import run_case  # noqa: E402 - after the sys.path fix above
from formation_sim.study.runner import run_study  # noqa: E402 - after the sys.path fix above
from formation_sim.study.spec import build_study  # noqa: E402 - after the sys.path fix above


def spec(cases: int) -> dict:
    """Random ETA-1 and ETA-2 teams of 3 to 12 agents over 0.5 s: tens of milliseconds each."""
    half = cases // 2
    common = {
        'n': {'integers': [3, 12]},
        'p': {'integers': [1, 3]},
        'graph': {'choice': ['geometric', 'star', 'path', 'cycle']},
        'slack': {'uniform': [0.1, 0.9]},
        'alpha': 10.0,
    }
    return {
        'name': 'bench',
        'seed': 11,
        'defaults': {'horizon': 0.5},
        'cases': [
            {'draws': half, 'algorithm': 'eta1', **common},
            {'draws': cases - half, 'algorithm': 'eta2', **common},
        ],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--cases', type=int, default=500)
    parser.add_argument('--workers', type=int, nargs='+', default=[2])
    parser.add_argument(
        '--sample', type=int, default=100, help='cases run one after the other in this process'
    )
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    study = build_study(spec(args.cases))
    print(f'load average before: {os.getloadavg()}', flush=True)
    step = max(1, len(study.cases) // args.sample)
    sample = study.cases[::step]
    started = time.perf_counter()
    for case in sample:
        run_case(case)
    sequential = (time.perf_counter() - started) * len(study.cases) / len(sample)
    print(
        f'sequential, in this process: {len(sample)} cases, {sequential:.1f} s extrapolated to '
        f'{len(study.cases)}',
        flush=True,
    )
    results = []
    for workers in args.workers:
        with tempfile.TemporaryDirectory() as folder:
            began = time.perf_counter()
            summary = run_study(study, out=Path(folder) / 'out', workers=workers)
            total = time.perf_counter() - began
        speedup = summary.sum_of_runs / summary.run_time
        result = {
            'workers': workers,
            'cases': summary.ran,
            'failed': summary.failed,
            'wall_total': total,
            'run_phase': summary.run_time,
            'sum_of_rows': summary.sum_of_runs,
            'speedup': speedup,
            'efficiency': speedup / workers,
            'sequential_estimate': sequential,
            'efficiency_vs_sequential': sequential / summary.run_time / workers,
        }
        results.append(result)
        print(json.dumps(result), flush=True)
    print(f'load average after: {os.getloadavg()}', flush=True)
    if args.json:
        args.json.write_text(json.dumps({'results': results, 'load_after': os.getloadavg()}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
