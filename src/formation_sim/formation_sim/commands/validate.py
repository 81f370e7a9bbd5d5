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

from formation_agent.core.kinds import FOOTPRINT_RADIUS, KindNames
from formation_agent.core.kinds.unicycle import CONTROL_POINT_DISTANCE
from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import (
    POSITIVE,
    RobotShape,
    add_safety_argument,
    add_scale_arguments,
    add_scenario_argument,
    add_shape_arguments,
    backend_safety,
    scale_options,
    shape_geometry,
)
from formation_sim.model.errors import LimitsError, ScenarioError
from formation_sim.model.scenario import load_scenario
from formation_sim.model.speed_choice import (
    RobotLimits,
    check_limits_apply,
    omega_at_formation,
    scenario_noise_floor,
)
from formation_sim.model.validate import validate_scenario

DEFAULT_POSE_PERIOD = 0.01  # [s]: the simulated robots' 100 Hz


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'validate',
        help='check a scenario against the hypotheses of Theorems 1 and 2 (and robot limits)',
        description='Check a scenario against the hypotheses of Theorem 1 (single integrators) or '
        'Theorem 2 (double integrators) and print every number involved. With --max-speed (and '
        '--max-angular-speed, --max-acceleration): the largest command the scenario asks of a robot, '
        'a bound from the proofs where it shows the limits are never reached, else the largest in an '
        'exact in-process run (which the output names), and the speed scales κ that keep the commands within '
        'them (guaranteed, observed; --speed-scale auto runs the observed) with the time each needs to '
        'settle. With --pose-noise: the threshold floor c0 that noise asks for. Exit 0 if valid '
        '(warnings allowed) and within the limits, 1 if a hypothesis is broken or a command exceeds a '
        'limit, 2 if the scenario cannot be read.',
    )
    add_scenario_argument(parser)
    add_scale_arguments(parser)
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    add_safety_argument(parser)
    parser.add_argument(
        '--max-speed', type=POSITIVE, default=None, metavar='V', help="the robots' speed limit [m/s]"
    )
    parser.add_argument(
        '--max-angular-speed',
        type=POSITIVE,
        default=None,
        metavar='W',
        help='unicycles: their turn-rate limit [rad/s]',
    )
    add_shape_arguments(parser, (CONTROL_POINT_DISTANCE, FOOTPRINT_RADIUS))
    parser.add_argument(
        '--robot',
        choices=KindNames(),
        default=None,
        metavar='KIND',
        help=(
            'the robots the scenario is for, as `formation run --backend KIND` takes them: --min-separation '
            "D between their origins (their control points D + c_i + c_j), and without it or the scenario's "
            "safety: the kind's footprints 2r + 0.05 m apart (docs/SAFETY.md); overlapping robots refused"
        ),
    )
    parser.add_argument(
        '--max-acceleration',
        type=POSITIVE,
        default=None,
        metavar='A',
        help='ETA-2: the acceleration limit [m/s²]',
    )
    parser.add_argument(
        '--pose-noise',
        type=POSITIVE,
        default=None,
        metavar='SIGMA',
        help=(
            "σ of the robots' position noise [m]: suggest the threshold floor c0 that keeps the noise from "
            'triggering (README, "Running on robots")'
        ),
    )
    parser.add_argument(
        '--pose-period',
        type=POSITIVE,
        default=DEFAULT_POSE_PERIOD,
        metavar='DT',
        help=(
            'ETA-2 with --pose-noise: the time between two poses a velocity is differenced from [s] '
            f'(default {DEFAULT_POSE_PERIOD:g}, 100 Hz)'
        ),
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        scenario = load_scenario(args.scenario).with_scale(**scale_options(args))
    except ScenarioError as error:
        print(f'formation validate: error: {error}', file=sys.stderr)
        return ExitCode.BAD_INPUT
    robots = None
    if args.robot is not None:
        shape = shape_geometry(args, (CONTROL_POINT_DISTANCE, FOOTPRINT_RADIUS))
        robots = RobotShape(model=args.robot, geometry=shape)
    if (safe := backend_safety(scenario, args.min_separation, robots, 'validate')) is None:
        return ExitCode.BAD_INPUT
    scenario = safe[0]
    report = validate_scenario(scenario)
    if report.ok and args.speed_scale == 'auto':
        from formation_sim.commands.limits import resolve_speed_scale

        if (resolved := resolve_speed_scale(scenario, args, 'validate')) is None:
            return ExitCode.BAD_INPUT
        scenario = resolved[0]
        report = validate_scenario(scenario)
    commands = floor = None
    if report.ok and any(
        value is not None for value in (args.max_speed, args.max_angular_speed, args.max_acceleration)
    ):
        try:
            commands = _commands(scenario, args)
        except LimitsError as error:
            print(f'formation validate: error: {error}', file=sys.stderr)
            return ExitCode.BAD_INPUT
    if report.ok and args.pose_noise is not None:
        floor = _noise_floor(scenario, args)
    if args.json:
        data = report.to_dict()
        if commands is not None:
            data['commands'] = commands
        if floor is not None:
            data['threshold_floor'] = floor
        if scenario.safety is not None:
            data['safety'] = _safety_numbers(scenario.safety)
        print(json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False))
    else:
        print(report.format())
        if scenario.safety is not None:
            print(_safety_numbers(scenario.safety)['line'])
        for part in (commands, floor):
            if part is not None:
                print('\n'.join(part['lines']))
    if not report.ok:
        return ExitCode.FAILED
    return ExitCode.FAILED if commands is not None and not commands['within'] else ExitCode.OK


def _commands(scenario, args: argparse.Namespace) -> dict:
    """The largest commands against the limits given: the numbers, the verdict, the lines to print."""
    from formation_sim.sim.largest_command import choose_speed_scale, largest_command

    limits = _limits(args)
    check_limits_apply(
        limits, scenario.dynamics
    )  # refused before any run: e.g. an acceleration limit on ETA-1

    turn_as_speed = (
        math.inf if args.max_angular_speed is None else args.max_angular_speed * args.control_point_distance
    )
    speed_limit = min(math.inf if args.max_speed is None else args.max_speed, turn_as_speed)
    acceleration_limit = math.inf if args.max_acceleration is None else args.max_acceleration
    answer, loose = largest_command(scenario, max_speed=speed_limit, max_acceleration=acceleration_limit)
    guaranteed = answer.source == 'theory'
    how = (
        'a bound from the theory' if guaranteed else 'the largest in an exact in-process run, not a guarantee'
    )
    lines = ['commands:']
    if loose is not None:
        lines.append(
            f'  the theory bounds the speed by {loose.max_speed:.4g} m/s'
            + (
                f' and the acceleration by {loose.max_acceleration:.4g} m/s²'
                if loose.max_acceleration is not None
                else ''
            )
            + ' — beyond the limits, which settles nothing; so an exact run decides'
        )
    checks = []
    speed = answer.max_speed
    if args.max_speed is not None:
        checks.append(('speed', speed, args.max_speed, 'm/s'))
    if args.max_angular_speed is not None:
        checks.append(
            (
                f'turn rate (unicycle, l = {args.control_point_distance:g} m: |ω| <= ||u|| / l)',
                answer.max_turn_rate(args.control_point_distance),
                args.max_angular_speed,
                'rad/s',
            )
        )
    if args.max_acceleration is not None and answer.max_acceleration is not None:
        checks.append(('acceleration', answer.max_acceleration, args.max_acceleration, 'm/s²'))
    within = True
    for what, value, limit, unit in checks:
        ok = value <= limit
        within &= ok
        lines.append(
            f'  largest {what}: {value:.4g} {unit} {"<=" if ok else "EXCEEDS"} {limit:g} {unit} ({how})'
        )
    lines.append(f'  from: {answer.reference}')
    if answer.dotyi is not None:
        lines.append(f'  (dotyi) as printed bounds it by {max(answer.dotyi.values()):.4g} m/s')
    lines.append(
        '  per agent [m/s]: ' + ', '.join(f'{agent}: {value:.4g}' for agent, value in answer.speed.items())
    )
    choice = choose_speed_scale(scenario, limits=limits)
    lines.extend(choice.lines())
    warp = _time_warp(scenario, limits, constant=choice.value, lines=lines)
    return {
        'within': within,
        'guaranteed': guaranteed,
        'largest': answer.to_dict(),
        'theory_too_loose': None if loose is None else loose.to_dict(),
        'speed_scale': choice.to_dict(),
        'time_warp': warp,
        'lines': lines,
    }


def _time_warp(scenario, limits: RobotLimits, *, constant: float, lines: list[str]) -> dict:
    """The time warps for `limits` (ETA-1) and the time to settle with them and with the constant
    κ, appended to `lines`; {'missing': why} where no warp applies."""
    from formation_sim.sim.largest_command import choose_time_warp

    try:
        warp = choose_time_warp(scenario, limits=limits)
    except LimitsError as error:
        lines.append(f'time warp: none: {error}')
        return {'missing': str(error)}
    lines.extend(warp.lines(constant=constant))
    settle = warp.settling.at(constant)
    return {**warp.to_dict(), 'constant_settle_time': settle if math.isfinite(settle) else None}


def _limits(args: argparse.Namespace) -> RobotLimits:
    def given(value: float | None) -> float:
        return math.inf if value is None else value

    return RobotLimits(
        max_speed=given(args.max_speed),
        max_angular_speed=given(args.max_angular_speed),
        control_point_distance=args.control_point_distance,
        max_acceleration=given(args.max_acceleration),
    )


def _noise_floor(scenario, args: argparse.Namespace) -> dict:
    """The threshold floor c0 a pose noise σ asks for (`formation_sim.model.speed_choice.noise_floor`)."""
    kappa = getattr(scenario.gains, 'speed_scale', 1.0)
    floor, per_agent, formula = scenario_noise_floor(
        scenario, pose_noise=args.pose_noise, pose_period=args.pose_period, speed_scale=kappa
    )
    present = getattr(scenario.gains, 'threshold_floor', 0.0)
    lines = [
        f'threshold floor for a pose noise σ = {args.pose_noise:g} m:',
        f'  suggested c0 = {floor:.3g} (gains.threshold_floor, or --threshold-floor {floor:.3g})',
        f'  {formula}',
        "  what one trigger's noisy sensing puts into e_i"
        + (' (E_i)' if scenario.dynamics == 'double' else '')
        + ', per axis [1σ]: '
        + ', '.join(f'{agent}: {value:.3g}' for agent, value in per_agent.items()),
    ]
    gains = scenario.gains
    alpha, beta = (
        (gains.alpha, gains.beta) if scenario.dynamics == 'single' else (gains.alpha_d, gains.beta_d)
    )
    if present < floor:
        below = (
            0.0 if alpha + present <= floor else math.log(alpha / (floor - present)) / beta
        )  # paper's time
        lines.append(
            f"  the scenario's c0 = {present:g}: its threshold c0 + α e^(-βt) is below c0 = {floor:.3g} "
            f'from t = {below / kappa:.4g} s on (κ = {kappa:g}; horizon {scenario.horizon:g} s): from '
            "then on the noise alone can set off triggers, each trigger's noise the next (the longer the "
            'run, the more events)'
        )
    if scenario.dynamics == 'single':
        reach = min(sum(omega_at_formation(scenario, agent)) for agent in scenario.agent_ids)
        lines.append(
            '  a floor costs accuracy: the formation settles to about c0 / min_i Σ_j ω_ij = '
            f'{floor / reach:.3g} m or better'
        )
    return {
        'suggested': floor,
        'per_agent': {str(a): v for a, v in per_agent.items()},
        'formula': formula,
        'scenario_floor': present,
        'lines': lines,
    }


def _safety_numbers(safety) -> dict:
    """The safety layer's settings and derived radii (docs/SAFETY.md); its rules held at loading."""
    numbers = {**safety.as_dict(), 'guard_radius': safety.guard_radius, 'heartbeat': safety.heartbeat}
    numbers['line'] = (
        f'safety layer: robots kept >= {safety.min_separation:g} m apart, edges within Δ - ||d_ij|| '
        f'(γ = {safety.gamma:g} 1/s, v̄ = {safety.max_speed:g} m/s, '
        f'sensing radius {safety.sensing_radius:g} m > guard radius {safety.guard_radius:.4g} m, '
        f'heartbeat {safety.heartbeat:.4g} s)'
    )
    return numbers
