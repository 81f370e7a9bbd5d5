"""`formation run SCENARIO [--backend B]`: the distributed run, one ROS 2 process per agent: on the
simulator's exact world (in lock-step sim time by default), on simulated robots, or on real ones."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import (
    DOMAIN_ID,
    POSITIVE,
    add_plan_arguments,
    add_run_arguments,
    add_safety_argument,
    backend_safety,
    load_valid_scenario,
    plan_options,
    refuse,
    scale_options,
)
from formation_sim.commands.limits import (
    AUTO,
    WARP,
    check_saturation,
    chosen_warp,
    resolve_speed_scale,
    resolve_time_warp,
    robot_limits,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'run',
        help='run the team as ROS 2 processes (one node per agent, a simulator or robots, recorder)',
        description='Distributed run over ROS 2, every agent its own node talking only to its neighbours. '
        'Backend exact (default): a simulator node holds the exact world and the sensing services, and '
        'time advances in lock-step from event to event. A backend named after a robot kind (holonomic, '
        'unicycle; formation_agent.core.kinds): one simulated robot of that kind per agent (pose and '
        'velocity-command topics), a coordinator keeps wall-clock time. Backend external: the '
        'coordinator, agents and recorder only; the robots are whatever publishes /agent_<i>/robot/pose '
        '(or odom) and takes /agent_<i>/robot/cmd_vel (README, "Running on robots"). Writes '
        'summary.json (same schema as `formation simulate`) and the rosbag2 bag (MCAP) into --out.',
        epilog='Exit status: 0 done; 1 the run failed; 2 bad input (nothing was started, nothing on disk '
        'changed); 3 a process or an agent was lost (summary.json extra.failure says which and when); 4 '
        "on robots, the robots' measured start breaks the initial condition on an edge (no Step 0, no "
        'command was sent); 5 an operator stopped the run (its emergency stop /formation/stop: `formation '
        'stop`, docs/EMERGENCY_STOP.md; extra.failure.kind stopped_by_operator); 130 interrupted. A run '
        'stopped early still writes summary.json up to that moment and a readable bag.',
    )
    add_run_arguments(parser, kind='run')
    add_plan_arguments(parser)
    parser.add_argument(
        '--domain-id',
        type=DOMAIN_ID,
        default=None,
        metavar='N',
        help='ROS_DOMAIN_ID to use (default: a free one in 100-232)',
    )
    parser.add_argument(
        '--timeout', type=POSITIVE, default=None, help='give up after this many wall-clock seconds'
    )
    parser.add_argument(
        '--network',
        action='store_true',
        help='let DDS discovery reach the local network (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET) for agents on '
        'other machines; default: this machine only (LOCALHOST)',
    )
    parser.add_argument(
        '--discovery-server',
        action='store_true',
        help=(
            'discover through a Fast DDS discovery server that the run starts (ROS_DISCOVERY_SERVER) '
            'instead of every process announcing itself to every other: for large teams (BENCHMARKS.md)'
        ),
    )
    parser.add_argument(
        '--allow-saturation',
        action='store_true',
        help=(
            'robot backends: run even when the exact run asks for commands beyond --max-speed, '
            '--max-angular-speed or --max-acceleration (refused by default, exit 2: clipped commands are '
            'outside the theorems; --speed-scale auto slows the team until they fit)'
        ),
    )
    add_safety_argument(parser)
    parser.add_argument('--no-plot', action='store_true', help='skip the figure')
    parser.add_argument('--quiet', action='store_true', help='no progress; print only the output folder')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_valid_scenario(args.scenario, 'run', **scale_options(args))
    if scenario is None:
        return ExitCode.BAD_INPUT
    try:
        options = plan_options(args)
    except RunError as error:
        return refuse('run', error)
    if (safe := backend_safety(scenario, args.min_separation, options['robots'], 'run')) is None:
        return ExitCode.BAD_INPUT
    scenario, extra = safe
    if isinstance(resolved := _speed_scale(scenario, args, options), int):
        return resolved
    scenario, chosen = resolved
    if chosen is not None:
        extra['speed_scale'] = chosen
    if options['robots'] is not None and not chosen_warp(chosen):  # a warp is chosen within the limits
        horizon = scenario.horizon if args.horizon is None else args.horizon
        refusal = check_saturation(
            scenario.replace(horizon=horizon), limits=robot_limits(args), allow=args.allow_saturation
        )
        if refusal is not None:
            return refuse('run', refusal)
    try:
        result = FormationRun(
            scenario,
            **options,
            domain_id=args.domain_id,
            progress=not args.quiet,
            timeout=args.timeout,
            localhost_only=not args.network,
            discovery='server' if args.discovery_server else 'simple',
            summary_extra=extra,
        ).run()
    except RunError as error:
        return refuse('run', error)
    out = result.out_dir
    figure = None
    if result.ok and not args.no_plot:
        from formation_sim.analysis.plots import plot_run
        from formation_sim.sim.summary import load_record

        figure = plot_run(load_record(out, scenario), out)
    if args.quiet:
        print(out)
    else:
        print(f'folder:  {out}')
        print(f'summary: {result.summary}')
        print(f'bag:     {result.bag}')
        if figure is not None:
            print(f'figure:  {figure}')
        print(f'logs:    {Path(out) / "logs"}')
    _warn_saturation(result)
    if args.quiet and result.message:  # otherwise the run's last progress line said it already
        print(f'formation run: {"" if not result.ok else "warning: "}{result.message}', file=sys.stderr)
    return result.exit_status


def _speed_scale(scenario, args: argparse.Namespace, options: dict):
    """(the scenario to run, what summary.json records of the speed's choice) for --speed-scale
    auto, warp (robot backends: the agents' time warp goes into `options`) or K; else the exit status
    after saying why not.  On robots, auto runs ETA-1 under the observed warp (issue 27), ETA-2 at
    the constant κ; in lock-step, auto is the constant κ (what `simulate --speed-scale auto` runs)."""
    import dataclasses

    warped_auto = args.speed_scale == AUTO and options['robots'] is not None and scenario.dynamics == 'single'
    if args.speed_scale != WARP and not warped_auto:
        resolved = resolve_speed_scale(scenario, args, 'run')
        return ExitCode.BAD_INPUT if resolved is None else resolved
    if options['robots'] is None:
        return refuse(
            'run',
            '--speed-scale warp: robot backends only so far (the lock-step simulator takes no warp; '
            'formation simulate --speed-scale warp runs it exactly)',
        )
    if (warped := resolve_time_warp(scenario, args, 'run', flag=args.speed_scale)) is None:
        return ExitCode.BAD_INPUT
    scenario, warp, chosen = warped
    options['robots'] = dataclasses.replace(options['robots'], time_warp=tuple(warp.to_parameter()))
    return scenario, chosen


def _warn_saturation(result) -> None:
    """Robot runs: say whether the agents clipped commands to the robots' limits (the theorems assume not)."""
    from formation_sim.sim.summary import RunSummary

    if result.summary is None:
        return
    saturation = RunSummary.read(result.summary).extra.get('saturation')
    if saturation and saturation.get('total'):
        kinds = ', '.join(
            f'{kind} {entry["count"]} (up to {entry["largest_requested"]:.3g} asked, '
            f'{entry["allowed"]:g} allowed)'
            for kind, entry in saturation['by_kind'].items()
        )
        print(
            f"warning: {saturation['total']} commands saturated at the robots' limits: {kinds}; agents "
            f'{", ".join(saturation["by_agent"])}; the theorems assume no saturation (summary.json '
            'extra.saturation)',
            file=sys.stderr,
        )
