"""Certified search for the first time ||e(t)|| reaches a triggering rule's threshold θ(t).

Step 4 of ETA-1 (step 5 of ETA-2) asks for the *smallest* solution of ||e_i(t)|| = α e^{-βt}
(eqs. triggersingle, triggerdouble); the threshold is a `TriggerRule` (formation_agent.core.trigger:
the paper's c0 + α e^{-βt}, `ExponentialRule`, or another). Between events e_i(t) is a closed-form
function of t, so instead of sampling it on a grid (which can step over an early crossing) we walk
forward in steps that are proven crossing-free:

With S = 1/θ(a) and r(t) = θ(t)/θ(a) (the rule's `scale` and `ratio`), the normalised margin
φ(t) = r(t)² - S²||e(t)||² is positive exactly while ||e(t)|| < θ(t). What the rule promises on
t >= a (trigger.py): (r²)'' in [0, K], |(r²)'| <= G (for the exponential rule G = 2β, K = 4β²).
Given bounds E >= ||e||, E1 >= ||ė||, E2 >= ||ë|| on [a, a+H]:

    φ''(t) >= -M,  M = 2 S² (E1² + E E2)       so  φ(a+h) >= φ(a) + φ'(a) h - M h²/2,
    |φ'(t)| <= L,  L = G + 2 S² E E1            so  φ(a+h) >= φ(a) - L h.

The largest h keeping either lower bound positive is crossing-free. Near a simple root the
quadratic bound makes the steps converge quadratically (a certified Newton iteration); near a
tangential touch they shrink like sqrt(φ/M) and pass it. The first-order bound serves where e is
only Lipschitz (ETA-2 when a relative position passes through its desired value).

The last step. At a step point a with φ(a) <= `tolerance` the search tries to finish:

* φ(a) <= 0: a is the first crossing (no crossing in [start, a), the threshold reached at a).
* φ'(a) >= 0: a touch within the tolerance (||e(a)|| >= (1 - tolerance)^{1/2} θ(a) while
  the margin does not fall); it counts as reached, and a is returned.
* Otherwise the bracket [a, b], b = a + 2φ(a)/|φ'(a)|, is used only once it is proven to hold
  exactly one root: with the same bounds over [a, b], φ'' <= K' = K + 2 S² E E2, and if
  K' (b - a) <= |φ'(a)|/2 then φ' <= φ'(a)/2 < 0 on [a, b] and φ(b) <= φ(a) - 3/4 |φ'(a)| (b - a)
  < 0. So φ has exactly one root in (a, b), the first crossing, which Illinois regula falsi
  (in plain Python: the agents need no scipy, which halves an agent process's start-up) refines
  to 4 ulps. Should the computed margin at b still be >= 0, rounding hides a sign change that
  is proven to lie in (a, b), and a is returned (within b - a of the crossing).
* Without that proof (the bracket may hold several roots, or e is only Lipschitz there) the
  search keeps taking certified steps from a and tries again at the next point.

The search also stops where a certified step falls below the resolution of t (a + h == a);
there it finishes as above, except that without the proof it returns a itself.

What is proven, then: with a the point where the search stops, no crossing lies in [start, a),
and the result is either the first crossing (to the 4 ulps of regula falsi, or to b - a where
rounding hides the sign change) or a itself: a touch within the tolerance, or the last point the
resolution of t lets the steps reach. So no result lies past the first crossing (beyond those
4 ulps), and a later root is never returned in place of an earlier one. All of this is for the
values and bounds the model computes; their own rounding is the model's (late in a run it is
what the engine's rounding floor watches).

The search is resumable (`CrossingSearch`): at any moment its `frontier` is a certified lower
bound on the answer (no crossing in [start, frontier)), so a simulator of many agents can advance
each agent's search only as far as the earliest event of the team requires (`advance(until=...)`)
and drop it unfinished when new information makes it obsolete. Advancing in pieces performs the
very same steps as running to the end (`first_crossing`), so the answer is the same float.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol, cast

import numpy as np

from formation_agent.core.errors import CrossingError
from formation_agent.core.trigger import TriggerRule

# What a CrossingError means for a run, said by the engine and by an agent node alike.
PRECISION_HINT = (
    'the rounded prediction no longer resolves its threshold '
    '(`formation validate` checks this for the initial state: rule [precision])'
)


class ErrorModel(Protocol):
    """Closed-form triggering error e(t) of one agent between two events.

    A model may also offer the plain-float methods `error_terms(t) -> (||e||², e·ė)` and
    `error_norm(t) -> ||e||`, which the search then uses instead of the two vector methods.
    """

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
# A search gives up (CrossingError) after this many certified steps.
MAX_STEPS = 200_000
# The relative margin 1 - ||e||²/θ(t)² at which the search starts to finish (its default).
DEFAULT_TOLERANCE = 1e-12
_RTOL = 4.0 * 2.0**-52  # 4 ulps relative


class CrossingSearch:
    """The certified search for the smallest t >= start with ||e(t)|| >= θ(t) of `rule`, resumable.

    `frontier` is the next point the search will examine; no crossing lies in [start, frontier).
    `result` is None until the search is done, then the crossing time (inf: none up to `limit`).
    """

    __slots__ = (
        '_cover',
        '_norm',
        '_span',
        '_terms',
        'frontier',
        'limit',
        'model',
        'result',
        'rule',
        'start',
        'steps',
        'tolerance',
    )

    def __init__(
        self,
        model: ErrorModel,
        *,
        start: float,
        rule: TriggerRule,
        limit: float,
        tolerance: float = DEFAULT_TOLERANCE,
        initial_step: float = 1e-3,
    ) -> None:
        self.model = model
        self.start = float(start)
        self.rule = rule  # the threshold θ(t) and its bounds (formation_agent.core.trigger)
        self.limit = float(limit)
        self.tolerance = float(tolerance)
        self.frontier = self.start
        self.result: float | None = None
        self.steps = 0
        self._span = float(initial_step)
        # (end, E, E2): bounds of the last step, valid from its point to end; the point it
        # leads to may use them to prove that its polishing bracket holds one root.
        self._cover = (-math.inf, math.nan, math.nan)
        self._terms = getattr(model, 'error_terms', None) or _vector_terms(model)
        self._norm = getattr(model, 'error_norm', None) or _vector_norm(model)

    @property
    def done(self) -> bool:
        return self.result is not None

    def run(self) -> float:
        """Search to the end; the crossing time, or inf if there is none up to `limit`."""
        self.advance(math.inf)
        return cast(float, self.result)  # set once the search reached inf

    def advance(self, until: float) -> float | None:
        """Take certified steps while the frontier is <= `until`; `result` (None: not done yet)."""
        a = self.frontier
        tolerance = self.tolerance
        terms, bounds = self._terms, self.model.bounds
        rule_scale, rule_terms = self.rule.scale, self.rule.margin_terms
        span = self._span
        cover_end, bound_e, bound_curv = self._cover
        while self.result is None and a <= until:
            if a > self.limit:
                self.result = math.inf
                break
            if self.steps >= MAX_STEPS:
                raise steps_error(a)
            self.steps += 1
            size_sq, size_rate = terms(a)
            scale = rule_scale(a)  # S = 1/θ(a)
            ratio_rate, slope = rule_terms(a, scale)  # (r²)'(a) and G >= |(r²)'| on t >= a
            s2 = scale * scale
            phi = 1.0 - s2 * size_sq
            phi_rate = ratio_rate - 2.0 * s2 * size_rate
            if not (math.isfinite(phi) and math.isfinite(phi_rate)):
                raise finite_error(a, size_sq, size_rate)
            size = math.sqrt(size_sq)
            if phi <= tolerance:
                result = self._finish(a, phi, phi_rate, size, cover_end, bound_e, bound_curv, stuck=False)
                if result is not None:
                    self.result = result
                    break
            span_eff, bound_e, bound_rate, bound_curv = bounds(a, span, size)
            cover_end = a + span_eff
            lipschitz = slope + 2.0 * s2 * bound_e * bound_rate
            step = phi / lipschitz if lipschitz > 0.0 else math.inf
            curvature = 2.0 * s2 * (bound_rate * bound_rate + bound_e * bound_curv)
            if curvature < math.inf:  # finite (a NaN bound never certifies a longer step)
                step = max(step, _quadratic_step(phi, phi_rate, curvature))
            if step >= span_eff:
                step = span_eff
                span = span_eff * _GROWTH
            else:
                span = max(step * _GROWTH, 1e-300)
            nxt = a + step
            if nxt <= a:
                # The certified step is below the resolution of t: we sit on the crossing.
                self.result = self._finish(a, phi, phi_rate, size, cover_end, bound_e, bound_curv, stuck=True)
                break
            a = nxt
        self.frontier = a
        self._span = span
        self._cover = (cover_end, bound_e, bound_curv)
        return self.result

    def _finish(
        self,
        a: float,
        phi: float,
        phi_rate: float,
        size: float,
        cover_end: float,
        bound_e: float,
        bound_curv: float,
        *,
        stuck: bool,
    ) -> float | None:
        """The crossing from a point whose margin is within tolerance; None: step on from a.

        `size` is ||e(a)||, so the margin at a costs no evaluation. `bound_e`, `bound_curv` bound
        ||e||, ||ë|| from at or before a up to `cover_end` (the last step's bounds). `stuck`: no
        certified step can leave a (then a is returned where the bracket is not proven).
        """
        if phi <= 0.0 or phi_rate >= 0.0:
            return a
        rule = self.rule
        scale = rule.scale(a)
        margin_a = 1.0 - scale * size  # r(a) = 1
        if margin_a <= 0.0:
            return a  # φ(a) > 0 in squares, but the margin itself rounds to <= 0: already there
        width = max(2.0 * phi / -phi_rate, 4.0 * math.ulp(a) if a else 1e-300)
        b = a + width
        if cover_end < b:
            span, bound_e, _, bound_curv = self.model.bounds(a, b - a, size)
            if a + span < b:
                return a if stuck else None
        # φ'' <= (r²)'' + 2 S² E E2 <= K + 2 S² E E2 on [a, b]: φ' stays below φ'(a)/2 < 0, so
        # [a, b] holds one root.
        curvature = rule.curvature(a, scale) + 2.0 * scale * scale * bound_e * bound_curv
        if not curvature * (b - a) <= -0.5 * phi_rate:  # also False for a NaN or infinite bound
            return a if stuck else None
        norm, ratio = self._norm, rule.ratio

        def margin(t: float) -> float:
            return ratio(t, a, scale) - scale * norm(t)  # r(t) - S ||e(t)||

        margin_b = margin(b)
        if margin_b >= 0.0:
            return a  # the root proven to lie in (a, b) is below the rounding of the margin
        return _root_in_bracket(margin, a, margin_a, b, margin_b)


def steps_error(a: float) -> CrossingError:
    """The search took MAX_STEPS steps and stands at `a`."""
    return CrossingError(f'no convergence after {MAX_STEPS} certified steps (t={a!r})')


def finite_error(a: float, size_sq: float, size_rate: float) -> CrossingError:
    """||e||² or e·ė is not finite at `a`."""
    return CrossingError(
        f'triggering error is not finite at t={a!r}: ||e||^2 = {size_sq!r}, e.de/dt = {size_rate!r}'
    )


def first_crossing(
    model: ErrorModel,
    *,
    start: float,
    rule: TriggerRule,
    limit: float,
    tolerance: float = DEFAULT_TOLERANCE,
    initial_step: float = 1e-3,
) -> float:
    """Smallest t >= start with ||e(t)|| >= θ(t) of `rule`; inf if there is none up to `limit`.

    `tolerance` is the relative margin 1 - ||e||² / θ(t)² below which a point counts as
    reached; the result is then refined to double precision by bracketing.
    """
    return CrossingSearch(
        model, start=start, rule=rule, limit=limit, tolerance=tolerance, initial_step=initial_step
    ).run()


def _root_in_bracket(
    f: Callable[[float], float], a: float, fa: float, b: float, fb: float, *, max_iterations: int = 200
) -> float:
    """A root of f in [a, b], where fa = f(a) and fb = f(b) have opposite signs (fa > 0 > fb here).

    Regula falsi with the Illinois modification (the value kept at an end that survives twice in
    a row is halved, so both ends converge), superlinear on a smooth f; a point the interpolation
    puts outside (a, b) is replaced by the midpoint. It stops when the bracket or the last move is
    within `_RTOL` (4 ulps) of the root, or on an exact zero.
    """
    kept = 0  # which end survived the last iteration: -1 a, +1 b
    weight_a, weight_b = fa, fb  # the values interpolated with (Illinois halves them)
    x = a
    for _ in range(max_iterations):
        if b - a <= _RTOL * max(abs(a), abs(b), 1e-300):
            break
        previous = x
        x = b - weight_b * ((b - a) / (weight_b - weight_a))
        if not a < x < b:
            x = a + 0.5 * (b - a)
        fx = f(x)
        if fx == 0.0:
            return x
        if (fx > 0.0) == (fa > 0.0):
            a, fa, weight_a = x, fx, fx
            if kept == 1:
                weight_b *= 0.5
            kept = 1
        else:
            b, fb, weight_b = x, fx, fx
            if kept == -1:
                weight_a *= 0.5
            kept = -1
        if abs(x - previous) <= _RTOL * abs(x):
            break
    return a if abs(fa) <= abs(fb) else b


def _vector_terms(model: ErrorModel) -> Callable[[float], tuple[float, float]]:
    def terms(t: float) -> tuple[float, float]:
        e, e_rate = model.error_and_rate(t)
        return float(e @ e), float(e @ e_rate)

    return terms


def _vector_norm(model: ErrorModel) -> Callable[[float], float]:
    def norm(t: float) -> float:
        return float(np.linalg.norm(model.error(t)))

    return norm


def _quadratic_step(phi: float, phi_rate: float, curvature: float) -> float:
    """Positive root of phi + phi_rate h - curvature h²/2 = 0, computed without cancellation."""
    if curvature <= 0.0:
        return phi / -phi_rate if phi_rate < 0.0 else math.inf
    root = math.sqrt(phi_rate * phi_rate + 2.0 * curvature * phi)
    if phi_rate > 0.0:
        return (phi_rate + root) / curvature
    return 2.0 * phi / (root - phi_rate)
