"""The safety layer's adversarial cases and its exact measures (docs/SAFETY.md), ROS-free.

Cases: the head-on swap of two robots, the 4-robot diagonal swap (the square turned by 180°:
every robot heads through the centre), three robots on a line whose ends swap past the middle
one, and seeded random placements of 4 robots in a 2.2 m square forming a 1 m square (Δ = 4,
the cycle 1-2-3-4). Measures: the exact closest approach of two robots over a run (positions are
linear between consecutive samples, which include every event: the minimum of a quadratic per
interval and pair), each edge's largest length, and the time the formation error stays below a
tolerance. `python -m formation_sim.sim.safety_cases` prints docs/SAFETY.md's table.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from formation_agent.core.safety import SafetyConfig
from formation_sim.model.scenario import Edge, Scenario, SingleGains, short_repr

DELTA = 4.0
GAINS = SingleGains(alpha=1.0, beta=0.3)  # β < β0 = ρ2(DD^T)/Δ0: 1/3 (path of 3) .. 2/3 (cycle of 4)
TABLE_SEEDS = 20  # the placements of docs/SAFETY.md's table
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # 1 m square, corners 1-2-3-4


def _scenario(name, positions, targets, pairs, *, safety, horizon):
    targets = np.asarray(targets, dtype=float)
    ids = tuple(range(1, len(targets) + 1))
    edges = tuple(Edge(i=i, j=j, d=targets[i - 1] - targets[j - 1]) for i, j in pairs)
    return Scenario(
        name=name,
        dynamics='single',
        delta=DELTA,
        agent_ids=ids,
        positions=np.asarray(positions, dtype=float),
        velocities=None,
        edges=edges,
        gains=GAINS,
        horizon=horizon,
        safety=safety,
    )


def swap_two(*, safety: SafetyConfig | None, horizon: float = 30.0, gap: float = 1.0) -> Scenario:
    """Two robots `gap` apart (1 m) that must trade places 1 m apart, head on."""
    return _scenario(
        'swap_two',
        [[0.0, 0.0], [gap, 0.0]],
        [[1.0, 0.0], [0.0, 0.0]],
        [(1, 2)],
        safety=safety,
        horizon=horizon,
    )


def swap_square(*, safety: SafetyConfig | None, horizon: float = 30.0) -> Scenario:
    """Four robots on a 1 m square that must each reach the opposite corner (a 180° rotation)."""
    return _scenario(
        'swap_square',
        SQUARE,
        SQUARE[[2, 3, 0, 1]],
        [(1, 2), (2, 3), (3, 4), (4, 1)],
        safety=safety,
        horizon=horizon,
    )


def line_three(*, safety: SafetyConfig | None, horizon: float = 30.0, spacing: float = 0.5) -> Scenario:
    """Three robots on a line, `spacing` apart (0.5 m), whose outer two must trade places past the
    middle one, to a line 0.5 m apart."""
    line = [[0.0, 0.0], [spacing, 0.0], [2.0 * spacing, 0.0]]
    targets = [[1.0, 0.0], [0.5, 0.0], [0.0, 0.0]]
    return _scenario('line_three', line, targets, [(1, 2), (2, 3)], safety=safety, horizon=horizon)


def random_square(
    seed: int, *, safety: SafetyConfig | None, side: float = 2.2, horizon: float = 30.0
) -> Scenario:
    """4 robots uniform in a `side` square (seeded; drawn again until every pair is more than
    0.3 m apart and (initial) holds with 10 % to spare) forming the 1 m square on the cycle."""
    rng = np.random.default_rng(seed)
    pairs = [(1, 2), (2, 3), (3, 4), (4, 1)]
    while True:
        x = rng.random((4, 2)) * side
        gaps = [np.linalg.norm(x[a] - x[b]) for a in range(4) for b in range(a + 1, 4)]
        errors = [np.linalg.norm(x[i - 1] - x[j - 1] - (SQUARE[i - 1] - SQUARE[j - 1])) for i, j in pairs]
        if min(gaps) > 0.3 and max(errors) < 0.9 * (DELTA - 1.0):
            return _scenario(f'random_square_{seed}', x, SQUARE, pairs, safety=safety, horizon=horizon)


def random_team(seed: int) -> Scenario:
    """The stress sweep's team `seed` (docs/SAFETY.md): 3-6 robots in a 1.5-3 m square, targets more
    than 2D apart, a path, cycle or complete graph, D 0.1-0.4 m, v̄ 0.3-1 m/s, γ 2-5 1/s, R = 3 m,
    α = 1, β = 0.2; the placement drawn again until every pair is more than 1.2 D apart and every
    edge within 90 % of its capacity (ValueError after 20 000 draws)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 7))
    d = float(rng.uniform(0.1, 0.4))
    side = float(rng.uniform(1.5, 3.0))
    while True:
        targets = rng.random((n, 2)) * side
        if _closest(targets) > 2 * d:
            break
    path = [(i, i + 1) for i in range(1, n)]
    pairs = [path, [*path, (n, 1)], [(i, j) for i in range(1, n + 1) for j in range(i + 1, n + 1)]]
    pairs = pairs[int(rng.integers(0, 3))]
    capacity = DELTA - max(np.linalg.norm(targets[i - 1] - targets[j - 1]) for i, j in pairs)
    for _ in range(20000):
        x = rng.random((n, 2)) * side
        errors = [np.linalg.norm(x[i - 1] - x[j - 1] - (targets[i - 1] - targets[j - 1])) for i, j in pairs]
        if _closest(x) > 1.2 * d and max(errors) < 0.9 * capacity:
            break
    else:
        raise ValueError(f'random_team({seed}): no placement in 20 000 draws')
    safety = SafetyConfig(
        min_separation=d,
        max_speed=float(rng.uniform(0.3, 1.0)),
        gamma=float(rng.uniform(2, 5)),
        sensing_radius=3.0,
    )
    scenario = _scenario(f'random_team_{seed}', x, targets, pairs, safety=safety, horizon=30.0)
    return scenario.replace(gains=SingleGains(alpha=1.0, beta=0.2))


def _closest(points: np.ndarray) -> float:
    n = len(points)
    return min(float(np.linalg.norm(points[a] - points[b])) for a in range(n) for b in range(a + 1, n))


def closest_approach(times: np.ndarray, positions: np.ndarray) -> tuple[float, float, tuple[int, int]]:
    """(distance, time, (row a, row b)): the least distance of two robots over the samples, exact
    when motion is linear between consecutive samples (every event is a sample): per interval and
    pair, the minimum of ||r0 + s (r1 - r0)|| over s in [0, 1] in closed form."""
    n = positions.shape[1]
    best = (math.inf, 0.0, (0, 0))
    for a in range(n):
        for b in range(a + 1, n):
            r = positions[:, a] - positions[:, b]
            r0, dr = r[:-1], r[1:] - r[:-1]
            dd = (dr * dr).sum(axis=1)
            s = np.clip(
                np.divide(-(r0 * dr).sum(axis=1), dd, out=np.zeros_like(dd), where=dd > 0.0), 0.0, 1.0
            )
            dist = np.linalg.norm(r0 + s[:, None] * dr, axis=1)
            k = int(np.argmin(dist))
            if dist[k] < best[0]:
                best = (float(dist[k]), float(times[k] + s[k] * (times[k + 1] - times[k])), (a, b))
    return best


def edge_maxima(scenario: Scenario, positions: np.ndarray) -> np.ndarray:
    """Each edge's largest length ||x_i - x_j|| (convex between samples: the largest sample)."""
    heads, tails, _ = scenario.edge_indices()
    return np.linalg.norm(positions[:, heads] - positions[:, tails], axis=2).max(axis=0)


def settling_time(scenario: Scenario, times: np.ndarray, positions: np.ndarray, tolerance: float) -> float:
    """The first sample time from which every ||x_i - x_j - d_ij|| stays <= tolerance (convex between
    samples, so checking the samples is exact up to the sample spacing); inf if never."""
    heads, tails, d = scenario.edge_indices()
    error = np.linalg.norm(positions[:, heads] - positions[:, tails] - d, axis=2).max(axis=1)
    above = np.flatnonzero(error > tolerance)
    if above.size == 0:
        return float(times[0])
    if above[-1] == len(times) - 1:
        return math.inf
    return float(times[above[-1] + 1])


def measure(scenario: Scenario) -> dict[str, float]:
    """One run's numbers for the table: closest approach, events, time to 5 cm, largest edge."""
    from formation_sim.sim.engine import simulate

    record = simulate(scenario, sample_dt=0.01)
    times, x = record.samples.times, np.asarray(record.samples.positions)
    gaps = [np.diff(v) for v in record.trigger_times.values() if len(v) > 1]
    return {
        'closest': closest_approach(times, x)[0],
        'events': record.total_events,
        'settle': settling_time(scenario, times, x, 0.05),
        'edge': float(edge_maxima(scenario, x).max()),
        'least_gap': float(min(g.min() for g in gaps)) if gaps else math.inf,
        'last_intervention': record.extra.get('safety', {}).get('last_intervention', 0.0),
    }


def stress(seeds) -> None:
    """Print the stress sweep of docs/SAFETY.md, a line per `random_team` (at most 20 000 events)."""
    from formation_sim.sim.engine import simulate

    def cap(t: float, events: int) -> None:
        if events > 20000:
            raise RuntimeError(f'more than 20000 events by t = {t:.3f}')

    for seed in seeds:
        try:
            scenario = random_team(seed)
            record = simulate(scenario, sample_dt=0.05, progress=cap)
        except (ValueError, RuntimeError) as error:
            print(f'{seed}: {error}')
            continue
        times, x = record.samples.times, np.asarray(record.samples.positions)
        gaps = min(np.diff(t).min() for t in record.trigger_times.values() if len(t) > 1)
        print(
            f'{seed}: n={scenario.n} D={scenario.safety.min_separation:.3f} '
            f'closest={closest_approach(times, x)[0]:.4f} events={record.total_events} '
            f'to 5 cm={settling_time(scenario, times, x, 0.05):.2f} least inter-event={gaps:.4g}'
        )


def _seed_count(text: str) -> int:
    """An integer >= 0 (argparse type: a value that breaks it is refused, exit 2)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'must be an integer >= 0, got {short_repr(text)}') from None
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be an integer >= 0, got {value!r}')
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='python -m formation_sim.sim.safety_cases',
        description=(
            "Print docs/SAFETY.md's table of the safety layer on seeded random placements (4 robots in a "
            '2.2 m square forming a 1 m square; D = 0.25 m, the layer off and on), or with --stress the '
            'stress sweep over random teams.'
        ),
        epilog=(
            'Examples: python -m formation_sim.sim.safety_cases 20 (the table, seeds 0-19); '
            'python -m formation_sim.sim.safety_cases --stress 0 40 (the sweep, seeds 0-39). '
            'Exit status: 0 printed; 2 bad arguments (nothing run).'
        ),
    )
    parser.add_argument(
        'seeds',
        nargs='?',
        type=_seed_count,
        default=None,
        metavar='SEEDS',
        help=f'how many placements: seeds 0 .. SEEDS-1 (an integer >= 0; default: {TABLE_SEEDS})',
    )
    parser.add_argument(
        '--stress',
        nargs=2,
        type=_seed_count,
        metavar=('FIRST', 'STOP'),
        help='print the stress sweep instead, a line per random team of seeds FIRST .. STOP-1 (FIRST < STOP)',
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Print the SEEDS-placement table of docs/SAFETY.md (D = 0.25 m, the layer's defaults;
    `TABLE_SEEDS` by default), or with `--stress FIRST STOP` the stress sweep over those seeds.
    Bad arguments: argparse's message naming the rule and the value, exit 2, nothing run."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.stress is None:
        print_table(range(TABLE_SEEDS if args.seeds is None else args.seeds))
        return 0
    first, stop = args.stress
    if args.seeds is not None:
        parser.error(
            f'SEEDS and --stress exclude each other (the table or the sweep), got SEEDS {args.seeds}'
        )
    if not first < stop:
        parser.error(f'argument --stress: FIRST must be < STOP, got FIRST {first} and STOP {stop}')
    stress(range(first, stop))
    return 0


def print_table(seeds) -> None:
    """docs/SAFETY.md's table, a row per `random_square` seed: the layer off and on."""
    safety = SafetyConfig(min_separation=0.25)
    print(
        '| seed | closest off [m] | closest on [m] | events off | events on | to 5 cm off [s] '
        '| to 5 cm on [s] | largest edge on [m] | least inter-event on [s] | last intervention [s] |'
    )
    print('|---|---|---|---|---|---|---|---|---|---|')
    for seed in seeds:
        off = measure(random_square(seed, safety=None))
        on = measure(random_square(seed, safety=safety))
        print(
            f'| {seed} | {off["closest"]:.4f} | {on["closest"]:.4f} | {off["events"]} | {on["events"]} | '
            f'{off["settle"]:.2f} | {on["settle"]:.2f} | {on["edge"]:.3f} | {on["least_gap"]:.4f} | '
            f'{on["last_intervention"]:.2f} |'
        )


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
