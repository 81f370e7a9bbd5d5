"""robots_lab (set down by hand) on the robot backends at the speed scale their limits allow (issue 18).

Runs `formation run robots_lab --backend B --speed-scale auto` as the command does (κ from
`formation_sim.commands.limits.resolve_speed_scale`, recorded in summary.json's extra.speed_scale)
on the backends unicycle, holonomic and car (speed 0.22 m/s; the unicycle a TurtleBot3, 2.84 rad/s
and l = 0.1 m; the car the geometry of car.params.yaml: wheelbase 0.33 m, steering ±0.42 rad,
l = 0.33 m), each quiet and with pose noise σ = 5 mm and 20 ms pose latency; and the unicycle at
σ = 2 mm, without and with the threshold floor c0 that `formation validate --pose-noise σ`
suggests (`formation_sim.model.speed_choice.scenario_noise_floor`).  Prints README's "Running on
robots" tables: κ, the largest speed of a control point against the limit, saturated commands,
events, when the formation error came within 5 cm and 1 cm for good (from the sampled trajectory,
`formation_sim.analysis.checks.run_series` and `formation_sim.model.speed_choice.settling_time`),
and the final formation error.

Each run's row is kept in OUT/<setting>-<seed>/row.json, so the settings can run one invocation at
a time (`--only`, each a minute or two) and `--table` prints the tables of what is there.
Wall-clock runs are not reproducible: numbers vary from run to run and with the machine's load.

    .venv/bin/python benchmarks/robots_lab.py --out runs/robots_lab --domain-id N \
        [--only unicycle,car-5mm] [--horizon 60]
    .venv/bin/python benchmarks/robots_lab.py --out runs/robots_lab --table
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from comm_faults import result_row  # benchmarks/ is on the path of a script run from it

from formation_sim.analysis.checks import run_series
from formation_sim.commands.limits import resolve_speed_scale
from formation_sim.model.scenario import Scenario, load_scenario
from formation_sim.model.speed_choice import scenario_noise_floor, settling_time
from formation_sim.runtime.launch.orchestrate import FormationRun
from formation_sim.runtime.launch.plan import RobotOptions
from formation_sim.sim.engine import simulate
from formation_sim.sim.summary import load_record

SCENARIO = 'robots_lab'
SPEED = 0.22  # [m/s] a TurtleBot3's; the car runs at the same speed, hence at the same κ
KINDS = {
    'unicycle': {'max_linear_speed': SPEED, 'max_angular_speed': 2.84, 'control_point_distance': 0.1},
    'holonomic': {'max_linear_speed': SPEED},
    'car': {
        'max_linear_speed': SPEED,
        'wheelbase': 0.33,
        'max_steering_angle': 0.42,
        'control_point_distance': 0.33,
    },
}
LATENCY = 0.02  # [s] with every noisy setting
ERRORS = (0.05, 0.01)  # [m] the formation errors whose times the table shows

# name: (label, backend, pose noise σ [m], threshold floor as suggested for σ)
SETTINGS: dict[str, tuple[str, str, float, bool]] = {
    'exact': (
        'exact, in process (`formation simulate`)',
        'exact',
        0.0,
        False,
    ),  # the reference, not run by --only
    'unicycle': ('unicycle', 'unicycle', 0.0, False),
    'unicycle-5mm': ('unicycle, σ = 5 mm, 20 ms', 'unicycle', 0.005, False),
    'holonomic': ('holonomic', 'holonomic', 0.0, False),
    'holonomic-5mm': ('holonomic, σ = 5 mm, 20 ms', 'holonomic', 0.005, False),
    'car': ('car', 'car', 0.0, False),
    'car-5mm': ('car, σ = 5 mm, 20 ms', 'car', 0.005, False),
    'unicycle-2mm': ('unicycle, σ = 2 mm, 20 ms', 'unicycle', 0.002, False),
    'unicycle-2mm-floor': ('unicycle, σ = 2 mm, 20 ms, c0', 'unicycle', 0.002, True),
    'unicycle-5mm-floor': ('unicycle, σ = 5 mm, 20 ms, c0', 'unicycle', 0.005, True),
}
TABLES = {
    'backends': ['exact', 'unicycle', 'unicycle-5mm', 'holonomic', 'holonomic-5mm', 'car', 'car-5mm'],
    'threshold floor (unicycle)': [
        'exact',
        'unicycle',
        'unicycle-2mm',
        'unicycle-2mm-floor',
        'unicycle-5mm',
        'unicycle-5mm-floor',
    ],
}


def planned(name: str, *, horizon: float, seed: int) -> tuple[Scenario, dict, RobotOptions]:
    """The scenario at the κ `--speed-scale auto` chooses for the setting's limits (and its floor),
    what `formation run` records of that choice, and the robots' options."""
    _, backend, sigma, floor = SETTINGS[name]
    limits = KINDS[backend]
    args = argparse.Namespace(
        speed_scale='auto',
        backend=backend,
        robot=None,
        horizon=horizon,
        max_speed=limits['max_linear_speed'],
        max_angular_speed=limits.get('max_angular_speed'),
        control_point_distance=limits.get('control_point_distance'),
        max_acceleration=None,
    )
    resolved = resolve_speed_scale(load_scenario(SCENARIO), args, 'run')
    if resolved is None:
        raise SystemExit(f'{name}: --speed-scale auto cannot choose (above)')
    scenario, chosen = resolved
    if floor:
        c0, _, _ = scenario_noise_floor(scenario, pose_noise=sigma, speed_scale=scenario.speed_scale)
        scenario = scenario.with_scale(threshold_floor=c0)
    robots = RobotOptions.of(
        model=backend, seed=seed, pose_noise=sigma, latency=LATENCY if sigma > 0.0 else 0.0, **limits
    )
    return scenario, chosen, robots


def measured(record) -> dict:
    """From a run's sampled trajectory: the times to ERRORS (inf: not within the run) and the
    largest speed of a control point (differences of the samples: 10 ms apart, and the events)."""
    series = run_series(record)
    times = series.times
    reached = {
        f'time_to_{error:g}': settling_time(times, series.formation_error, threshold=error)
        for error in ERRORS
    }
    steps = np.diff(times)
    moves = np.linalg.norm(np.diff(np.asarray(record.sample_positions, dtype=float), axis=0), axis=2)
    speeds = moves[steps > 1e-4] / steps[steps > 1e-4, None]
    return {
        **reached,
        'largest_speed': float(speeds.max()),
        'final_formation_error': float(series.formation_error[-1]),
    }


def reference(horizon: float) -> dict:
    """The row of the exact in-process run (`formation simulate`) at the κ of the settings."""
    scenario, chosen, _ = planned('holonomic', horizon=horizon, seed=0)
    record = simulate(scenario, horizon=horizon)
    events = sum(len(times) for times in record.trigger_times.values())
    return {
        'setting': 'exact',
        'ok': True,
        'kappa': chosen['value'],
        'threshold_floor': 0.0,
        'saturated': None,
        'total_events': events,
        **measured(record),
    }


def run_setting(name: str, *, out: Path, seed: int, horizon: float, domain_id: int | None) -> dict:
    scenario, chosen, robots = planned(name, horizon=horizon, seed=seed)
    run_dir = out / f'{name}-{seed}'
    result = FormationRun(
        scenario,
        out_dir=run_dir,
        horizon=horizon,
        domain_id=domain_id,
        record=False,
        progress=False,
        timeout=horizon + 300.0,
        backend=robots.model,
        robots=robots,
        summary_extra={'speed_scale': chosen},
    ).run()
    row, summary = result_row(result)
    row.update(setting=name, seed=seed, horizon=horizon, threshold_floor=scenario.gains.threshold_floor)
    if summary is not None and result.ok:
        row['kappa'] = summary['extra']['speed_scale']['value']
        saturation = summary['extra'].get('saturation') or {'total': 0, 'by_kind': {}}
        row['saturated'] = saturation['total']
        row['saturated_by_kind'] = saturation['by_kind']
        row.update(measured(load_record(run_dir, scenario)))
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / 'row.json').write_text(json.dumps(row, indent=1, default=str))
    return row


def _seconds(value: float) -> str:
    return 'not reached' if math.isinf(value) else f'{value:.1f} s'


def _saturated(rows: list[dict]) -> str:
    if rows[0]['saturated'] is None:
        return '–'
    counts = ', '.join(f'{row["saturated"]}' for row in rows)
    kinds = {
        kind: max(
            row['saturated_by_kind'][kind]['largest_requested']
            for row in rows
            if kind in row['saturated_by_kind']
        )
        for row in rows
        for kind in row['saturated_by_kind']
    }
    limits = {kind: entry['allowed'] for row in rows for kind, entry in row['saturated_by_kind'].items()}
    return counts + ''.join(
        f' ({kind}: up to {value:.3g} / {limits[kind]:g})' for kind, value in kinds.items()
    )


def table(rows: dict[str, list[dict]], names: list[str]) -> str:
    lines = [
        '| setting | runs done | κ | c0 | largest speed / limit | saturated commands | events | to '
        '5 cm | to 1 cm | final formation error |',
        '|---|---|---|---|---|---|---|---|---|---|',
    ]
    for name in names:
        done = [row for row in rows.get(name, []) if row['ok'] and 'kappa' in row]
        every = rows.get(name, [])
        if not done:
            failed = '; '.join(row['message'][:120] for row in every) or 'not run'
            lines.append(f'| {SETTINGS[name][0]} | 0/{len(every)} | | | | | | | | {failed} |')
            continue
        speed = max(row['largest_speed'] for row in done)
        events = ', '.join(str(row['total_events']) for row in done)
        final = ', '.join(f'{1000 * row["final_formation_error"]:.1f}' for row in done)
        lines.append(
            f'| {SETTINGS[name][0]} | {"–" if name == "exact" else f"{len(done)}/{len(every)}"} | '
            f'{done[0]["kappa"]:.4g} | {done[0]["threshold_floor"]:.3g} | '
            f'{speed:.3f} / {SPEED:g} m/s | {_saturated(done)} | {events} | '
            f'{", ".join(_seconds(row["time_to_0.05"]) for row in done)} | '
            f'{", ".join(_seconds(row["time_to_0.01"]) for row in done)} | '
            f'{final} mm |'
        )
    return '\n'.join(lines)


def load_rows(out: Path) -> dict[str, list[dict]]:
    rows: dict[str, list[dict]] = {}
    for path in sorted(out.glob('*/row.json')):
        row = json.loads(path.read_text())
        rows.setdefault(row['setting'], []).append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument(
        '--out', type=Path, required=True, help='the benchmark folder (one run folder per setting and seed)'
    )
    parser.add_argument(
        '--only', default=None, help=f'comma-separated settings to run (default: all): {", ".join(SETTINGS)}'
    )
    parser.add_argument(
        '--seeds', default='0', help='comma-separated robot seeds, one run per setting and seed (default: 0)'
    )
    parser.add_argument('--horizon', type=float, default=60.0)
    parser.add_argument(
        '--domain-id', type=int, default=None, help='ROS_DOMAIN_ID for every run (default: a free one)'
    )
    parser.add_argument(
        '--table', action='store_true', help='run nothing: print the tables of the runs in --out'
    )
    args = parser.parse_args(argv)
    names = [name for name in SETTINGS if name != 'exact'] if args.only is None else args.only.split(',')
    unknown = [name for name in names if name not in SETTINGS or name == 'exact']
    if unknown:
        parser.error(f'--only: unknown settings {unknown}; known: {", ".join(SETTINGS)}')
    if not args.table:
        args.out.mkdir(parents=True, exist_ok=True)
        for name in names:
            for seed in map(int, args.seeds.split(',')):
                row = run_setting(
                    name, out=args.out, seed=seed, horizon=args.horizon, domain_id=args.domain_id
                )
                status = 'ok' if row['ok'] else f'FAILED: {row["message"][:200]}'
                print(f'{name:20s} run {seed}: {status}', file=sys.stderr, flush=True)
    rows = load_rows(args.out)
    horizons = {row['horizon'] for every in rows.values() for row in every}
    if len(horizons) == 1:
        rows['exact'] = [reference(horizons.pop())]
    for title, table_names in TABLES.items():
        print(f'\n{title}\n\n{table(rows, table_names)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
