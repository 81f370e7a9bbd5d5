"""Toy triggering rules, each plugged in through this one module (docs/DESIGN.md, "Adding a triggering
rule"): nothing in the packages names them. A run reaches them by their import path,
`toy_trigger_rule:Polynomial`, with this folder on PYTHONPATH (tests/formation_agent/core/test_trigger.py
and tests/formation_sim/runtime/test_trigger_rule_run.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from formation_agent.core.trigger import register_rule


@register_rule
@dataclass(frozen=True, kw_only=True, slots=True)
class Polynomial:
    """θ(t) = c0 + α / (1 + βt)²: it decays polynomially, not exponentially.

    With S = 1/θ(a) and r = S θ on t >= a: r' = -2αβ S (1 + βt)^{-3} and r'' = 6αβ² S (1 + βt)^{-4}
    shrink in size as t grows, and 0 < r <= 1, so |(r²)'| = 2r|r'| <= 2|r'(a)| and
    (r²)'' = 2r'² + 2r r'' <= 2r'(a)² + 2r''(a); θ is positive, decreasing and convex, so θ² (and r²)
    is convex. Built from (s c0, s α, κβ) it is s θ(κt): the speed scale's law.
    """

    name = 'polynomial'

    floor: float
    alpha: float
    beta: float

    def __post_init__(self) -> None:
        if not (self.alpha > 0.0 and self.beta >= 0.0 and self.floor >= 0.0):
            raise ValueError(f'polynomial: needs alpha > 0, beta >= 0, floor >= 0, got {self!r}')

    def _decay(self, t: float) -> float:
        grow = 1.0 + self.beta * t
        return 1.0 / (grow * grow)

    def __call__(self, t: float) -> float:
        return self.floor + self.alpha * self._decay(t)

    def scale(self, a: float) -> float:
        return 1.0 / self(a)

    def _slopes(self, a: float, scale: float) -> tuple[float, float]:
        """r'(a) and r''(a)."""
        grow = 1.0 + self.beta * a
        rate = -2.0 * self.alpha * self.beta * scale / (grow * grow * grow)
        return rate, 6.0 * self.alpha * self.beta * self.beta * scale / (grow * grow * grow * grow)

    def margin_terms(self, a: float, scale: float) -> tuple[float, float]:
        rate, _ = self._slopes(a, scale)
        return 2.0 * rate, 2.0 * abs(rate)

    def ratio(self, t: float, a: float, scale: float) -> float:
        return scale * self(t)

    def curvature(self, a: float, scale: float) -> float:
        rate, second = self._slopes(a, scale)
        return 2.0 * rate * rate + 2.0 * second


@register_rule
@dataclass(frozen=True, kw_only=True, slots=True)
class Exponential:
    """c0 + α e^{-βt} written again, outside the package, through the generic rule path: the engine
    runs it in pure Python (the compiled core knows only the package's `ExponentialRule`), so its
    run equals the built-in rule's bit for bit only if the generic search is the compiled one's
    arithmetic."""

    name = 'exponential_again'

    floor: float
    alpha: float
    beta: float

    def __call__(self, t: float) -> float:
        return self.floor + self.alpha * math.exp(-self.beta * t)

    def scale(self, a: float) -> float:
        if self.floor == 0.0:
            return math.exp(self.beta * a) / self.alpha
        return 1.0 / (self.floor + self.alpha * math.exp(-self.beta * a))

    def margin_terms(self, a: float, scale: float) -> tuple[float, float]:
        return -2.0 * self.beta * (1.0 - self.floor * scale), 2.0 * self.beta

    def ratio(self, t: float, a: float, scale: float) -> float:
        share = self.floor * scale
        return share + (1.0 - share) * math.exp(-self.beta * (t - a))

    def curvature(self, a: float, scale: float) -> float:
        return 4.0 * self.beta * self.beta
