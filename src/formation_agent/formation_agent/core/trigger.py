"""Triggering rules: the threshold θ(t) an agent's error is held below, one module per rule (issue 29).

Agent i triggers when ||e_i(t)|| reaches θ(t) (ETA-1 step 4, eq. triggersingle, θ(t) = α e^{-βt})
or when ||E_i(t)|| reaches it (ETA-2 step 5, eq. triggerdouble, θ(t) = α_d e^{-β_d t}). A rule is a
family of thresholds θ(t; c0, α, β) built from three numbers, the scenario's (α, β) or (α_d, β_d)
and the threshold floor c0: the gains every node already takes. The rule is picked by its name
(the scenario's `trigger_rule`, the agent's parameter `trigger_rule`) from the registry below;
`exponential`, c0 + α e^{-βt} (the paper's at c0 = 0; with a floor Seyboth, Dimarogonas and
Johansson's mixed threshold, docs/SPEED_SCALE.md), is the default and the one Theorems 1 and 2 are
proven for: another rule runs, certified, but carries none of their guarantees.

**What a rule gives** (`TriggerRule`): its value θ(t), and for the certified search
(`formation_agent.core.crossing.CrossingSearch`) what that search's certificate assumes of it. From
a point a on, the search watches the normalised margin φ(t) = r(t)² − S²||e(t)||², S = 1/θ(a),
r(t) = θ(t)/θ(a), which is positive exactly while the error is below the threshold. It assumes,
for every a >= 0 at which a search may stand and every t >= a:

* θ(t) > 0 and finite (so S and r are);
* r(t)² is convex: (r²)'' >= 0. This is what lets the quadratic step of the search bound φ'' from
  below by the error's bounds alone (φ'' >= −2S²(E1² + E E2));
* |(r²)'(t)| <= G(a), the `slope` of `margin_terms`: the first-order step's Lipschitz bound
  |φ'| <= G + 2S² E E1;
* (r²)''(t) <= K(a), `curvature`: the last step's proof that its bracket holds one root
  (φ'' <= K + 2S² E E2).

A positive, non-increasing, convex θ whose |θ'| and θ'' do not grow (the exponential, c0 alone,
c0 + α/(1 + βt)²) meets them with the bounds taken at t = a: (r²)' = 2 r r', |r| <= 1, so
G = 2|r'(a)| and K = 2 r'(a)² + 2 r''(a). The bounds must be those of the rule's floats only in the
sense the search's proof already is (the search's proof is for the computed values and bounds).

**Speed scale.** A family must obey the scaling law of docs/SPEED_SCALE.md: built from (s c0, s α,
κβ) it is s θ(κt; c0, α, β), s = 1 (ETA-1) or κ² (ETA-2). The agent builds its rule in real time
that way (`speed_scale.eta1_gains`, `eta2_gains`), so a run at κ is the paper's run at κt.

**Adding a rule** is one module: a class with the methods of `TriggerRule`, its `name`, a
constructor taking `floor`, `alpha`, `beta` (keywords), and `register_rule(TheClass)`; docs/DESIGN.md
("Adding a triggering rule") shows the diff. A rule outside this package reaches every process of a
run by its import path: the name `package.module:Class` imports `package.module` and takes its
`Class` (the process must be able to import it: PYTHONPATH, or an installed package).

The compiled core (`formation_agent.core._fastcore`) knows the exponential rule only; an agent whose
rule is another runs its search in pure Python (`formation_agent.core.compiled.search_type`).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from formation_agent.core.errors import RuleError

DEFAULT_RULE = 'exponential'
"""The rule of the paper (and of every scenario that names none)."""


@runtime_checkable
class TriggerRule(Protocol):
    """A threshold θ(t) and the bounds the certified search needs of it (the module's docstring says
    exactly what they must satisfy). `a` is a point the search stands at; `scale` is S = 1/θ(a)."""

    name: str

    def __call__(self, t: float) -> float:
        """θ(t), in the units of the agent's error."""

    def scale(self, a: float) -> float:
        """S = 1/θ(a), finite however late a is."""

    def margin_terms(self, a: float, scale: float) -> tuple[float, float]:
        """((r²)'(a), G): the rate of r² at a (r(t) = θ(t)/θ(a)) and G >= |(r²)'(t)| for every t >= a."""

    def ratio(self, t: float, a: float, scale: float) -> float:
        """r(t) = θ(t)/θ(a) = S θ(t) for t >= a, computed without cancellation (r(a) = 1)."""

    def curvature(self, a: float, scale: float) -> float:
        """K >= (r²)''(t) for every t >= a (and (r²)'' >= 0 there: the rule's convexity)."""


RuleFactory = Callable[..., TriggerRule]
"""A rule family: `factory(floor=c0, alpha=α, beta=β)` -> its rule (a class registered by name)."""

_RULES: dict[str, RuleFactory] = {}


def register_rule(factory: RuleFactory) -> RuleFactory:
    """Add the rule family `factory` under its `name` (returned, so it serves as a decorator); the
    same family again is a no-op, another under a taken name is a RuleError."""
    name = getattr(factory, 'name', None)
    if not isinstance(name, str) or not name or ':' in name:
        raise RuleError(f'trigger_rule: a rule needs a name without ":", got {name!r}')
    held = _RULES.get(name)
    if held is not None and held is not factory:
        raise RuleError(f'trigger_rule: {name!r} is registered already ({held!r})')
    _RULES[name] = factory
    return factory


def unregister_rule(name: str) -> None:
    """Remove a rule (for tests that register a toy rule)."""
    _RULES.pop(name, None)


def rule_names() -> tuple[str, ...]:
    """The registered rules' names, sorted."""
    return tuple(sorted(_RULES))


def rule_factory(name: str) -> RuleFactory:
    """The family registered as `name`, or found at the import path `package.module:Class`;
    RuleError naming the rule trigger_rule and the value otherwise."""
    if not isinstance(name, str):
        raise RuleError(f'trigger_rule: must be a rule name, got {name!r}')
    if name in _RULES:
        return _RULES[name]
    if ':' not in name:
        raise RuleError(
            f'trigger_rule: must be one of {list(rule_names())} or an import path package.module:Class, '
            f'got {name!r}'
        )
    module_name, _, attribute = name.partition(':')
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise RuleError(f'trigger_rule: cannot import {module_name!r} for {name!r} ({error})') from None
    found = getattr(module, attribute, None)
    if found is None or not callable(found):
        raise RuleError(f'trigger_rule: {module_name!r} has no rule {attribute!r} (from {name!r})')
    factory: RuleFactory = found
    _RULES[name] = factory
    return factory


def make_rule(name: str, *, floor: float, alpha: float, beta: float) -> TriggerRule:
    """The rule `name` with c0 = `floor`, α = `alpha`, β = `beta` (already in the agent's units and
    real time); RuleError if the name is unknown or the family's constructor refuses the numbers."""
    factory = rule_factory(name)
    try:
        rule = factory(floor=floor, alpha=alpha, beta=beta)
    except RuleError:
        raise
    except (TypeError, ValueError) as error:
        raise RuleError(
            f'trigger_rule: {name!r} refused floor={floor!r}, alpha={alpha!r}, beta={beta!r}: {error}'
        ) from None
    if type(rule) not in _CONFORMING:
        if not isinstance(rule, TriggerRule):
            raise RuleError(f'trigger_rule: {name!r} built {rule!r}, which lacks the methods of TriggerRule')
        _CONFORMING.add(type(rule))
    return rule


_CONFORMING: set[type] = set()
"""The rule types whose instances were found to have every member of TriggerRule: a protocol's
isinstance costs ~80 µs on Python 3.11, once per agent otherwise (a thousand agents: 0.08 s of a run)."""


@register_rule
@dataclass(frozen=True, kw_only=True, slots=True)
class ExponentialRule:
    """θ(t) = c0 + α e^{-βt} (triggersingle / triggerdouble with the floor c0; docs/SPEED_SCALE.md).

    With w = c0 S (the floor's share of θ(a)), r(t) = w + (1 - w) e^{-β(t-a)}: 0 < r <= 1,
    |r'| <= (1 - w)β and r'' >= 0 on t >= a, so (r²)' lies in [-2β, 0] and (r²)'' in [0, 4β²]:
    G = 2β, K = 4β². The floats are those the search computed before rules existed (and the compiled
    core computes): at c0 = 0, S = e^{βa}/α.
    """

    name = DEFAULT_RULE

    floor: float
    alpha: float
    beta: float

    def __call__(self, t: float) -> float:
        return self.floor + self.alpha * math.exp(-self.beta * t)  # + 0.0 is exact: the paper's

    def scale(self, a: float) -> float:
        if self.floor == 0.0:  # the paper's threshold, as before the floor existed
            return math.exp(self.beta * a) / self.alpha
        return 1.0 / (self.floor + self.alpha * math.exp(-self.beta * a))  # finite however late a is

    def margin_terms(self, a: float, scale: float) -> tuple[float, float]:
        beta = self.beta
        return -2.0 * beta * (1.0 - self.floor * scale), 2.0 * beta  # (r²)'(a) = -2β(1-w)

    def ratio(self, t: float, a: float, scale: float) -> float:
        share = self.floor * scale  # w
        return share + (1.0 - share) * math.exp(-self.beta * (t - a))

    def curvature(self, a: float, scale: float) -> float:
        beta = self.beta
        return 4.0 * beta * beta
