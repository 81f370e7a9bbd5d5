"""`formation validate SCENARIO [--json] [--max-speed V ...]`: check a scenario against the theorems'
hypotheses, and, with limits, whether a robot could carry out the commands it asks for.

Exit codes: 0 valid (warnings allowed) and within the limits given, 1 a hypothesis is broken or
a command exceeds a limit, 2 the scenario cannot be read or a limit is not a number > 0.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

from formation_sim.commands.common import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    POSITIVE,
    add_scale_arguments,
    add_scenario_argument,
    scale_options,
)
from formation_sim.model.scenario import ScenarioError, load_scenario
from formation_sim.model.validate import validate_scenario

EXIT_VALID = EXIT_OK
EXIT_INVALID = EXIT_FAILED
EXIT_UNREADABLE = EXIT_BAD_INPUT


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'validate',
        help='check a scenario against the hypotheses of Theorems 1 and 2 (and robot limits)',
        description='Check a scenario against the hypotheses of Theorem 1 (single integrators) or '
        'Theorem 2 (double integrators) and print every number involved. With --max-speed (and '
        '--max-angular-speed, --max-acceleration): the largest command the scenario asks of a robot, '
        'a bound from the proofs where it shows the limits are never reached, else the largest in an '
        'exact in-process run (which the output names). Exit 0 if valid (warnings allowed) and within '
        'the limits, 1 if a hypothesis is broken or a command exceeds a limit, 2 if the scenario '
        'cannot be read.',
    )
    add_scenario_argument(parser)
    add_scale_arguments(parser)
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.add_argument('--max-speed', type=POSITIVE, default=None, metavar='V', help="the robots' speed limit [m/s]")
    parser.add_argument('--max-angular-speed', type=POSITIVE, default=None, metavar='W', help='unicycles: their turn-rate limit [rad/s]')
    parser.add_argument('--control-point-distance', type=POSITIVE, default=0.1, metavar='L', help='unicycles: the control point l ahead of the axle [m] (default 0.1)')
    parser.add_argument('--max-acceleration', type=POSITIVE, default=None, metavar='A', help='ETA-2: the acceleration limit [m/s²]')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        scenario = load_scenario(args.scenario).with_scale(**scale_options(args))
    except ScenarioError as error:
        print(f'formation validate: error: {error}', file=sys.stderr)
        return EXIT_UNREADABLE
    report = validate_scenario(scenario)
    commands = None
    if report.ok and any(value is not None for value in (args.max_speed, args.max_angular_speed, args.max_acceleration)):
        commands = _commands(scenario, args)
    if args.json:
        data = report.to_dict()
        if commands is not None:
            data['commands'] = commands
        print(json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False))
    else:
        print(report.format())
        if commands is not None:
            print('\n'.join(commands['lines']))
    if not report.ok:
        return EXIT_INVALID
    return EXIT_INVALID if commands is not None and not commands['within'] else EXIT_VALID


def _commands(scenario, args: argparse.Namespace) -> dict:
    """The largest commands against the limits given: the numbers, the verdict, the lines to print."""
    from formation_sim.sim.largest_command import largest_command

    turn_as_speed = math.inf if args.max_angular_speed is None else args.max_angular_speed * args.control_point_distance
    speed_limit = min(math.inf if args.max_speed is None else args.max_speed, turn_as_speed)
    acceleration_limit = math.inf if args.max_acceleration is None else args.max_acceleration
    answer, loose = largest_command(scenario, max_speed=speed_limit, max_acceleration=acceleration_limit)
    guaranteed = answer.source == 'theory'
    how = 'a bound from the theory' if guaranteed else 'the largest in an exact in-process run, not a guarantee'
    lines = ['commands:']
    if loose is not None:
        lines.append(
            f'  the theory bounds the speed by {loose.max_speed:.4g} m/s'
            + (f' and the acceleration by {loose.max_acceleration:.4g} m/s²' if loose.max_acceleration is not None else '')
            + ' — beyond the limits, which settles nothing; so an exact run decides'
        )
    checks = []
    speed = answer.max_speed
    if args.max_speed is not None:
        checks.append(('speed', speed, args.max_speed, 'm/s'))
    if args.max_angular_speed is not None:
        checks.append((f'turn rate (unicycle, l = {args.control_point_distance:g} m: |ω| <= ||u|| / l)', answer.max_turn_rate(args.control_point_distance), args.max_angular_speed, 'rad/s'))
    if args.max_acceleration is not None and answer.max_acceleration is not None:
        checks.append(('acceleration', answer.max_acceleration, args.max_acceleration, 'm/s²'))
    within = True
    for what, value, limit, unit in checks:
        ok = value <= limit
        within &= ok
        lines.append(f'  largest {what}: {value:.4g} {unit} {"<=" if ok else "EXCEEDS"} {limit:g} {unit} ({how})')
    lines.append(f'  from: {answer.reference}')
    if answer.dotyi is not None:
        lines.append(f'  (dotyi) as printed bounds it by {max(answer.dotyi.values()):.4g} m/s')
    lines.append('  per agent [m/s]: ' + ', '.join(f'{agent}: {value:.4g}' for agent, value in answer.speed.items()))
    return {'within': within, 'guaranteed': guaranteed, 'largest': answer.to_dict(), 'theory_too_loose': None if loose is None else loose.to_dict(), 'lines': lines}
