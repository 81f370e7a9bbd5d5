"""Pieces several subcommands share: scenario and output arguments, the ROS domain, a throwaway node.

Not a subcommand itself (`formation_sim.cli.COMMANDS` lists those).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from formation_sim.model.scenario import Scenario, ScenarioError, builtin_scenarios, load_scenario, short_repr
from formation_sim.model.validate import validate_scenario
from formation_sim.sim.run_folder import RunFolderError, check_report_dir

if TYPE_CHECKING:
    from rclpy.node import Node


# Exit codes of every command (README, "Exit codes").
EXIT_OK = 0
EXIT_FAILED = 1  # the command ran and the answer is no (a run failed, a check does not hold)
EXIT_BAD_INPUT = 2  # bad arguments or unreadable input: refused, nothing started, nothing changed


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
DOMAIN_ID = _number('an integer in [0, 232] (a ROS_DOMAIN_ID)', lambda v: 0 <= v <= 232, integer=True)


def bounded_int(low: int, high: int) -> Callable[[str], float]:
    return _number(f'an integer in [{low}, {high}]', lambda v: low <= v <= high, integer=True)


def refuse(command: str, error: Exception | str) -> int:
    """Print why the command refuses its input; the exit code of bad input (2)."""
    print(f'formation {command}: error: {error}', file=sys.stderr)
    return EXIT_BAD_INPUT


# --------------------------------------------------------------------------- scenarios and outputs


def add_scenario_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('scenario', metavar='SCENARIO', help=f'YAML file or built-in name ({", ".join(builtin_scenarios())})')


def add_run_arguments(parser: argparse.ArgumentParser, *, kind: str) -> None:
    """SCENARIO, --horizon, --out (default: a new folder under runs/) and --force."""
    add_scenario_argument(parser)
    parser.add_argument('--horizon', type=POSITIVE, default=None, help="final time in seconds (default: the scenario's)")
    parser.add_argument(
        '--out',
        type=Path,
        default=None,
        help=f'output folder, new or empty (default: a new folder runs/<scenario>-{kind}-<date>-<time>)',
    )
    parser.add_argument(
        '--force',
        action='store_true',
        help='replace the earlier run in --out: its files are removed first (files no run writes are never removed)',
    )


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


def load_valid_scenario(name: str, command: str) -> Scenario | None:
    """The scenario, or None after printing why it cannot be run (nothing is started then)."""
    try:
        scenario = load_scenario(name)
    except ScenarioError as error:
        refuse(command, error)
        return None
    report = validate_scenario(scenario)
    if not report.ok:
        print(f'formation {command}: the scenario breaks the theorems\' hypotheses; nothing was run.', file=sys.stderr)
        print(report.format(), file=sys.stderr)
        return None
    for warning in report.warnings:
        print(f'warning: {warning.message}', file=sys.stderr)
    return scenario


# --------------------------------------------------------------------------- ROS


def add_domain_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--domain-id', type=DOMAIN_ID, default=None, metavar='N', help="ROS_DOMAIN_ID (default: the environment's)")


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
        node = Node(f'formation_{command}_{os.getpid()}', context=context, start_parameter_services=False, enable_rosout=False)
        yield node
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
