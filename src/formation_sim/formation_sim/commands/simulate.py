"""`formation simulate SCENARIO`: exact event-driven run of the whole team in one process."""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import (
    NON_NEGATIVE,
    POSITIVE,
    add_run_arguments,
    add_safety_argument,
    load_valid_scenario,
    refuse,
    scale_options,
    with_min_separation,
)
from formation_sim.commands.limits import WARP, add_limit_arguments, resolve_speed_scale, resolve_time_warp

DEFAULT_SAMPLE_DT = 0.01
SAMPLE_POLICIES = ('auto', 'events', 'grid', 'none')
AUTO_EVENTS_MAX_AGENTS = (
    1000  # above, `auto` keeps the grid only: n = 10 000, T = 2 has 74 000 events of 160 kB
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'simulate',
        help='run ETA-1/ETA-2 exactly in one process (no ROS)',
        description='Exact event-driven simulation: every agent runs the same ETA-1/ETA-2 core '
        'as the ROS agent node; the world moves in closed form from event to event. Writes '
        'summary.json, trajectory/ (streamed as the run goes: memory stays O(agents + events)) and '
        'formation.png into --out.',
        epilog='Exit status: 0 done; 1 the simulation failed; 2 bad input (nothing was written).',
    )
    add_run_arguments(parser, kind='simulate')
    parser.add_argument(
        '--sample-dt',
        type=NON_NEGATIVE,
        default=None,
        help=f'spacing of the grid of trajectory samples [s] (default {DEFAULT_SAMPLE_DT}; 0: no grid)',
    )
    parser.add_argument(
        '--samples',
        choices=SAMPLE_POLICIES,
        default='auto',
        help='which states the trajectory keeps: events = the whole team at every event time and on '
        'the grid; grid = on the grid, at t = 0 and at the horizon; none = at t = 0 and the horizon '
        f'only. Default auto: events for teams of up to {AUTO_EVENTS_MAX_AGENTS} agents, grid for '
        "larger ones (every event sample holds the whole team). The summary's edge maxima cover "
        'every triggering time either way',
    )
    baseline = parser.add_mutually_exclusive_group()
    baseline.add_argument(
        '--period',
        type=POSITIVE,
        default=None,
        help='baseline: periodic sampling with this period instead of event triggering',
    )
    baseline.add_argument(
        '--continuous',
        action='store_true',
        help=(
            'baseline: the continuous controller (weights and states at every instant), integrated by scipy '
            '(DOP853, rtol 1e-10)'
        ),
    )
    parser.add_argument(
        '--tolerance',
        type=POSITIVE,
        default=None,
        help="relative margin at which a crossing counts as reached (default: the agents' own, 1e-12)",
    )
    add_safety_argument(parser)
    parser.add_argument('--no-plot', action='store_true', help='skip the figure')
    parser.add_argument('--quiet', action='store_true', help='print only the output folder')
    add_limit_arguments(parser)
    parser.set_defaults(func=run)


def sample_policy(args: argparse.Namespace, agents: int) -> tuple[str, float | None] | str:
    """(policy, grid spacing) for `--samples` and `--sample-dt`, or why they do not go together."""
    policy = args.samples
    if args.continuous:
        if policy != 'auto':
            return (
                'argument --samples: the continuous controller has no events; its trajectory is the grid '
                f'(--sample-dt), got {policy}'
            )
        if args.sample_dt == 0.0:
            return 'argument --sample-dt: must be > 0 with --continuous (its trajectory is the sample grid)'
        return 'grid', DEFAULT_SAMPLE_DT if args.sample_dt is None else args.sample_dt
    if policy == 'auto':
        policy = 'events' if agents <= AUTO_EVENTS_MAX_AGENTS else 'grid'
    if policy == 'none':
        if args.sample_dt is not None:
            return (
                'argument --sample-dt: --samples none keeps no grid (only t = 0 and the horizon), got '
                f'--sample-dt {args.sample_dt:g}'
            )
        return policy, None
    if policy == 'grid' and args.sample_dt == 0.0:
        return (
            'argument --sample-dt: --samples grid needs a grid spacing > 0 (t = 0 and the horizon alone: '
            '--samples none)'
        )
    return policy, DEFAULT_SAMPLE_DT if args.sample_dt is None else args.sample_dt


def run(args: argparse.Namespace) -> int:
    from formation_sim.analysis.plots import plot_run
    from formation_sim.sim.engine import check_sample_dt, simulate
    from formation_sim.sim.errors import EngineError, RunFolderError
    from formation_sim.sim.run_folder import claim_out_dir
    from formation_sim.sim.samples import TRAJECTORY_DIR
    from formation_sim.sim.summary import write_summary

    scenario = load_valid_scenario(args.scenario, 'simulate', **scale_options(args))
    if scenario is None or (scenario := _with_safety(scenario, args)) is None:
        return ExitCode.BAD_INPUT
    if isinstance(resolved := _speed_scale(scenario, args), int):
        return resolved
    scenario, warp, auto_scale = resolved
    chosen = sample_policy(args, scenario.n)
    if isinstance(chosen, str):
        return refuse('simulate', chosen)
    policy, sample_dt = chosen
    try:
        check_sample_dt(
            sample_dt, horizon=scenario.horizon if args.horizon is None else args.horizon, scenario=scenario
        )
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

            record = simulate_continuous(scenario, horizon=args.horizon, sample_dt=sample_dt)
        else:
            record = simulate(
                scenario,
                horizon=args.horizon,
                sample_dt=sample_dt,
                sample_events=policy == 'events',
                **({} if args.tolerance is None else {'tolerance': args.tolerance}),
                period=args.period,
                trajectory_dir=out,  # the samples go to disk as they come
                progress=progress,
                time_warp=warp,
            )
    except (EngineError, ValueError, ArithmeticError, OSError) as error:
        return _run_failed(error, out)
    if auto_scale is not None:
        record.extra['speed_scale'] = auto_scale
    try:
        summary_path = write_summary(record, out)
        figure = None if args.no_plot else plot_run(record, out)
    except OSError as error:
        print(f'\nformation simulate: error: cannot write the results: {error}', file=sys.stderr)
        return ExitCode.FAILED
    if args.quiet:
        print(out)
        return ExitCode.OK
    what = (
        f'continuous controller, {record.extra["rhs_evaluations"]} evaluations'
        if args.continuous
        else f'{record.total_events} events'
    )
    kept = f'samples: {policy}' + (' (auto)' if args.samples == 'auto' and not args.continuous else '')
    print(
        f'\r{scenario.name}: {what} up to t = {record.horizon:g} s in {record.wall_time:.2f} s wall time; '
        f'{kept}, {len(record.sample_times)} states',
        file=sys.stderr,
    )
    print(f'run folder: {out}')
    print(f'summary:    {summary_path}')
    print(f'trajectory: {record.samples.path or Path(out) / TRAJECTORY_DIR}/')
    if figure is not None:
        print(f'figure:     {figure}')
    return ExitCode.OK


def _with_safety(scenario, args: argparse.Namespace):
    """The scenario with --min-separation applied, or None after saying why it cannot run."""
    scenario = with_min_separation(scenario, args.min_separation, 'simulate')
    if scenario is not None and scenario.safety is not None and (args.period is not None or args.continuous):
        refuse('simulate', 'the safety layer (--min-separation or safety:) runs with event triggering only')
        return None
    return scenario


def _speed_scale(scenario, args: argparse.Namespace):
    """(the scenario to run, the time warp or None, what summary.json records of the choice or None)
    for --speed-scale auto, warp or K; the exit status after saying why not."""
    if args.speed_scale != WARP:
        resolved = resolve_speed_scale(scenario, args, 'simulate')
        return ExitCode.BAD_INPUT if resolved is None else (resolved[0], None, resolved[1])
    if args.continuous or args.period is not None:
        return refuse(
            'simulate', '--speed-scale warp: the event-triggered engine only (no --continuous, --period)'
        )
    warped = resolve_time_warp(scenario, args, 'simulate')
    return ExitCode.BAD_INPUT if warped is None else warped


def _run_failed(error: Exception, out: Path) -> int:
    """A run that failed: the error said, its run folder emptied and removed; the exit status."""
    from formation_sim.sim.errors import EngineError
    from formation_sim.sim.samples import discard_incomplete

    # ArithmeticError: a length or gain so far from 1 that the agents' arithmetic left the doubles;
    # OSError: the trajectory could not be written (a full disk)
    kind = (
        ''
        if isinstance(error, (EngineError, ValueError))
        else 'cannot write the trajectory: '
        if isinstance(error, OSError)
        else f'{type(error).__name__} (a number left the range of doubles): '
    )
    print(f'\nformation simulate: error: {kind}{error}', file=sys.stderr)
    discard_incomplete(out)  # a failed run's samples are no result
    with contextlib.suppress(OSError):
        out.rmdir()  # the run folder made for this run, empty again
    return ExitCode.FAILED
