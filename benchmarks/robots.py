"""robots_square on each backend, without and with pose noise and latency, against the exact run.

Runs `formation run robots_square` on the backends exact (lock-step and wall clock), holonomic and
unicycle (TurtleBot3 limits 0.22 m/s, 2.84 rad/s; the unicycles' control point 0.1 m ahead of
the axle), the simulated robots without and with pose noise (σ = 5 mm) and 20 ms pose latency,
and prints the README's "Running on robots" table: completed runs, final formation error, the
longest edge against Δ, events, saturated commands, and the largest distance of the trajectories
from those of the exact in-process run.  Wall-clock runs are not reproducible: numbers vary from
run to run and with the machine's load.

    .venv/bin/python benchmarks/robots.py --out runs/robots_bench [--runs 3] [--horizon 30] [--domain-id N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from comm_faults import median_of, result_row  # benchmarks/ is on the path of a script run from it

from formation_sim.analysis.compare import RunData, compare_trajectories
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.launch.orchestrate import FormationRun
from formation_sim.runtime.launch.plan import RobotOptions
from formation_sim.sim.engine import simulate
from formation_sim.sim.samples import load_trajectory
from formation_sim.sim.summary import build_summary

SCENARIO = 'robots_square'
LIMITS = {'max_linear_speed': 0.22, 'max_angular_speed': 2.84, 'control_point_distance': 0.1}
NOISY = {'pose_noise': 0.005, 'latency': 0.02}

# (label, backend, clock, robot options beyond the limits)
SETTINGS: list[tuple[str, str, str | None, dict | None]] = [
    ('exact, lock-step', 'exact', 'lockstep', None),
    ('exact, wall clock', 'exact', 'realtime', None),
    ('holonomic', 'holonomic', None, {}),
    ('holonomic, σ = 5 mm, 20 ms', 'holonomic', None, NOISY),
    ('unicycle', 'unicycle', None, {}),
    ('unicycle, σ = 5 mm, 20 ms', 'unicycle', None, NOISY),
]


def _trajectory(out: Path, label: str, scenario) -> RunData:
    samples = load_trajectory(out)
    times, positions = np.asarray(samples.times, dtype=float), np.asarray(samples.positions, dtype=float)
    return RunData(
        label=label,
        source=str(out),
        scenario=scenario.name,
        dynamics=scenario.dynamics,
        mode='',
        horizon=float(times[-1]),
        agent_ids=scenario.agent_ids,
        edges=[],
        trigger_times={},
        messages_sent=0,
        sensing_calls=0,
        times=times,
        positions=positions,
    )


def run_once(
    out: Path,
    backend: str,
    clock: str | None,
    robot: dict | None,
    *,
    seed: int,
    horizon: float,
    domain_id: int | None,
) -> dict:
    robots = None
    if robot is not None:
        robots = RobotOptions.of(model=backend, seed=seed, **LIMITS, **robot)
    result = FormationRun(
        SCENARIO,
        out_dir=out,
        horizon=horizon,
        domain_id=domain_id,
        record=False,
        progress=False,
        timeout=horizon + 300.0,
        backend=backend,
        clock=clock,
        robots=robots,
    ).run()
    row, summary = result_row(result)
    if summary is not None:
        saturation = summary['extra'].get('saturation')
        row['saturated'] = None if saturation is None else saturation['total']  # robots only
    return row


def table(results: dict[str, list[dict]], reference: dict) -> str:
    delta = reference['delta']
    lines = [
        '| backend | completed | final formation error | max edge length / Δ | events | saturated commands | '
        'max distance from the exact run | max lateness |',
        '|---|---|---|---|---|---|---|---|',
        f'| exact, in process (`formation simulate`) | – | {reference["final_formation_error"]:.2e} | '
        f'{reference["max_edge_length"]:.4f} / {delta:g} | {reference["total_events"]} | – | 0 | – |',
    ]
    for label, rows in results.items():
        done = [row for row in rows if row['ok']]
        error = median_of(done, 'final_formation_error')
        worst_edge = max((row['max_edge_length'] for row in done), default=None)
        events = median_of(done, 'total_events')
        saturated = median_of(done, 'saturated')
        distance = median_of(done, 'distance_from_exact')
        lateness = median_of(done, 'max_lateness')
        lines.append(
            f'| {label} | {len(done)}/{len(rows)} | {"–" if error is None else f"{error:.2e}"} | '
            f'{"–" if worst_edge is None else f"{worst_edge:.4f} / {delta:g}"} | '
            f'{"–" if events is None else f"{events:g}"} | '
            f'{"–" if saturated is None else f"{saturated:g}"} | '
            f'{"–" if distance is None else f"{1000 * distance:.1f} mm"} | '
            f'{"–" if lateness is None else f"{1000 * lateness:.0f} ms"} |'
        )
    lines += ['', 'Medians over the completed runs; max edge length: the worst completed run.']
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument(
        '--out', type=Path, default=Path('runs') / f'robots_bench-{time.strftime("%Y%m%d-%H%M%S")}'
    )
    parser.add_argument('--runs', type=int, default=3, help='runs per setting (robot seeds 0, 1, ...)')
    parser.add_argument('--horizon', type=float, default=30.0)
    parser.add_argument(
        '--domain-id', type=int, default=None, help='ROS_DOMAIN_ID for every run (default: a free one)'
    )
    args = parser.parse_args(argv)

    scenario = load_scenario(SCENARIO)
    exact = simulate(scenario, horizon=args.horizon)
    reference = build_summary(exact)
    reference_run = RunData(
        label='exact',
        source='in process',
        scenario=scenario.name,
        dynamics=scenario.dynamics,
        mode='in_process',
        horizon=args.horizon,
        agent_ids=scenario.agent_ids,
        edges=[],
        trigger_times={},
        messages_sent=0,
        sensing_calls=0,
        times=exact.sample_times,
        positions=exact.sample_positions,
    )
    results: dict[str, list[dict]] = {}
    for label, backend, clock, robot in SETTINGS:
        rows = results.setdefault(label, [])
        for seed in range(1 if backend == 'exact' and clock == 'lockstep' else args.runs):
            out = args.out / f'{backend}-{clock or ("noisy" if robot else "clean")}-{seed}'
            row = run_once(
                out, backend, clock, robot, seed=seed, horizon=args.horizon, domain_id=args.domain_id
            )
            if row['ok']:
                deviation = compare_trajectories(_trajectory(out, label, scenario), reference_run)
                row['distance_from_exact'] = deviation.max_deviation
            rows.append(row)
            status = 'ok' if row['ok'] else f'FAILED: {row["message"][:200]}'
            print(f'{label:30s} run {seed}: {status}', file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'robots.json').write_text(
        json.dumps({'reference': reference, 'results': results}, indent=1, default=str)
    )
    print(table(results, reference))
    return 0


if __name__ == '__main__':
    sys.exit(main())
