"""The speed scale κ and the threshold floor c0 (docs/SPEED_SCALE.md): the one place where the
paper's gains become the gains an agent, the exact world and a robot's velocity reference use.

Speed scale κ > 0. The run at κ is the paper's system in the time s = κt: every path is the
same, every triggering time is divided by κ (κ < 1: slower). With x(t) = x_p(κt):

* ETA-1: u_i(t) = κ u_p,i with u_p,i the paper's (uxsingle); e_i is the paper's (it is made of
  positions only) and the threshold of (triggersingle) decays at κβ in real time.
* ETA-2: q(t) = κ q_p(κt) and dq/dt = κ² u_p(κt), so (uxdouble) becomes
  u^d_i = -κ²k1 Σ ω_ij y_ij - κk2 Σ ω_ij q_ij with damping κk3: the gains (κ²k1, κk2, κk3). The
  agent's error K1 e_i + K2 e_qi with these gains is κ² times the paper's E_i of (triggerdouble),
  so its threshold is κ²(c0 + α_d e^{-κβ_d t}). The scenario's initial velocities are the paper's
  q_p(0): the scaled run starts at κ q(0) (`initial_velocities`).

Threshold floor c0 >= 0: the mixed threshold c0 + α e^{-βt} (Seyboth, Dimarogonas, Johansson,
Automatica 2013), in the units of the paper's e_i / E_i; with κ, c0 + α e^{-κβt}. Another triggering
rule (formation_agent.core.trigger) is scaled the same way: built from (s c0, s α, κβ).

κ = 1 and c0 = 0 are the paper's: every product with 1.0 and every sum with 0.0 is exact, so
they reproduce its event chains bit for bit.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from formation_agent.core.errors import ScaleError
from formation_agent.core.trigger import DEFAULT_RULE, TriggerRule, make_rule

DEFAULT_SPEED_SCALE = 1.0
DEFAULT_THRESHOLD_FLOOR = 0.0

SPEED_SCALE_LIMITS = (1e-6, 1e6)
"""κ must lie in these bounds (rule speed_scale): ETA-2's gains hold κ² and its certified search
bounds up to κ⁴ of the paper's; beyond a factor 10⁶ either way the scaled times, rates and bounds
would leave the range in which the run's floats resolve them (1e-6 turns 10 s into ~4 months)."""


def check_speed_scale(value: Any) -> float:  # any value given: checked here
    """κ as a float, or ScaleError naming the rule speed_scale and the value."""
    try:
        kappa = float(value)
    except (TypeError, ValueError):
        raise ScaleError(f'speed_scale: must be a finite number > 0, got {value!r}') from None
    if not (math.isfinite(kappa) and kappa > 0.0):
        raise ScaleError(f'speed_scale: must be a finite number > 0, got {kappa!r}')
    low, high = SPEED_SCALE_LIMITS
    if not low <= kappa <= high:
        raise ScaleError(
            f'speed_scale: must lie in [{low:g}, {high:g}] (the scaled times, rates and bounds must stay '
            f'within what a double resolves), got {kappa!r}'
        )
    return kappa


def check_threshold_floor(value: Any) -> float:  # any value given: checked here
    """c0 as a float, or ScaleError naming the rule threshold_floor and the value."""
    try:
        floor = float(value)
    except (TypeError, ValueError):
        raise ScaleError(f'threshold_floor: must be a finite number >= 0, got {value!r}') from None
    if not (math.isfinite(floor) and floor >= 0.0):
        raise ScaleError(f'threshold_floor: must be a finite number >= 0, got {floor!r}')
    return floor


def eta1_gains(
    *, alpha: float, beta: float, speed_scale: float, threshold_floor: float, trigger_rule: str = DEFAULT_RULE
) -> tuple[float, TriggerRule]:
    """(command gain, threshold) of ETA-1 at κ: u_i = κ u_p,i, ||e_i|| reaches θ(κt; c0, α, β) of the
    rule `trigger_rule` (the paper's: c0 + α e^{-κβt}; formation_agent.core.trigger)."""
    kappa = check_speed_scale(speed_scale)
    floor = check_threshold_floor(threshold_floor)
    return kappa, make_rule(trigger_rule, floor=floor, alpha=alpha, beta=kappa * beta)


def eta2_gains(
    *,
    alpha_d: float,
    beta_d: float,
    k1: float,
    k2: float,
    k3: float,
    speed_scale: float,
    threshold_floor: float,
    trigger_rule: str = DEFAULT_RULE,
) -> tuple[tuple[float, float, float], TriggerRule]:
    """((K1, K2, K3), threshold) of ETA-2 at κ: (κ²k1, κk2, κk3), and κ² θ(κt; c0, α_d, β_d) of the
    rule `trigger_rule` (the paper's: κ²(c0 + α_d e^{-κβ_d t})) on K1 e_i + K2 e_qi = κ² E_i (the
    paper's E_i of (triggerdouble))."""
    kappa = check_speed_scale(speed_scale)
    floor = check_threshold_floor(threshold_floor)
    square = kappa * kappa
    gains = (square * k1, kappa * k2, damping(k3, kappa))
    return gains, make_rule(trigger_rule, floor=square * floor, alpha=square * alpha_d, beta=kappa * beta_d)


def damping(k3: float, speed_scale: float) -> float:
    """The damping of (uxdouble) in real time, κ k3: the exact plant's and a robot's velocity reference's."""
    return speed_scale * k3


def initial_velocities(velocities: npt.ArrayLike | None, speed_scale: float) -> np.ndarray | None:
    """The scaled run's q(0) = κ q_p(0) from the scenario's (paper) velocities; None stays None."""
    if velocities is None:
        return None
    return speed_scale * np.asarray(velocities, dtype=float)


def paper_velocities(velocities: npt.ArrayLike | None, speed_scale: float) -> np.ndarray | None:
    """q_p = q / κ: a run's velocities in the paper's time (for V_d, ν_d and the proofs' bounds)."""
    if velocities is None:
        return None
    return np.asarray(velocities, dtype=float) / speed_scale


def real_duration(duration: float, speed_scale: float) -> float:
    """A duration of the paper's time (ξ_i, 1/β) in real seconds: divided by κ."""
    return duration / speed_scale


def real_rate(rate: float, speed_scale: float) -> float:
    """A rate of the paper's time (β, β_d, β0) per real second: multiplied by κ."""
    return speed_scale * rate
