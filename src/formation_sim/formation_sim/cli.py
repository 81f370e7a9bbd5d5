"""The `formation` command: one subcommand per module in `formation_sim.commands`.

Each module `formation_sim/commands/<name>.py` exposes `register(subparsers)`, which adds its
parser and sets `func(args) -> int` (the exit code) as the parser's default.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# One entry per subcommand module, in help order.
COMMANDS: tuple[str, ...] = ('validate', 'simulate', 'run', 'recover', 'analyze', 'compare', 'replay', 'topics', 'echo')


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='formation',
        description='Event-triggered formation control with connectivity preservation '
        '(Yi, Wei, Dimarogonas, Johansson 2017).',
    )
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name in COMMANDS:
        importlib.import_module(f'formation_sim.commands.{name}').register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, 'func', None) is None:
        parser.print_help(sys.stderr)
        return 2
    return int(args.func(args))


if __name__ == '__main__':
    sys.exit(main())
