"""`formation validate SCENARIO [--json]`: check a scenario against the theorems' hypotheses.

Exit codes: 0 valid (warnings allowed), 1 a hypothesis is broken, 2 the scenario cannot be read.
"""

from __future__ import annotations

import argparse
import json
import sys

from formation_sim.commands.common import EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK, add_scenario_argument
from formation_sim.model.scenario import ScenarioError, load_scenario
from formation_sim.model.validate import validate_scenario

EXIT_VALID = EXIT_OK
EXIT_INVALID = EXIT_FAILED
EXIT_UNREADABLE = EXIT_BAD_INPUT


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'validate',
        help='check a scenario against the hypotheses of Theorems 1 and 2',
        description='Check a scenario against the hypotheses of Theorem 1 (single integrators) or '
        'Theorem 2 (double integrators) and print every number involved. Exit 0 if valid '
        '(warnings allowed), 1 if a hypothesis is broken, 2 if the scenario cannot be read.',
    )
    add_scenario_argument(parser)
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as error:
        print(f'formation validate: error: {error}', file=sys.stderr)
        return EXIT_UNREADABLE
    report = validate_scenario(scenario)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2, ensure_ascii=False, allow_nan=False))
    else:
        print(report.format())
    return EXIT_VALID if report.ok else EXIT_INVALID
