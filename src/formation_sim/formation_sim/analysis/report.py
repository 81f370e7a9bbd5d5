"""The analysis report of a run: its metrics, its checks, and where the bag differs from summary.json.

`diff_summaries` lists every key where the summary recomputed from a bag (`bag_summary`) differs
from the run's own summary.json; `build_report` gathers everything, `render_markdown` and
`write_report` write `analysis.md` and `analysis.json`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from formation_msgs_py.topics import STEP_TOPIC
from formation_sim.analysis.checks import (
    Series,
    TheoryBounds,
    inter_event_stats,
    printed_chain_ratios,
    theorem_checks,
)
from formation_sim.analysis.load import BagRun
from formation_sim.sim.record import RunRecord
from formation_sim.sim.summary import build_summary

# summary.json keys a bag cannot give back: wall-clock measurements of the live run. Besides
# these, `extra` holds implementation-specific details (summary.py); those of its keys the bag
# does not give (e.g. the simulator's own rejection counts) are listed as not recomputed.
NOT_IN_BAG = ('wall_time',)


@dataclass(frozen=True, kw_only=True)
class Difference:
    key: str  # dotted path, list elements as [k]
    bag: Any
    summary: Any

    def to_dict(self) -> dict[str, Any]:
        return {'key': self.key, 'bag': self.bag, 'summary': self.summary}


_MISSING = object()


def diff_summaries(from_bag: dict, from_file: dict) -> tuple[list[Difference], list[str]]:
    """Every leaf where the bag's summary differs from summary.json (floats compared exactly).

    Returns (differences, keys of summary.json a bag cannot reproduce, see NOT_IN_BAG).
    """
    for name, value in (('from_bag', from_bag), ('from_file', from_file)):
        if not isinstance(value, dict):
            raise TypeError(
                f'diff_summaries takes two summary dicts, bag_summary(record) and load_summary(path); '
                f'{name} is {type(value).__name__}'
            )
    differences: list[Difference] = []
    skipped: list[str] = []

    def walk(a: Any, b: Any, key: str) -> None:
        if (key in NOT_IN_BAG and (a is _MISSING or a is None)) or (
            key.startswith('extra.') and a is _MISSING
        ):
            skipped.append(key)
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for name in list(a) + [name for name in b if name not in a]:
                walk(a.get(name, _MISSING), b.get(name, _MISSING), f'{key}.{name}' if key else str(name))
            return
        if isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                differences.append(Difference(key=f'{key} (length)', bag=len(a), summary=len(b)))
            for k, (x, y) in enumerate(zip(a, b)):
                walk(x, y, f'{key}[{k}]')
            return
        if a is _MISSING or b is _MISSING or not _same(a, b):
            differences.append(
                Difference(key=key, bag=None if a is _MISSING else a, summary=None if b is _MISSING else b)
            )

    walk(from_bag, from_file, '')
    return differences, skipped


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):  # True == 1 in Python, not in a summary
        return type(a) is type(b) and a == b
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def bag_summary(record: RunRecord, *, horizon: float | None = None) -> dict:
    """summary.json's schema computed from the rebuilt record (wall_time: not in a bag, null).

    `horizon`: the horizon the run was asked for, which summary.json states also for a run that
    stopped early (the record itself ends where the bag does).
    """
    summary = build_summary(record)
    summary['wall_time'] = None
    if horizon is not None:
        summary['horizon'] = horizon
    return summary


def json_safe(value: Any) -> Any:
    """Replace non-finite floats by their names (JSON has none) and tuples/arrays by lists."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        return json_safe(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    return value


def build_report(
    run: BagRun,
    *,
    series: Series,
    bounds: TheoryBounds | None,
    bounds_error: str | None = None,
    summary_path: Path | None = None,
    figures: dict[str, str] | None = None,
) -> dict[str, Any]:
    """The analysis as a JSON-ready dictionary (`render_markdown` prints it)."""
    record = run.record
    scenario = record.scenario
    summary = bag_summary(record, horizon=run.horizon)
    stop = None if run.stop is None else {**run.stop, 'reason': None}
    comparison = None if summary_path is None else _summary_comparison(record, summary, summary_path, stop)
    return json_safe(
        {
            'schema': 'formation-analysis/1',
            'bag': str(run.bag),
            'scenario_source': run.scenario_source,
            'run': {
                'scenario': scenario.name,
                'dynamics': scenario.dynamics,
                'mode': record.mode,
                'clock': record.extra.get('clock'),
                'horizon': record.horizon,
                'n_agents': scenario.n,
                'dimension': scenario.dimension,
                'delta': scenario.delta,
                'stopped': stop,
            },
            'topics': {
                name: {'type': run.topics[name], 'messages': run.counts[name]} for name in sorted(run.topics)
            },
            'bag_checks': [check.to_dict() for check in run.checks],
            'theorem_checks': [check.to_dict() for check in theorem_checks(record, series, bounds)],
            'theory': None if bounds is None else _theory_section(series, bounds),
            'theory_error': bounds_error,
            'inter_event_times': inter_event_stats(record, None if bounds is None else bounds.xi),
            'series': _series_section(series),
            'summary': summary,
            'summary_json': comparison,
            'figures': figures or {},
        }
    )


def _summary_comparison(
    record: RunRecord, summary: dict, summary_path: Path, stop: dict[str, Any] | None
) -> dict[str, Any]:
    """The bag's summary against the run's summary.json; a run that stopped early takes its reason
    from the file's extra.failure (into `stop`). The file is read as it is, not as a `RunSummary`:
    a damaged or foreign one is reported as differences, not refused."""
    file_summary = json.loads(Path(summary_path).read_text(encoding='utf-8'))
    failure = (file_summary.get('extra') or {}).get('failure')
    if stop is not None and isinstance(failure, dict):
        stop['reason'] = f'{failure.get("kind")}: {failure.get("message")}'
    differences, skipped = diff_summaries(summary, file_summary)
    return {
        'path': str(summary_path),
        'equal': not differences,
        'differences': [difference.to_dict() for difference in differences],
        'not_in_bag': skipped,
        'notes': _difference_notes(record) if differences else [],
    }


def _theory_section(series: Series, bounds: TheoryBounds) -> dict[str, Any]:
    """The theorem's constants and bounds, and the printed chain's ratios when it has one."""
    return {
        'theorem': bounds.theorem,
        'note': bounds.note,
        'rate': bounds.rate,
        'speed_scale': bounds.speed_scale,
        'threshold_floor': None if bounds.floor is None else bounds.floor.to_dict(),
        'k_nu': bounds.k_nu,
        'k_V': bounds.k_V,
        'error_gain': bounds.error_gain,
        'xi': bounds.xi,
        'printed_chain': None
        if bounds.printed_k_V is None
        else {
            'k_V': bounds.printed_k_V,
            'error_gain': bounds.printed_error_gain,
            **printed_chain_ratios(series, bounds),
        },
    }


def _series_section(series: Series) -> dict[str, Any]:
    """The formation error, tension and Lyapunov function at the ends of the run (the tension's
    largest too)."""
    return {
        'samples': len(series.times),
        'formation_error': {
            'initial': float(series.formation_error[0]),
            'final': float(series.formation_error[-1]),
        },
        'tension': {
            'initial': float(series.tension[0]),
            'max': float(series.tension.max()),
            'final': float(series.tension[-1]),
        },
        'lyapunov': {'initial': float(series.lyapunov[0]), 'final': float(series.lyapunov[-1])},
    }


def _difference_notes(record: RunRecord) -> list[str]:
    """Known reasons for a bag to differ from its summary.json."""
    notes = []
    if record.extra.get('clock') == 'realtime':
        at_end = [
            agent for agent, times in record.trigger_times.items() if times and times[-1] >= record.horizon
        ]
        if at_end:
            notes.append(
                f'agents {at_end} triggered at the horizon t = {record.horizon!r} (wall clock): '
                'summary.json counts a trigger only once its command has acted on the world before the '
                'run ended, which a bag cannot show'
            )
    return notes


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.6g}'
    if value is None:
        return '—'
    return str(value)


def render_markdown(report: dict[str, Any]) -> str:
    run = report['run']
    summary = report['summary']
    lines = [
        f'# Analysis of `{report["bag"]}`',
        '',
        f'Scenario **{run["scenario"]}** ({run["dynamics"]} integrators, n = {run["n_agents"]}, '
        f'p = {run["dimension"]}, Δ = {_fmt(run["delta"])}), {run["mode"]} run, '
        f'clock {run["clock"] or "—"}, horizon {_fmt(run["horizon"])} s. '
        f'Scenario from: {report["scenario_source"]}. Every number below is recomputed from the bag.',
        '',
        *([f'**The run stopped early**: {describe_stop(run["stopped"])}.', ''] if run.get('stopped') else []),
        '## Events and messages',
        '',
        '| agent | events | min inter-event [s] | median | max | ξ_i (proof bound) |',
        '|---|---|---|---|---|---|',
    ]
    for agent, stats in report['inter_event_times'].items():
        lines.append(
            f'| {agent} | {stats["events"]} | {_fmt(stats["min"])} | {_fmt(stats["median"])} | '
            f'{_fmt(stats["max"])} | {_fmt(stats["xi"])} |'
        )
    lines += [
        '',
        f'Total events {summary["total_events"]}, triggering-information messages '
        f'{summary["messages_sent"]}, '
        f'sensing calls {summary["sensing_calls"]}.',
        '',
        '| edge | max length | Δ − max length | final error ‖x_i − x_j − d_ij‖ |',
        '|---|---|---|---|',
    ]
    for edge in summary['edges']:
        lines.append(
            f'| {edge["i"]}-{edge["j"]} | {_fmt(edge["max_length"])} | {_fmt(edge["min_range_slack"])} '
            f'| {_fmt(edge["final_error"])} |'
        )
    series = report['series']
    lines += [
        '',
        f'Formation error: {_fmt(series["formation_error"]["initial"])} at t = 0, '
        f'{_fmt(series["formation_error"]["final"])} at the horizon. '
        f'Tension: {_fmt(series["tension"]["initial"])} → max {_fmt(series["tension"]["max"])} → '
        f'{_fmt(series["tension"]["final"])}. '
        f'Lyapunov: {_fmt(series["lyapunov"]["initial"])} → {_fmt(series["lyapunov"]["final"])} '
        f'({series["samples"]} samples).',
        '',
        '## Theorem checks (at every sample)',
        '',
    ]
    lines += _theory_lines(report)
    lines += _check_table(report['theorem_checks'])
    lines += ['', '## Bag consistency', '']
    lines += _check_table(report['bag_checks'])
    lines += ['', '| topic | type | messages |', '|---|---|---|']
    for name, info in report['topics'].items():
        lines.append(f'| `{name}` | {info["type"]} | {info["messages"]} |')
    lines += ['', '## The bag against summary.json', '']
    lines += _summary_json_lines(report['summary_json'])
    if report['figures']:
        lines += ['', '## Figures', '']
        for title, name in report['figures'].items():
            if name.endswith(('.gif', '.png')):
                lines.append(f'![{title}]({name})')
            else:
                lines.append(f'- {title}: `{name}`')
    return '\n'.join(lines) + '\n'


def _theory_lines(report: dict[str, Any]) -> list[str]:
    """The proof constants of the theorem checks (or why there are none)."""
    lines: list[str] = []
    if report['theory']:
        theory_info = report['theory']
        lines.append(
            f'{theory_info["note"]}: rate {_fmt(theory_info["rate"])}, k_ν = {_fmt(theory_info["k_nu"])}, '
            f'k_V = {_fmt(theory_info["k_V"])}, error bound gain {_fmt(theory_info["error_gain"])}.'
        )
        printed = theory_info.get('printed_chain')
        if printed:
            above = printed['first_time_above']
            lines.append(
                f'For comparison, the chain as printed (rate (2-k4)ρ2(P)): k_V = {_fmt(printed["k_V"])}; '
                f'V_d reaches {_fmt(printed["max_ratio"])} × its bound k_V e^{{-2β_d t}} (at t = '
                f'{_fmt(printed["at_time"])} s)'
                + (
                    f', above it from t = {_fmt(above)} s on (docs/THEOREM2.md).'
                    if above is not None
                    else '; below it throughout.'
                )
            )
        lines.append('')
    elif report['theory_error']:
        lines += [f'No proof constants: {report["theory_error"]}', '']
    return lines


def _summary_json_lines(comparison: dict[str, Any] | None) -> list[str]:
    """The bag against summary.json: equal, or the values that differ."""
    lines: list[str] = []
    if comparison is None:
        lines.append('No summary.json next to the bag.')
    elif comparison['equal']:
        lines.append(
            f'`{comparison["path"]}`: every metric recomputed from the bag equals the file '
            f'(floats compared exactly). Not recomputed from the bag (wall-clock measurements, runtime '
            f'details): {", ".join(comparison["not_in_bag"]) or "—"}.'
        )
    else:
        differences = comparison['differences']
        lines += [
            f'`{comparison["path"]}` differs from the bag in {len(differences)} value(s) '
            f'(not recomputed from the bag, not compared: {", ".join(comparison["not_in_bag"]) or "—"}):',
            '',
            '| key | from the bag | summary.json |',
            '|---|---|---|',
        ]
        limit = 200
        for difference in differences[:limit]:
            lines.append(
                f'| `{difference["key"]}` | {_short(difference["bag"])} | {_short(difference["summary"])} |'
            )
        if len(differences) > limit:
            lines.append(f'| … {len(differences) - limit} more (see the JSON report) | | |')
        for note in comparison.get('notes', []):
            lines += ['', f'Note: {note}.']
    return lines


def describe_stop(stop: dict[str, Any]) -> str:
    """'at t = 4.97 (step 123), before its horizon 600: interrupted: stopped by a signal (summary.json)'."""
    where = f'at t = {_fmt(stop["time"])}' + (
        f' (step {stop["step"]})' if stop.get('step') is not None else ''
    )
    if stop.get('horizon') is not None:
        where += f', before its horizon {_fmt(stop["horizon"])}'
    if not stop.get('final_step'):
        where += f' (the bag has no final {STEP_TOPIC} message: the run or its recording ended there)'
    return where + (f': {stop["reason"]} (summary.json)' if stop.get('reason') else '')


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 120 else text[:117] + '…'


def _check_table(checks: list[dict[str, Any]]) -> list[str]:
    lines = ['| check | holds | detail |', '|---|---|---|']
    for check in checks:
        holds = 'yes' if check['ok'] else '**NO**' if check.get('binding', True) else 'no (not binding)'
        lines.append(f'| {check["name"]} | {holds} | {check["detail"]} |')
    return lines


def write_report(report: dict[str, Any], out_dir: str | Path) -> tuple[Path, Path]:
    """`analysis.md` and `analysis.json` in `out_dir`."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    markdown = out / 'analysis.md'
    data = out / 'analysis.json'
    markdown.write_text(render_markdown(report), encoding='utf-8')
    data.write_text(json.dumps(report, indent=1, allow_nan=False) + '\n', encoding='utf-8')
    return markdown, data
