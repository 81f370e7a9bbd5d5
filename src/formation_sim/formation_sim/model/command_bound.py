"""The largest command a scenario asks of a robot, bounded from the proofs (ROS-free).

A robot carries out velocity commands, and its base has limits (a TurtleBot3: 0.22 m/s,
2.84 rad/s); the theorems assume none.  Where the proofs bound the commands, `command_bound`
gives the bound, so `formation validate --max-speed V` can say the limits are never reached:

- ETA-1 (Theorem 1): the command is u_i(t) = u_i(t^i_k), (uxsingle).  With (wij),
  ω_ij < f_ij(k_ij), and the edge errors bounded by (lengthys), ||y_i - y_j|| <= k_ij, and by
  (lengthysV), ||y_i - y_j|| < 2 sqrt(k_V) e^{-βt} <= 2 sqrt(k_V):
      ||u_i|| <= Σ_{j∈N_i} f_ij(k_ij) min(k_ij, 2 sqrt(k_V)),
  at most the bound (dotyi) on ||ẏ_i||, α + Σ_j 2 f_ij(k_ij) sqrt(k_V), without its α (the
  sampled command has no e_i(t) term), which is also reported.
- ETA-2 (Theorem 2): a velocity-commanded robot is sent q_i, the velocity of (double) that the
  agent integrates from u^d_i - k3 q_i.  Part (i) of the proof gives ν_d <= k^d_ν, and
  ν_d = k1 ν + ½ Σ ||q_i||², so ||q_i|| <= sqrt(2 k^d_ν); its acceleration
  ||u^d_i - k3 q_i|| <= Σ_j f_ij(k^d_ij) (k1 k^d_ij + 2 k2 sqrt(2 k^d_ν)) + k3 sqrt(2 k^d_ν), from
  (uxdouble), (wij) with (kijd), and ||q_i - q_j|| <= ||q_i|| + ||q_j||.  Part (i) does not
  depend on β_d, so these hold whichever reading of Theorem 2 (docs/THEOREM2.md).

A unicycle steered at its control point l ahead of the axle turns at |ω| <= ||u|| / l (the
diffeomorphism: ω = (-sin θ u_x + cos θ u_y) / l), so the same bound bounds its turn rate.

At a speed scale κ (docs/SPEED_SCALE.md) the run is the paper's in the time s = κt: the proofs
bound the paper's commands, and the robot's are κ times them (ETA-2: its velocity κ q_i, its
acceleration κ² (u^d_i − k3 q_i)); `command_bound` reports the robot's.  With a threshold floor
c0 > 0 the proofs do not apply (ν is no longer bounded by them): TheoryError.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formation_sim.model import theory
from formation_sim.model.errors import TheoryError
from formation_sim.model.scenario import Scenario


@dataclass(frozen=True, kw_only=True)
class CommandBound:
    """Per agent, the largest linear command [m/s] (and, ETA-2, acceleration [m/s²]) and how it was found."""

    source: str  # 'theory' (a bound that always holds) or 'exact run' (the largest in one exact run)
    speed: dict[int, float]
    acceleration: dict[int, float] | None  # ETA-2 only
    reference: str  # where it comes from: the equations, or the run
    dotyi: dict[int, float] | None = None  # ETA-1 theory: the bound (dotyi) as printed, for comparison

    @property
    def max_speed(self) -> float:
        return max(self.speed.values())

    @property
    def max_acceleration(self) -> float | None:
        return None if self.acceleration is None else max(self.acceleration.values())

    def max_turn_rate(self, control_point_distance: float) -> float:
        """A unicycle steered at its control point: |ω| <= ||u|| / l."""
        return self.max_speed / control_point_distance

    def to_dict(self) -> dict:
        return {
            'source': self.source,
            'reference': self.reference,
            'max_speed': self.max_speed,
            'speed': {str(i): v for i, v in self.speed.items()},
            'max_acceleration': self.max_acceleration,
            'acceleration': None
            if self.acceleration is None
            else {str(i): v for i, v in self.acceleration.items()},
            'dotyi': None if self.dotyi is None else {str(i): v for i, v in self.dotyi.items()},
        }


def command_bound(scenario: Scenario) -> CommandBound:
    """The proofs' bound on every agent's command at the scenario's speed scale κ; raises
    TheoryError outside the hypotheses, or with a threshold floor c0 > 0."""
    if scenario.gains.threshold_floor > 0.0:
        raise TheoryError(
            'the proofs bound the commands for the threshold α e^(-βt) of '
            f'(triggersingle)/(triggerdouble); with a floor c0 = {scenario.gains.threshold_floor:g} '
            'they bound neither ν nor the commands'
        )
    kappa = scenario.gains.speed_scale
    constants = theory.theorem_constants(scenario)
    capacities = theory.edge_capacities(scenario)
    k_edge = np.array([constants.k_edge[edge.pair] for edge in scenario.edges])
    f = theory.f_ij(k_edge, capacity=capacities)
    heads, tails, _ = scenario.edge_indices()
    ids = scenario.agent_ids

    def per_agent(per_edge: np.ndarray) -> np.ndarray:
        total = np.zeros(scenario.n)
        np.add.at(total, heads, per_edge)
        np.add.at(total, tails, per_edge)
        return total

    if constants.theorem == 1:
        root = math.sqrt(constants.k_V)
        speed = per_agent(f * np.minimum(k_edge, 2.0 * root))  # (uxsingle), (wij), (lengthys), (lengthysV)
        dotyi = scenario.gains.alpha + per_agent(2.0 * f * root)  # (dotyi)
        return CommandBound(
            source='theory',
            speed=dict(zip(ids, (kappa * speed).tolist())),
            acceleration=None,
            reference=(
                'Theorem 1: ||u_i|| <= Σ_j f_ij(k_ij) min(k_ij, 2 sqrt(k_V)) from (uxsingle), (wij), '
                '(lengthys), (lengthysV); (dotyi) for comparison'
                + ('' if kappa == 1.0 else f'; times κ = {kappa:g}')
            ),
            dotyi=dict(zip(ids, (kappa * dotyi).tolist())),
        )
    gains = scenario.gains
    q_max = math.sqrt(2.0 * constants.k_nu)  # Theorem 2 (i): ½ Σ ||q_i||² <= ν_d <= k^d_ν
    acceleration = per_agent(f * (gains.k1 * k_edge + 2.0 * gains.k2 * q_max)) + gains.k3 * q_max
    return CommandBound(
        source='theory',
        speed=dict.fromkeys(ids, kappa * q_max),
        acceleration=dict(zip(ids, (kappa * kappa * acceleration).tolist())),
        reference=(
            'Theorem 2 (i): ||q_i|| <= sqrt(2 k^d_ν); ||u^d_i - k3 q_i|| <= '
            'Σ_j f_ij(k^d_ij)(k1 k^d_ij + 2 k2 sqrt(2 k^d_ν)) + k3 sqrt(2 k^d_ν) '
            'from (uxdouble), (wij), (kijd)'
            + ('' if kappa == 1.0 else f'; times κ = {kappa:g} (speed) and κ² (acceleration)')
        ),
    )
