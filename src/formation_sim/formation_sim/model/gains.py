"""Theorem 2's gains: P from (riccatti), the range of k3, k4, and the bounds on β_d.

ROS-free and free of the scenario model, so that both `formation_sim.model.scenario` (which fills
in P, k1, k2, k3 from β1) and `formation_sim.model.theory` (which checks them) can use it.
"""

from __future__ import annotations

import math

import numpy as np

from formation_sim.model.errors import GainsError

# z_i' = (C⊗I_p) z_i + (B⊗I_p) u_i for z_i = (y_i, q_i) (Section 4).
C_MATRIX = np.array([[0.0, 1.0], [0.0, 0.0]])
B_MATRIX = np.array([[0.0], [1.0]])

# A user's value compared with a computed bound (β0 = ρ2(DD^T)/Δ0, an eigenvalue ratio; k3's range;
# the rate bounds (2-k4) ρ2(P), (2-k4)/λmax(P)) may sit on the bound as the user computed it and
# still be a few ulps off ours: within ROUNDING_ULPS ulps of the bound it is taken as equal to it
# (accepted, with a warning naming the margin); by more, the bound decides. One place: `against_bound`.
ROUNDING_ULPS = 4
INSIDE, ROUNDING, OUTSIDE = 'inside', 'rounding', 'outside'
# (riccatti)'s margin: its left side is 0 for P = riccati_solution(β1) (equality), so it is compared
# with 0 up to this fraction of max(1, |P|): its rounding scales with β1 |P|², not with ulps of a bound.
RICCATI_TOLERANCE = 1e-9


def against_bound(value: float, bound: float, *, strict: bool) -> str:
    """INSIDE if value < bound (strict) or value <= bound holds as computed; ROUNDING if it fails by
    at most ROUNDING_ULPS ulps of the bound (the rounding of a computed bound: taken as equal);
    OUTSIDE otherwise, also when either is NaN or the bound is infinite."""
    if value < bound or (not strict and value <= bound):
        return INSIDE
    if math.isfinite(bound) and value <= bound + ROUNDING_ULPS * math.ulp(bound):
        return ROUNDING
    return OUTSIDE


def ulps_above(value: float, bound: float) -> int:
    """How many ulps of `bound` `value` lies above it (0 at equality): the margin a warning names."""
    return round((value - bound) / math.ulp(bound))


def riccati_solution(beta1: float) -> np.ndarray:
    """P = [[k0, k1], [k1, k2]] solving (riccatti) with equality: ½(PC+C^T P) - β1 P B B^T P + 2I = 0.

    Entrywise: (1,1) 2 - β1 k1² = 0, (2,2) k1 - β1 k2² + 2 = 0, (1,2) k0/2 - β1 k1 k2 = 0, so the
    stabilising (positive definite) solution is k1 = sqrt(2/β1), k2 = sqrt((k1+2)/β1),
    k0 = 2 β1 k1 k2 — the same as scipy's solve_continuous_are(C, B, 4I, 1/(2β1)), but exact.
    """
    beta1 = float(beta1)
    if not (beta1 > 0.0 and math.isfinite(beta1)):
        raise GainsError(f'(riccatti) needs β1 > 0, got {beta1!r}')
    k1 = math.sqrt(2.0 / beta1)
    k2 = math.sqrt((k1 + 2.0) / beta1)
    k0 = 2.0 * beta1 * k1 * k2
    return np.array([[k0, k1], [k1, k2]])


def riccati_lhs(P, beta1: float) -> np.ndarray:
    """½(PC + C^T P) - β1 P B B^T P + 2I, which (riccatti) requires to be <= 0."""
    P = np.asarray(P, dtype=float)
    return 0.5 * (P @ C_MATRIX + C_MATRIX.T @ P) - beta1 * (P @ B_MATRIX @ B_MATRIX.T @ P) + 2.0 * np.eye(2)


def riccati_holds(P, beta1: float, *, tolerance: float = RICCATI_TOLERANCE) -> bool:
    """P > 0 and (riccatti) <= 0 up to `tolerance` (relative to the size of P)."""
    P = np.asarray(P, dtype=float)
    scale = max(1.0, float(np.abs(P).max()))
    positive = float(np.linalg.eigvalsh(P).min()) > 0.0
    return positive and float(np.linalg.eigvalsh(riccati_lhs(P, beta1)).max()) <= tolerance * scale


def paper_k3(k1: float, k2: float) -> float:
    """The paper's example choice k3 = 2 / (k2 + sqrt(k1² + k2²)), i.e. half the bound, k4 = 1."""
    return 2.0 / (k2 + math.hypot(k1, k2))


def k3_upper_bound(k1: float, k2: float) -> float:
    """Theorem 2 requires 0 < k3 < 4 / (k2 + sqrt(k1² + k2²)), equivalently k4 < 2."""
    return 4.0 / (k2 + math.hypot(k1, k2))


def k4_value(k1: float, k2: float, k3: float) -> float:
    """k4 = k3 (k2 + sqrt(k1² + k2²)) / 2 = k3 ρ((PBB^T + BB^T P)/2) (Theorem 2)."""
    return k3 * (k2 + math.hypot(k1, k2)) / 2.0


def beta_d_bound_paper(gains) -> float:
    """(2 - k4) ρ2(P): the bound on β_d printed in Theorem 2 (not implied by its proof)."""
    k4 = k4_value(gains.k1, gains.k2, gains.k3)
    return (2.0 - k4) * float(np.linalg.eigvalsh(gains.P).min())


def beta_d_bound_corrected(gains) -> float:
    """(2 - k4) / λmax(P): the rate the proof of Theorem 2 (ii) actually supports."""
    k4 = k4_value(gains.k1, gains.k2, gains.k3)
    return (2.0 - k4) / float(np.linalg.eigvalsh(gains.P).max())
