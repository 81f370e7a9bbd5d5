"""Pieces several subcommands share: scenario and output arguments, the ROS domain, a throwaway node.

Not a subcommand itself (`formation_sim.cli.COMMANDS` lists those).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from formation_sim.model.scenario import Scenario, ScenarioError, builtin_scenarios, load_scenario
from formation_sim.model.validate import validate_scenario

if TYPE_CHECKING:
    from rclpy.node import Node


# --------------------------------------------------------------------------- scenarios and outputs


def add_scenario_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('scenario', metavar='SCENARIO', help=f'YAML file or built-in name ({", ".join(builtin_scenarios())})')


def add_run_arguments(parser: argparse.ArgumentParser, *, kind: str) -> None:
    """SCENARIO, --horizon and --out, whose default `default_out_dir` makes."""
    add_scenario_argument(parser)
    parser.add_argument('--horizon', type=float, default=None, help="final time in seconds (default: the scenario's)")
    parser.add_argument('--out', type=Path, default=None, help=f'output folder (default: runs/<scenario>-{kind}-<time>)')


def default_out_dir(scenario_name: str, kind: str) -> Path:
    return Path('runs') / f'{scenario_name}-{kind}-{time.strftime("%Y%m%d-%H%M%S")}'


def load_valid_scenario(name: str, command: str) -> Scenario | None:
    """The scenario, or None after printing why it cannot be run (nothing is started then)."""
    try:
        scenario = load_scenario(name)
    except ScenarioError as error:
        print(f'formation {command}: error: {error}', file=sys.stderr)
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
    parser.add_argument('--domain-id', type=int, default=None, metavar='N', help="ROS_DOMAIN_ID (default: the environment's)")


def check_domain(command: str, domain_id: int | None) -> bool:
    """False after printing why, if `domain_id` is not a valid ROS_DOMAIN_ID."""
    if domain_id is not None and not 0 <= domain_id <= 232:
        print(f'formation {command}: error: --domain-id must lie in [0, 232], got {domain_id}', file=sys.stderr)
        return False
    return True


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
