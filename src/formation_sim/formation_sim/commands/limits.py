"""Robot limits in the commands: the speed scale `--speed-scale auto` chooses from them, and the
refusal of a robot run whose commands would exceed them (`formation run`, `--allow-saturation`).

Not a subcommand itself (`formation_sim.cli.COMMANDS` lists those).  The arithmetic is
`formation_sim.model.speed_choice`; the exact run it reads, `formation_sim.sim.largest_command`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys

from formation_agent.core.kinds import KIND_NAMES, robot_kind
from formation_agent.core.kinds.unicycle import CONTROL_POINT_DISTANCE
from formation_sim.commands.common import POSITIVE, add_shape_arguments, refuse
from formation_sim.model.errors import LimitsError, ScenarioError
from formation_sim.model.scenario import Scenario
from formation_sim.model.speed_choice import OBSERVED_MARGIN, RobotLimits, SpeedScaleChoice


def robot_limits(args: argparse.Namespace) -> RobotLimits:
    """The limits of the parsed robot arguments (`--max-speed` ...; absent or inf: none).  The turn
    rate limits the control point's speed only on robots steered at a control point ahead of their
    axle (`RobotKind.steered`); the robots are `--robot`, else the backend's kind, else (no robot
    named: `simulate`, `validate`, the exact backend) taken to be steered."""

    def given(name: str) -> float:
        value = getattr(args, name, None)
        return math.inf if value is None else value

    model = getattr(args, 'robot', None) or getattr(args, 'backend', None)
    steered = robot_kind(model).steered if model in KIND_NAMES else True
    return RobotLimits(
        max_speed=given('max_speed'),
        max_angular_speed=given('max_angular_speed') if steered else math.inf,
        control_point_distance=getattr(args, 'control_point_distance', None)
        or CONTROL_POINT_DISTANCE.default,
        max_acceleration=given('max_acceleration'),
    )


AUTO = 'auto'
WARP = 'warp'
WARP_COMMANDS = ('simulate', 'validate', 'run')
"""The commands that apply a time warp (`--speed-scale warp`); `run` on robot backends only."""


def speed_scale_of(scenario: Scenario) -> float:
    """The scenario's speed scale κ (1: the paper's time)."""
    return float(scenario.gains.speed_scale)


def add_limit_arguments(parser: argparse.ArgumentParser) -> None:
    """The robots' limits, for a command that has no robots but may choose κ from them (`simulate`)."""
    group = parser.add_argument_group('robot limits (for --speed-scale auto)')
    group.add_argument(
        '--max-speed', type=POSITIVE, default=None, metavar='V', help="the robots' speed limit [m/s]"
    )
    group.add_argument(
        '--max-angular-speed',
        type=POSITIVE,
        default=None,
        metavar='W',
        help='unicycles: their turn-rate limit [rad/s]',
    )
    add_shape_arguments(group, (CONTROL_POINT_DISTANCE,))
    group.add_argument(
        '--max-acceleration',
        type=POSITIVE,
        default=None,
        metavar='A',
        help='ETA-2: the acceleration limit [m/s²]',
    )


def resolve_speed_scale(
    scenario: Scenario, args: argparse.Namespace, command: str
) -> tuple[Scenario, dict | None] | None:
    """`--speed-scale auto`: (the scenario at the observed κ of `choose_speed_scale` for the parsed
    limits, what to record in summary.json's extra.speed_scale), after saying so on stderr; any
    other value: (the scenario, None).  None after printing why auto cannot choose (nothing started)."""
    from formation_sim.sim.largest_command import choose_speed_scale

    if getattr(args, 'speed_scale', None) == WARP and command not in WARP_COMMANDS:
        refuse(
            command,
            f'--speed-scale warp: only formation {", ".join(WARP_COMMANDS)} apply a time warp so far '
            '(docs/SPEED_SCALE.md, "A time warp"): use --speed-scale auto',
        )
        return None
    if getattr(args, 'speed_scale', None) != AUTO:
        return scenario, None
    if (choice := _choose(choose_speed_scale, scenario, args, command, f'--speed-scale {AUTO}')) is None:
        return None
    kappa, horizon = choice.value, _horizon(scenario, args)
    try:
        scaled = scenario.with_scale(speed_scale=kappa)
    except ScenarioError as error:  # κ outside the rule speed_scale: the limits cannot be met
        refuse(
            command, f'--speed-scale auto: the limits ask for κ = {kappa:.4g}, which cannot be run: {error}'
        )
        return None
    observed = choice.observed
    settle = observed.settle_time
    print(
        f'formation {command}: --speed-scale auto: κ = {kappa:.4g} ({choice.source}: the exact run '
        f'at κ = 1 asks for {observed.speed:.4g} m/s'
        + ('' if observed.acceleration is None else f', {observed.acceleration:.4g} m/s²')
        + f', kept {observed.margin:g}× below the {observed.binding}'
        + (
            f'; {100 * choice.settling.fraction:g} % of the formation error after {settle:.3g} s'
            if math.isfinite(settle)
            else ''
        )
        + (f', beyond the horizon {horizon:g} s' if math.isfinite(settle) and settle > horizon else '')
        + ')',
        file=sys.stderr,
    )
    record = {
        'value': kappa,
        'source': choice.source,
        'binding': observed.binding,
        'margin': observed.margin,
        'limits': choice.limits.to_dict(),
        'guaranteed': None if choice.guaranteed is None else choice.guaranteed.value,
    }
    if record['guaranteed'] is not None and not math.isfinite(record['guaranteed']):
        record['guaranteed'] = None
    return scaled, record


def _horizon(scenario: Scenario, args: argparse.Namespace) -> float:
    return scenario.horizon if getattr(args, 'horizon', None) is None else args.horizon


def _choose(choose, scenario: Scenario, args: argparse.Namespace, command: str, option: str):
    """`choose` (`choose_speed_scale`, `choose_time_warp`) for the parsed limits over the run's
    horizon; None after refusing with the limits' error, named by `option`."""
    try:
        return choose(scenario.replace(horizon=_horizon(scenario, args)), limits=robot_limits(args))
    except LimitsError as error:
        refuse(command, f'{option}: {error}')
        return None


def exceeded(choice: SpeedScaleChoice, kappa: float) -> list[str]:
    """What the exact run asks for at κ beyond the limits of `choice`, one phrase per limit."""
    limits = choice.limits
    speed = kappa * choice.observed.speed
    found = []
    if speed > limits.max_speed:
        found.append(f'{speed:.4g} m/s beyond --max-speed {limits.max_speed:g} m/s')
    turn = speed / limits.control_point_distance
    if turn > limits.max_angular_speed:
        found.append(
            f'{turn:.4g} rad/s beyond --max-angular-speed {limits.max_angular_speed:g} rad/s '
            f'(a unicycle steered at l = {limits.control_point_distance:g} m turns at up to ||u||/l)'
        )
    acceleration = choice.observed.acceleration
    if acceleration is not None and kappa * kappa * acceleration > limits.max_acceleration:
        found.append(
            f'{kappa * kappa * acceleration:.4g} m/s² beyond --max-acceleration '
            f'{limits.max_acceleration:g} m/s²'
        )
    return found


def check_saturation(
    scenario: Scenario, *, limits: RobotLimits, allow: bool, command: str = 'run'
) -> str | None:
    """Before a robot run: None if the exact run at the scenario's κ stays within `limits` (or there
    are none); else the refusal (or, with `allow`, after printing it as a warning, None).

    The exact run, not the proofs' bound, decides: the bound of a team set down by hand is many
    times what any run asks for (robots_lab: 3.9 m/s against 1.16 m/s), and a refusal must be
    about commands the robots would really be sent; the exact run is what they are sent without
    noise, so a run it refuses saturates for certain."""
    from formation_sim.sim.largest_command import choose_speed_scale

    if not limits.any:
        return None
    kappa = speed_scale_of(scenario)
    try:
        choice = choose_speed_scale(scenario, limits=limits, paper_horizon=kappa * scenario.horizon)
    except LimitsError as error:
        return str(error)
    found = exceeded(choice, kappa)
    if not found:
        return None
    remedy = (
        f'--speed-scale auto (κ = {choice.value:.4g}: the largest command {OBSERVED_MARGIN:g}× below '
        'the limits'
        + (
            f', settling to {100 * choice.settling.fraction:g} % in {choice.observed.settle_time:.3g} s'
            if math.isfinite(choice.observed.settle_time)
            else ''
        )
        + ')'
    )
    message = (
        f'the exact run of {scenario.name} at speed scale κ = {kappa:g} asks for '
        + '; '.join(found)
        + ': those commands would be clipped, which the theorems do not cover (connectivity and '
        f'convergence are not guaranteed while clipping lasts). Run slower with {remedy}, or add '
        '--allow-saturation to run anyway'
    )
    if allow:
        print(
            f'formation {command}: warning: '
            f'{message.replace(", or add --allow-saturation to run anyway", "")} (--allow-saturation: '
            'running anyway; summary.json extra.saturation counts the clipped commands)',
            file=sys.stderr,
        )
        return None
    return message


def chosen_warp(record: dict | None) -> bool:
    """Whether summary.json's extra.speed_scale `record` is a time warp's."""
    return record is not None and record.get('kind') == 'time_warp'


def resolve_time_warp(scenario: Scenario, args: argparse.Namespace, command: str, *, flag: str = WARP):
    """`--speed-scale warp` (or `flag`: auto on robots): (the scenario at κ = 1, the observed warp of
    `choose_time_warp` for the parsed limits, what to record in summary.json's extra.speed_scale),
    after saying so on stderr; None after printing why no warp applies (nothing started)."""
    from formation_sim.sim.largest_command import choose_time_warp, unit_scale

    if (choice := _choose(choose_time_warp, scenario, args, command, f'--speed-scale {flag}')) is None:
        return None
    warp = choice.warp
    settle = choice.settle_time(warp)
    if choice.turn is not None and scenario.safety is not None:  # a jam at the default turn: every agent's λ
        scenario = scenario.replace(safety=dataclasses.replace(scenario.safety, turn=choice.turn))
        print(f'formation {command}: {choice.turn_line()}', file=sys.stderr)
    print(
        f'formation {command}: --speed-scale {flag}: a time warp, κ(t) in {warp.pieces} pieces from '
        f'{warp.rates[0]:.4g} '
        f'to {warp.max_rate:.4g} (observed: the exact run at κ = 1 kept {choice.margin:g}× below the speed '
        f'limit {choice.limits.speed_limit()[0]:.4g} m/s, capped at {choice.cap:g}'
        + (
            f'; {100 * choice.settling.fraction:g} % of the formation error after {settle:.3g} s'
            if math.isfinite(settle)
            else ''
        )
        + ')',
        file=sys.stderr,
    )
    return unit_scale(scenario), warp, choice.to_dict()
