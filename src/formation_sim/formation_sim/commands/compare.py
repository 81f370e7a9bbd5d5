"""`formation compare RUN_A RUN_B`: events, messages, trajectories and triggering times of two runs.

Exit codes: 0 compared (with --tolerance: and the runs agree within it), 1 they do not agree
within --tolerance, 2 a run cannot be read or the runs are of different agents.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import NON_NEGATIVE, check_report_argument, refuse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'compare',
        help='compare two runs: events, messages, trajectories, triggering times',
        description='Compare two runs of a scenario (run folders, bags or summary.json files), e.g. '
        'distributed against in-process, or event-triggered against `formation simulate --period`. '
        'Triggering times are matched per agent index by index (count mismatches are listed); '
        'trajectories are interpolated on the common times. Writes compare.md, compare.json and '
        'overlay figures.',
    )
    parser.add_argument('run_a', metavar='RUN_A', type=Path, help='run folder, bag or summary.json')
    parser.add_argument('run_b', metavar='RUN_B', type=Path, help='run folder, bag or summary.json')
    parser.add_argument(
        '--out', type=Path, default=None, help='output folder (default: RUN_A/compare-<name of RUN_B>)'
    )
    parser.add_argument(
        '--scenario',
        default=None,
        metavar='NAME_OR_YAML',
        help='scenario for bags that do not hold it (see formation analyze)',
    )
    parser.add_argument('--label-a', default=None, help='name of run A in the report (default: its mode)')
    parser.add_argument('--label-b', default=None, help='name of run B in the report (default: its mode)')
    parser.add_argument(
        '--tolerance',
        type=NON_NEGATIVE,
        default=None,
        metavar='T',
        help='exit 1 unless event counts are equal and every deviation is <= T',
    )
    parser.add_argument('--no-figures', action='store_true', help='report only')
    parser.add_argument('--quiet', action='store_true', help='no progress; print only the report path')
    parser.set_defaults(func=run)


def _default_out(a: Path, b: Path) -> Path:
    """RUN_A's run folder (never inside a bag), named after RUN_B's folder."""
    from formation_sim.analysis.load import locate

    location = locate(a)
    base = location.run_dir or (location.bag.parent if location.bag is not None else location.summary.parent)
    other = locate(b)
    name = (other.run_dir or (other.bag if other.bag is not None else other.summary.parent)).resolve().name
    return base / f'compare-{name}'


def run(args: argparse.Namespace) -> int:
    from formation_sim.analysis.compare import (
        compare_runs,
        load_run,
        overlay_figures,
        within,
        write_comparison,
    )
    from formation_sim.analysis.errors import CompareError
    from formation_sim.progress import Progress

    if not check_report_argument('compare', args.out):
        return ExitCode.BAD_INPUT
    show = not args.quiet
    try:
        runs = []
        for path, label in ((args.run_a, args.label_a), (args.run_b, args.label_b)):
            progress = Progress(f'reading {path}', enabled=show)
            loaded = load_run(path, label=label or '', scenario=args.scenario, progress=progress)
            progress.close()
            loaded.label = label or loaded.mode
            runs.append(loaded)
        a, b = runs
        if a.label == b.label:
            a.label, b.label = f'{a.label} (A)', f'{b.label} (B)'
        report = compare_runs(a, b)
    except CompareError as error:
        return refuse('compare', error)
    out = args.out or _default_out(args.run_a, args.run_b)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        return refuse('compare', f'cannot create {out}: {error.strerror or error}')
    figures = None if args.no_figures else overlay_figures(a, b, out)
    markdown, data = write_comparison(report, out, figures)
    agree = args.tolerance is None or within(report, args.tolerance)
    if args.quiet:
        print(markdown)
    else:
        deviation = report['max_trigger_deviation']
        trajectory = report['trajectory']
        print(
            f'events A {a.total_events} / B {b.total_events}; messages A {a.messages_sent} / B '
            f'{b.messages_sent}; max triggering-time deviation '
            f'{deviation if deviation is not None else "—"}; max trajectory deviation '
            f'{trajectory["max_deviation"] if trajectory else "—"}',
            file=sys.stderr,
        )
        for line in report['count_mismatches']:
            print(f'event count mismatch: {line}', file=sys.stderr)
        print(f'report: {markdown}')
        print(f'json:   {data}')
        for title, (name, _) in (figures or {}).items():
            print(f'{title}: {out / name}')
    if not agree:
        print(f'formation compare: the runs differ by more than {args.tolerance}', file=sys.stderr)
        return ExitCode.FAILED
    return ExitCode.OK
