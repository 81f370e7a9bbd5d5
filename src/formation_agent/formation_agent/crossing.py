"""Certified search for the first time ||e(t)|| reaches α e^{-βt}.

Steps 4-5 of ETA-1/ETA-2 ask for the *smallest* solution of ||e_i(t)|| = α e^{-βt}. Between events
e_i(t) is a closed-form function of t, so instead of sampling it on a grid (which can step over an
early crossing) we walk forward in steps that are proven crossing-free:

With S = e^{βa}/α, the normalised margin φ(t) = e^{-2β(t-a)} - S²||e(t)||² is positive exactly
while ||e(t)|| < α e^{-βt}. Given bounds E >= ||e||, E1 >= ||ė||, E2 >= ||ë|| on [a, a+H]:

    φ''(t) >= -M,  M = 2 S² (E1² + E E2)       so  φ(a+h) >= φ(a) + φ'(a) h - M h²/2,
    |φ'(t)| <= L,  L = 2β + 2 S² E E1           so  φ(a+h) >= φ(a) - L h.

The largest h keeping either lower bound positive is crossing-free. Near a simple root the
quadratic bound makes the steps converge quadratically (a certified Newton iteration); near a
tangential touch they shrink like sqrt(φ/M) and pass it. The first-order bound serves where e is
only Lipschitz (ETA-2 when a relative position passes through its desired value). Once the margin
is below `tolerance`, the root is polished by Brent's method inside a bracket of width ~φ/|φ'|.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from scipy.optimize import brentq


class CrossingError(RuntimeError):
    """The search could not proceed (non-finite error, or a step that does not advance)."""


class ErrorModel(Protocol):
    """Closed-form triggering error e(t) of one agent between two events."""

    def error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """e(t) and de/dt at t."""

    def error(self, t: float) -> np.ndarray:
        """e(t)."""

    def bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
        """(H, E, E1, E2) with H <= span and bounds on ||e||, ||ė||, ||ë|| over [a, a+H].

        `size` is ||e(a)||, which the search has at hand.

        E2 may be inf where e is not twice differentiable in [a, a+H].
        """


# Steps never grow by more than this factor, so that bounds stay tight around the current point.
_GROWTH = 4.0
_MAX_STEPS = 200_000


def first_crossing(
    model: ErrorModel,
    *,
    start: float,
    alpha: float,
    beta: float,
    limit: float,
    tolerance: float = 1e-12,
    initial_step: float = 1e-3,
) -> float:
    """Smallest t >= start with ||e(t)|| >= α e^{-βt}; inf if there is none up to `limit`.

    `tolerance` is the relative margin 1 - ||e||² / (α e^{-βt})² below which a point counts as
    reached; the result is then refined to double precision by bracketing.
    """
    a = float(start)
    span = float(initial_step)
    for _ in range(_MAX_STEPS):
        if a > limit:
            return math.inf
        e, e_rate = model.error_and_rate(a)
        scale = math.exp(beta * a) / alpha
        se = scale * e
        phi = 1.0 - float(se @ se)
        phi_rate = -2.0 * beta - 2.0 * scale * float(se @ e_rate)
        if not (math.isfinite(phi) and math.isfinite(phi_rate)):
            raise CrossingError(f'triggering error is not finite at t={a!r}: {e.tolist()}')
        if phi <= tolerance:
            return _polish(model, a, phi, phi_rate, alpha=alpha, beta=beta)

        span_eff, bound_e, bound_rate, bound_curv = model.bounds(a, span, math.sqrt(float(e @ e)))
        s2 = scale * scale
        lipschitz = 2.0 * beta + 2.0 * s2 * bound_e * bound_rate
        step = phi / lipschitz if lipschitz > 0.0 else math.inf
        curvature = 2.0 * s2 * (bound_rate * bound_rate + bound_e * bound_curv)
        if math.isfinite(curvature):
            step = max(step, _quadratic_step(phi, phi_rate, curvature))
        if step >= span_eff:
            step = span_eff
            span = span_eff * _GROWTH
        else:
            span = max(step * _GROWTH, 1e-300)
        nxt = a + step
        if nxt <= a:
            # The certified step is below the resolution of t: we sit on the crossing.
            return _polish(model, a, phi, phi_rate, alpha=alpha, beta=beta)
        a = nxt
    raise CrossingError(f'no convergence after {_MAX_STEPS} certified steps (t={a!r})')


def _quadratic_step(phi: float, phi_rate: float, curvature: float) -> float:
    """Positive root of phi + phi_rate h - curvature h²/2 = 0, computed without cancellation."""
    if curvature <= 0.0:
        return phi / -phi_rate if phi_rate < 0.0 else math.inf
    root = math.sqrt(phi_rate * phi_rate + 2.0 * curvature * phi)
    if phi_rate > 0.0:
        return (phi_rate + root) / curvature
    return 2.0 * phi / (root - phi_rate)


def _polish(model: ErrorModel, a: float, phi: float, phi_rate: float, *, alpha: float, beta: float) -> float:
    """Refine a point whose margin is within tolerance to where ||e|| = α e^{-βt}."""
    if phi <= 0.0 or phi_rate >= 0.0:
        return a
    scale = math.exp(beta * a) / alpha

    def margin(t: float) -> float:
        return math.exp(-beta * (t - a)) - scale * float(np.linalg.norm(model.error(t)))

    if margin(a) <= 0.0:
        return a  # φ(a) > 0 in squares, but the margin itself rounds to <= 0: already there
    width = max(2.0 * phi / -phi_rate, 4.0 * math.ulp(a) if a else 1e-300)
    b = a + width
    if margin(b) >= 0.0:
        return a  # a touch, or a crossing closer than the resolution: trigger here
    return brentq(margin, a, b, xtol=1e-300, rtol=4.0 * np.finfo(float).eps, maxiter=200)
