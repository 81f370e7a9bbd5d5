"""Robot limits in the commands: the speed scale `--speed-scale auto` chooses from them, and the
refusal of a robot run whose commands would exceed them (`formation run`, `--allow-saturation`).

Not a subcommand itself (`formation_sim.cli.COMMANDS` lists those).  The arithmetic is
`formation_sim.model.speed_choice`; the exact run it reads, `formation_sim.sim.largest_command`.
"""

from __future__ import annotations

import argparse
import math
import sys

from formation_sim.model.scenario import Scenario
from formation_sim.model.speed_choice import OBSERVED_MARGIN, LimitsError, RobotLimits, SpeedScaleChoice


def robot_limits(args: argparse.Namespace) -> RobotLimits:
    """The limits of the parsed robot arguments (`--max-speed` ...; absent or inf: none)."""

    def given(name: str) -> float:
        value = getattr(args, name, None)
        return math.inf if value is None else value

    return RobotLimits(
        max_speed=given('max_speed'),
        max_angular_speed=given('max_angular_speed'),
        control_point_distance=getattr(args, 'control_point_distance', None) or 0.1,
        max_acceleration=given('max_acceleration'),
    )


def speed_scale_of(scenario: Scenario) -> float:
    """The scenario's speed scale κ (1: the paper's time)."""
    return float(getattr(scenario.gains, 'speed_scale', 1.0))


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
        found.append(f'{kappa * kappa * acceleration:.4g} m/s² beyond --max-acceleration {limits.max_acceleration:g} m/s²')
    return found


def check_saturation(scenario: Scenario, *, limits: RobotLimits, allow: bool, command: str = 'run') -> str | None:
    """Before a robot run: None if the exact run at the scenario's κ stays within `limits` (or there
    are none); else the refusal (or, with `allow`, after printing it as a warning, None).

    The exact run, not the proofs' bound, decides: the bound of a team set down by hand is many
    times what any run asks for (robots_lab: 3.8 m/s against 1.16 m/s), and a refusal must be
    about commands the robots would really be sent; the exact run is what they are sent without
    noise, so a run it refuses saturates for certain."""
    from formation_sim.sim.largest_command import choose_speed_scale

    if not limits.any:
        return None
    kappa = speed_scale_of(scenario)
    try:
        choice = choose_speed_scale(scenario, limits=limits, horizon=kappa * scenario.horizon)
    except LimitsError as error:
        return str(error)
    found = exceeded(choice, kappa)
    if not found:
        return None
    remedy = (
        f'--speed-scale auto (κ = {choice.value:.4g}: the largest command {OBSERVED_MARGIN:g}× below the limits'
        + (f', settling to {100 * choice.settling.fraction:g} % in {choice.observed.settle_time:.3g} s' if math.isfinite(choice.observed.settle_time) else '')
        + ')'
    )
    message = (
        f'the exact run of {scenario.name} at speed scale κ = {kappa:g} asks for ' + '; '.join(found)
        + f': those commands would be clipped, which the theorems do not cover (connectivity and convergence are '
        f'not guaranteed while clipping lasts). Run slower with {remedy}, or add --allow-saturation to run anyway'
    )
    if allow:
        print(f'formation {command}: warning: {message.replace(", or add --allow-saturation to run anyway", "")} '
              '(--allow-saturation: running anyway; summary.json extra.saturation counts the clipped commands)', file=sys.stderr)  # fmt: skip
        return None
    return message
