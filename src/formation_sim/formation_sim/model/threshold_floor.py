"""What stays guaranteed with a threshold floor c0 > 0: the bounds of docs/SPEED_SCALE.md, "The
threshold floor", in the paper's time s (a run at speed scale κ reaches them at t = s/κ).

With ||e_i(s)|| <= θ(s) = c0 + α e^{-βs} (ETA-1) or ||E_i(s)|| <= c0 + α_d e^{-β_d s} (ETA-2) the
paper's tension bound no longer stays bounded and the decay to the formation becomes practical:

* ETA-1, proven: if c0 < β0 c_min sqrt(2/n) (c_min = min Δ - ||d_ij||; equivalently the ultimate
  ball c0 sqrt(n/2)/β0 lies within c_min), the tension stays below k_ν (a sublevel-set argument,
  `_tension_bound`), so every edge stays within k_ij < Δ - ||d_ij||; V(s) <= B(s) (`lyapunov_bound`)
  with B(s) -> V_∞ = n c0²/(8β0²); and the inter-event times are at least ξ_i = c0/c_i.
* ETA-2, proven only where 2 sqrt(sup V_d / λmin(P)) < c_min (the corrected chain of
  docs/THEOREM2.md): then V_d(s) <= B_d(s) -> n c0²/(8 β1 γ), γ = (2-k4)/λmax(P), every edge and
  relative velocity stays within that radius, and ξ^d_i = c0/c^d_i. Where the condition fails
  (the paper's example, already at c0 = 0) nothing is proven: runs check it numerically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from formation_sim.model import theory

# Trial values of λ in (1+λ)c0² + (1+1/λ)α² e^{-2βs} >= θ(s)², over which k_ν is minimised.
_LAMBDA_TRIALS = 400


@dataclass(frozen=True, kw_only=True)
class FloorBounds:
    """The guarantees with a floor c0 > 0, in the paper's time; see the module docstring."""

    theorem: int
    floor: float  # c0
    condition: str  # the connectivity condition, in words
    value: float  # its left side ...
    limit: float  # ... below its right side when it holds
    proven: bool  # value < limit: connectivity and every bound below are proven
    ultimate: float  # V_∞ (ETA-1) or V_d∞ (ETA-2)
    ball: float  # ultimate bound on ||x_i - x_j - d_ij||: 2 sqrt(z_gain V_∞)
    z_gain: float  # ||y_i - y_j||² <= 4 z_gain V (1; ETA-2 corrected: 1/λmin(P))
    k_nu: float | None  # ETA-1: sup ν
    k_edge: dict[tuple[int, int], float] | None  # ||y_ij|| <= k_edge
    c: dict[int, float] | None  # sup ||ė_i|| (||Ė_i||)
    xi: dict[int, float] | None  # c0 / c_i: inter-event time lower bounds
    V0: float
    decay: float  # 2β0 (ETA-1) or 2γ (ETA-2): V' <= -decay V + gain ||e||²
    gain: float  # 1/(4β0) or 1/(4β1), times n for the team
    n: int
    alpha: float
    rate: float  # β or β_d

    def lyapunov_bound(self, s):
        """B(s) >= V(s) (V_d(s)): the solution of V' = -decay V + gain n θ(s)², V(0) = V0."""
        s = np.asarray(s, dtype=float)
        c0, alpha, rate, decay = self.floor, self.alpha, self.rate, self.decay
        forced = c0 * c0 * _kernel(s, decay, 0.0) + 2.0 * c0 * alpha * _kernel(s, decay, rate)
        forced = forced + alpha * alpha * _kernel(s, decay, 2.0 * rate)
        return self.V0 * np.exp(-decay * s) + self.gain * self.n * forced

    def to_dict(self) -> dict[str, Any]:
        return {
            'threshold_floor': self.floor,
            'condition': self.condition,
            'value': self.value,
            'limit': self.limit,
            'proven': self.proven,
            'V_inf': self.ultimate,
            'ball': self.ball,
            'k_nu': self.k_nu,
            'k_ij': None if self.k_edge is None else {f'{i}-{j}': v for (i, j), v in self.k_edge.items()},
            'c_i': None if self.c is None else {str(k): v for k, v in self.c.items()},
            'xi_i': None if self.xi is None else {str(k): v for k, v in self.xi.items()},
        }


def _kernel(s, r1: float, r2: float):
    """∫_0^s e^{-r1 (s-τ)} e^{-r2 τ} dτ = e^{-r2 s} (1 - e^{-(r1-r2) s}) / (r1 - r2), without cancellation."""
    if r1 == r2:
        return s * np.exp(-r1 * s)
    return np.exp(-r2 * s) * -np.expm1(-(r1 - r2) * s) / (r1 - r2)


def floor_bounds(scenario) -> FloorBounds | None:
    """The floor's guarantees for `scenario` (None without a floor: the paper's theorems hold).

    Raises TheoryError outside the theorems' hypotheses (the floor changes none of them).
    """
    c0 = scenario.gains.threshold_floor
    if c0 == 0.0:
        return None
    constants = theory.theorem_constants(scenario)
    if constants.theorem == 1:
        return _eta1(scenario, constants, c0)
    return _eta2(scenario, constants, c0)


def eta1_floor_limit(beta0: float, smallest_capacity: float, n: int) -> float:
    """The largest c0 (excluded) for which ETA-1's connectivity is proven: β0 c_min sqrt(2/n)."""
    return beta0 * smallest_capacity * math.sqrt(2.0 / n)


def _eta1(scenario, constants, c0: float) -> FloorBounds:
    n, alpha, beta, b0 = scenario.n, scenario.gains.alpha, scenario.gains.beta, constants.beta0
    capacities = theory.edge_capacities(scenario)
    c_min = float(capacities.min())
    limit = eta1_floor_limit(b0, c_min, n)
    proven = c0 < limit
    common = dict(
        theorem=1,
        floor=c0,
        value=c0,
        limit=limit,
        proven=proven,
        z_gain=1.0,
        V0=constants.V0,
        decay=2.0 * b0,
        gain=1.0 / (4.0 * b0),
        n=n,
        alpha=alpha,
        rate=beta,
        condition=(
            f'c0 < β0 min(Δ-||d_ij||) sqrt(2/n) = {limit:.6g} (the ultimate ball c0 sqrt(n/2)/β0 within '
            'every capacity)'
        ),
        ultimate=n * c0 * c0 / (8.0 * b0 * b0),
        ball=c0 * math.sqrt(n / 2.0) / b0,
    )
    if not proven:
        return FloorBounds(k_nu=None, k_edge=None, c=None, xi=None, **common)
    k_nu = _tension_bound(
        constants.nu0, n=n, m=len(scenario.edges), alpha=alpha, beta=beta, beta0=b0, c0=c0, c_min=c_min
    )
    # ||y_ij|| within both the tension's bound (kij) and 2 sqrt(sup V), sup V <= max(V0, n θ(0)²/(8β0²)).
    sup_v = max(constants.V0, n * (c0 + alpha) ** 2 / (8.0 * b0 * b0))
    k_edge = np.minimum(theory._edge_bound(k_nu, capacities), 2.0 * math.sqrt(sup_v))
    heads, tails, _ = scenario.edge_indices()
    f = theory.f_ij(k_edge, capacity=capacities)
    g = theory.g_ij(k_edge, capacity=capacities)
    # ||ẏ_i|| <= ||e_i|| + Σ_l ω_il ||y_il|| <= c0 + α + Σ_l f_il(k_il) k_il   (dotyi), and
    # ||ė_i|| <= Σ_j g_ij(k_ij) (||ẏ_i|| + ||ẏ_j||)   (dotnormei), without the decay.
    speed = (c0 + alpha) + theory._per_agent_sum(n, heads, tails, f * k_edge)
    c = theory._per_agent_sum(n, heads, tails, g * (speed[heads] + speed[tails]))
    return FloorBounds(
        k_nu=k_nu,
        k_edge=dict(zip((e.pair for e in scenario.edges), k_edge.tolist())),
        c=dict(zip(scenario.agent_ids, c.tolist())),
        xi=dict(zip(scenario.agent_ids, (c0 / c).tolist())),
        **common,
    )


def _tension_bound(
    nu0: float, *, n: int, m: int, alpha: float, beta: float, beta0: float, c0: float, c_min: float
) -> float:
    """sup ν for ETA-1 with the floor (a = 1/2), the smallest over λ of max(ν0, N_c) + A:

    ν' <= -4β0² V + (n/2) θ², θ² <= (1+λ) c0² + (1+1/λ) α² e^{-2βs}; W = ν - A (1 - e^{-2βs}),
    A = n (1+1/λ) α² / (4β), has W' <= -4β0² V + n (1+λ) c0² / 2, which is <= 0 once V >= R²/4,
    R = c0 sqrt(n (1+λ)/2) / β0 < c_min; ν >= N_c = m R²/(c_min - R) forces an edge to ||y_ij|| >= R,
    hence V >= R²/4. So W <= max(ν0, N_c) and ν <= max(ν0, N_c) + A.
    """
    top = 2.0 * (beta0 * c_min / c0) ** 2 / n  # (1+λ) must stay below this for R < c_min
    best = math.inf
    for lam in np.geomspace(1e-9 * (top - 1.0), (top - 1.0) * (1.0 - 1e-9), _LAMBDA_TRIALS):
        radius = c0 * math.sqrt(n * (1.0 + lam) / 2.0) / beta0
        if not radius < c_min:
            continue
        level = max(nu0, m * radius * radius / (c_min - radius))
        best = min(best, level + n * (1.0 + 1.0 / lam) * alpha * alpha / (4.0 * beta))
    return best


def _eta2(scenario, constants, c0: float) -> FloorBounds:
    n, gains = scenario.n, scenario.gains
    k1, k2, k3, alpha_d, beta_d, beta1 = (
        gains.k1,
        gains.k2,
        gains.k3,
        gains.alpha_d,
        gains.beta_d,
        gains.beta1,
    )
    capacities = theory.edge_capacities(scenario)
    c_min = float(capacities.min())
    gamma = (2.0 - constants.k4) / constants.lambda_max_P  # the corrected rate (docs/THEOREM2.md)
    z_gain = 1.0 / constants.rho2_P
    sup_v = max(constants.V0, n * (c0 + alpha_d) ** 2 / (8.0 * beta1 * gamma))
    radius = 2.0 * math.sqrt(z_gain * sup_v)  # ||y_ij||, ||q_ij|| <= radius
    proven = radius < c_min
    ultimate = n * c0 * c0 / (8.0 * beta1 * gamma)
    common = dict(
        theorem=2,
        floor=c0,
        value=radius,
        limit=c_min,
        proven=proven,
        z_gain=z_gain,
        V0=constants.V0,
        decay=2.0 * gamma,
        gain=1.0 / (4.0 * beta1),
        n=n,
        alpha=alpha_d,
        rate=beta_d,
        k_nu=None,
        condition=f'2 sqrt(sup V_d / λmin(P)) = {radius:.6g} < min(Δ-||d_ij||) = {c_min:.6g}',
        ultimate=ultimate,
        ball=2.0 * math.sqrt(z_gain * ultimate),
    )
    if not proven:
        return FloorBounds(k_edge=None, c=None, xi=None, **common)
    heads, tails, _ = scenario.edge_indices()
    k_edge = np.full(len(scenario.edges), radius)
    f = theory.f_ij(k_edge, capacity=capacities)
    g = theory.g_ij(k_edge, capacity=capacities)
    h = theory.h_ij(k_edge, capacity=capacities)
    F = theory._per_agent_sum(n, heads, tails, f)
    # (cijq) and c^d_i (doteq) with every decaying factor replaced by its supremum.
    c_q = 2.0 * (c0 + alpha_d) + ((k1 + k2) * (F[heads] + F[tails]) + k3) * radius
    per_edge = k1 * g * radius + k2 * h * radius * radius + k2 * f * c_q
    c = theory._per_agent_sum(n, heads, tails, per_edge)
    return FloorBounds(
        k_edge=dict(zip((e.pair for e in scenario.edges), k_edge.tolist())),
        c=dict(zip(scenario.agent_ids, c.tolist())),
        xi=dict(zip(scenario.agent_ids, (c0 / c).tolist())),
        **common,
    )
