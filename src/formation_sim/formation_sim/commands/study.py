"""`formation study SPEC --out DIR`: many cases on Dask; `formation study report DIR`: their figures
and table.

The SPEC (YAML, formation_sim.study.spec) lists the cases; each runs through the exact engine on a
Dask worker (a LocalCluster of processes, or `--scheduler tcp://HOST:PORT`) and its row is
appended to DIR/rows.csv as it finishes. Run again into the same DIR, a study runs only the cases
without a row. docs/STUDY.md has the SPEC's reference and how to start a cluster.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import POSITIVE_INT, refuse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'study',
        help='run a study (many cases, on Dask) or report on one',
        description=(
            '`formation study SPEC --out DIR` runs every case of SPEC (grids and random draws over teams, '
            'gains, algorithm and horizon; docs/STUDY.md) through the exact engine on Dask distributed and '
            'appends one row per case to DIR/rows.csv as it finishes; run again into the same DIR, it runs '
            'only the cases still missing. Every case is validated against its theorem before any runs. '
            '`formation study report DIR` writes figures and a Markdown table from the rows into DIR/report.'
        ),
        epilog=(
            'Exit status: 0 every case has a row and none failed; 1 some cases failed (their rows hold the '
            'error); 2 bad input (a SPEC key, range or a case breaking a hypothesis: nothing was run); 130 '
            'interrupted (the rows written are kept).'
        ),
    )
    parser.add_argument(
        'spec', metavar='SPEC', help="the study's YAML file, or the word report followed by DIR"
    )
    parser.add_argument('folder', metavar='DIR', nargs='?', help='with report: the study folder')
    parser.add_argument(
        '--out',
        type=Path,
        default=None,
        help='the study folder: new, empty, or one this SPEC ran into before',
    )
    parser.add_argument(
        '--scheduler',
        default=None,
        metavar='tcp://HOST:PORT',
        help='run on this Dask scheduler instead of a LocalCluster',
    )
    parser.add_argument(
        '--workers',
        type=POSITIVE_INT,
        default=None,
        help='LocalCluster: worker processes (default: one per core)',
    )
    parser.add_argument('--quiet', action='store_true', help='no progress lines')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.spec == 'report':
        return _report(args)
    if args.folder is not None:
        return refuse(
            'study',
            f'unexpected argument {args.folder!r} (formation study SPEC --out DIR, or formation study '
            'report DIR)',
        )
    if args.out is None:
        return refuse('study', 'argument --out: the study folder is required (rows.csv goes there)')
    if args.scheduler is not None and args.workers is not None:
        return refuse(
            'study', 'argument --workers: only for the LocalCluster; a --scheduler has its own workers'
        )
    from formation_sim.study.errors import StudyError
    from formation_sim.study.runner import run_study
    from formation_sim.study.spec import load_study

    try:
        study = load_study(args.spec)
    except StudyError as error:
        return refuse('study', error)
    say = (lambda _line: None) if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    try:
        summary = run_study(study, out=args.out, scheduler=args.scheduler, workers=args.workers, report=say)
    except StudyError as error:
        return refuse('study', error)
    print(summary.format())
    print(f'rows: {args.out / "rows.csv"}')
    if summary.interrupted:
        return ExitCode.INTERRUPTED
    return ExitCode.OK if summary.complete and not summary.failed else ExitCode.FAILED


def _report(args: argparse.Namespace) -> int:
    from formation_sim.study.errors import StudyError
    from formation_sim.study.report import write_report

    if args.folder is None:
        return refuse('study', 'report: the study folder is required (formation study report DIR)')
    try:
        path = write_report(Path(args.folder), out=args.out)
    except StudyError as error:
        return refuse('study', error)
    print(f'report: {path}')
    return ExitCode.OK
