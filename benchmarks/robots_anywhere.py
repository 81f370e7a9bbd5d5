"""Robots set down anywhere (issue 27): the safety layer's table on random placements and swaps.

Two parts.

``measure RUN...``: the numbers of issue 27's held-out check from robot run folders (`formation run
X.yaml --backend unicycle ... --out RUN`): the closest two robots' origins over the run, from the
bag's poses (each robot's odometry, linearly interpolated on a common 100 Hz grid), the closest
pair at t = 0, the time after which every edge's error ||x_i - x_j - d_ij|| of the control points
(trajectory/) stays within 5 cm, the final error, the largest edge, summary.json's saturated
commands and whether every robot's last command in the bag is zero.

``table``: docs/BENCHMARKS.md's table "Robots set down anywhere", from the exact engine: 20 random
placements of 4 robots in a 2.2 m square (seeds 300-319, every pair > 0.3 m apart, the 1 m square
on the cycle, Δ = 4) and the swaps (head-on pair, 4-robot diagonal swap, three on a line), with
the layer at each kind's default (origins 2r + 5 cm apart, control points D_s = D + 2c) and
without it, for holonomic robots (r = 0.07 m, c = 0), unicycles (TurtleBot3 Burger: r = 0.105 m,
c = l = 0.1 m) and cars (F1TENTH: r = 0.49 m, c = 0.33 m; everything scaled 3x, as its footprint
does not fit a 1 m square). The engine runs the control points exactly (the scenario's points);
a unicycle's or a car's heading under a command u held between events follows the control point's
map in closed form, tan((θ - φ)/2) = tan((θ0 - φ)/2) e^{-||u|| τ / l} (φ the direction of u), so
the origins o = x - l (cos θ, sin θ) are exact too. Columns: the smallest separation of two
origins (sampled at 0.01 s and at every event), the time to 5 cm and to 1 cm (the formation
error of the control points, for good), events, saturated commands (held commands whose
(v, ω) = (||u|| cos ψ, ||u|| sin ψ / l) exceeds the kind's limits at any instant of its hold,
at κ = 1: the paper's time), the exit status of `formation simulate` for the same scenario (`-`:
the layer's robots jam at every tie-break turn tried) and the turn λ every agent took: as
`formation run --speed-scale auto` does, a jam at the default turn is run again at the next one
(docs/SAFETY.md, "Ties").

    .venv/bin/python benchmarks/robots_anywhere.py measure /tmp/runs/out_100 ...
    .venv/bin/python benchmarks/robots_anywhere.py table [--seeds 300-319] [--horizon 30]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from formation_msgs_py.cdr import odometry_fields, twist_fields
from formation_sim.bag.io import read_bag
from formation_sim.model.scenario import SingleGains, load_scenario
from formation_sim.sim import safety_cases
from formation_sim.sim.samples import load_trajectory


def _yaw(qx: float, qy: float, qz: float, qw: float) -> float:
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _closest_pair(points: np.ndarray) -> float:
    n = len(points)
    return min(float(np.linalg.norm(points[a] - points[b])) for a in range(n) for b in range(a + 1, n))


def measure_run(folder: Path) -> dict:
    """Issue 27's numbers of one robot run folder."""
    scenario = load_scenario(folder / 'scenario.yaml')
    summary = json.loads((folder / 'summary.json').read_text())
    odom: dict[int, list[tuple[float, float, float]]] = {a: [] for a in scenario.agent_ids}
    last_command: dict[int, tuple[float, ...]] = {}
    for message in read_bag(folder / 'bag'):
        parts = message.topic.split('/')
        if len(parts) != 4 or parts[2] != 'robot':
            continue
        agent = int(parts[1].removeprefix('agent_'))
        if parts[3] == 'odom':
            sec, nanosec, pose, _ = odometry_fields(message.rawdata)
            odom[agent].append((sec + nanosec * 1e-9, pose[0], pose[1]))
        elif parts[3] == 'cmd_vel':
            last_command[agent] = tuple(twist_fields(message.rawdata))
    tracks = {a: np.array(sorted(rows)) for a, rows in odom.items()}
    start = max(track[0, 0] for track in tracks.values())
    end = min(track[-1, 0] for track in tracks.values())
    grid = np.arange(start, end, 0.01)
    origins = np.stack(
        [
            np.stack(
                [np.interp(grid, track[:, 0], track[:, 1]), np.interp(grid, track[:, 0], track[:, 2])], 1
            )
            for track in tracks.values()
        ],
        axis=1,
    )
    gaps = [
        np.linalg.norm(origins[:, a] - origins[:, b], axis=1) for a in range(len(tracks)) for b in range(a)
    ]
    trajectory = load_trajectory(folder)
    times, x = np.asarray(trajectory.times), np.asarray(trajectory.positions)
    heads, tails, d = scenario.edge_indices()
    errors = np.linalg.norm(x[:, heads] - x[:, tails] - d[None], axis=2).max(axis=1)
    return {
        'run': folder.name,
        'closest_origins': float(np.min(gaps)),
        'closest_at_start': _closest_pair(origins[0]),
        'to_5cm': safety_cases.settling_time(scenario, times, x, 0.05),
        'final_error': float(errors[-1]),
        'largest_edge': float(safety_cases.edge_maxima(scenario, x).max()),
        'saturated': summary['extra'].get('saturation', {}).get('total'),
        'events': summary['total_events'],
        'last_commands_zero': all(not any(c) for c in last_command.values())
        and len(last_command) == len(tracks),
    }


def _measure(folders: list[str]) -> None:
    print(
        '| run | closest at t = 0 [m] | closest origins [m] | to 5 cm [s] | final error [m] '
        '| largest edge [m] | saturated | events | last commands zero |'
    )
    print('|---|---|---|---|---|---|---|---|---|')
    for folder in folders:
        m = measure_run(Path(folder))
        print(
            f'| {m["run"]} | {m["closest_at_start"]:.3f} | {m["closest_origins"]:.3f} | {m["to_5cm"]:.1f} | '
            f'{m["final_error"]:.1e} | {m["largest_edge"]:.3f} | {m["saturated"]} | {m["events"]} | '
            f'{"yes" if m["last_commands_zero"] else "NO"} |'
        )


# kind -> (its robots as formation run takes them, the limits its warp is chosen for, the scale of
# the scene: cars, r = 0.49 m, need a formation with room for their footprints)
KINDS = {
    'holonomic': ({}, {'max_speed': 0.5}, 1.0),  # crazyflie.params.yaml
    'unicycle': ({}, {'max_speed': 0.22, 'max_angular_speed': 2.84, 'control_point_distance': 0.1}, 1.0),
    'car': (
        {'control_point_distance': 0.33, 'wheelbase': 0.33},  # car.params.yaml
        {'max_speed': 1.0, 'control_point_distance': 0.33},
        3.0,
    ),
}
SHORTEST_HOLD = 1e-9
"""[s] Two samples closer than this are one instant up to rounding (an event and a grid point 1 ulp
apart: 3e-16 s in the diagonal swap): their positions differ by rounding only, which divided by
the interval read as commands of any speed (15 'saturated' holds of 0.76 m/s at v̄ = 0.5 m/s).
No command is held over them."""
CAR_STEERING = 0.42  # [rad] φ_max (car.params.yaml): |ω| <= |v| tan φ_max / L


def _cases(seeds, horizon: float) -> dict:
    cases = {
        'head-on swap': safety_cases.swap_two(safety=None, horizon=horizon),
        'diagonal swap': safety_cases.swap_square(safety=None, horizon=horizon),
        'three on a line': safety_cases.line_three(safety=None, horizon=horizon).replace(
            gains=SingleGains(alpha=1.0, beta=0.25)  # β0 = ρ2 / Δ0 = 1 / 3.5 for the path of 3
        ),
    }
    for seed in seeds:
        cases[f'random {seed}'] = safety_cases.random_square(seed, safety=None, side=2.2, horizon=horizon)
    return cases


def _scaled(scenario, factor: float):
    from formation_sim.model.scenario import Edge

    if factor == 1.0:
        return scenario
    import dataclasses

    edges = tuple(Edge(i=e.i, j=e.j, d=factor * e.d) for e in scenario.edges)
    gains = dataclasses.replace(scenario.gains, beta=scenario.gains.beta / factor)  # β0 = ρ2 / Δ0 shrinks too
    return scenario.replace(
        positions=factor * scenario.positions, edges=edges, delta=factor * scenario.delta, gains=gains
    )


def _headings(times, x, distance: float):
    """Each robot's heading at the samples (rows: times; θ(0) = 0) under its held command, the
    control point map's closed form; and (ψ at each hold's start, ψ at its end, ||u||) per hold."""
    dt = np.diff(times)[:, None]
    held = (dt > SHORTEST_HOLD)[:, :, None]
    u = np.where(held, np.diff(x, axis=0) / np.where(held, dt[:, :, None], 1.0), 0.0)  # the held commands
    speed = np.linalg.norm(u, axis=2)
    phi = np.arctan2(u[..., 1], u[..., 0])
    theta = np.zeros((len(times), x.shape[1]))
    start = np.zeros_like(speed)
    end = np.zeros_like(speed)
    for k in range(len(dt)):
        psi = (theta[k] - phi[k] + math.pi) % (2 * math.pi) - math.pi
        moving = speed[k] > 0.0
        after = np.where(
            moving, 2.0 * np.arctan(np.tan(psi / 2.0) * np.exp(-speed[k] * dt[k, 0] / distance)), psi
        )
        theta[k + 1] = np.where(moving, phi[k] + after, theta[k])
        start[k], end[k] = np.where(moving, psi, 0.0), np.where(moving, after, 0.0)
    return theta, start, end, speed


def _saturated(kind: str, limits: dict, start, end, speed, kappa) -> int:
    """Held commands whose (v, ω) under the warp (κ at the hold) exceeds the kind's limits."""
    v_max = limits['max_speed']
    if kind == 'holonomic':
        return int(np.sum(kappa[:, None] * speed > v_max * (1 + 1e-9)))
    l = limits['control_point_distance']
    v = kappa[:, None] * speed * np.abs(np.cos(end))  # |v| grows as ψ -> 0: largest at the end
    w = kappa[:, None] * speed * np.abs(np.sin(start)) / l  # |ω| largest at the start
    over = v > v_max * (1 + 1e-9)
    if kind == 'unicycle':
        over |= w > limits['max_angular_speed'] * (1 + 1e-9)
    else:  # the steering cone |tan ψ| <= l tan φ_max / L, widest ψ at the start
        over |= np.abs(np.tan(start)) > l * math.tan(CAR_STEERING) / 0.33 * (1 + 1e-9)
    return int(np.sum(over & (speed > 0)))


def table_row(scenario, kind: str, layer: bool) -> dict:
    """One row of the table: the engine's run with the kind's default layer (or none)."""
    import contextlib
    import dataclasses
    import io

    from formation_sim.commands.common import robot_safety
    from formation_sim.model.errors import JamError
    from formation_sim.model.speed_choice import RobotLimits
    from formation_sim.model.validate import validate_scenario
    from formation_sim.runtime.launch.plan import RobotOptions
    from formation_sim.sim.engine import simulate
    from formation_sim.sim.largest_command import choose_time_warp

    shape, limits, factor = KINDS[kind]
    scenario = _scaled(scenario, factor)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        safe = robot_safety(scenario, None if layer else 0.0, RobotOptions.of(model=kind, **shape))
    if safe is None:
        return {'exit': 2, 'why': err.getvalue().strip().splitlines()[0]}
    scenario = safe[0]
    if layer and scenario.safety is None:  # the default does not apply: said why
        return {
            'exit': 0,
            'why': 'layer off: ' + err.getvalue().strip().splitlines()[0].split('does not apply: ')[-1],
        }
    if not validate_scenario(scenario).ok:
        return {'exit': 1, 'why': "the theorems' hypotheses fail"}

    try:  # as `formation run --speed-scale auto`: a jam at the default turn is run again at the next
        choice = choose_time_warp(scenario, limits=RobotLimits(**limits))
    except JamError as error:
        turns = ', '.join(f'λ = {turn:g}: {events} events by t = {t:.1f} s' for turn, events, t in error.jams)
        return {'exit': '-', 'why': f'jam ({turns}; paper time)'}
    if choice.turn is not None:
        scenario = scenario.replace(safety=dataclasses.replace(scenario.safety, turn=choice.turn))
    record = simulate(scenario, sample_dt=0.01)  # the samples hold every event
    times, x = np.asarray(record.samples.times), np.asarray(record.samples.positions)
    distance = limits.get('control_point_distance', 0.0)
    warp = choice.observed
    kappa = np.array([warp.paper_rate(float(t)) for t in times[:-1]])
    if kind == 'holonomic':  # origins = control points, linear between the samples: exact
        dt = np.diff(times)[:, None]
        held = dt > SHORTEST_HOLD
        speed = np.where(held, np.linalg.norm(np.diff(x, axis=0), axis=2) / np.where(held, dt, 1.0), 0.0)
        saturated = _saturated(kind, limits, None, None, speed, kappa)
        closest = safety_cases.closest_approach(times, x)[0]
    else:  # origins sampled (0.01 s and every event)
        theta, start, end, speed = _headings(times, x, distance)
        origins = x - distance * np.stack([np.cos(theta), np.sin(theta)], axis=2)
        saturated = _saturated(kind, limits, start, end, speed, kappa)
        n = x.shape[1]
        closest = min(
            float(np.linalg.norm(origins[:, a] - origins[:, b], axis=1).min())
            for a in range(n)
            for b in range(a)
        )
    settle = {tol: safety_cases.settling_time(scenario, times, x, tol * factor) for tol in (0.05, 0.01)}
    return {
        'exit': 0,
        'closest': closest,
        'to_5cm': warp.real(settle[0.05]) if math.isfinite(settle[0.05]) else math.inf,
        'to_1cm': warp.real(settle[0.01]) if math.isfinite(settle[0.01]) else math.inf,
        'events': record.total_events,
        'saturated': saturated,
        'turn': scenario.safety.turn if scenario.safety is not None else None,
    }


def _table(seeds, horizon: float) -> None:
    print(
        '| placement | kind | layer | exit | smallest separation [m] | to 5 cm [s] | to 1 cm [s] | events '
        '| saturated | λ |'
    )
    print('|---|---|---|---|---|---|---|---|---|---|')
    for name, scenario in _cases(seeds, horizon).items():
        for kind in KINDS:
            for layer in (False, True):
                row = table_row(scenario, kind, layer)
                state = 'on' if layer else 'off'
                if 'why' in row:
                    print(f'| {name} | {kind} | {state} | {row["exit"]} | {row["why"]} | | | | | |')
                    continue
                print(
                    f'| {name} | {kind} | {state} | {row["exit"]} | {row["closest"]:.3f} | '
                    f'{row["to_5cm"]:.1f} | {row["to_1cm"]:.1f} | {row["events"]} | {row["saturated"]} | '
                    f'{"" if row["turn"] is None else format(row["turn"], "g")} |',
                    flush=True,
                )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    sub = parser.add_subparsers(dest='part', required=True)
    measure = sub.add_parser('measure', help='issue 27 numbers of robot run folders')
    measure.add_argument('folders', nargs='+')
    table = sub.add_parser('table', help="docs/BENCHMARKS.md's table, from the exact engine")
    table.add_argument('--seeds', default='300-319', help='random placements: FIRST-LAST (default 300-319)')
    table.add_argument('--horizon', type=float, default=30.0, help="the paper's time to run [s] (default 30)")
    args = parser.parse_args(argv)
    if args.part == 'measure':
        _measure(args.folders)
    else:
        first, last = (int(part) for part in args.seeds.split('-'))
        _table(range(first, last + 1), args.horizon)
    return 0


if __name__ == '__main__':
    sys.exit(main())
