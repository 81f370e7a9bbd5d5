"""`formation robots SCENARIO --model M --domain-id N`: simulated robots on their own, as real robots
would be, for `formation run SCENARIO --backend external --robot M --domain-id N`.

Exit status: 0 stopped (Ctrl-C, SIGTERM, or --duration over); 2 bad input; 3 a robot process died.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from formation_sim.commands.common import add_robot_arguments, add_scenario_argument, load_valid_scenario, robot_options


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'robots',
        help='start simulated robots on their own (the world of --backend external)',
        description='Start one simulated kinematic robot per agent of SCENARIO, each its own process, in ROS '
        'domain N, placed at the scenario positions (a unicycle by its control point): each publishes '
        '/agent_<i>/robot/pose, odom and true_odom and takes /agent_<i>/robot/cmd_vel. They run until '
        'Ctrl-C or SIGTERM. Then run the team on them: formation run SCENARIO --backend external --robot M '
        '--domain-id N.',
        epilog='Exit status: 0 stopped; 2 bad input; 3 a robot process died (see OUT/logs).',
    )
    add_scenario_argument(parser)
    parser.add_argument('--domain-id', type=int, required=True, metavar='N', help='ROS_DOMAIN_ID of the run to serve')
    parser.add_argument('--out', type=Path, default=None, help='folder for robots.params.yaml and logs (default: runs/<scenario>-robots-<time>)')
    parser.add_argument('--duration', type=float, default=None, metavar='S', help='stop after this many seconds (default: run until stopped)')
    parser.add_argument('--network', action='store_true', help='let DDS discovery reach the local network (default: this machine only)')
    add_robot_arguments(parser, model_flag='--model')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.runtime.fleet import RobotFleet
    from formation_sim.runtime.launch import RunError

    scenario = load_valid_scenario(args.scenario, 'robots')
    if scenario is None:
        return 2
    if args.model is None:
        print('formation robots: error: --model holonomic|unicycle is required', file=sys.stderr)
        return 2
    out = args.out or Path('runs') / f'{scenario.name}-robots-{time.strftime("%Y%m%d-%H%M%S")}'
    try:
        fleet = RobotFleet(scenario, robots=robot_options(args, args.model), out_dir=out, domain_id=args.domain_id, localhost_only=not args.network)
    except RunError as error:
        print(f'formation robots: error: {error}', file=sys.stderr)
        return 2
    print(f'{len(scenario.agent_ids)} {args.model} robots in ROS domain {args.domain_id}; logs in {out / "logs"}; Ctrl-C stops them', file=sys.stderr)
    status = fleet.run(duration=args.duration)
    if status:
        print(f'formation robots: {", ".join(child.describe() for child in fleet.died)}', file=sys.stderr)
    return status
