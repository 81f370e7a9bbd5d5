"""Closed-form motion between events, shared by the agents' predictions and the true world.

Single integrators (eq. single) move linearly under a constant input. Double integrators under
(uxdouble) obey q' = u^d - k3 q with u^d constant between events, so over an interval of length
tau (with z = k3 * tau):

    q(t) = e^{-z} q(s) + (1 - e^{-z}) u^d / k3                                   (stateqiqj)
    x(t) = x(s) + (1 - e^{-z}) q(s) / k3 + (z - 1 + e^{-z}) u^d / k3^2           (statexixjd)

The paper's (statexixjd) omits the x_i(s) - x_j(s) term; it is restored here. Both factors are
computed without cancellation for small z.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

Floats = npt.NDArray[np.float64]


def one_minus_exp(z: npt.ArrayLike) -> Floats:
    """1 - e^{-z}, accurate for small z (scalar or array)."""
    out: Floats = -np.expm1(-np.asarray(z, dtype=float))
    return out


# Below this |z| the series replaces z + expm1(-z), which loses digits to cancellation.
SERIES_LIMIT = 0.1
# Coefficients 1/(k+2)! of z - 1 + e^{-z} = z^2 sum_k (-z)^k / (k+2)!, enough for |z| < 0.1.
_SERIES = tuple(1.0 / math.factorial(k + 2) for k in range(14))
# For one float, eleven terms already reach double precision at |z| < 0.1: the first term left
# out, z^13 / 13!, is below 2^-60 of the sum, about z^2 / 2.
_C = _SERIES[:11]


def z_minus_one_plus_exp_float(z: float) -> float:
    """z - 1 + e^{-z} for one float with |z| < SERIES_LIMIT, by the series (Horner, unrolled)."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8, c9, c10 = _C
    acc = c8 - z * (c9 - z * c10)
    return z * z * (c0 - z * (c1 - z * (c2 - z * (c3 - z * (c4 - z * (c5 - z * (c6 - z * (c7 - z * acc))))))))


def z_minus_one_plus_exp(z: npt.ArrayLike) -> Floats:
    """z - 1 + e^{-z}, accurate for small z, where it behaves as z^2/2 (scalar or array)."""
    z = np.asarray(z, dtype=float)
    out: Floats = z + np.expm1(-z)
    small = np.abs(z) < SERIES_LIMIT
    if small.any():
        zs = z[small]
        acc = np.full_like(zs, _SERIES[-1])
        for coefficient in _SERIES[-2::-1]:
            acc = coefficient - zs * acc
        out = np.array(out)  # writable even for a 0-d input
        out[small] = zs * zs * acc
    return out


def advance_double(x: Floats, q: Floats, u: Floats, k3: float, tau: npt.ArrayLike) -> tuple[Floats, Floats]:
    """State (x, q) after `tau` seconds of q' = u - k3 q (eqs. statexixjd, stateqiqj).

    `tau` may be a scalar or one value per row of x, q, u.
    """
    z = k3 * np.asarray(tau, dtype=float)
    a = one_minus_exp(z)
    b = z_minus_one_plus_exp(z)
    if a.ndim:
        a = a[..., None]
        b = b[..., None]
    q_new = (1.0 - a) * q + (a / k3) * u
    x_new = x + (a / k3) * q + (b / (k3 * k3)) * u
    return x_new, q_new
