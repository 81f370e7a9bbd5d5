"""The certified first-crossing search on adversarial error curves with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.crossing import first_crossing
from formation_agent.core.trigger import ExponentialRule


class Bump:
    """e(t) = (A exp(-((t - c)/w)^2), 0) + (B t, 0): a narrow bump on a slow ramp.

    Its derivatives are bounded by hand: |d/dt bump| <= A sqrt(2/e)/w, |d²/dt² bump| <= 2A/w².
    """

    def __init__(self, *, height, centre, width, ramp):
        self.a, self.c, self.w, self.b = height, centre, width, ramp

    def value(self, t):
        return self.a * math.exp(-(((t - self.c) / self.w) ** 2)) + self.b * t

    def error_and_rate(self, t):
        z = (t - self.c) / self.w
        bump = self.a * math.exp(-z * z)
        return np.array([bump + self.b * t, 0.0]), np.array([-2 * z / self.w * bump + self.b, 0.0])

    def error(self, t):
        return self.error_and_rate(t)[0]

    def bounds(self, a, span, size):
        e = self.a + self.b * (a + span)
        e1 = self.a * math.sqrt(2 / math.e) / self.w + self.b
        e2 = 2 * self.a / self.w**2
        return span, e, e1, e2


def _crossings_by_bisection(model, alpha, beta, t0, t1, samples=2_000_001):
    """All sign changes of α e^{-βt} - |e(t)| on a very fine grid (the brute-force reference)."""
    t = np.linspace(t0, t1, samples)
    z = (t - model.c) / model.w
    margin = alpha * np.exp(-beta * t) - np.abs(model.a * np.exp(-z * z) + model.b * t)
    return t[1:][np.diff(np.sign(margin)) != 0]


def test_narrow_early_spike_is_found_before_the_late_crossing():
    # A spike of width 1e-4 s at t = 1 that pokes 1e-3 above the threshold, then a slow ramp that
    # crosses near t = 10: a 0.01 s grid would step over the spike.
    model = Bump(height=1.001, centre=1.0, width=1e-4, ramp=0.1)
    t = first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.1, beta=0.0), limit=100.0)
    reference = _crossings_by_bisection(model, 1.1, 0.0, 0.99, 1.01)
    assert abs(t - reference[0]) < 1e-7
    assert t < 1.0
    assert abs(abs(model.value(t)) / 1.1 - 1.0) < 1e-12


def test_near_touch_below_threshold_does_not_trigger():
    # The bump reaches 1 - 1e-9 of the threshold and falls back: no crossing until the ramp's.
    model = Bump(height=1.0 - 1e-9, centre=1.0, width=1e-3, ramp=0.0)
    assert (
        first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=5.0)
        == math.inf
    )


def test_exact_touch_triggers_at_the_touch():
    # Touching the threshold exactly (within the tolerance) counts as reaching it.
    model = Bump(height=1.0, centre=2.0, width=1e-2, ramp=0.0)
    t = first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=5.0)
    assert abs(t - 2.0) < 1e-5


def test_decaying_threshold_meets_a_constant_error():
    # |e| = 0.5 constant, threshold e^{-t}: the crossing is at t = ln 2.
    model = Bump(height=0.0, centre=0.0, width=1.0, ramp=0.0)
    model.a = 0.5
    model.w = 1e100  # the bump is flat: e(t) = 0.5
    t = first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=1.0), limit=10.0)
    assert t == pytest.approx(math.log(2.0), rel=1e-14)


def test_limit_bounds_the_search():
    model = Bump(height=0.0, centre=0.0, width=1.0, ramp=0.1)
    assert (
        first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=5.0)
        == math.inf
    )
    assert first_crossing(
        model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=20.0
    ) == pytest.approx(10.0, rel=1e-14)


def test_already_above_threshold_is_due_at_start():
    model = Bump(height=0.0, centre=0.0, width=1.0, ramp=1.0)
    assert (
        first_crossing(model, start=3.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=20.0)
        == 3.0
    )


@pytest.mark.parametrize('pieces', [1, 3, 17, 200])
def test_search_advanced_in_pieces_gives_the_same_float(pieces):
    # The engine advances each agent's search only as far as the team needs; the steps, and so
    # the answer, must be those of one uninterrupted search.
    from formation_agent.core.crossing import CrossingSearch

    model = Bump(height=1.001, centre=1.0, width=1e-4, ramp=0.1)
    whole = first_crossing(
        model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.1, beta=0.0), limit=100.0
    )
    search = CrossingSearch(
        model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.1, beta=0.0), limit=100.0
    )
    frontiers = [search.frontier]
    for until in np.linspace(0.0, 1.0, pieces):
        if search.advance(float(until)) is not None:
            break
        assert search.frontier > until  # stopped only once past `until`
        frontiers.append(search.frontier)
    assert search.run() == whole
    assert all(a <= b for a, b in zip(frontiers, frontiers[1:]))
    assert frontiers[-1] <= whole  # the frontier is a lower bound on the crossing


def test_search_reports_no_crossing_up_to_its_limit():
    from formation_agent.core.crossing import CrossingSearch

    search = CrossingSearch(
        Bump(height=0.0, centre=0.0, width=1.0, ramp=0.1),
        start=0.0,
        rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0),
        limit=5.0,
    )
    assert search.advance(2.0) is None
    assert search.frontier > 2.0
    assert search.run() == math.inf


@pytest.mark.parametrize(
    ('f', 'a', 'b', 'root'),
    [
        (lambda x: math.cos(x) - x, 0.0, 1.0, 0.7390851332151607),  # the Dottie number
        (lambda x: math.exp(-x) - x * x, 0.0, 2.0, 0.7034674224983917),
        (lambda x: 1e-3 - (x - 5.0) ** 3, 0.0, 10.0, 5.1),  # flat near its root
        (lambda x: 1.0 - x * 1e12, 0.0, 1e-11, 1e-12),  # a bracket of sub-ulp size in seconds
    ],
)
def test_polishing_root_finder_reaches_a_few_ulps(f, a, b, root):
    from formation_agent.core.crossing import _root_in_bracket

    x = _root_in_bracket(f, a, f(a), b, f(b))
    assert abs(x - root) <= 8 * math.ulp(root)


class ThreeRoots:
    """||e(t)||² = 1 - φ0 P(t/τ): with α = 1, β = 0 the margin φ(t) = φ0 P(t/τ) exactly.

    P(s) = (1-s)(2-s)(3-s)/6 (1 + c1 s + c2 s²) has roots 1, 2, 3 in [0, 5] and no other, P(0) = 1,
    P'(0) = -0.4, P(5) = -1. So at t = 0 the margin φ0 is within the search's tolerance and the
    polishing bracket [0, 2φ/|φ'|] = [0, 5τ] holds the three roots τ, 2τ, 3τ; regula falsi's first
    point is 2.5τ, between the second and the third root, where the margin is positive.
    """

    C1 = 11 / 6 - 0.4
    C2 = (0.25 - 1 - 5 * C1) / 25

    def __init__(self, *, tau, margin0):
        cubic = np.polynomial.Polynomial.fromroots([1.0, 2.0, 3.0]) * (-1 / 6)
        self.poly = cubic * np.polynomial.Polynomial([1.0, self.C1, self.C2])
        self.tau, self.margin0 = tau, margin0

    def _p(self, t, order=0):
        return self.poly.deriv(order)(t / self.tau) / self.tau**order if order else self.poly(t / self.tau)

    def error_and_rate(self, t):
        e = math.sqrt(1.0 - self.margin0 * self._p(t))
        return np.array([e]), np.array([-self.margin0 * self._p(t, 1) / (2 * e)])

    def error(self, t):
        return self.error_and_rate(t)[0]

    def bounds(self, a, span, size):
        # |P^(k)(s)| <= sum_m |c_m| |s|^m over the span, with the chain rule's 1/τ^k.
        top = max(abs(a), abs(a + span)) / self.tau
        p0, p1, p2 = (
            sum(abs(c) * top**m for m, c in enumerate(self.poly.deriv(k).coef)) / self.tau**k
            for k in range(3)
        )
        low = math.sqrt(1.0 - self.margin0 * p0)  # ||e|| >= low on the span
        rate = self.margin0 * p1 / (2 * low)
        return (
            span,
            math.sqrt(1.0 + self.margin0 * p0),
            rate,
            self.margin0 * p2 / (2 * low) + rate * rate / low,
        )


def test_polishing_bracket_with_three_roots_gives_the_first():
    # Regula falsi alone finds *a* root of its bracket: here it would return 3τ. The search must
    # prove the bracket holds one root before refining, or keep stepping.
    tau = 1e-3
    model = ThreeRoots(tau=tau, margin0=5e-13)
    assert [model._p(k * tau) for k in (1, 2, 3)] == pytest.approx([0.0] * 3, abs=1e-14)
    assert model._p(0.0) == 1.0 and model._p(2.5 * tau) > 0.0 and model._p(5 * tau) == pytest.approx(-1.0)
    t = first_crossing(
        model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=1.0, tolerance=1e-12
    )
    # The margin is evaluated to ~1e-16 absolute and falls at 3.5e-10 per second at τ: the
    # crossing is resolvable to ~3e-7 s.
    assert abs(t - tau) < 1e-3 * tau


@pytest.mark.parametrize('pieces', [2, 7, 50])
def test_search_past_the_tolerance_advanced_in_pieces_gives_the_same_float(pieces):
    # The steps the search takes inside the tolerance (the bracket not yet proven) carry the
    # last step's bounds over to the next point; pieces must not change them.
    from formation_agent.core.crossing import CrossingSearch

    model = ThreeRoots(tau=1e-3, margin0=5e-13)
    whole = first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=1.0)
    search = CrossingSearch(model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=0.0), limit=1.0)
    for until in np.linspace(0.0, 1e-3, pieces):
        if search.advance(float(until)) is not None:
            break
    assert search.run() == whole


# --- the threshold floor c0 + α e^{-βt} (docs/SPEED_SCALE.md) ---------------------------------------


def test_floored_threshold_meets_a_constant_error_where_the_formula_says():
    # |e| = 0.5, threshold 0.2 + e^{-t}: the crossing is at t = ln(1/0.3), late in the decay.
    model = Bump(height=0.5, centre=0.0, width=1e100, ramp=0.0)
    t = first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.2, alpha=1.0, beta=1.0), limit=10.0)
    assert t == pytest.approx(math.log(1.0 / 0.3), rel=1e-13)


def test_an_error_below_the_floor_never_crosses_however_late():
    # The paper's threshold vanishes and any constant error crosses it; the floor keeps 0.5 < 0.5001
    # below it for ever, also where e^{βt} overflows a double (t >> 709/β).
    model = Bump(height=0.5, centre=0.0, width=1e100, ramp=0.0)
    assert (
        first_crossing(model, start=0.0, rule=ExponentialRule(floor=0.5001, alpha=1.0, beta=1.0), limit=1e4)
        == math.inf
    )
    assert first_crossing(
        model, start=0.0, rule=ExponentialRule(floor=0.0, alpha=1.0, beta=1.0), limit=10.0
    ) == pytest.approx(math.log(2.0), rel=1e-14)


@pytest.mark.parametrize('floor', [0.05, 0.4, 1.0])
def test_with_a_floor_the_narrow_spike_is_still_found_first(floor):
    # The spike pokes 1e-3 above the floored threshold at t = 1; a later ramp crosses too.
    alpha, beta = 1.0, 0.5
    level = floor + alpha * math.exp(-beta * 1.0)
    model = Bump(height=level * 1.001, centre=1.0, width=1e-4, ramp=0.01)
    t = first_crossing(
        model, start=0.0, rule=ExponentialRule(floor=floor, alpha=alpha, beta=beta), limit=100.0
    )
    grid = np.linspace(0.99, 1.01, 2_000_001)
    z = (grid - model.c) / model.w
    margin = floor + alpha * np.exp(-beta * grid) - np.abs(model.a * np.exp(-z * z) + model.b * grid)
    first = grid[1:][np.diff(np.sign(margin)) != 0][0]
    assert abs(t - first) < 1e-7 and t < 1.0
    assert abs(model.value(t) / (floor + alpha * math.exp(-beta * t)) - 1.0) < 1e-12
