"""`formation params SCENARIO --out DIR`: the parameter files `formation run` would write, without a run.

The same launch plan as `formation run` (`formation_sim.runtime.launch.plan.LaunchPlan.write_inputs`,
the one place they are built) writes the scenario and every node's parameter file into DIR, and
prints the command that starts each process by hand (`ProcessSpec.command`): for agents on
separate machines, robots, or a node to inspect with `ros2 param describe`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import (
    add_plan_arguments,
    add_run_arguments,
    add_safety_argument,
    backend_safety,
    load_valid_scenario,
    plan_options,
    refuse,
    scale_options,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'params',
        help=(
            'write the parameter files of a distributed run (agents, recorder, simulator or coordinator, '
            'robots) without starting it'
        ),
        description=(
            'Write what `formation run` with the same arguments would write before it starts its processes: '
            'scenario.yaml, agents.params.yaml, recorder.params.yaml, simulator.params.yaml (backend exact) '
            'or coordinator.params.yaml (robot backends) and robots.params.yaml (simulated robots), each '
            'keyed by node name; then print the command that starts each process by hand. Nothing is '
            'started.'
        ),
        epilog=(
            'The output folder follows the run-folder rule of `formation run`: new or empty, or --force to '
            'replace an earlier run there. Exit status: 0 written; 2 bad input (nothing written).'
        ),
    )
    add_run_arguments(parser, kind='params')
    add_plan_arguments(parser)
    add_safety_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_msgs_py.middleware import FASTDDS_PROFILE
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.orchestrate import FormationRun
    from formation_sim.sim.errors import RunFolderError
    from formation_sim.sim.run_folder import claim_out_dir

    scenario = load_valid_scenario(args.scenario, 'params', **scale_options(args))
    if scenario is None:
        return ExitCode.BAD_INPUT
    try:
        options = plan_options(args)
    except RunError as error:
        return refuse('params', error)
    # The safety layer as formation run takes it: on robots the origins apart, the footprints' default.
    if (safe := backend_safety(scenario, args.min_separation, options['robots'], 'params')) is None:
        return ExitCode.BAD_INPUT
    scenario = safe[0]
    from formation_sim.commands.limits import resolve_speed_scale

    if (resolved := resolve_speed_scale(scenario, args, 'params')) is None:
        return ExitCode.BAD_INPUT
    scenario = resolved[0]  # the agents' parameter files carry κ
    try:
        plan = FormationRun(scenario, **options).plan  # every argument checked, nothing touched yet
        out = claim_out_dir(args.out, scenario_name=scenario.name, kind='params', force=args.force)
    except (RunError, RunFolderError) as error:
        return refuse('params', error)
    plan = dataclasses.replace(plan, out_dir=out)
    paths = plan.write_inputs()
    print(f'folder: {out}')
    for role, path in paths.items():
        print(f'  {role + ":":10s} {path.name}')
    print(
        '\nStart the processes by hand, each with the same ROS_DOMAIN_ID (and '
        f'FASTRTPS_DEFAULT_PROFILES_FILE={FASTDDS_PROFILE}, as formation run does), in this order:'
    )
    for spec in plan.processes(paths):
        print(f'  {spec.command}')
    sys.stdout.flush()
    return 0
