"""The `formation` command: one subcommand per module in `formation_sim.commands`.

Each module `formation_sim/commands/<name>.py` exposes `register(subparsers)`, which adds its
parser and sets `func(args) -> int` (the exit code) as the parser's default.  Exit codes are the
same for every command (`formation_msgs_py.exit_codes.ExitCode`, docs/EXIT_CODES.md): 0 done, 1
the command ran and the answer is no, 2 bad input (refused before anything started or changed).
"""

from __future__ import annotations

import argparse
import importlib
import platform
import sys
from importlib import metadata

from formation_msgs_py import exit_codes

# One entry per subcommand module, in help order.
COMMANDS: tuple[str, ...] = (
    'validate',
    'generate',
    'simulate',
    'study',
    'measure',
    'run',
    'params',
    'robots',
    'recover',
    'analyze',
    'compare',
    'replay',
    'topics',
    'echo',
    'stop',
)


# Subcommands whose parser is built alone when one is named first: an emergency stop must not
# wait for the other subcommands' imports (scipy: 2-4 s on a loaded 2-core machine).
ALONE: tuple[str, ...] = ('stop',)

PACKAGES = ('formation_sim', 'formation_agent', 'formation_msgs_py')

# The exit statuses, written from the one enum (docs/EXIT_CODES.md and the README say the same).
EPILOG = f'Exit status of every command: {exit_codes.SENTENCE}'


def version_text() -> str:
    """'formation 0.1.0 (formation_sim 0.1.0, ...; Python 3.11.7)': what `formation --version` prints."""
    versions = []
    for package in PACKAGES:
        try:
            versions.append(f'{package} {metadata.version(package)}')
        except metadata.PackageNotFoundError:  # run from a source tree without installing
            versions.append(f'{package} (not installed)')
    return (
        f'formation {versions[0].split(" ", 1)[1]} ({", ".join(versions)}; Python '
        f'{platform.python_version()})'
    )


class _Version(argparse.Action):
    """--version: print `version_text()` unwrapped (argparse's own action rewraps it) and exit 0."""

    def __init__(self, option_strings, dest, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(version_text())
        parser.exit()


def build_parser(*, only: str | None = None) -> argparse.ArgumentParser:
    """The `formation` parser; `only`: with that subcommand alone (one of ALONE)."""
    parser = argparse.ArgumentParser(
        prog='formation',
        description='Event-triggered formation control with connectivity preservation '
        '(Yi, Wei, Dimarogonas, Johansson 2017).',
        epilog=EPILOG,
    )
    parser.add_argument('--version', action=_Version, help="print the packages' versions and exit")
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name in (only,) if only in ALONE else COMMANDS:
        importlib.import_module(f'formation_sim.commands.{name}').register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(only=argv[0] if argv else None)
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # argparse: 2 after a bad argument (it printed why), 0 after --help
        return done.code if isinstance(done.code, int) else 0 if done.code is None else 2
    if getattr(args, 'func', None) is None:
        parser.print_help(sys.stderr)
        return 2
    return int(args.func(args))


if __name__ == '__main__':
    sys.exit(main())
