"""`formation measure SCENARIO --robot KIND --out FILE`: the scenario, started from where the robots are.

Robots set down by hand are not where a scenario file says.  This command reads each robot's
current pose (`/agent_<i>/robot/odom` or `.../pose`, as its agent would), takes the point the
scenario speaks of (a unicycle's or car's control point, `control_point_distance` ahead of its
axle; `formation_agent.core.kinds`), and writes the scenario with those positions, the robots'
headings and, for double integrators, the velocities from odometry.  The agents' positions in
SCENARIO may be missing.  Then `formation validate` and `formation run FILE --backend external
--speed-scale auto` work from the real start; the coordinator checks the start again before
step 0 (the robots may have moved since).
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from formation_agent.core.kinds import KIND_NAMES, robot_kind
from formation_agent.core.kinds.shape import declared
from formation_sim.commands.common import (
    POSITIVE,
    add_domain_argument,
    add_shape_arguments,
    refuse,
    shape_geometry,
)

POSE_TYPES = ('odom', 'pose')


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'measure',
        help='write a scenario whose agents start where the robots are (their poses, now)',
        description=__doc__.split('\n\n', 1)[1].replace('\n', ' '),
    )
    parser.add_argument(
        'scenario', metavar='SCENARIO', help='built-in scenario or file; agent positions may be missing'
    )
    parser.add_argument('--robot', required=True, choices=KIND_NAMES, help='what the robots are (their kind)')
    parser.add_argument(
        '--pose-type',
        choices=POSE_TYPES,
        default='odom',
        help='the topic read per robot: robot/odom (default) or robot/pose',
    )
    add_shape_arguments(parser, declared(node='robot'))  # what places a robot's control point
    parser.add_argument(
        '--timeout',
        type=POSITIVE,
        default=10.0,
        metavar='S',
        help='wait up to S seconds for every robot (default 10)',
    )
    parser.add_argument(
        '--out',
        type=Path,
        required=True,
        metavar='FILE',
        help='the scenario to write (.json or YAML); never overwritten',
    )
    add_domain_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.model.errors import ScenarioError
    from formation_sim.model.scenario import dump_scenario, load_scenario_data, scenario_from_dict

    if args.out.exists():
        return refuse(
            'measure',
            f'--out {args.out}: exists; choose a new file (an earlier scenario is never overwritten)',
        )
    try:
        data, name, source = load_scenario_data(args.scenario)
        ids, dimension, double = _team(data)
        geometry = shape_geometry(args, declared(node='robot'))
        problems = robot_kind(args.robot).placement_problems(dimension=dimension, geometry=geometry)
        if problems:
            raise ScenarioError('; '.join(problems))
        if double and args.pose_type == 'pose':
            raise ScenarioError(
                'double integrators start with a velocity: read it from odometry (--pose-type odom)'
            )
    except ScenarioError as error:
        return refuse('measure', error)
    try:
        measured = _read_poses(args, ids)
    except KeyboardInterrupt:
        return 130
    if missing := [i for i in ids if i not in measured]:
        print(
            f'formation measure: no pose within {args.timeout:g} s from robots '
            f'{", ".join(map(str, missing))} (topics /agent_<i>/robot/{args.pose_type}, ROS domain '
            f'{args.domain_id if args.domain_id is not None else "of the environment"})',
            file=sys.stderr,
        )
        return 1
    starts = {
        i: _start(fields, args=args, dimension=dimension, double=double) for i, fields in measured.items()
    }
    completed = complete(data, starts)
    try:
        scenario = scenario_from_dict(completed, name=name)
    except ScenarioError as error:
        return refuse('measure', f'{source} with the measured start: {error}')
    dump_scenario(scenario, args.out)
    for i in ids:
        position, heading, _ = starts[i]
        print(f'robot {i}: at {", ".join(f"{v:.4f}" for v in position)} m, heading {heading:.4f} rad')
    print(
        f'wrote {args.out}: `formation validate {args.out}` checks the start, `formation run {args.out} '
        '--backend external` runs it'
    )
    return 0


def _team(data: Any) -> tuple[list[int], int, bool]:
    """The agent ids, the dimension p (from the edges' d_ij, else 2) and whether ETA-2."""
    from formation_sim.model.errors import ScenarioError

    if not isinstance(data, Mapping) or not isinstance(data.get('agents'), Mapping) or not data['agents']:
        raise ScenarioError(
            'the scenario needs a mapping `agents` of agent ids (their positions may be missing)'
        )
    try:
        ids = sorted(int(agent) for agent in data['agents'])
    except (TypeError, ValueError):
        raise ScenarioError(f'agents: ids must be integers, got {sorted(map(str, data["agents"]))}') from None
    edges = data.get('edges') or []
    first = edges[0].get('d') if edges and isinstance(edges[0], Mapping) else None
    dimension = len(first) if isinstance(first, list) and first else 2
    return ids, dimension, data.get('dynamics') == 'double'


def _start(
    fields: tuple, *, args: argparse.Namespace, dimension: int, double: bool
) -> tuple[list[float], float, list[float] | None]:
    """(the scenario position, the heading, the velocity if ETA-2) from a pose's fields."""
    from formation_agent.core import kinematics
    from formation_sim.sim.robots import sample_from_fields

    sample = sample_from_fields(
        *fields,
        model=args.robot,
        dimension=dimension,
        control_point_distance=args.control_point_distance,
        epoch=0.0,
    )
    pose = fields[2]
    heading = kinematics.yaw(pose[3:])
    velocity = [float(v) for v in sample.velocity] if double else None
    return [float(v) for v in sample.position], heading, velocity


def complete(data: Mapping, starts: Mapping[int, tuple[list[float], float, list[float] | None]]) -> dict:
    """`data` with each agent's position, heading (and velocity) replaced by its measured start."""
    completed = copy.deepcopy(dict(data))
    agents = {}
    for raw_id, entry in data['agents'].items():
        position, heading, velocity = starts[int(raw_id)]
        agent = dict(entry or {})
        agent.update(position=position, heading=heading)
        if velocity is not None:
            agent['velocity'] = velocity
        agents[raw_id] = agent
    completed['agents'] = agents
    return completed


def _read_poses(args: argparse.Namespace, ids: list[int]) -> dict[int, tuple]:
    """Each robot's latest pose fields (formation_msgs_py.cdr) within the timeout."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.cdr import odometry_fields, pose_stamped_fields
    from formation_msgs_py.errors import MessageError
    from formation_msgs_py.qos import ROBOT_POSE_QOS
    from formation_msgs_py.topics import robot_odom_topic, robot_pose_topic
    from formation_sim.commands.common import inspection_node

    kind, topic, fields_of = (
        (Odometry, robot_odom_topic, odometry_fields)
        if args.pose_type == 'odom'
        else (PoseStamped, robot_pose_topic, pose_stamped_fields)
    )
    measured: dict[int, tuple] = {}

    def take(data: bytes, robot: int) -> None:
        try:
            fields = fields_of(data)
        except MessageError as error:
            print(f'formation measure: robot {robot}: {error}', file=sys.stderr)
            return
        if all(math.isfinite(v) for v in fields[2]):
            measured[robot] = fields

    with inspection_node('measure', args.domain_id) as node:
        subscriptions = [
            node.create_subscription(
                kind, topic(i), lambda data, robot=i: take(data, robot), ROBOT_POSE_QOS, raw=True
            )
            for i in ids
        ]
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        deadline = time.monotonic() + args.timeout
        while len(measured) < len(ids) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        executor.shutdown()
        del subscriptions
    return measured
