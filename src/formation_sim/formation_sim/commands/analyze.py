"""`formation analyze RUN_DIR_OR_BAG`: recompute a run's metrics from its bag; report, figures, animation.

Exit codes: 0 every check holds (and the bag agrees with summary.json), 1 a check fails or the
bag differs from summary.json (the report says where), 2 the run cannot be analysed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.commands.common import POSITIVE_INT, bounded_int, check_report_argument
from formation_sim.model.errors import TheoryError


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'analyze',
        help='recompute every metric of a run from its bag; report, figures, animation',
        description='Rebuild a run from its rosbag2 bag alone (triggering times from the TriggerInfo '
        'messages, trajectories from /formation/state, or on robots from their pose topics) and '
        'recompute every metric of summary.json, '
        'check them against Theorems 1/2, and write analysis.md, analysis.json, the figures (the '
        "paper's Fig. 1/2 style, edge lengths, formation error, inter-event times, energy) and an "
        "animation. Differences from the run's summary.json are listed. Exit 0: all checks hold; "
        '1: a check fails or the bag differs from summary.json; 2: cannot analyse.',
    )
    parser.add_argument(
        'run', metavar='RUN_DIR_OR_BAG', type=Path, help='run folder (with bag/), bag folder or .mcap file'
    )
    parser.add_argument(
        '--out', type=Path, default=None, help='output folder (default: RUN_DIR/analysis, or <bag>_analysis)'
    )
    parser.add_argument(
        '--scenario',
        default=None,
        metavar='NAME_OR_YAML',
        help=(
            "the run's scenario, used only if neither the bag (/formation/scenario) nor its run folder "
            '(scenario.yaml) holds it'
        ),
    )
    parser.add_argument(
        '--markers',
        action='store_true',
        help=(
            'also write OUT/bag_markers: a copy of the bag with /formation/markers (MarkerArray) for Foxglove'
        ),
    )
    parser.add_argument('--no-figures', action='store_true', help='report only')
    parser.add_argument('--no-animation', action='store_true', help='skip the GIF (the slowest part)')
    parser.add_argument('--frames', type=POSITIVE_INT, default=150, help='animation frames (default 150)')
    parser.add_argument(
        '--fps', type=bounded_int(1, 100), default=15, help='animation frames per second, 1-100 (default 15)'
    )
    parser.add_argument('--quiet', action='store_true', help='no progress; print only the report path')
    parser.set_defaults(func=run)


def default_out_dir(location) -> Path:
    if location.run_dir is not None:
        return location.run_dir / 'analysis'
    return location.bag.parent / f'{location.bag.name}_analysis'


def _refuse_unstarted(summary: Path | None) -> None:
    """A run that never reached Step 0 (discovery failed, or the robots' measured start broke the
    initial condition): no trajectory to check; its summary.json says why."""
    from formation_sim.analysis.errors import AnalysisError
    from formation_sim.sim.summary import RunSummary

    if summary is None:
        return
    try:
        extra = RunSummary.read(summary).extra
    except (OSError, ValueError):
        return  # the bag is what is analysed: a damaged summary is reported as a difference
    if isinstance(extra, dict) and extra.get('started') is False:
        failure = extra.get('failure') or {}
        raise AnalysisError(
            f'{summary.parent}: the run did not start (no Step 0; extra.failure {failure.get("kind")}: '
            f'{failure.get("message")}): there is no run to analyse'
        )


def run(args: argparse.Namespace) -> int:
    from formation_sim.analysis.checks import run_series, theory_bounds
    from formation_sim.analysis.errors import AnalysisError
    from formation_sim.analysis.report import build_report
    from formation_sim.progress import Progress

    show = not args.quiet
    if not check_report_argument('analyze', args.out):
        return ExitCode.BAD_INPUT
    try:
        location, bag_run = _load(args, show=show)
    except AnalysisError as error:
        print(f'formation analyze: error: {error}', file=sys.stderr)
        return ExitCode.BAD_INPUT
    record = bag_run.record
    out = args.out or default_out_dir(location)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        print(f'formation analyze: error: cannot create {out}: {error.strerror or error}', file=sys.stderr)
        return ExitCode.BAD_INPUT
    evaluating = Progress('evaluating ν and V', enabled=show)
    series = run_series(record, progress=evaluating)
    evaluating.close()
    try:
        bounds, bounds_error = theory_bounds(record.scenario), None
    except TheoryError as error:
        bounds, bounds_error = None, str(error)
    written = {} if args.no_figures else _write_figures(args, record, series, bounds, out, show=show)
    if args.markers:
        marked = _write_markers(location.bag, out, record.scenario, show=show)
        if marked is None:
            return ExitCode.BAD_INPUT
        written.update(marked)
    report = build_report(
        bag_run,
        series=series,
        bounds=bounds,
        bounds_error=bounds_error,
        summary_path=location.summary,
        figures=written,
    )
    return _conclude(args, record, report, out=out, written=written)


def _load(args: argparse.Namespace, *, show: bool):
    """The run's location and its run rebuilt from the bag; AnalysisError when there is none."""
    from formation_sim.analysis.errors import AnalysisError
    from formation_sim.analysis.load import load_bag_run, locate
    from formation_sim.progress import Progress

    location = locate(args.run)
    _refuse_unstarted(location.summary)
    if location.bag is None:
        raise AnalysisError(
            f'{args.run}: no bag found (a run folder needs bag/; `formation run` records one, '
            '`formation simulate` does not)'
        )
    reading = Progress(f'reading {location.bag}', enabled=show)
    bag_run = load_bag_run(location.bag, run_dir=location.run_dir, scenario=args.scenario, progress=reading)
    reading.close()
    return location, bag_run


def _write_figures(
    args: argparse.Namespace, record, series, bounds, out: Path, *, show: bool
) -> dict[str, str]:
    """The figures and (unless --no-animation) the animation in `out`: title -> file name."""
    from formation_sim.analysis import figures
    from formation_sim.progress import Progress

    written: dict[str, str] = {}
    written.update(figures.write_figures(record, series, bounds, out))
    if not args.no_animation:
        frames = Progress('animation frames', enabled=show)
        figures.animate(record, out / 'animation.gif', frames=args.frames, fps=args.fps, progress=frames)
        frames.close()
        written['animation'] = 'animation.gif'
    return written


def _write_markers(bag: Path, out: Path, scenario, *, show: bool) -> dict[str, str] | None:
    """OUT/bag_markers, a copy of the bag with /formation/markers: its entry for the report, or
    None (the error printed) when it cannot be written."""
    from formation_sim.analysis.errors import MarkerError
    from formation_sim.analysis.markers import write_bag_with_markers
    from formation_sim.bag.errors import BagError
    from formation_sim.progress import Progress

    target = out / 'bag_markers'
    copying = Progress(f'writing {target}', enabled=show)
    try:
        marked = write_bag_with_markers(bag, target, scenario, progress=copying)
    except (BagError, MarkerError) as error:
        print(f'formation analyze: error: {error}', file=sys.stderr)
        return None
    copying.close()
    if marked.skipped_topics:
        print(
            f'warning: topics of unknown type left out of {target}: {list(marked.skipped_topics)}',
            file=sys.stderr,
        )
    return {'bag with /formation/markers': target.name}


def _conclude(args: argparse.Namespace, record, report: dict, *, out: Path, written: dict[str, str]) -> int:
    """Write analysis.md and analysis.json, say what was found; the exit code."""
    from formation_sim.analysis.report import write_report

    markdown, data = write_report(report, out)
    checks = report['bag_checks'] + report['theorem_checks']
    failed = [check['name'] for check in checks if not check['ok'] and check['binding']]
    unmet = [check['name'] for check in checks if not check['ok'] and not check['binding']]
    differs = report['summary_json'] is not None and not report['summary_json']['equal']
    if args.quiet:
        print(markdown)
    else:
        _print_findings(
            record,
            report,
            failed=failed,
            unmet=unmet,
            differs=differs,
            markdown=markdown,
            data=data,
            out=out,
            written=written,
        )
    return ExitCode.FAILED if failed or differs else ExitCode.OK


def _print_findings(
    record,
    report: dict,
    *,
    failed: list[str],
    unmet: list[str],
    differs: bool,
    markdown,
    data,
    out,
    written: dict[str, str],
) -> None:
    """What `formation analyze` found, on stderr, and the files it wrote, on stdout."""
    from formation_sim.analysis.report import describe_stop

    summary = report['summary']
    print(
        f'{record.scenario.name}: {summary["total_events"]} events, {summary["messages_sent"]} messages, '
        f'max edge length {summary["max_edge_length"]:.6g} (Δ = {record.scenario.delta:g}), '
        f'final formation error {summary["final_formation_error"]:.3g}',
        file=sys.stderr,
    )
    if report['run']['stopped']:
        print(f'the run stopped early {describe_stop(report["run"]["stopped"])}', file=sys.stderr)
    if report['summary_json'] is not None:
        state = (
            'equals the bag'
            if not differs
            else f'DIFFERS from the bag in {len(report["summary_json"]["differences"])} values'
        )
        print(f'summary.json {state}', file=sys.stderr)
    for name in failed:
        print(f'check failed: {name}', file=sys.stderr)
    for name in unmet:
        print(f'not guaranteed here and not met: {name}', file=sys.stderr)
    saturation = record.extra.get('saturation')
    if saturation and saturation.get('total'):
        kinds = ', '.join(f'{kind} {entry["count"]}' for kind, entry in saturation['by_kind'].items())
        print(
            f'saturated commands: {saturation["total"]} ({kinds}); the theorems assume none', file=sys.stderr
        )
    print(f'report:  {markdown}')
    print(f'json:    {data}')
    for title, name in written.items():
        print(f'{title}: {out / name}')
