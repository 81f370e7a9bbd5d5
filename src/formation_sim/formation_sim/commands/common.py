"""Pieces several subcommands share: scenario and output arguments, the ROS domain, a throwaway node.

Not a subcommand itself (`formation_sim.cli.COMMANDS` lists those).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.middleware import DEFAULT_EXECUTOR, DOMAIN_ID_MAX, EXECUTORS, domain_id_ok
from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import Scenario, builtin_scenarios, load_scenario, short_repr
from formation_sim.model.validate import validate_scenario
from formation_sim.sim.errors import RunFolderError
from formation_sim.sim.run_folder import check_report_dir

if TYPE_CHECKING:
    from rclpy.node import Node

    from formation_agent.core.kinds.shape import Geometry


# --------------------------------------------------------------------------- argument values
#
# argparse types: a value that breaks its rule is refused while the command line is parsed, before
# anything starts or anything on disk changes ("argument --fps: must be an integer in [1, 100],
# got 0", exit 2).


def _number(rule: str, holds: Callable[[float], bool], *, integer: bool = False) -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'must be {rule}, got {short_repr(text)}') from None
        if not holds(value):
            raise argparse.ArgumentTypeError(f'must be {rule}, got {short_repr(value)}')
        return value

    parse.__name__ = 'integer' if integer else 'number'
    return parse


POSITIVE = _number('a finite number > 0', lambda v: math.isfinite(v) and v > 0.0)
NON_NEGATIVE = _number('a finite number >= 0', lambda v: math.isfinite(v) and v >= 0.0)
POSITIVE_INT = _number('an integer >= 1', lambda v: v >= 1, integer=True)
NON_NEGATIVE_INT = _number('an integer >= 0', lambda v: v >= 0, integer=True)
FINITE = _number('a finite number', math.isfinite)
DOMAIN_ID = _number(f'an integer in [0, {DOMAIN_ID_MAX}] (a ROS_DOMAIN_ID)', domain_id_ok, integer=True)
UNIT_FRACTION = _number('a number in (0, 1]', lambda v: 0.0 < v <= 1.0)


def POSITIVE_INT_OR_AUTO(text: str) -> int | str:
    """An integer >= 1, or 'auto'."""
    if text == 'auto':
        return text
    try:
        return POSITIVE_INT(text)
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(
            str(error).replace('an integer >= 1', "an integer >= 1 or 'auto'", 1)
        ) from None


def POSITIVE_OR_AUTO(text: str) -> float | str:
    """A finite number > 0, 'auto' or 'warp' (a time warp: `formation_sim.commands.limits`)."""
    if text in ('auto', 'warp'):
        return text
    try:
        return POSITIVE(text)
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(
            str(error).replace('a finite number > 0', "a finite number > 0 or 'auto'", 1)
            + " (or 'warp': a time warp, simulate and validate)"
        ) from None


def bounded_int(low: int, high: int) -> Callable[[str], float]:
    return _number(f'an integer in [{low}, {high}]', lambda v: low <= v <= high, integer=True)


def refuse(command: str, error: Exception | str) -> int:
    """Print why the command refuses its input; the exit code of bad input (2)."""
    print(f'formation {command}: error: {error}', file=sys.stderr)
    return ExitCode.BAD_INPUT


# --------------------------------------------------------------------------- scenarios and outputs


def add_safety_argument(parser: argparse.ArgumentParser) -> None:
    """--min-separation D: the collision layer on, the scenario's other safety keys kept (docs/SAFETY.md)."""
    parser.add_argument(
        '--min-separation',
        type=NON_NEGATIVE,
        default=None,
        metavar='D',
        help='keep every two robots at least D metres apart, composed with connectivity: the safety '
        'layer of docs/SAFETY.md (ETA-1, the plane); 0: the layer off. The simulator keeps the points '
        "the agents control D apart, robot backends the robots' origins (their poses), so their "
        "control points D + c_i + c_j. The scenario's other safety keys are kept, the defaults taken "
        "where it has none. Default: the scenario's safety.min_separation; else on robot backends "
        "(ETA-1, planar) the kind's footprints 2r + 0.05 m apart (docs/ROBOTS.md), elsewhere off",
    )


def with_min_separation(scenario: Scenario, separation: float | None, command: str) -> Scenario | None:
    """The scenario with the safety layer at `separation` (None: as it is), or None after saying why not."""
    if separation is None:
        return scenario
    if separation == 0.0:
        return scenario.replace(safety=None)
    from formation_agent.core.errors import SafetyError
    from formation_agent.core.safety import SafetyConfig

    keys = {} if scenario.safety is None else scenario.safety.as_dict()
    try:
        return scenario.replace(safety=SafetyConfig(**{**keys, 'min_separation': separation}))
    except (ScenarioError, SafetyError) as error:
        refuse(command, f'argument --min-separation: {error}')
        return None


def robot_safety(
    scenario: Scenario, separation: float | None, robots, command: str = 'run'
) -> tuple[Scenario, dict] | None:
    """On a robot backend (`robots`: its RobotOptions): the scenario with the safety layer keeping
    the robots' origins D apart, so their control points D_s = D + c_i + c_j (docs/ROBOTS.md,
    "Footprints"), and what summary.json's extra.safety adds (D, D_s, where D came from); None
    after saying why not.  D: `separation` (0: off), else the scenario's safety.min_separation,
    else, for ETA-1 in the plane, the kind's default (footprints 2r + SEPARATION_MARGIN apart)."""
    from formation_agent.core.kinds import SEPARATION_MARGIN, control_point_separation, robot_kind

    kind = robot_kind(robots.model)
    if separation == 0.0:
        note = {'layer': 'off', 'source': '--min-separation 0'}
        print(f'formation {command}: the safety layer is off (--min-separation 0)', file=sys.stderr)
        return scenario.replace(safety=None), note
    if separation is not None:
        origins, source = separation, '--min-separation'
    elif scenario.safety is not None:
        origins, source = scenario.safety.min_separation, 'scenario safety.min_separation'
    elif scenario.dynamics == 'single' and scenario.dimension == 2:
        footprint = kind.footprint(robots.geometry)
        origins, source = 2.0 * footprint + SEPARATION_MARGIN, f'{kind.name} footprints (r = {footprint:g} m)'
    else:
        print(
            f'formation {command}: the safety layer is off (ETA-1 in the plane only; docs/SAFETY.md)',
            file=sys.stderr,
        )
        return scenario, {'layer': 'off', 'source': f'{scenario.dynamics}, dimension {scenario.dimension}'}
    points = control_point_separation(origins, kind=kind, geometry=robots.geometry)
    if (overlap := footprint_overlap(scenario, kind=kind, geometry=robots.geometry)) is not None:
        refuse(command, overlap)
        return None
    if separation is None and scenario.safety is None:
        safe, problem = default_layer(scenario, points, reach=points - origins)
        if safe is None:
            print(  # the default never refuses a run: it says why the layer stays off
                f"formation {command}: warning: the safety layer is off: the default, the robots' origins "
                f'{origins:g} m apart ({source}, control points {points:g} m), does not apply: {problem}; '
                'give --min-separation D (or 0 to silence this)',
                file=sys.stderr,
            )
            return scenario, {'layer': 'off', 'source': source, 'origin_separation': origins, 'why': problem}
        if problem is not None:  # applies, with the sensing radius or the separation it needs
            print(f'formation {command}: {problem}', file=sys.stderr)
            fitted = points if safe.safety is None else safe.safety.min_separation
            if fitted != points:  # fitted to the formation
                origins, points = fitted - (points - origins), fitted
                source = f'{source}, fitted to the formation'
    elif (safe := with_min_separation(scenario, points, command)) is None:
        print(
            f"formation {command}: (the robots' origins {origins:g} m apart, from {source}, are their "
            f'control points {points:g} m apart: D_s = D + c_i + c_j, docs/ROBOTS.md "Footprints")',
            file=sys.stderr,
        )
        return None
    print(
        f"formation {command}: the safety layer keeps the robots' origins {origins:g} m apart ({source}): "
        f'their control points {points:g} m',
        file=sys.stderr,
    )
    if (inside := inside_the_margin(safe)) is not None:
        print(f'formation {command}: {inside}', file=sys.stderr)
    return safe, {'origin_separation': origins, 'control_point_separation': points, 'source': source}


def _closest_pair(points: np.ndarray) -> tuple[int, int, float]:
    """(row a, row b, distance) of the closest two of `points` (a < b)."""
    best = (0, 1, math.inf)
    for a in range(len(points)):
        gaps = np.linalg.norm(points[a + 1 :] - points[a], axis=1)
        if gaps.size and float(gaps.min()) < best[2]:
            best = (a, a + 1 + int(np.argmin(gaps)), float(gaps.min()))
    return best


def footprint_overlap(scenario: Scenario, *, kind, geometry) -> str | None:
    """Why robots of `kind` set down at the scenario's points (their control points) and headings (0
    without any) would overlap, or None: two origins (their poses) no more than two footprints 2r
    apart is a real error, not a start the safety layer can recover from (docs/SAFETY.md (S9))."""
    if scenario.dimension != 2:
        return None
    yaws = scenario.headings if scenario.headings is not None else np.zeros(len(scenario.agent_ids))
    origins = np.array(
        [kind.origin(point, float(yaw), geometry) for point, yaw in zip(scenario.positions, yaws)]
    )
    a, b, gap = _closest_pair(origins)
    footprint = kind.footprint(geometry)
    if gap > 2.0 * footprint:
        return None
    ids = scenario.agent_ids
    return (
        f'robots overlap: agents {ids[a]} and {ids[b]} are set down with their origins {gap:.6g} m apart, '
        f'not more than two footprints 2r = {2.0 * footprint:g} m ({kind.name}, r = {footprint:g} m; '
        'docs/ROBOTS.md "Footprints"): move them apart'
    )


def inside_the_margin(scenario: Scenario) -> str | None:
    """What the safety layer does first when two of the scenario's points start closer than its D
    (they are moved apart, docs/SAFETY.md (S9)), or None."""
    if scenario.safety is None or scenario.dimension != 2:
        return None
    a, b, gap = _closest_pair(np.asarray(scenario.positions))
    separation = scenario.safety.min_separation
    if gap >= separation:
        return None
    ids = scenario.agent_ids
    return (
        f'agents {ids[a]} and {ids[b]} start {gap:.6g} m apart, inside the separation {separation:g} m: '
        'the safety layer moves every such pair apart first, its distance never decreasing until it '
        'holds, then kept (docs/SAFETY.md, "A start inside the margin")'
    )


@dataclass(frozen=True)
class RobotShape:
    """What `robot_safety` reads of a run's robots (`RobotOptions` has both): their kind and shape."""

    model: str
    geometry: Geometry


def backend_safety(scenario: Scenario, separation: float | None, robots, command: str):
    """(the scenario with the safety layer as `command` runs it, summary.json's extra so far), or None
    after saying why not: on robot backends (`robots`: their RobotOptions) the robots' origins kept
    apart, by default their footprints (`robot_safety`); on the simulator (None) the points the
    agents control, `--min-separation` alone (`formation run`, `formation params`, `formation validate`)."""
    if robots is not None:
        if (safe := robot_safety(scenario, separation, robots, command)) is None:
            return None
        return safe[0], {'safety': safe[1]}
    chosen = with_min_separation(scenario, separation, command)
    return None if chosen is None else (chosen, {})


DEFAULT_HEARTBEAT = 1.0
"""[s]: where the default separation's guard radius reaches the default sensing radius, the default
takes R = ρ* + 2 v̄ · DEFAULT_HEARTBEAT (robots read every other robot's pose: R is how far an agent
looks, not a sensor's range)."""


FORMATION_SHARE = 0.9
"""Where the formation has no room for the default separation, the default keeps the control points
this share of the formation's closest pair apart."""


def default_layer(
    scenario: Scenario, separation: float, *, reach: float
) -> tuple[Scenario | None, str | None]:
    """The robot backends' default layer, control points `separation` (D_s) apart (`reach`: c_i +
    c_j, so origins D_s - reach): (the scenario with it, a note or None), or (None, why it cannot
    apply). Its rules: the formation itself keeps every two agents more than D_s apart, else the
    layer would hold the team off it: there D_s is FORMATION_SHARE of the formation's closest pair
    instead (F1TENTH cars on the 1 m square: 0.9 m, origins 0.24 m apart: less than their
    footprints, said), none if that leaves the origins no room; and the sensing radius exceeds the
    guard radius ρ*: the default R (2 m), raised to ρ* + 2 v̄ · 1 s where ρ* reaches it (cars on a
    formation with room: D_s = 1.69 m, ρ* = 2.26 m, R = 3.26 m)."""
    from formation_agent.core.errors import SafetyError
    from formation_agent.core.safety import (
        DEFAULT_GAMMA,
        DEFAULT_MAX_SPEED,
        DEFAULT_SENSING_RADIUS,
        SafetyConfig,
    )

    shape = formation_shape(scenario)
    a, b, gap = _closest_pair(shape[1])
    notes = []
    if gap <= separation:
        ids, fitted = shape[0], FORMATION_SHARE * gap
        where = (
            f'the formation itself puts agents {ids[a]} and {ids[b]} {gap:.6g} m apart, not more than the '
            f"control points' separation {separation:g} m"
        )
        if not fitted > reach:
            return None, f'{where}, and {FORMATION_SHARE:g} of it leaves their origins no room'
        separation = fitted
        notes.append(
            f'{where}: the layer keeps them {fitted:.4g} m apart instead ({FORMATION_SHARE:g} of it), their '
            f"origins {fitted - reach:.4g} m: less than the robots' footprints (docs/SAFETY.md)"
        )
    v, g = DEFAULT_MAX_SPEED, DEFAULT_GAMMA
    guard = (2.0 * v + math.sqrt(4.0 * v * v + g * g * separation * separation)) / g  # ρ* (SafetyConfig)
    radius = DEFAULT_SENSING_RADIUS
    if not radius > guard:
        radius = guard + 2.0 * v * DEFAULT_HEARTBEAT
        notes.append(
            f'the default sensing radius {DEFAULT_SENSING_RADIUS:g} m is within the guard radius ρ* = '
            f'{guard:.4g} m of these footprints: the agents take R = {radius:.4g} m (ρ* + 2 v̄ · 1 s; they '
            "read every robot's pose)"
        )
    note = '; '.join(notes) or None
    try:
        return scenario.replace(safety=SafetyConfig(min_separation=separation, sensing_radius=radius)), note
    except (ScenarioError, SafetyError) as error:
        return None, str(error)


def formation_shape(scenario: Scenario) -> tuple[tuple[int, ...], np.ndarray]:
    """(agent ids, their target positions): the formation the edges' d_ij define, agent ids[0] at
    the origin, over the agents its graph reaches from it (d_ij = x_i - x_j at the formation)."""
    first = scenario.agent_ids[0]
    places = {first: np.zeros(scenario.dimension)}
    queue = [first]
    while queue:
        i = queue.pop(0)
        for j, d in sorted(scenario.neighbours(i).items()):
            if j not in places:
                places[j] = places[i] - np.asarray(d, dtype=float)
                queue.append(j)
    ids = tuple(sorted(places))
    return ids, np.array([places[a] for a in ids])


def add_scenario_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        'scenario', metavar='SCENARIO', help=f'YAML file or built-in name ({", ".join(builtin_scenarios())})'
    )


def add_run_arguments(parser: argparse.ArgumentParser, *, kind: str) -> None:
    """SCENARIO, --horizon, --out (default: a new folder under runs/) and --force."""
    add_scenario_argument(parser)
    parser.add_argument(
        '--horizon', type=POSITIVE, default=None, help="final time in seconds (default: the scenario's)"
    )
    add_scale_arguments(parser)
    parser.add_argument(
        '--out',
        type=Path,
        default=None,
        help=f'output folder, new or empty (default: a new folder runs/<scenario>-{kind}-<date>-<time>)',
    )
    parser.add_argument(
        '--force',
        action='store_true',
        help=(
            'replace the earlier run in --out: its files are removed first (files no run writes are never '
            'removed)'
        ),
    )


def add_scale_arguments(parser: argparse.ArgumentParser) -> None:
    """--speed-scale K and --threshold-floor C, overriding the scenario's gains (docs/SPEED_SCALE.md)."""
    parser.add_argument(
        '--speed-scale',
        type=POSITIVE_OR_AUTO,
        default=None,
        metavar='K',
        help="speed scale κ > 0: the scenario's run κ times faster (< 1: slower), the same paths, every "
        "triggering time divided by κ; the horizon stays in seconds (default: the scenario's "
        'gains.speed_scale, 1). '
        "auto: the largest κ that keeps the exact run's commands 1.25 times below the robots' limits "
        '(--max-speed, --max-angular-speed, --max-acceleration; README, "Running on robots"). '
        'warp (simulate, validate; ETA-1): a speed that follows the run, κ(t) from the same limits '
        '(docs/SPEED_SCALE.md, "A time warp")',
    )
    parser.add_argument(
        '--threshold-floor',
        type=NON_NEGATIVE,
        default=None,
        metavar='C',
        help="threshold floor c0 >= 0 of c0 + α e^{-κβt}, in the units of the paper's e_i / E_i "
        "(default: the scenario's gains.threshold_floor, 0)",
    )


def scale_options(args: argparse.Namespace) -> dict:
    """The scale overrides of `add_scale_arguments` (None: the scenario's), for `load_valid_scenario`;
    `--speed-scale auto` is left to `formation_sim.commands.limits.resolve_speed_scale` (None here)."""
    speed_scale = getattr(args, 'speed_scale', None)
    return {
        'speed_scale': None if speed_scale in ('auto', 'warp') else speed_scale,
        'threshold_floor': getattr(args, 'threshold_floor', None),
    }


def check_report_argument(command: str, out: Path | None) -> bool:
    """False after printing why, if a report's --out would overwrite a run's files."""
    if out is None:
        return True
    try:
        check_report_dir(out)
    except RunFolderError as error:
        refuse(command, error)
        return False
    return True


def load_valid_scenario(
    name: str, command: str, *, speed_scale: float | None = None, threshold_floor: float | None = None
) -> Scenario | None:
    """The scenario (with κ and c0 replaced where given), or None after printing why it cannot be
    run (nothing is started then)."""
    try:
        scenario = load_scenario(name).with_scale(speed_scale=speed_scale, threshold_floor=threshold_floor)
    except ScenarioError as error:
        refuse(command, error)
        return None
    report = validate_scenario(scenario)
    if not report.ok:
        print(
            f"formation {command}: the scenario breaks the theorems' hypotheses; nothing was run.",
            file=sys.stderr,
        )
        print(report.format(), file=sys.stderr)
        return None
    for warning in report.warnings:
        print(f'warning: {warning.message}', file=sys.stderr)
    if (note := paper_example_note(name, [warning.rule for warning in report.warnings])) is not None:
        print(note, file=sys.stderr)
    return scenario


# Why the paper's own examples (Section 5, built in by these names) raise these warnings: they are
# the paper's choices, and every hypothesis of the theorems still holds.  Per validation rule.
PAPER_EXAMPLE_WARNINGS = {
    'initial': 'edge (2, 3) starts that close to Δ (first inter-event times ~5e-7 s)',
    'remark': "the Remark's bound only limits what an agent can check locally, and β < β0 holds",
    'beta_d_corrected': 'β_d = 1 lies outside the corrected rate condition of Theorem 2 (docs/THEOREM2.md)',
}
PAPER_EXAMPLES = ('paper_single', 'paper_double')


def paper_example_note(name: str, rules: list[str]) -> str | None:
    """One line saying that the warnings of a paper example, run by its built-in name, are expected
    and why; None for any other scenario, or for a warning the paper's example does not raise."""
    if name not in PAPER_EXAMPLES or not rules or not set(rules) <= set(PAPER_EXAMPLE_WARNINGS):
        return None
    reasons = '; '.join(PAPER_EXAMPLE_WARNINGS[rule] for rule in dict.fromkeys(rules))
    return (
        f"note: {'this warning is' if len(rules) == 1 else 'these warnings are'} expected for the paper's "
        f'example (Section 5), whose values these are: {reasons}'
    )


# --------------------------------------------------------------------------- what a run starts


def add_plan_arguments(parser: argparse.ArgumentParser) -> None:
    """What decides a distributed run's processes and their parameters (`formation run`, `formation
    params`)."""
    from formation_sim.runtime.launch.backends import BACKENDS
    from formation_sim.runtime.launch.plan import ROBOT_MODELS

    parser.add_argument(
        '--backend',
        choices=BACKENDS,
        default='exact',
        help=(
            f'the world: exact (the simulator, default), a robot kind ({", ".join(ROBOT_MODELS)}: simulated '
            'robots), external (real robots)'
        ),
    )
    parser.add_argument(
        '--agents-per-process',
        type=POSITIVE_INT_OR_AUTO,
        default=1,
        metavar='K',
        help=(
            'agent nodes sharing one process (default 1: every agent its own process); auto: one each up to '
            '24 agents, beyond that the team in at most 6 processes (for large teams: BENCHMARKS.md)'
        ),
    )
    parser.add_argument('--no-record', action='store_true', help='do not record a bag')
    parser.add_argument(
        '--sample-dt',
        type=NON_NEGATIVE,
        default=0.01,
        help='spacing of the published state samples [s] (default 0.01; 0: samples at events only)',
    )
    parser.add_argument(
        '--real-time',
        action='store_true',
        help='wall-clock mode, as on robots: agents keep their own timers; triggers come late by the '
        'processing delays, which the summary reports (default: lock-step sim time, exact)',
    )
    parser.add_argument(
        '--executor',
        choices=EXECUTORS,
        default=DEFAULT_EXECUTOR,
        help=(
            'rclpy executor of the simulator and agents: events (rclpy.experimental.EventsExecutor, '
            'default, 4-5x faster lock-step here) or single (SingleThreadedExecutor)'
        ),
    )
    add_robot_arguments(parser, model_flag='--robot')


def plan_options(args: argparse.Namespace) -> dict:
    """`FormationRun`'s arguments from `add_run_arguments` and `add_plan_arguments`' (RunError: refused)."""
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.backends import EXTERNAL, backend_kind
    from formation_sim.runtime.launch.plan import ROBOT_MODELS

    kind = backend_kind(args.backend)  # one of argparse's choices
    robots = None
    if kind.on_robots:
        if kind is EXTERNAL and args.robot is None:
            raise RunError(f'--backend external needs --robot {"|".join(ROBOT_MODELS)} (what the robots are)')
        robots = robot_options(args, args.robot or args.backend)
    return {
        'out_dir': args.out,
        'force': args.force,
        'horizon': args.horizon,
        'agents_per_process': args.agents_per_process,
        'record': not args.no_record,
        'sample_period': args.sample_dt,
        'clock': 'realtime' if args.real_time else kind.default_clock,
        'executor': args.executor,
        'backend': args.backend,
        'robots': robots,
    }


# --------------------------------------------------------------------------- robots


def add_robot_arguments(parser: argparse.ArgumentParser, *, model_flag: str) -> None:
    """The options of simulated or external robots (`formation_sim.runtime.launch.plan.RobotOptions`)."""
    from formation_sim.runtime.launch.plan import ROBOT_MODELS, RobotOptions

    defaults = RobotOptions()
    group = parser.add_argument_group(f'robots (backends {", ".join(ROBOT_MODELS)}, external)')
    group.add_argument(
        model_flag,
        choices=ROBOT_MODELS,
        default=None,
        help="what the robots are (default: the backend's model)",
    )
    _add_robot_limits(group, defaults)
    _add_robot_interface(group, defaults)
    _add_simulated_robots(group, defaults)


def _add_robot_limits(group, defaults) -> None:
    """A robot's shape (every declared shape parameter) and limits, each a number > 0:
    (flag, default, metavar, help)."""
    add_shape_arguments(group)
    for flag, default, metavar, text in (
        ('--max-speed', math.inf, 'V', 'speed limit of agents and robots [m/s] (default: none)'),
        ('--max-angular-speed', math.inf, 'W', 'turn-rate limit [rad/s] (default: none)'),
        (
            '--max-steering-angle',
            math.inf,
            'PHI',
            'car: steering limit φ_max [rad], below π/2 (|ω| <= |v| tan φ_max / wheelbase)',
        ),
        ('--max-acceleration', math.inf, 'A', 'ETA-2 agents: acceleration limit [m/s²] (default: none)'),
    ):
        group.add_argument(flag, type=POSITIVE, default=default, metavar=metavar, help=text)


def add_shape_arguments(group, parameters=None) -> None:
    """A flag per shape parameter (`formation_agent.core.kinds.shape`; all declared by default):
    `--name-with-dashes`, checked by its rule, its default (None: each kind's own), its help."""
    from formation_agent.core.kinds.shape import declared

    for parameter in declared() if parameters is None else parameters:
        group.add_argument(
            parameter.flag,
            type=POSITIVE if parameter.positive else NON_NEGATIVE,
            default=parameter.default,
            metavar=parameter.metavar,
            help=shape_help(parameter),
        )


def shape_help(parameter) -> str:
    """'<kinds that take it>: <help> (default ...)' of a shape parameter."""
    from formation_agent.core.kinds import robot_kind
    from formation_agent.core.kinds.shape import owners

    kinds = owners(parameter.name)
    if parameter.default is None:
        default = "the kind's: " + ', '.join(
            f'{name} {getattr(robot_kind(name), parameter.name):g}' for name in kinds
        )
    else:
        default = f'{parameter.default:g}' if parameter.positive else 'none'
    return f'{", ".join(kinds)}: {parameter.help} (default {default})'


def shape_geometry(args: argparse.Namespace, parameters=None):
    """The `Geometry` of the parsed shape flags (those not given: their declared defaults)."""
    from formation_agent.core.kinds.shape import Geometry, declared

    given = {p.name: getattr(args, p.name, None) for p in (declared() if parameters is None else parameters)}
    return Geometry(**{name: value for name, value in given.items() if value is not None})


def _add_robot_interface(group, defaults) -> None:
    """How agents and robots talk: the command rate, the poses the agents read, the world frame."""
    from formation_sim.runtime.launch.plan import POSE_TYPES

    group.add_argument(
        '--command-rate',
        type=POSITIVE,
        default=defaults.command_rate,
        metavar='HZ',
        help=f'how often an agent re-sends its velocity command (default {defaults.command_rate:g})',
    )
    group.add_argument(
        '--pose-type',
        choices=POSE_TYPES,
        default=defaults.pose_type,
        help=f'what the agents read (default {defaults.pose_type})',
    )
    group.add_argument(
        '--pose-timeout',
        type=POSITIVE,
        default=defaults.pose_timeout,
        metavar='S',
        help=f'an agent with no pose this recent stops safely (default {defaults.pose_timeout})',
    )
    group.add_argument(
        '--world-frame',
        default=defaults.world_frame,
        help=f'frame of poses and holonomic commands (default {defaults.world_frame!r})',
    )


def _add_simulated_robots(group, defaults) -> None:
    """What only simulated robots take: noise, latency, seed, rate, heading, packing
    (flag, type, default, metavar, help)."""
    from formation_sim.runtime.launch.plan import ROBOTS_PER_PROCESS

    for flag, kind, default, metavar, text in (
        ('--pose-noise', NON_NEGATIVE, 0.0, 'SIGMA', 'simulated robots: σ of the position noise [m]'),
        ('--yaw-noise', NON_NEGATIVE, 0.0, 'SIGMA', 'simulated robots: σ of the heading noise [rad]'),
        ('--latency', NON_NEGATIVE, 0.0, 'S', 'simulated robots: delay of every pose [s]'),
        ('--command-latency', NON_NEGATIVE, 0.0, 'S', 'simulated robots: delay before a command acts [s]'),
        ('--robot-seed', NON_NEGATIVE_INT, 0, 'N', 'simulated robots: seed of the noise'),
        (
            '--robot-rate',
            POSITIVE,
            defaults.rate,
            'HZ',
            f'simulated robots: ticks per second (default {defaults.rate:g})',
        ),
        (
            '--initial-heading',
            FINITE,
            None,
            'RAD',
            "simulated robots: every robot's heading at t = 0 (default: the scenario's per-agent "
            '`heading`, else 0)',
        ),
        (
            '--robots-per-process',
            POSITIVE_INT,
            ROBOTS_PER_PROCESS,
            'K',
            f'simulated robots sharing one process (default {ROBOTS_PER_PROCESS})',
        ),
    ):
        group.add_argument(flag, type=kind, default=default, metavar=metavar, help=text)


def robot_options(args: argparse.Namespace, model: str):
    """The `RobotOptions` of the parsed robot arguments."""
    from formation_sim.runtime.launch.plan import RobotOptions

    return RobotOptions(
        model=model,
        geometry=shape_geometry(args),
        max_linear_speed=args.max_speed,
        max_angular_speed=args.max_angular_speed,
        max_steering_angle=args.max_steering_angle,
        max_linear_acceleration=args.max_acceleration,
        command_rate=args.command_rate,
        pose_type=args.pose_type,
        pose_timeout=args.pose_timeout,
        world_frame=args.world_frame,
        rate=args.robot_rate,
        yaw=args.initial_heading,
        pose_noise=args.pose_noise,
        yaw_noise=args.yaw_noise,
        latency=args.latency,
        command_latency=args.command_latency,
        seed=args.robot_seed,
        robots_per_process=args.robots_per_process,
    )


# --------------------------------------------------------------------------- ROS


def add_domain_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        '--domain-id',
        type=DOMAIN_ID,
        default=None,
        metavar='N',
        help="ROS_DOMAIN_ID (default: the environment's)",
    )


@contextmanager
def inspection_node(command: str, domain_id: int | None) -> Iterator[Node]:
    """A node `formation_<command>_<pid>` in its own rclpy context, destroyed and shut down on leaving.

    Its own context so that the command never touches a global rclpy state the caller may hold.
    """
    import os

    import rclpy
    from rclpy.node import Node

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = None
    try:
        node = Node(
            f'formation_{command}_{os.getpid()}',
            context=context,
            start_parameter_services=False,
            enable_rosout=False,
        )
        yield node
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
