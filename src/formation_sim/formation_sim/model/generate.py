"""Random scenarios that satisfy every hypothesis of Theorem 1 or 2 by construction.

Construction (seeded, numpy Generator):

1. Target points τ_i and the graph (`graph`, one of GRAPH_FAMILIES), with reach r = REACH_FRACTION Δ:
   'geometric' (the default): τ_i uniform in a box sized for the requested mean degree; pairs
   within r (KD-tree) are the edges; agents outside the largest component are moved, one by one,
   next to an already connected agent, which makes the graph connected without any O(n²) step.
   'star' (agent 1 in the centre), 'cycle' (n >= 3) and 'complete': τ_i uniform in a ball of
   diameter r, so every pair is within r; 'path': a random walk with steps of 0.3..0.9 r.
   Either way d_ij = τ_i - τ_j, so the formation is feasible and ||d_ij|| <= r < Δ (Assumption 1).
3. Offsets y_i from a ball are scaled so that the tightest edge has exactly
   ||y_i - y_j|| = (1 - slack)(Δ - ||d_ij||); x_i(0) = τ_i + y_i then meets (initial) with at least
   that slack on every edge.
4. Gains: single β = β0/2; double β1 = β0, P from (riccatti), k3 half its bound (k4 = 1, the paper's
   choice) and β_d half the smaller of the printed and the corrected bound (docs/THEOREM2.md).
   The keyword arguments beta, beta1, k3 and beta_d choose other fractions of those bounds
   (what `formation study` draws); their defaults are the rule above, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from formation_sim.model import theory
from formation_sim.model.errors import GenerateError
from formation_sim.model.gains import beta_d_bound_corrected, beta_d_bound_paper, k3_upper_bound
from formation_sim.model.scenario import DoubleGains, Edge, Scenario, SingleGains

REACH_FRACTION = 0.75  # ||d_ij|| <= 0.75 Δ, leaving at least Δ/4 for ||y_i - y_j||
BETA_FRACTION = 0.5  # β = β0 / 2
BETA_D_FRACTION = 0.5  # β_d = half of min(printed, corrected) bound
GRAPH_FAMILIES = ('geometric', 'star', 'path', 'cycle', 'complete')


def _ball_volume(radius: float, dimension: int) -> float:
    return math.pi ** (dimension / 2.0) * radius**dimension / math.gamma(dimension / 2.0 + 1.0)


def _in_ball(rng: np.random.Generator, count: int, dimension: int) -> np.ndarray:
    """`count` points uniform in the unit ball of R^dimension."""
    direction = rng.standard_normal((count, dimension))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = rng.random(count) ** (1.0 / dimension)
    return direction * radius[:, None]


def _connected_points(
    rng: np.random.Generator, n: int, dimension: int, reach: float, degree: float
) -> tuple[np.ndarray, np.ndarray]:
    """Points and their geometric-graph pairs (i < j, distance <= reach) forming a connected graph."""
    mean_degree = min(degree, n - 1)
    side = (n * _ball_volume(reach, dimension) / mean_degree) ** (1.0 / dimension)
    points = rng.uniform(0.0, side, size=(n, dimension))
    pairs = cKDTree(points).query_pairs(reach, output_type='ndarray')
    adjacency = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(adjacency, directed=False)
    largest = np.bincount(labels).argmax()
    anchors = list(np.flatnonzero(labels == largest))
    strays = np.flatnonzero(labels != largest)
    if strays.size:
        rng.shuffle(strays)
        for k in strays:
            anchor = anchors[rng.integers(len(anchors))]
            # Within 0.3..0.9 r of a connected agent: linked to it, never a duplicate point.
            offset = _in_ball(rng, 1, dimension)[0]
            offset *= reach * rng.uniform(0.3, 0.9) / np.linalg.norm(offset)
            points[k] = points[anchor] + offset
            anchors.append(k)
        pairs = cKDTree(points).query_pairs(reach, output_type='ndarray')
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return points, pairs[order]


def _family_points(
    rng: np.random.Generator, n: int, dimension: int, reach: float, graph: str
) -> tuple[np.ndarray, np.ndarray]:
    """Points and the pairs (i < j, sorted) of a star, path, cycle or complete graph, each pair within
    reach."""
    if graph == 'path':
        steps = _in_ball(rng, n - 1, dimension)
        norms = np.linalg.norm(steps, axis=1, keepdims=True)
        steps = steps / np.where(norms > 0.0, norms, 1.0) * (reach * rng.uniform(0.3, 0.9, size=(n - 1, 1)))
        points = np.vstack([np.zeros((1, dimension)), np.cumsum(steps, axis=0)])
    else:
        points = 0.5 * reach * _in_ball(rng, n, dimension)  # a ball of diameter r: every pair within r
    first = np.arange(n - 1)
    if graph == 'star':
        pairs = np.column_stack([np.zeros(n - 1, dtype=np.intp), first + 1])
    elif graph in ('path', 'cycle'):
        pairs = np.column_stack([first, first + 1])
        if graph == 'cycle':
            pairs = np.vstack([pairs, [[0, n - 1]]])
    else:
        pairs = np.column_stack(np.triu_indices(n, 1))
    pairs = pairs.astype(np.intp)
    points -= points.mean(axis=0)  # centred: the smaller the coordinates, the finer their rounding
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return points, pairs[order]


def random_scenario(
    *,
    n: int,
    seed: int,
    dynamics: str = 'single',
    dimension: int = 2,
    slack: float = 0.5,
    delta: float = 4.0,
    degree: float = 6.0,
    horizon: float = 10.0,
    alpha: float = 1.0,
    max_speed: float = 1.0,
    name: str | None = None,
    graph: str = 'geometric',
    beta: float = BETA_FRACTION,
    beta1: float = 1.0,
    k3: float | None = None,
    beta_d: float | None = None,
) -> Scenario:
    """A valid scenario with agents 1..n (see the module docstring for the construction).

    slack in (0, 1]: the least relative slack of (initial) over the edges (1 = start in formation).
    degree: target mean degree of the geometric graph. max_speed: |q_i(0)| bound (double).
    graph: one of GRAPH_FAMILIES. Gains as fractions of the theorems' bounds: beta of β0 in (0, 1)
    (single); beta1 of β0 in (0, 1], k3 of 4/(k2+sqrt(k1²+k2²)) in (0, 1) (None: the paper's k3,
    half the bound), beta_d of the printed (2-k4)ρ2(P) in (0, 1) (None: half the smaller of the
    printed and the corrected bound) (double).
    """
    _check_arguments(
        n=n,
        dynamics=dynamics,
        dimension=dimension,
        slack=slack,
        graph=graph,
        beta=beta,
        beta1=beta1,
        k3=k3,
        beta_d=beta_d,
        delta=delta,
        degree=degree,
        horizon=horizon,
        alpha=alpha,
        max_speed=max_speed,
    )

    rng = np.random.default_rng(seed)
    positions, velocities, pairs, d = _random_team(
        rng,
        n=n,
        dimension=dimension,
        delta=delta,
        degree=degree,
        graph=graph,
        slack=slack,
        max_speed=max_speed if dynamics == 'double' else None,
    )
    ids = tuple(range(1, n + 1))
    edges = tuple(Edge(i=int(i) + 1, j=int(j) + 1, d=dk) for (i, j), dk in zip(pairs, d))
    placeholder = (
        SingleGains(alpha=alpha, beta=1.0)
        if dynamics == 'single'
        else DoubleGains.from_riccati(alpha_d=alpha, beta_d=1.0, beta1=1.0, k3='paper')
    )
    scenario = Scenario(
        name=name or f'random_{dynamics}_n{n}_seed{seed}',
        dynamics=dynamics,
        delta=float(delta),
        agent_ids=ids,
        positions=positions,
        velocities=velocities,
        edges=edges,
        gains=placeholder,
        horizon=float(horizon),
    )
    beta0 = theory.beta0(scenario)
    if dynamics == 'single':
        return scenario.replace(gains=SingleGains(alpha=alpha, beta=beta * beta0))
    return scenario.replace(gains=_double_gains(alpha=alpha, beta1=beta1 * beta0, k3=k3, beta_d=beta_d))


def _random_team(
    rng: np.random.Generator,
    *,
    n: int,
    dimension: int,
    delta: float,
    degree: float,
    graph: str,
    slack: float,
    max_speed: float | None,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """The drawn team: positions, velocities (None without `max_speed`), the edges' index pairs and
    their d_ij (module docstring), drawn from `rng` in that order."""
    reach = REACH_FRACTION * delta
    if graph == 'geometric':
        tau, pairs = _connected_points(rng, n, dimension, reach, degree)
    else:
        tau, pairs = _family_points(rng, n, dimension, reach, graph)
    d = tau[pairs[:, 0]] - tau[pairs[:, 1]]
    capacities = delta - np.linalg.norm(d, axis=1)

    offsets = _in_ball(rng, n, dimension)
    ratios = np.linalg.norm(offsets[pairs[:, 0]] - offsets[pairs[:, 1]], axis=1) / capacities
    worst = float(ratios.max())
    offsets = offsets * ((1.0 - slack) / worst) if worst > 0.0 else np.zeros_like(offsets)
    positions = tau + offsets
    velocities = max_speed * _in_ball(rng, n, dimension) if max_speed is not None else None
    return positions, velocities, pairs, d


def _check_arguments(
    *, n, dynamics, dimension, slack, graph, beta, beta1, k3, beta_d, delta, degree, horizon, alpha, max_speed
) -> None:
    """random_scenario's arguments, each against its rule (GenerateError names the first broken)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise GenerateError(f'n must be an integer >= 2, got {n!r}')
    if dynamics not in ('single', 'double'):
        raise GenerateError(f"dynamics must be 'single' or 'double', got {dynamics!r}")
    if isinstance(dimension, bool) or not isinstance(dimension, int) or dimension < 1:
        raise GenerateError(f'dimension must be an integer >= 1, got {dimension!r}')
    if not 0.0 < slack <= 1.0:
        raise GenerateError(f'slack must lie in (0, 1], got {slack!r}')
    if graph not in GRAPH_FAMILIES:
        raise GenerateError(f'graph must be one of {", ".join(GRAPH_FAMILIES)}, got {graph!r}')
    if graph == 'cycle' and n < 3:
        raise GenerateError(f'a cycle needs n >= 3 agents, got n = {n}')
    for label, value, closed in (
        ('beta', beta, False),
        ('beta1', beta1, True),
        ('k3', k3, False),
        ('beta_d', beta_d, False),
    ):
        if value is not None and not (0.0 < value < 1.0 or (closed and value == 1.0)):
            raise GenerateError(
                f'{label} is a fraction of its bound in (0, {"1]" if closed else "1)"}, got {value!r}'
            )
    for label, value in (('delta', delta), ('degree', degree), ('horizon', horizon), ('alpha', alpha)):
        if not (math.isfinite(value) and value > 0.0):
            raise GenerateError(f'{label} must be finite and > 0, got {value!r}')
    if not (math.isfinite(max_speed) and max_speed >= 0.0):
        raise GenerateError(f'max_speed must be finite and >= 0, got {max_speed!r}')


def _double_gains(*, alpha: float, beta1: float, k3: float | None, beta_d: float | None) -> DoubleGains:
    """ETA-2's gains for this β1: P from (riccatti), k3 and β_d as fractions of their bounds
    (random_scenario)."""
    gains = DoubleGains.from_riccati(alpha_d=alpha, beta_d=1.0, beta1=beta1, k3='paper')
    k3_value = 'paper' if k3 is None else k3 * k3_upper_bound(gains.k1, gains.k2)
    gains = DoubleGains.from_riccati(alpha_d=alpha, beta_d=1.0, beta1=beta1, k3=k3_value)
    if beta_d is None:
        rate = BETA_D_FRACTION * min(beta_d_bound_paper(gains), beta_d_bound_corrected(gains))
    else:
        rate = beta_d * beta_d_bound_paper(gains)
    return DoubleGains.from_riccati(alpha_d=alpha, beta_d=rate, beta1=beta1, k3=k3_value)
