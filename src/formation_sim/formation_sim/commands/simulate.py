"""`formation simulate SCENARIO`: exact event-driven run of the whole team in one process."""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from formation_sim.commands.common import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    NON_NEGATIVE,
    POSITIVE,
    add_run_arguments,
    load_valid_scenario,
    refuse,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'simulate',
        help='run ETA-1/ETA-2 exactly in one process (no ROS)',
        description='Exact event-driven simulation: every agent runs the same ETA-1/ETA-2 core '
        'as the ROS agent node; the world moves in closed form from event to event. Writes '
        'summary.json, trajectory.npz and formation.png into --out.',
        epilog='Exit status: 0 done; 1 the simulation failed; 2 bad input (nothing was written).',
    )
    add_run_arguments(parser, kind='simulate')
    parser.add_argument(
        '--sample-dt',
        type=NON_NEGATIVE,
        default=0.01,
        help='spacing of the dense trajectory samples [s] (default 0.01; 0: samples at events only)',
    )
    baseline = parser.add_mutually_exclusive_group()
    baseline.add_argument('--period', type=POSITIVE, default=None, help='baseline: periodic sampling with this period instead of event triggering')
    baseline.add_argument(
        '--continuous',
        action='store_true',
        help='baseline: the continuous controller (weights and states at every instant), integrated by scipy (DOP853, rtol 1e-10)',
    )
    parser.add_argument(
        '--tolerance', type=POSITIVE, default=None,
        help='relative margin at which a crossing counts as reached (default: the agents\' own, 1e-12)',
    )  # fmt: skip
    parser.add_argument('--no-plot', action='store_true', help='skip the figure')
    parser.add_argument('--quiet', action='store_true', help='print only the output folder')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.analysis.plots import plot_run
    from formation_sim.sim.engine import EngineError, check_sample_dt, simulate
    from formation_sim.sim.run_folder import RunFolderError, claim_out_dir
    from formation_sim.sim.summary import write_summary

    scenario = load_valid_scenario(args.scenario, 'simulate')
    if scenario is None:
        return EXIT_BAD_INPUT
    if args.continuous and args.sample_dt == 0.0:
        return refuse('simulate', 'argument --sample-dt: must be > 0 with --continuous (its trajectory is the sample grid)')
    try:
        check_sample_dt(args.sample_dt, horizon=scenario.horizon if args.horizon is None else args.horizon, scenario=scenario)
    except EngineError as error:
        return refuse('simulate', f'argument --sample-dt: {error}')
    try:
        out = claim_out_dir(args.out, scenario_name=scenario.name, kind='simulate', force=args.force)
    except RunFolderError as error:
        return refuse('simulate', error)

    def progress(t: float, events: int) -> None:
        if not args.quiet:
            print(f'\r  t = {t:9.4f} s   events = {events}', end='', file=sys.stderr, flush=True)

    try:
        if args.continuous:
            from formation_sim.sim.baselines import simulate_continuous

            record = simulate_continuous(scenario, horizon=args.horizon, sample_dt=args.sample_dt)
        else:
            record = simulate(
                scenario,
                horizon=args.horizon,
                sample_dt=args.sample_dt,
                **({} if args.tolerance is None else {'tolerance': args.tolerance}),
                period=args.period,
                progress=progress,
            )
    except (EngineError, ValueError, ArithmeticError) as error:
        # ArithmeticError: a length or gain so far from 1 that the agents' arithmetic left the doubles
        kind = '' if isinstance(error, (EngineError, ValueError)) else f'{type(error).__name__} (a number left the range of doubles): '
        print(f'\nformation simulate: error: {kind}{error}', file=sys.stderr)
        with contextlib.suppress(OSError):
            out.rmdir()  # the run folder made for this run, still empty
        return EXIT_FAILED
    summary_path = write_summary(record, out)
    figure = None if args.no_plot else plot_run(record, out)
    if args.quiet:
        print(out)
        return EXIT_OK
    what = (
        f'continuous controller, {record.extra["rhs_evaluations"]} evaluations'
        if args.continuous
        else f'{record.total_events} events'
    )
    print(f'\r{scenario.name}: {what} up to t = {record.horizon:g} s in {record.wall_time:.2f} s wall time', file=sys.stderr)
    print(f'run folder: {out}')
    print(f'summary:    {summary_path}')
    print(f'trajectory: {Path(out) / "trajectory.npz"}')
    if figure is not None:
        print(f'figure:     {figure}')
    return EXIT_OK
