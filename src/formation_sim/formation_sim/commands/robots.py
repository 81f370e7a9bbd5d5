"""`formation robots SCENARIO --model M --domain-id N`: simulated robots on their own, as real robots
would be, for `formation run SCENARIO --backend external --robot M --domain-id N`.

Exit status: 0 stopped (Ctrl-C, SIGTERM, or --duration over); 2 bad input; 3 a robot process died
(the other robots run on until stopped, as independent robots would).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import (
    DOMAIN_ID,
    POSITIVE,
    add_robot_arguments,
    add_scenario_argument,
    load_valid_scenario,
    refuse,
    robot_options,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'robots',
        help='start simulated robots on their own (the world of --backend external)',
        description='Start one simulated kinematic robot per agent of SCENARIO, each its own process, in ROS '
        'domain N, placed at the scenario positions (a unicycle by its control point): each publishes '
        '/agent_<i>/robot/pose, odom and true_odom and takes /agent_<i>/robot/cmd_vel. They run until '
        'Ctrl-C or SIGTERM. Then run the team on them: formation run SCENARIO --backend external --robot M '
        '--domain-id N.',
        epilog='Exit status: 0 stopped; 2 bad input; 3 a robot process died (see OUT/logs; the other robots '
        'ran on until stopped).',
    )
    add_scenario_argument(parser)
    parser.add_argument(
        '--domain-id', type=DOMAIN_ID, required=True, metavar='N', help='ROS_DOMAIN_ID of the run to serve'
    )
    parser.add_argument(
        '--out',
        type=Path,
        default=None,
        help=(
            'folder for robots.params.yaml and logs, new or empty (default: a new folder '
            'runs/<scenario>-robots-<date>-<time>)'
        ),
    )
    parser.add_argument('--force', action='store_true', help="replace an earlier run's files in --out")
    parser.add_argument(
        '--duration',
        type=POSITIVE,
        default=None,
        metavar='S',
        help='stop after this many seconds (default: run until stopped)',
    )
    parser.add_argument(
        '--network',
        action='store_true',
        help='let DDS discovery reach the local network (default: this machine only)',
    )
    add_robot_arguments(parser, model_flag='--model')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.fleet import RobotFleet

    scenario = load_valid_scenario(args.scenario, 'robots')
    if scenario is None:
        return ExitCode.BAD_INPUT
    if args.model is None:
        from formation_sim.runtime.launch.plan import ROBOT_MODELS

        return refuse('robots', f'--model {"|".join(ROBOT_MODELS)} is required')
    try:
        fleet = RobotFleet(
            scenario,
            robots=robot_options(args, args.model),
            out_dir=args.out,
            force=args.force,
            domain_id=args.domain_id,
            localhost_only=not args.network,
        )
    except RunError as error:
        return refuse('robots', error)
    print(
        f'{len(scenario.agent_ids)} {args.model} robots in ROS domain {args.domain_id}; Ctrl-C stops them',
        file=sys.stderr,
    )
    try:
        status = fleet.run(duration=args.duration, on_death=_tell_death)
    except RunError as error:
        return refuse('robots', error)
    print(f'logs: {fleet.plan.out_dir / "logs"}', file=sys.stderr)
    if status:
        print(f'formation robots: {", ".join(child.describe() for child in fleet.died)}', file=sys.stderr)
    return status


def _tell_death(child) -> None:
    """A robot process died: said at once; the other robots run on until Ctrl-C."""
    print(
        f'formation robots: {child.describe()}; the other robots run on until stopped',
        file=sys.stderr,
        flush=True,
    )
