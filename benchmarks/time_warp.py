"""The time warp against the constant speed scale (issue 27): when random hand placements form.

Four robots set down uniformly at random in a 2.2 m square, to form a 1 m square (Δ = 4, α = 0.05,
β = 0.1, robots_lab's gains), limits 0.22 m/s and 2.84 rad/s at l = 0.1 m.  For each seed, the
exact engine's run at the constant κ that `--speed-scale auto` chooses and under the warp that
`--speed-scale warp` chooses (`formation_sim.sim.largest_command`), to the horizon: the time the
formation error (the largest ||x_i - x_j - d_ij||) comes within 5 % of its initial value and
within 5 cm for good (exact: ETA-1's positions are linear between the event samples), the
final error, the largest command against the limit, and the events.  Prints docs/SPEED_SCALE.md's
table.

    .venv/bin/python benchmarks/time_warp.py [--seeds 1-8] [--horizon 90]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from formation_sim.model.scenario import Edge, Scenario, SingleGains
from formation_sim.model.speed_choice import RobotLimits, linear_crossing, settling_time
from formation_sim.model.validate import validate_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.largest_command import choose_speed_scale, choose_time_warp

LIMITS = RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1)
SQUARE = ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))  # corners of agents 1..4


def placement(seed: int, *, horizon: float) -> Scenario:
    """Four robots uniformly in [0, 2.2]², agent k to corner k, redrawn until valid."""
    rng = np.random.default_rng(seed)
    edges = tuple(
        Edge(i=i + 1, j=(i + 1) % 4 + 1, d=np.subtract(SQUARE[i], SQUARE[(i + 1) % 4])) for i in range(4)
    )
    while True:
        scenario = Scenario(
            name=f'square-{seed}',
            dynamics='single',
            delta=4.0,
            agent_ids=(1, 2, 3, 4),
            positions=rng.uniform(0.0, 2.2, size=(4, 2)),
            velocities=None,
            edges=edges,
            gains=SingleGains(alpha=0.05, beta=0.1),
            horizon=horizon,
        )
        if validate_scenario(scenario).ok:
            return scenario


def formed(scenario: Scenario, record, level: float) -> tuple[float, float]:
    """(the first time after which the formation error stays <= level (exact between events), the
    final formation error)."""
    times = np.asarray(record.sample_times, dtype=float)
    x = np.asarray(record.sample_positions, dtype=float)
    heads, tails, d = scenario.edge_indices()
    edge_errors = x[:, heads] - x[:, tails] - d
    errors = np.linalg.norm(edge_errors, axis=2).max(axis=1)

    def crossing(k: int) -> float:
        return linear_crossing(
            edge_errors[k], edge_errors[k + 1], t0=times[k], t1=times[k + 1], threshold=level
        )

    return settling_time(times, errors, threshold=level, segment_crossing=crossing), float(errors[-1])


def row(seed: int, horizon: float) -> dict:
    scenario = placement(seed, horizon=horizon)
    constant = choose_speed_scale(scenario, limits=LIMITS)
    warp = choose_time_warp(scenario, limits=LIMITS).warp
    scaled = scenario.with_scale(speed_scale=constant.value)
    runs = {
        'constant': (scaled, simulate(scaled, horizon=horizon, sample_dt=None)),
        'warp': (scenario, simulate(scenario, horizon=horizon, sample_dt=None, time_warp=warp)),
    }
    error0 = constant.settling.initial_error
    out = {'seed': seed, 'error0': error0, 'kappa': constant.value, 'pieces': warp.pieces}
    for name, (run_scenario, record) in runs.items():
        five_percent, final = formed(run_scenario, record, 0.05 * error0)
        five_cm, _ = formed(run_scenario, record, 0.05)
        out[name] = {
            '5%': five_percent,
            '5cm': five_cm,
            'final': final,
            'events': record.total_events,
            'largest': largest_speed(record),
        }
    return out


def largest_speed(record) -> float:
    """The largest speed of a control point over the run, from the sampled positions (linear
    between events): the largest displacement over time between consecutive samples."""
    times = np.asarray(record.sample_times, dtype=float)
    x = np.asarray(record.sample_positions, dtype=float)
    dt = np.diff(times)
    moving = dt > 1e-9
    speed = np.linalg.norm(np.diff(x, axis=0), axis=2)[moving] / dt[moving, None]
    return float(speed.max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', default='1-8')
    parser.add_argument('--horizon', type=float, default=90.0)
    args = parser.parse_args()
    low, _, high = args.seeds.partition('-')
    seeds = range(int(low), int(high or low) + 1)
    print(
        '| seed | error at 0 | κ (constant) | 5 % / 5 cm, constant κ | 5 % / 5 cm, warp | final error, '
        'constant / warp | largest speed, constant / warp | events, constant / warp |'
    )
    print('|---|---|---|---|---|---|---|---|')
    for seed in seeds:
        r = row(seed, args.horizon)
        c, w = r['constant'], r['warp']

        def t(v: float) -> str:
            return f'{v:.1f} s' if math.isfinite(v) else f'> {args.horizon:g} s'

        print(
            f'| {seed} | {r["error0"]:.2f} m | {r["kappa"]:.3f} | {t(c["5%"])} / {t(c["5cm"])} | '
            f'{t(w["5%"])} / {t(w["5cm"])} | {1000 * c["final"]:.2f} / {1000 * w["final"]:.2f} mm | '
            f'{c["largest"]:.3f} / {w["largest"]:.3f} m/s | {c["events"]} / {w["events"]} |',
            flush=True,
        )


if __name__ == '__main__':
    main()
