#!/usr/bin/env python3
"""Run a formation scenario as ROS 2 processes and print where the results are.

Copy and adapt: everything is the public API of formation_sim.runtime.launch.orchestrate.

    python scripts/run_formation.py                     # paper_single up to t = 10, into a new runs/ folder
    python scripts/run_formation.py paper_double --horizon 5 --out runs/double [--force]
"""

import argparse
import sys

from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.orchestrate import FormationRun


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        'scenario',
        nargs='?',
        default='paper_single',
        help='built-in name (paper_single, paper_double) or YAML file (default paper_single)',
    )
    parser.add_argument(
        '--horizon', type=float, default=None, help="final time in seconds (default: the scenario's)"
    )
    parser.add_argument(
        '--out', default=None, help='output folder, new or empty (default: a new folder under runs/)'
    )
    parser.add_argument('--force', action='store_true', help='replace the earlier run in --out')
    args = parser.parse_args()

    try:
        run = FormationRun(args.scenario, out_dir=args.out, force=args.force, horizon=args.horizon)
        result = run.run()  # Ctrl-C stops every process cleanly
    except (RunError, ValueError) as error:  # ValueError: unreadable or invalid scenario (names the rule)
        print(f'error: {error}', file=sys.stderr)
        return 2

    print(f'exit status {result.exit_status} after {result.wall_time:.1f} s (ROS domain {result.domain_id})')
    print(f'folder:  {result.out_dir}')
    print(f'summary: {result.summary}')
    print(f'bag:     {result.bag}')
    if not result.ok:
        print(result.message, file=sys.stderr)
    return result.exit_status


if __name__ == '__main__':
    sys.exit(main())
