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


def one_minus_exp(z: float) -> float:
    """1 - e^{-z}, accurate for small z."""
    return -math.expm1(-z)


def z_minus_one_plus_exp(z: float) -> float:
    """z - 1 + e^{-z}, accurate for small z (it behaves as z^2/2 there)."""
    if abs(z) < 0.1:
        # Taylor series sum_{k>=2} (-z)^k / k!; 12 terms reach double precision for |z| < 0.1.
        term = z * z / 2.0
        total = term
        for k in range(3, 16):
            term *= -z / k
            total += term
        return total
    return z + math.expm1(-z)


def advance_double(
    x: np.ndarray, q: np.ndarray, u: np.ndarray, k3: float, tau: float
) -> tuple[np.ndarray, np.ndarray]:
    """State (x, q) after `tau` seconds of q' = u - k3 q (eqs. statexixjd, stateqiqj)."""
    z = k3 * tau
    a = one_minus_exp(z)
    b = z_minus_one_plus_exp(z)
    q_new = (1.0 - a) * q + (a / k3) * u
    x_new = x + (a / k3) * q + (b / (k3 * k3)) * u
    return x_new, q_new
