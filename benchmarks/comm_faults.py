"""Communication faults on the wall clock: how injected loss and delay change the formation.

Runs `benchmarks/gentle_square.yaml` with `formation run --real-time` semantics (one process per
agent, a simulator, no bag) for each fault setting and seed, and prints a Markdown table of the
final formation error, the longest edge against Δ, event counts and what was dropped or delayed
(the README's "Reliability" table).  Faults are injected on the receiving side of the
triggering-information topics (agent node parameters inject_loss / inject_delay_ms / inject_seed,
a test facility).  Wall-clock runs are not reproducible: numbers vary from run to run.

    .venv/bin/python benchmarks/comm_faults.py --out runs/comm_faults [--seeds 3] [--domain-id N]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.launch.orchestrate import FormationRun
from formation_sim.sim.engine import simulate
from formation_sim.sim.summary import build_summary

SCENARIO = Path(__file__).with_name('gentle_square.yaml')

# (label, inject options)
SETTINGS: list[tuple[str, dict[str, float]]] = [
    ('none', {}),
    ('loss 1 %', {'loss': 0.01}),
    ('loss 10 %', {'loss': 0.10}),
    ('loss 20 %', {'loss': 0.20}),
    ('loss 30 %', {'loss': 0.30}),
    ('delay 1 ms', {'delay_ms': 1.0}),
    ('delay 10 ms', {'delay_ms': 10.0}),
    ('delay 50 ms', {'delay_ms': 50.0}),
    ('loss 10 % + delay 50 ms', {'loss': 0.10, 'delay_ms': 50.0}),
]


def run_once(out: Path, inject: dict[str, float], seed: int, domain_id: int | None) -> dict:
    run = FormationRun(
        SCENARIO,
        out_dir=out,
        domain_id=domain_id,
        record=False,
        progress=False,
        clock='realtime',
        timeout=300.0,
        inject={**inject, 'seed': seed} if inject else None,
    )
    row, summary = result_row(run.run())
    if summary is not None:
        extra = summary['extra']
        row.update(
            messages_sent=summary['messages_sent'],
            dropped=extra['injected_faults']['dropped'],
            delayed=extra['injected_faults']['delayed'],
            reached_time=extra['reached_time'],
        )
    return row


def result_row(result) -> tuple[dict, dict | None]:
    """A run's outcome and the numbers every table shows, and its summary (None: none written)."""
    row: dict = {'ok': result.ok, 'message': result.message, 'wall_time': result.wall_time}
    if result.summary is None:
        return row, None
    summary = json.loads(result.summary.read_text())
    row.update(
        final_formation_error=summary['final_formation_error'],
        max_edge_length=summary['max_edge_length'],
        delta=summary['delta'],
        total_events=summary['total_events'],
        max_lateness=summary['extra'].get('max_lateness'),
        failure=summary['extra']['failure'],
    )
    return row, summary


def median_of(rows: list[dict], key: str) -> float | None:
    values = [row[key] for row in rows if row.get(key) is not None]
    return statistics.median(values) if values else None


def table(results: dict[str, list[dict]], reference: dict) -> str:
    lines = [
        '| faults | completed | connectivity lost (at t) | final formation error | max edge length / Δ | '
        'events | dropped / delayed | max lateness |',
        '|---|---|---|---|---|---|---|---|',
        f'| exact, in process (`formation simulate`) | – | – | {reference["final_formation_error"]:.4f} | '
        f'{reference["max_edge_length"]:.3f} / {reference["delta"]:g} | '
        f'{reference["total_events"]} | – | – |',
    ]
    delta = reference['delta']
    for label, rows in results.items():
        done = [row for row in rows if row['ok']]
        cut = [row for row in rows if (row.get('failure') or {}).get('kind') == 'connectivity_lost']
        cut_at = ', '.join(f'{row["failure"]["time"]:.2f} s' for row in cut)
        worst_edge = max((row['max_edge_length'] for row in done), default=None)
        error = median_of(done, 'final_formation_error')
        events = median_of(done, 'total_events')
        lateness = median_of(done, 'max_lateness')
        dropped, delayed = median_of(rows, 'dropped'), median_of(rows, 'delayed')
        lines.append(
            f'| {label} | {len(done)}/{len(rows)} | {len(cut)}{f" ({cut_at})" if cut else ""} | '
            f'{"–" if error is None else f"{error:.4f}"} | '
            f'{"–" if worst_edge is None else f"{worst_edge:.3f} / {delta:g}"} | '
            f'{"–" if events is None else f"{events:g}"} | '
            f'{"–" if dropped is None else f"{dropped:g} / {delayed:g}"} | '
            f'{"–" if lateness is None else f"{1000 * lateness:.0f} ms"} |'
        )
    lines.append('')
    lines.append(
        'Medians over the completed runs (dropped / delayed: over all runs); max edge length: the '
        'worst completed run.'
    )
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument(
        '--out', type=Path, default=Path('runs') / f'comm_faults-{time.strftime("%Y%m%d-%H%M%S")}'
    )
    parser.add_argument('--seeds', type=int, default=3, help='runs per setting (seeds 0, 1, ...)')
    parser.add_argument(
        '--domain-id', type=int, default=None, help='ROS_DOMAIN_ID for every run (default: a free one)'
    )
    args = parser.parse_args(argv)

    scenario = load_scenario(SCENARIO)
    reference = build_summary(simulate(scenario))
    results: dict[str, list[dict]] = {}
    for label, inject in SETTINGS:
        rows = results.setdefault(label, [])
        for seed in range(args.seeds):
            out = args.out / f'{label.replace(" ", "").replace("%", "pct").replace("+", "_")}-seed{seed}'
            row = run_once(out, inject, seed, args.domain_id)
            rows.append(row)
            status = 'ok' if row['ok'] else f'FAILED: {row["message"][:160]}'
            print(f'{label:26s} seed {seed}: {status}', file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'comm_faults.json').write_text(
        json.dumps(
            {'reference': reference['final_formation_error'], 'results': results}, indent=1, default=str
        )
    )
    print(table(results, reference))
    return 0


if __name__ == '__main__':
    sys.exit(main())
