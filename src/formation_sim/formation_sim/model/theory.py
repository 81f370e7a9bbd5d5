"""Graph quantities, the paper's hypotheses and the constants of the proofs of Theorems 1 and 2.

ROS-free. Every function takes a `formation_sim.model.scenario.Scenario` (duck-typed, so this module does
not import it) and arrays in the scenario's agent order (row k is agent `agent_ids[k]`).

Conventions and corrections (equation labels are the paper's):

* The incidence matrix orients edge e_k = (i, j) with head i (+1) and tail j (-1), so D^T x stacks
  x_i - x_j; DD^T = L does not depend on the orientation (Lemma 1).
* ρ2(DD^T) is the smallest positive Laplacian eigenvalue, the algebraic connectivity of a connected
  graph; 0 is returned for a disconnected graph.
* (betaV) prints [e^{-2βt} - 1]; the solution of V' <= -2β0 V + (nα²/4β0) e^{-2βt} has
  [e^{-2βt} - e^{-2β0 t}]. (kV) and everything after it are unaffected.
* Proof of Theorem 2 (ii): V_d' <= -(2-k4) ||δz||² (δz = (K_n⊗I_2⊗I_p) z) and
  V_d = ½ δz^T (I_n⊗P⊗I_p) δz <= ½ λmax(P) ||δz||², hence V_d' <= -2 (2-k4)/λmax(P) V_d + ...
  The paper writes ρ2(P) (= λmin(P) for P > 0) in place of 1/λmax(P); that inequality goes the wrong
  way. Likewise (yiyj) needs ||z_i - z_j||² <= 2||δz||² <= 4 V_d / λmin(P); the paper drops the
  1/λmin(P). Both readings are computed (`Theorem2Chain`); see docs/THEOREM2.md for the evidence.
* (dotqie)/(dotqi) are garbled in print; the bound meant is ||q_i' - q_j'|| < c^q_ij e^{-β_d t}.
* The derivative of V_d has "(PC + CP^T)/2" and "E(T)"; meant are (PC + C^T P)/2 and E(t).

Every constant here is of the paper's time s: a run at speed scale κ (docs/SPEED_SCALE.md) is the
paper's at s = κt, so its rates are κβ, κβ_d and its inter-event bounds ξ_i/κ in seconds (the
analysis and the summary convert); with a threshold floor c0 > 0 the guarantees are those of
`formation_sim.model.threshold_floor`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from formation_agent.core.tension import omega, omega_prime, weight_gain
from formation_sim.model.errors import TheoryError
from formation_sim.model.gains import (
    INSIDE,
    OUTSIDE,
    ROUNDING_ULPS,
    against_bound,
    k3_upper_bound,
    k4_value,
    riccati_holds,
)

if TYPE_CHECKING:  # pragma: no cover
    from formation_sim.model.scenario import Scenario

# Below this many agents eigenvalues come from a dense solver, above from sparse shift-invert.
DENSE_LIMIT = 400

# Default free parameters of the proofs: any a in (0, 1) (Theorem 1 (i)) and b in (0, k3)
# (Theorem 2 (i)) give valid bounds; the midpoints are the documented defaults.
DEFAULT_A = 0.5
DEFAULT_B_FRACTION = 0.5


# --------------------------------------------------------------------------- graph


def incidence_matrix(scenario: Scenario, *, sparse: bool = False):
    """The n x m incidence matrix D: column k has +1 at edge k's i (head) and -1 at its j (tail)."""
    heads, tails, _ = scenario.edge_indices()
    m = heads.size
    columns = np.concatenate([np.arange(m), np.arange(m)])
    rows = np.concatenate([heads, tails])
    values = np.concatenate([np.ones(m), -np.ones(m)])
    matrix = sp.csr_matrix((values, (rows, columns)), shape=(scenario.n, m))
    return matrix if sparse else matrix.toarray()


def laplacian(scenario: Scenario, weights=None, *, sparse: bool = False):
    """L = DD^T, or L_ω = D W D^T with W = diag(weights) in edge order (Lemma 1)."""
    d_matrix = incidence_matrix(scenario, sparse=True)
    w = np.ones(d_matrix.shape[1]) if weights is None else np.asarray(weights, dtype=float)
    matrix = (d_matrix @ sp.diags(w) @ d_matrix.T).tocsr()
    return matrix if sparse else matrix.toarray()


def graph_components(scenario: Scenario) -> list[tuple[int, ...]]:
    """Connected components as tuples of agent ids, largest first."""
    adjacency = incidence_matrix(scenario, sparse=True)
    adjacency = (abs(adjacency) @ abs(adjacency).T).tocsr()
    count, labels = connected_components(adjacency, directed=False)
    groups: list[list[int]] = [[] for _ in range(count)]
    for agent, label in zip(scenario.agent_ids, labels):
        groups[label].append(agent)
    return sorted((tuple(group) for group in groups), key=lambda g: (-len(g), g[0]))


def is_connected(scenario: Scenario) -> bool:
    return len(graph_components(scenario)) == 1


def algebraic_connectivity(scenario: Scenario) -> float:
    """ρ2(DD^T): second smallest Laplacian eigenvalue (0 when the graph is disconnected)."""
    if not is_connected(scenario):
        return 0.0
    lap = laplacian(scenario, sparse=True)
    if scenario.n <= DENSE_LIMIT:
        return float(np.linalg.eigvalsh(lap.toarray())[1])
    # Shift-invert just below 0: the two eigenvalues nearest the shift are 0 and ρ2.
    shift = 1e-9 * float(lap.diagonal().max())
    start = np.random.default_rng(0).standard_normal(scenario.n)
    values = spla.eigsh(lap.tocsc(), k=2, sigma=-shift, which='LM', v0=start, return_eigenvectors=False)
    return float(np.sort(values)[1])


def edge_capacities(scenario: Scenario) -> np.ndarray:
    """The capacity c = Δ - ||d_ij|| of each edge: what (initial) leaves for ||y_i - y_j||."""
    _, _, d = scenario.edge_indices()
    return scenario.delta - np.linalg.norm(d, axis=1)


def delta0(scenario: Scenario) -> float:
    """Δ0 = max over edges of Δ - ||d_ij|| (Theorem 1)."""
    return float(edge_capacities(scenario).max())


def beta0(scenario: Scenario) -> float:
    """β0 = ρ2(DD^T) / Δ0 (Theorem 1); the paper's example gives 1.5."""
    return algebraic_connectivity(scenario) / delta0(scenario)


def remark_beta_bound(scenario: Scenario) -> float:
    """4 / (n (n-1) Δ) <= β0, the lower bound of Remark 3.2 that each agent can evaluate alone."""
    n = scenario.n
    return 4.0 / (n * (n - 1) * scenario.delta)


def edge_errors(scenario: Scenario, positions) -> np.ndarray:
    """||x_i - x_j - d_ij|| = ||y_i - y_j|| per edge."""
    heads, tails, d = scenario.edge_indices()
    x = np.asarray(positions, dtype=float)
    return np.linalg.norm(x[heads] - x[tails] - d, axis=1)


def formation_error(scenario: Scenario, positions) -> float:
    """max over edges of ||x_i - x_j - d_ij||."""
    return float(edge_errors(scenario, positions).max())


@dataclass(frozen=True, kw_only=True)
class Feasibility:
    """Least-squares τ for τ_i - τ_j = d_ij; Φ is non-empty iff the residual is (numerically) 0."""

    tau: np.ndarray  # (n, p), one τ per component pinned at 0 for the component's first agent
    edge_residuals: np.ndarray  # (m,) ||τ_i - τ_j - d_ij||
    residual: float  # max of edge_residuals
    tolerance: float
    feasible: bool


def formation_feasibility(scenario: Scenario) -> Feasibility:
    """Solve min_τ Σ ||τ_i - τ_j - d_ij||² through its normal equations DD^T τ = D d."""
    heads, tails, d = scenario.edge_indices()
    n, p = scenario.n, scenario.dimension
    d_matrix = incidence_matrix(scenario, sparse=True)
    lap = (d_matrix @ d_matrix.T).tocsc()
    rhs = np.asarray(d_matrix @ d, dtype=float).reshape(n, p)
    # L is singular once per component: pin the first agent of each component at 0.
    index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
    pinned = np.array([index[group[0]] for group in graph_components(scenario)])
    free = np.setdiff1d(np.arange(n), pinned)
    tau = np.zeros((n, p))
    if free.size:
        reduced = lap[free][:, free].tocsc()
        solver = spla.splu(reduced)
        solution = solver.solve(rhs[free])
        solution += solver.solve(rhs[free] - reduced @ solution)  # one step of refinement
        tau[free] = solution
    residuals = np.linalg.norm(tau[heads] - tau[tails] - d, axis=1)
    residual = float(residuals.max()) if residuals.size else 0.0
    tolerance = 1e-9 * max(1.0, scenario.delta)
    return Feasibility(
        tau=tau,
        edge_residuals=residuals,
        residual=residual,
        tolerance=tolerance,
        feasible=residual <= tolerance,
    )


# --------------------------------------------------------------------------- (fij), (gij), (hij)


def _edge_domain(l, capacity):
    l = np.asarray(l, dtype=float)
    c = np.asarray(capacity, dtype=float)
    if np.any(c <= 0.0):
        raise TheoryError(f'Δ - ||d_ij|| must be > 0, got {np.min(c)!r}')
    if np.any(l < 0.0) or np.any(l >= c):
        raise TheoryError(f'l = ||y_i - y_j|| must lie in [0, Δ - ||d_ij||), got l={l!r}, Δ-||d||={c!r}')
    return l, c


def f_ij(l, *, capacity):
    """(fij): (2c - l) / (c - l)², c = Δ - ||d_ij||; ω_ij = f_ij(||y_i - y_j||)."""
    l, c = _edge_domain(l, capacity)
    return omega(l, c)


def g_ij(l, *, capacity):
    """(gij): 2c² / (c - l)³ = h_ij(l) l + f_ij(l), the gain in ||e_i'|| of (dotnormei)."""
    l, c = _edge_domain(l, capacity)
    return weight_gain(l, c)


def h_ij(l, *, capacity):
    """(hij): (3c - l) / (c - l)³ = f_ij'(l)."""
    l, c = _edge_domain(l, capacity)
    return omega_prime(l, c)


def rounding_step(capacity, slack, ulp_y, *, k1=1.0, k2=0.0, speed=0.0, ulp_q=0.0):
    """How far one rounding step of an edge's relative state moves the triggering error.

    ETA-1: e_i = Σ_j ω_ij y_ij + u_i, and y -> ω(||y||) y has derivative at most g_ij (gij), so an
    ulp of y_ij moves e_i by up to ρ = g_ij ulp(y_ij). ETA-2: E_i = Σ_j ω_ij (k1 y_ij + k2 q_ij) +
    u^d_i (triggerdouble) moves by (k1 g_ij + k2 h_ij ||q_ij||) ulp(y_ij) + k2 f_ij ulp(q_ij)
    (hij), (fij). ρ has the units of the threshold. Written through c/σ, with the slack
    σ = c - ||y_ij|| (c = `capacity`, Δ - ||d_ij||): g = 2c²/σ³, h = (2c + σ)/σ³, f = (c + σ)/σ²,
    so no intermediate overflows for any finite Δ. Elementwise on arrays (edges); `k2` a number.
    The one place of this formula: the `precision` rule of `formation_sim.model.validate` (at
    t = 0) and the engine's rounding floor (`formation_sim.sim.engine.rounding_floor`, at every event).
    """
    return rounding_step_of(rounding_factors(capacity, slack, k1=k1, k2=k2), ulp_y, speed=speed, ulp_q=ulp_q)


def rounding_factors(capacity, slack, *, k1=1.0, k2=0.0) -> tuple:
    """`rounding_step`'s factors of the ulps, which the states do not change: (k1 g, k2 h', k2 f) with
    g = 2c²/σ³, h' = (2c + σ)/σ³ (h_ij(σ) without its ||q_ij||), f = (c + σ)/σ²; the last two None
    where k2 <= 0 (ETA-1). Computed once for a fixed edge (the engine's rounding floor, at every event)."""
    ratio = capacity / slack
    gain = k1 * (2.0 * ratio * ratio / slack)
    if k2 > 0.0:
        return gain, k2 * ((2.0 * ratio + 1.0) / (slack * slack)), k2 * ((ratio + 1.0) / slack)
    return gain, None, None


def rounding_step_of(factors: tuple, ulp_y, *, speed=0.0, ulp_q=0.0):
    """`rounding_step` from its `rounding_factors`: the same operations in the same order (a * b * c is
    (a * b) * c), so the same floats."""
    gain, speed_gain, q_gain = factors
    step = gain * ulp_y
    if speed_gain is not None:
        step = step + speed_gain * (speed * ulp_y)
        step = step + q_gain * ulp_q
    return step


# --------------------------------------------------------------------------- ν, V


def tensions(scenario: Scenario, positions) -> np.ndarray:
    """ν(Δ, y) at each of K samples (positions (K, n, p)): Σ_edges ||y_i-y_j||² / (Δ-||d_ij||-||y_i-y_j||),
    inf where an edge leaves its range. Each sample's value is `tension`'s float for that sample."""
    heads, tails, d = scenario.edge_indices()
    x = np.asarray(positions, dtype=float)
    l = np.linalg.norm(x[:, heads] - x[:, tails] - d, axis=2)
    c = edge_capacities(scenario)
    with np.errstate(divide='ignore', invalid='ignore'):
        terms = l * l / (c - l)
    # one 1-D sum per sample: numpy's sum over axis 1 of a (K, m) array adds in another order (the
    # last bit differs from the sample's own sum, which `tension` and the proofs' constants use)
    values = np.fromiter((np.add.reduce(row) for row in terms), dtype=float, count=len(terms))
    return np.where(np.any(l >= c, axis=1), math.inf, values)


def tension(scenario: Scenario, positions) -> float:
    """ν(Δ, y) = ½ Σ_i Σ_{j∈N_i} ν_ij = Σ_edges ||y_i-y_j||² / (Δ-||d_ij||-||y_i-y_j||); inf outside."""
    return float(tensions(scenario, np.asarray(positions, dtype=float)[None])[0])


def tensions_double(scenario: Scenario, positions, velocities) -> np.ndarray:
    """ν_d = k1 ν + ½ Σ ||q_i||² at each of K samples (positions, velocities (K, n, p))."""
    q = np.asarray(velocities, dtype=float)
    return scenario.gains.k1 * tensions(scenario, positions) + 0.5 * np.sum(q * q, axis=(1, 2))


def tension_double(scenario: Scenario, positions, velocities) -> float:
    """ν_d = k1 ν + ½ Σ ||q_i||² (proof of Theorem 2 (i))."""
    return float(tensions_double(scenario, *_one_sample(positions, velocities))[0])


def _one_sample(*arrays) -> list[np.ndarray]:
    return [np.asarray(a, dtype=float)[None] for a in arrays]


def _deviations(scenario: Scenario, positions, tau=None) -> np.ndarray:
    """δ = y - mean(y) at each sample, y_i = x_i - τ_i (positions (K, n, p))."""
    tau = formation_feasibility(scenario).tau if tau is None else np.asarray(tau, dtype=float)
    y = np.asarray(positions, dtype=float) - tau
    return y - y.mean(axis=1, keepdims=True)


def lyapunovs(scenario: Scenario, positions, *, tau=None) -> np.ndarray:
    """V = ½ δ^T δ at each of K samples (positions (K, n, p)); each is `lyapunov`'s float."""
    delta = _deviations(scenario, positions, tau)
    return 0.5 * np.sum(delta * delta, axis=(1, 2))


def lyapunov(scenario: Scenario, positions, *, tau=None) -> float:
    """V = ½ δ^T δ, δ = (K_n⊗I_p) y, y_i = x_i - τ_i (proof of Theorem 1 (ii)); any τ ∈ Φ gives the same V."""
    return float(lyapunovs(scenario, *_one_sample(positions), tau=tau)[0])


def lyapunovs_double(scenario: Scenario, positions, velocities, *, tau=None) -> np.ndarray:
    """V_d = ½ z^T (K_n⊗P⊗I_p) z at each of K samples (positions, velocities (K, n, p))."""
    dy = _deviations(scenario, positions, tau)
    q = np.asarray(velocities, dtype=float)
    dq = q - q.mean(axis=1, keepdims=True)
    P = scenario.gains.P
    axes = (1, 2)
    return 0.5 * (
        P[0, 0] * np.sum(dy * dy, axis=axes)
        + 2.0 * P[0, 1] * np.sum(dy * dq, axis=axes)
        + P[1, 1] * np.sum(dq * dq, axis=axes)
    )


def lyapunov_double(scenario: Scenario, positions, velocities, *, tau=None) -> float:
    """V_d = ½ z^T (K_n⊗P⊗I_p) z, z_i = (y_i, q_i) (proof of Theorem 2 (ii))."""
    return float(lyapunovs_double(scenario, *_one_sample(positions, velocities), tau=tau)[0])


# --------------------------------------------------------------------------- proof constants


def _json_float(value: float | None) -> float | None:
    if value is None or not math.isfinite(value):
        return None
    return float(value)


def _json_map(mapping, key=str) -> dict[str, float | None] | None:
    if mapping is None:
        return None
    return {key(k): _json_float(v) for k, v in mapping.items()}


def _edge_name(pair: tuple[int, int]) -> str:
    return f'{pair[0]}-{pair[1]}'


@dataclass(frozen=True, kw_only=True)
class Theorem2Chain:
    """Constants of the proof of Theorem 2 (ii)-(iii) under one reading of the step to V_d.

    reading 'paper': rate_bound = (2-k4) ρ2(P) and ||z_i-z_j||² <= 4 V_d, as printed.
    reading 'corrected': rate_bound = (2-k4)/λmax(P) and ||z_i-z_j||² <= 4 V_d / λmin(P).
    When β_d >= rate_bound the proof gives nothing and k_V, c_q, c, xi are None.
    """

    reading: str
    rate_bound: float
    z_gain: float  # ||z_i - z_j||² <= 4 z_gain V_d
    holds: bool
    k_V: float | None  # (kVd)
    c_q: dict[tuple[int, int], float] | None  # (cijq), per edge as stored
    c: dict[int, float] | None  # c^d_i
    xi: dict[int, float] | None  # (xid)

    def to_dict(self) -> dict[str, Any]:
        return {
            'reading': self.reading,
            'beta_d_bound': _json_float(self.rate_bound),
            'z_gain': _json_float(self.z_gain),
            'holds': self.holds,
            'k_V_d': _json_float(self.k_V),
            'c_q_ij': _json_map(self.c_q, _edge_name),
            'c_i_d': _json_map(self.c),
            'xi_i_d': _json_map(self.xi),
        }


@dataclass(frozen=True, kw_only=True)
class TheoremConstants:
    """Constants of the proof of Theorem 1 (single) or Theorem 2 (double) for one scenario.

    For Theorem 2, k_V, c and xi are those of the corrected chain (None when β_d is not below
    (2-k4)/λmax(P)); `paper_chain` keeps the constants exactly as printed for comparison.
    """

    theorem: int
    n: int
    algebraic_connectivity: float  # ρ2(DD^T)
    delta0: float
    beta0: float
    remark_beta_bound: float
    free_parameter: float  # a in (0,1) (Theorem 1) or b in (0,k3) (Theorem 2)
    nu0: float  # ν(Δ, y(0)) or ν_d(Δ, y(0))
    k_nu: float  # (kν) k_ν or k^d_ν
    k_edge: dict[tuple[int, int], float]  # (kij) k_ij or (kijd) k^d_ij
    V0: float  # V(0) or V_d(0)
    k_V: float | None  # (kV) or corrected (kVd)
    c: dict[int, float] | None  # c_i or corrected c^d_i
    xi: dict[int, float] | None  # (xi) or corrected (xid): inter-event time lower bounds
    # Theorem 2 only
    P: np.ndarray | None = None
    rho2_P: float | None = None
    lambda_max_P: float | None = None
    k3_upper_bound: float | None = None
    k4: float | None = None
    beta_d_bound_paper: float | None = None
    beta_d_bound_corrected: float | None = None
    c_q: dict[tuple[int, int], float] | None = None
    paper_chain: Theorem2Chain | None = None
    corrected_chain: Theorem2Chain | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly: agent ids and edges 'i-j' as string keys, None for unavailable values."""
        single = self.theorem == 1
        suffix = '' if single else '_d'
        result: dict[str, Any] = {
            'theorem': self.theorem,
            'n': self.n,
            'rho2_laplacian': self.algebraic_connectivity,
            'delta0': self.delta0,
            'beta0': self.beta0,
            'remark_beta_bound': self.remark_beta_bound,
            ('a' if single else 'b'): self.free_parameter,
            f'nu{suffix}0': _json_float(self.nu0),
            f'k_nu{suffix}': _json_float(self.k_nu),
            f'k_ij{suffix}': _json_map(self.k_edge, _edge_name),
            f'V{suffix}0': _json_float(self.V0),
            f'k_V{suffix}': _json_float(self.k_V),
            f'c_i{suffix}': _json_map(self.c),
            f'xi_i{suffix}': _json_map(self.xi),
        }
        if not single:
            result.update(
                P=self.P.tolist(),
                rho2_P=self.rho2_P,
                lambda_max_P=self.lambda_max_P,
                k3_upper_bound=self.k3_upper_bound,
                k4=self.k4,
                beta_d_bound_paper=self.beta_d_bound_paper,
                beta_d_bound_corrected=self.beta_d_bound_corrected,
                c_q_ij=_json_map(self.c_q, _edge_name),
                paper_chain=self.paper_chain.to_dict(),
                corrected_chain=self.corrected_chain.to_dict(),
            )
        return result


def _require(condition: bool, rule: str, message: str) -> None:
    if not condition:
        raise TheoryError(f'[{rule}] {message}')


def _edge_bound(k_nu_scaled: float, capacities: np.ndarray) -> np.ndarray:
    # (kij) / (kijd): the positive root of l² + 2K l - 2K c = 0 from ν_ij <= 2K. The paper's
    # ν_ij <= 2ν is loose (ν sums each edge once, so ν_ij <= ν) but valid; kept as printed.
    # Written as 2Kc / (K + sqrt(K² + 2Kc)): -K + sqrt(...) cancels for K >> c and rounded to
    # l >= c (a false TheoryError) for teams with large k_ν (α² n / β of 1e8 and more).
    return (
        2.0
        * k_nu_scaled
        * capacities
        / (k_nu_scaled + np.sqrt(k_nu_scaled * k_nu_scaled + 2.0 * k_nu_scaled * capacities))
    )


def _per_agent_sum(n: int, heads, tails, values) -> np.ndarray:
    total = np.zeros(n)
    np.add.at(total, heads, values)
    np.add.at(total, tails, values)
    return total


@dataclass(frozen=True, kw_only=True)
class _Common:
    """What both theorems' constants start from: the graph, its hypotheses, the initial state."""

    n: int
    heads: np.ndarray
    tails: np.ndarray
    pairs: list[tuple[int, int]]
    capacities: np.ndarray  # Δ - ||d_ij|| per edge
    tau: np.ndarray  # a point of Φ
    fields: dict[str, float]  # TheoremConstants' common fields


def _common(scenario: Scenario) -> _Common:
    """Check Assumption 1, (initial) and connectivity; compute β0 (Theorem 1) and the Remark's bound."""
    _require(is_connected(scenario), 'connected', 'the graph must be connected')
    feasibility = formation_feasibility(scenario)
    _require(
        feasibility.feasible,
        'feasible',
        f'the formation is infeasible: least-squares residual {feasibility.residual:.3g}',
    )
    capacities = edge_capacities(scenario)
    _require(bool(np.all(capacities > 0.0)), 'edge_length', '||d_ij|| < Δ must hold on every edge')
    errors0 = edge_errors(scenario, scenario.positions)
    _require(bool(np.all(errors0 < capacities)), 'initial', '(initial) must hold on every edge')
    heads, tails, _ = scenario.edge_indices()
    lam2 = algebraic_connectivity(scenario)
    d0 = float(capacities.max())
    return _Common(
        n=scenario.n,
        heads=heads,
        tails=tails,
        pairs=[edge.pair for edge in scenario.edges],
        capacities=capacities,
        tau=feasibility.tau,
        fields={
            'n': scenario.n,
            'algebraic_connectivity': lam2,
            'delta0': d0,
            'beta0': lam2 / d0,
            'remark_beta_bound': remark_beta_bound(scenario),
        },
    )


def theorem_constants(
    scenario: Scenario, *, a: float = DEFAULT_A, b: float | None = None
) -> TheoremConstants:
    """All constants of the proof of Theorem 1 (single) or 2 (double).

    `a` is Theorem 1's free parameter in (0, 1), `b` Theorem 2's in (0, k3) (default k3/2).
    Raises TheoryError when a hypothesis of the theorem, as stated in the paper, fails; run
    `formation_sim.model.validate.validate_scenario` first for a full report.
    """
    common = _common(scenario)
    if scenario.dynamics == 'single':
        return _theorem1_constants(scenario, common, a=a)
    return _theorem2_constants(scenario, common, b=b)


def _theorem1_constants(scenario: Scenario, common: _Common, *, a: float) -> TheoremConstants:
    n, heads, tails, capacities = common.n, common.heads, common.tails, common.capacities
    b0 = common.fields['beta0']
    alpha, beta = scenario.gains.alpha, scenario.gains.beta
    _require(alpha > 0.0, 'alpha', f'α > 0 required, got {alpha!r}')
    state = against_bound(beta, b0, strict=True)
    _require(beta > 0.0 and state != OUTSIDE, 'beta', f'0 < β < β0 = {b0!r} required, got β = {beta!r}')
    _require(
        state == INSIDE,
        'beta',
        f'β = {beta!r} equals β0 = {b0!r} up to rounding ({ROUNDING_ULPS} ulps; validation accepts it): '
        f"the proof's k_V = V0 + nα²/(8β0(β0-β)) is unbounded there",
    )
    _require(0.0 < a < 1.0, 'a', f'the free parameter a must lie in (0, 1), got {a!r}')
    nu0 = tension(scenario, scenario.positions)
    k_nu = nu0 + n * alpha * alpha / (8.0 * a * beta)  # (kν)
    k_edge = _edge_bound(k_nu, capacities)  # (kij)
    V0 = lyapunov(scenario, scenario.positions, tau=common.tau)
    # (kV); the (betaV) line before it should read [e^{-2βt} - e^{-2β0 t}], not [e^{-2βt} - 1].
    k_V = V0 + n * alpha * alpha / (8.0 * b0 * (b0 - beta))
    f = f_ij(k_edge, capacity=capacities)
    g = g_ij(k_edge, capacity=capacities)
    F = _per_agent_sum(n, heads, tails, f)  # Σ_{l∈N_i} f_il(k_il)
    # c_i = Σ_{j∈N_i} g_ij(k_ij) [2α + 2 sqrt(k_V) (F_i + F_j)], bounding ||y_i'|| + ||y_j'||.
    per_edge = g * (2.0 * alpha + 2.0 * math.sqrt(k_V) * (F[heads] + F[tails]))
    c = _per_agent_sum(n, heads, tails, per_edge)
    xi = alpha / (c + alpha * beta)  # (xi)
    return TheoremConstants(
        theorem=1,
        free_parameter=a,
        nu0=nu0,
        k_nu=k_nu,
        k_edge=dict(zip(common.pairs, k_edge.tolist())),
        V0=V0,
        k_V=k_V,
        c=dict(zip(scenario.agent_ids, c.tolist())),
        xi=dict(zip(scenario.agent_ids, xi.tolist())),
        **common.fields,
    )


def _theorem2_constants(scenario: Scenario, common: _Common, *, b: float | None) -> TheoremConstants:
    n, capacities = common.n, common.capacities
    b0 = common.fields['beta0']
    gains = scenario.gains
    k1, k2, k3 = gains.k1, gains.k2, gains.k3
    alpha_d, beta_d, beta1 = gains.alpha_d, gains.beta_d, gains.beta1
    _require(alpha_d > 0.0, 'alpha_d', f'α_d > 0 required, got {alpha_d!r}')
    _require(
        beta1 > 0.0 and against_bound(beta1, b0, strict=False) != OUTSIDE,
        'beta1',
        f'0 < β1 <= β0 = {b0!r} required, got β1 = {beta1!r}',
    )
    _require(k1 > 0.0 and k2 > 0.0, 'k1_k2', f'k1, k2 > 0 required, got k1={k1!r}, k2={k2!r}')
    _require(riccati_holds(gains.P, beta1), 'riccati', f'P = {gains.P.tolist()} must satisfy (riccatti)')
    upper = k3_upper_bound(k1, k2)
    _require(
        k3 > 0.0 and against_bound(k3, upper, strict=True) != OUTSIDE,
        'k3',
        f'0 < k3 < {upper!r} required, got k3 = {k3!r}',
    )
    k4 = k4_value(k1, k2, k3)
    eigenvalues = np.linalg.eigvalsh(gains.P)
    rho2_p, lam_max_p = float(eigenvalues.min()), float(eigenvalues.max())
    bound_paper = (2.0 - k4) * rho2_p
    bound_corrected = (2.0 - k4) / lam_max_p
    _require(
        beta_d > 0.0
        and against_bound(beta_d, bound_paper, strict=True)
        != OUTSIDE,  # at it up to rounding: the chain gives no decay bound
        'beta_d',
        f'0 < β_d < (2-k4) ρ2(P) = {bound_paper!r} required, got β_d = {beta_d!r}',
    )
    b = k3 * DEFAULT_B_FRACTION if b is None else float(b)
    _require(0.0 < b < k3, 'b', f'the free parameter b must lie in (0, k3 = {k3!r}), got {b!r}')

    velocities = (
        scenario.velocities
    )  # the paper's q_p(0): a run at speed scale κ starts at κ q(0) (docs/SPEED_SCALE.md)
    nu0 = tension_double(scenario, scenario.positions, velocities)
    k_nu = nu0 + n * alpha_d * alpha_d / (8.0 * b * beta_d)  # k^d_ν
    k_edge = _edge_bound(k_nu / k1, capacities)  # (kijd)
    V0 = lyapunov_double(scenario, scenario.positions, velocities, tau=common.tau)
    edges = _Theorem2Edges(
        f=f_ij(k_edge, capacity=capacities),
        g=g_ij(k_edge, capacity=capacities),
        h=h_ij(k_edge, capacity=capacities),
    )
    paper_chain = _theorem2_chain(
        scenario, common, edges, V0=V0, reading='paper', rate_bound=bound_paper, z_gain=1.0
    )
    corrected_chain = _theorem2_chain(
        scenario, common, edges, V0=V0, reading='corrected', rate_bound=bound_corrected, z_gain=1.0 / rho2_p
    )
    return TheoremConstants(
        theorem=2,
        free_parameter=b,
        nu0=nu0,
        k_nu=k_nu,
        k_edge=dict(zip(common.pairs, k_edge.tolist())),
        V0=V0,
        k_V=corrected_chain.k_V,
        c=corrected_chain.c,
        xi=corrected_chain.xi,
        P=np.array(gains.P),
        rho2_P=rho2_p,
        lambda_max_P=lam_max_p,
        k3_upper_bound=upper,
        k4=k4,
        beta_d_bound_paper=bound_paper,
        beta_d_bound_corrected=bound_corrected,
        c_q=corrected_chain.c_q,
        paper_chain=paper_chain,
        corrected_chain=corrected_chain,
        **common.fields,
    )


@dataclass(frozen=True)
class _Theorem2Edges:
    """f_ij, g_ij, h_ij ((fij), (gij), (hij)) at k^d_ij, per edge."""

    f: np.ndarray
    g: np.ndarray
    h: np.ndarray


def _theorem2_chain(
    scenario: Scenario,
    common: _Common,
    edges: _Theorem2Edges,
    *,
    V0: float,
    reading: str,
    rate_bound: float,
    z_gain: float,
) -> Theorem2Chain:
    """Theorem 2 (ii)-(iii) with the rate bound γ and the factor of (yiyj) of one reading.

    Printed: γ = (2-k4) ρ2(P), z_gain = 1. Corrected (docs/THEOREM2.md): γ = (2-k4)/λmax(P),
    z_gain = 1/λmin(P). A reading whose γ does not exceed β_d gives no decay bound (holds=False).
    """
    gains = scenario.gains
    k1, k2, k3, alpha_d, beta_d, beta1 = (
        gains.k1,
        gains.k2,
        gains.k3,
        gains.alpha_d,
        gains.beta_d,
        gains.beta1,
    )
    n, heads, tails = common.n, common.heads, common.tails
    if not 0.0 < beta_d < rate_bound:
        return Theorem2Chain(
            reading=reading,
            rate_bound=rate_bound,
            z_gain=z_gain,
            holds=False,
            k_V=None,
            c_q=None,
            c=None,
            xi=None,
        )
    # (kVd) with γ = rate_bound in place of (2-k4)ρ2(P).
    k_V = V0 + n * alpha_d * alpha_d / (8.0 * beta1 * (rate_bound - beta_d))
    # (yiyj): ||z_i-z_j||² <= 4 z_gain V_d.
    s = 2.0 * math.sqrt(z_gain * k_V)  # ||y_i-y_j||, ||q_i-q_j|| < s e^{-β_d t}
    F = _per_agent_sum(n, heads, tails, edges.f)  # Σ_{l∈N_i} f_il(k^d_il)
    # (cijq), bounding ||q_i' - q_j'|| < c^q_ij e^{-β_d t} (the garbled (dotqie)-(dotqi)).
    c_q = 2.0 * alpha_d + ((k1 + k2) * (F[heads] + F[tails]) + k3) * s
    # c^d_i from (doteq): e^{-2β_d t} <= e^{-β_d t} bounds the ||q_i-q_j||² term.
    per_edge = k1 * edges.g * s + k2 * edges.h * s * s + k2 * edges.f * c_q
    c = _per_agent_sum(n, heads, tails, per_edge)
    xi = alpha_d / (c + alpha_d * beta_d)  # (xid)
    return Theorem2Chain(
        reading=reading,
        rate_bound=rate_bound,
        z_gain=z_gain,
        holds=True,
        k_V=k_V,
        c_q=dict(zip(common.pairs, c_q.tolist())),
        c=dict(zip(scenario.agent_ids, c.tolist())),
        xi=dict(zip(scenario.agent_ids, xi.tolist())),
    )
