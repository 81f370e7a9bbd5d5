"""An event-by-event audit of the guarantees of Theorems 1 and 2 on one exact run.

Four guarantees, each counted as checks, violations and the smallest margin:

- connectivity (Theorem 1/2 (i)): every edge ||x_i - x_j|| < Δ at every instant. Between two
  consecutive events of the team the inputs are constant and the motion closed form
  (formation_agent.core.closed_form), so `EdgeWatch` bounds each edge on each interval: the chord
  of r(s) = x_i - x_j is within max(||r(s0)||, ||r(s1)||) (a norm is convex) and r is within
  sup||r''|| w²/8 of its chord (r'' = e^{-k3 s}(u_i - u_j - k3 (q_i - q_j)) for ETA-2, 0 for ETA-1).
  Intervals whose bound exceeds the largest length seen so far are bisected until the bound is
  within TOLERANCE Δ of it: the result is the run's exact largest edge length, to TOLERANCE Δ,
  with the upper bound as the one checked. One check per edge per event and per interval.
- convergence (Theorem 1 (ii); Theorem 2 (ii) corrected): V < k_V e^{-2 rate t} and the formation
  error < 2 sqrt(z_gain k_V) e^{-rate t} at every triggering time (analysis.checks.theory_bounds).
- Zeno (Theorem 1/2 (iii)): every inter-event time t_{k+1} - t_k >= ξ_i.
- rate as printed (Theorem 2 only): the same two inequalities with the printed chain's constants.

The paper's quantities come from formation_sim.analysis.checks (run_series, theory_bounds) and
formation_sim.model.theory; the margins are relative: 1 - length/Δ, 1 - value/bound, gap/ξ - 1.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from formation_agent.core.closed_form import advance_double
from formation_sim.analysis.checks import Series, TheoryBounds

TOLERANCE = 1e-12  # the edge maxima between events are exact to this fraction of Δ
MAX_SPLITS = 200  # bisections of one interval before its bound is taken as it is


class EdgeWatch:
    """The largest edge length of a run, exact between events (`on_event` is the engine's hook)."""

    def __init__(self, scenario) -> None:
        self.heads, self.tails, _ = scenario.edge_indices()
        self.delta = scenario.delta
        self.k3 = None  # the world's damping (k3, or κ k3 at a speed scale κ), from the first event
        self.tolerance = TOLERANCE * scenario.delta
        self.checks = 0
        self.largest = 0.0  # the largest length evaluated
        self.bound = 0.0  # an upper bound on every length between the events seen
        self.interior = 0  # intervals where a length between two events exceeded both ends
        self._last: tuple[float, np.ndarray, np.ndarray | None] | None = None
        self._world = None

    def on_event(self, t: float, world, _due) -> None:
        """At an event time, before the due agents trigger: the inputs still those of [last, t]."""
        self._world = world
        self.k3 = world.damping if world.double else None
        x, q = world.positions, world.velocities
        lengths = np.linalg.norm(x[self.heads] - x[self.tails], axis=1)
        self.checks += lengths.size
        self._note(float(lengths.max()))
        if self._last is not None and t > self._last[0]:
            self._interval(t, world.controls)
        self._last = (t, x, q)

    def finish(self, horizon: float) -> None:
        """The last interval, from the last event to the horizon (the world is there now)."""
        if self._world is not None and self._last is not None and horizon > self._last[0]:
            x = self._world.positions
            self._note(float(np.linalg.norm(x[self.heads] - x[self.tails], axis=1).max()))
            self._interval(horizon, self._world.controls)

    def _note(self, length: float) -> None:
        self.largest = max(self.largest, length)
        self.bound = max(self.bound, length)

    def _relative(self, a, b, c, s: float) -> np.ndarray:
        """x_i - x_j at s after the interval's start (ETA-2: relative state a, b and input c)."""
        assert self.k3 is not None  # only ETA-2's intervals are evaluated inside
        return advance_double(a, b, c, self.k3, s)[0]

    def _interval(self, t: float, controls: np.ndarray) -> None:
        if self.k3 is None:  # single integrators: a length is convex in s, its largest value is at an
            self.checks += len(self.heads)  # end, and both ends are checked at their events
            return
        t0, x0, q0 = self._last
        h = t - t0
        a = x0[self.heads] - x0[self.tails]
        c = controls[self.heads] - controls[self.tails]
        b = q0[self.heads] - q0[self.tails]
        f0 = np.linalg.norm(a, axis=1)
        f1 = np.linalg.norm(self._relative(a, b, c, h), axis=1)
        self.checks += f0.size
        curvature = self._curvature(b, c)
        bound = np.maximum(f0, f1) + curvature * h * h / 8.0
        for k in np.flatnonzero(bound > self.largest + self.tolerance):
            self._refine(a[k], b[k], c[k], h, float(f0[k]), float(f1[k]), float(curvature[k]))

    def _curvature(self, b, c) -> np.ndarray:
        """sup ||r''|| over an interval per edge, for ETA-2: ||c - k3 b|| (e^{-k3 s} <= 1)."""
        return np.linalg.norm(c - self.k3 * b, axis=1)

    def _refine(self, a, b, c, h: float, f0: float, f1: float, curvature: float) -> None:
        """Bisect [0, h] until every piece's bound is within the tolerance of the largest length."""
        pieces = [(0.0, h, f0, f1)]
        before = self.largest
        splits = 0
        while pieces:
            s0, s1, g0, g1 = pieces.pop()
            w = s1 - s0
            top = max(g0, g1) + curvature * w * w / 8.0
            if top <= self.largest + self.tolerance:
                continue
            if splits >= MAX_SPLITS:
                self.bound = max(self.bound, top)
                continue
            splits += 1
            mid = 0.5 * (s0 + s1)
            gm = float(np.linalg.norm(self._relative(a, b, c, mid)))
            self._note(gm)
            pieces += [(s0, mid, g0, gm), (mid, s1, gm, g1)]
        if self.largest > max(before, f0, f1):
            self.interior += 1
        self.bound = max(self.bound, self.largest + self.tolerance)

    def result(self) -> dict[str, Any]:
        return {
            'conn_checks': self.checks,
            'conn_violations': int(not self.bound < self.delta),
            'conn_margin': 1.0 - self.bound / self.delta,
            'max_edge_exact': self.largest,
            'interior_maxima': self.interior,
        }


def _ratio_check(
    series: Series, k_V: float | None, gain: float | None, rate: float
) -> tuple[int, int, float | None]:
    """(checks, violations, margin) of V < k_V e^{-2 rate t} and error < gain e^{-rate t} at every sample."""
    if k_V is None or gain is None:
        return 0, 0, None
    t = series.times
    decay = np.exp(-rate * t)
    ratios = np.concatenate(
        [series.lyapunov / (k_V * decay * decay), series.formation_error / (gain * decay)]
    )
    return int(ratios.size), int(np.count_nonzero(~(ratios < 1.0))), float(1.0 - ratios.max())


def theorem_audit(record, series: Series, bounds: TheoryBounds | None) -> dict[str, Any]:
    """Convergence, Zeno and (Theorem 2) the printed rate, from the run's series and the proofs' bounds."""
    out: dict[str, Any] = {}
    if bounds is None:
        return out
    checks, violations, margin = _ratio_check(series, bounds.k_V, bounds.error_gain, bounds.rate)
    out.update(conv_checks=checks, conv_violations=violations, conv_margin=margin)
    if bounds.theorem == 2:
        checks, violations, margin = _ratio_check(
            series, bounds.printed_k_V, bounds.printed_error_gain, bounds.rate
        )
        out.update(printed_checks=checks, printed_violations=violations, printed_margin=margin)
        ratio = series.lyapunov / (bounds.printed_k_V * np.exp(-2.0 * bounds.rate * series.times))
        above = np.flatnonzero(ratio >= 1.0)
        out['printed_first_violation'] = float(series.times[above[0]]) if above.size else None
    gaps, worst = 0, math.inf
    below = 0
    if bounds.xi is not None:
        for agent, times in record.trigger_times.items():
            diffs = np.diff(np.asarray(times, dtype=float))
            if diffs.size:
                gaps += diffs.size
                ratios = diffs / bounds.xi[agent]
                below += int(np.count_nonzero(~(ratios >= 1.0)))
                worst = min(worst, float(ratios.min()))
    out.update(zeno_checks=gaps, zeno_violations=below, zeno_margin=None if not gaps else worst - 1.0)
    return out
