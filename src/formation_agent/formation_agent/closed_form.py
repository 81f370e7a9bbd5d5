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


def one_minus_exp(z):
    """1 - e^{-z}, accurate for small z (scalar or array)."""
    return -np.expm1(-np.asarray(z, dtype=float))


# Coefficients 1/(k+2)! of z - 1 + e^{-z} = z^2 sum_k (-z)^k / (k+2)!, enough for |z| < 0.1.
_SERIES = tuple(1.0 / math.factorial(k + 2) for k in range(14))


def z_minus_one_plus_exp(z):
    """z - 1 + e^{-z}, accurate for small z, where it behaves as z^2/2 (scalar or array)."""
    z = np.asarray(z, dtype=float)
    out = z + np.expm1(-z)
    small = np.abs(z) < 0.1
    if small.any():
        zs = z[small]
        acc = np.full_like(zs, _SERIES[-1])
        for coefficient in _SERIES[-2::-1]:
            acc = coefficient - zs * acc
        out = np.array(out)  # writable even for a 0-d input
        out[small] = zs * zs * acc
    return out


def advance_double(x, q, u, k3: float, tau):
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
