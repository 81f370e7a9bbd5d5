"""Edge-tension weight ω_ij and the functions that bound it (paper, Section 3).

All functions take the edge error length r = ||y_i - y_j|| = ||x_i - x_j - d_ij|| and the edge's
capacity c = Δ - ||d_ij||; they are defined for 0 <= r < c and increase in r, which is what lets
an upper bound on r over an interval turn into an upper bound on each of them.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import numpy.typing as npt

# An edge error length and a capacity: floats, or one per edge (arrays); the result is the same kind.
Real = TypeVar('Real', float, npt.NDArray[np.float64])


def omega(r: Real, c: Real) -> Real:
    """ω_ij = f_ij(r) = (2c - r) / (c - r)^2  (eq. fij; the weight in eq. uxsingle)."""
    gap = c - r
    return (2.0 * c - r) / (gap * gap)


def omega_prime(r: Real, c: Real) -> Real:
    """dω/dr = h_ij(r) = (3c - r) / (c - r)^3  (eq. hij)."""
    gap = c - r
    return (3.0 * c - r) / (gap * gap * gap)


def omega_second(r: Real, c: Real) -> Real:
    """d²ω/dr² = (8c - 2r) / (c - r)^4  (not in the paper; bounds the second derivative of e_i)."""
    gap = c - r
    return (8.0 * c - 2.0 * r) / (gap * gap * gap * gap)


def weight_gain(r: Real, c: Real) -> Real:
    """g_ij(r) = 2c^2 / (c - r)^3 = ω + r dω/dr  (eq. gij).

    It bounds the derivative of y -> ω(||y||) y: ||D[ω y] v|| <= g_ij(||y||) ||v||.
    """
    gap = c - r
    return 2.0 * c * c / (gap * gap * gap)


def curvature_gain(r: Real, c: Real) -> Real:
    """r d²ω/dr² + 3 dω/dr: bounds the second derivative of y -> ω(||y||) y (per unit ||v||^2)."""
    return r * omega_second(r, c) + 3.0 * omega_prime(r, c)


def edge_capacity(delta: float, offsets: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """c_ij = Δ - ||d_ij|| for each row of `offsets` (real floats).

    ||d_ij|| is `np.linalg.norm(offsets, axis=-1)`'s own formula for a real array, sqrt of the
    add.reduce of the squares (the same floats, tests/formation_agent/core/test_neighbourhood.py), without
    its argument handling: every agent's constructor calls this."""
    capacity: npt.NDArray[np.float64] = delta - np.sqrt(np.add.reduce(offsets * offsets, axis=-1))
    return capacity
