"""ETA-1 and ETA-2 as run by one agent: only what that agent knows, no global state, no ROS.

An agent knows its neighbours' desired displacements d_ij, the radius Δ and its gains. At its own
triggering times it is handed what it senses and returns its new input and the triggering
information for each neighbour; in between it is handed its neighbours' triggering information.
From these it predicts every relative state in closed form (eqs. statexixj, statexixjd,
stateqiqj) and finds its next triggering time as the first crossing of ||e_i(t)|| = α e^{-βt}
(resp. ||E_i(t)|| = α_d e^{-β_d t}), certified by `formation_agent.core.crossing`; the threshold is
the agent's triggering rule (`trigger_rule`, formation_agent.core.trigger: that one by default). With a speed
scale κ and a threshold floor c0 (`formation_agent.core.speed_scale`, docs/SPEED_SCALE.md) the
agent runs in real time with the gains that module derives, against c0 + α e^{-κβt}.

Per edge the agent keeps an anchor: the time of the edge's last event (its own trigger or the
neighbour's) and the relative state then, plus the neighbour's current input. Since both inputs
are constant between the edge's events, the closed form from the anchor is exact.

Speed: a search evaluates e_i and its bounds a few dozen times on a handful of edges, where numpy's
per-call overhead dominates. For p <= 3 (every distributed run, the paper's examples) the agents
therefore evaluate them edge by edge in plain floats, on vectors padded to three components (a
zero component changes no sum, norm or product); numpy serves p > 3. The formulas are those of
`formation_agent.core.tension` (ω, dω/dr, g, the curvature gain), which the numpy path and the
triggers call; inside the plain-float loops they are written out, each citing its equation,
because calling the functions there costs 2-3.5 % of the engine's time (measured). The edge rows
of those loops are plain tuples laid out by `_row`. tests/formation_agent/core/test_eta.py checks
both paths against independent formulas.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from formation_agent.core import compiled
from formation_agent.core.closed_form import SERIES_LIMIT as _SERIES_LIMIT
from formation_agent.core.closed_form import advance_double, one_minus_exp, z_minus_one_plus_exp_float
from formation_agent.core.crossing import DEFAULT_TOLERANCE, CrossingSearch
from formation_agent.core.errors import AgentError, RuleError, ScaleError
from formation_agent.core.neighbourhood import PADDED, Neighbourhood
from formation_agent.core.neighbourhood import positive as _positive
from formation_agent.core.safety import CappedSearch, SafetyConfig, SafetyLayer
from formation_agent.core.speed_scale import (
    DEFAULT_SPEED_SCALE,
    DEFAULT_THRESHOLD_FLOOR,
    eta1_gains,
    eta2_gains,
)
from formation_agent.core.tension import curvature_gain, omega, omega_prime, omega_second, weight_gain
from formation_agent.core.trigger import DEFAULT_RULE, ExponentialRule, TriggerRule
from formation_msgs_py.types import SensedState, TriggerInfo

# Agents of this dimension or less evaluate their prediction in plain floats.
_FAST_DIMENSION = PADDED

# First trial span of a search [s] before the agent has an inter-event time of its own, and its
# least value (the search's former fixed choice).
_FIRST_SPAN = 1e-3

ALGORITHM_GAINS: dict[str, tuple[str, ...]] = {
    'eta1': ('alpha', 'beta'),
    'eta2': ('alpha_d', 'beta_d', 'k1', 'k2', 'k3'),
}
"""The gains each algorithm takes, by name (Theorem 1: α, β; Theorem 2: α_d, β_d, k1, k2, k3)."""

SCALE_GAINS: dict[str, float] = {
    'speed_scale': DEFAULT_SPEED_SCALE,
    'threshold_floor': DEFAULT_THRESHOLD_FLOOR,
}
"""The gains both algorithms take optionally, with their defaults (the paper's): κ and c0."""

# A step may use at most this fraction of an edge's gap c - ||y_ij|| (what is left of its capacity
# c = Δ - ||d_ij||), so that the bounds, which are evaluated at the far end of the step, stay
# within a small factor of the local values.
_GAP_FRACTION = 0.125


@dataclass(frozen=True, kw_only=True, slots=True)
class TriggerOutput:
    """Result of a trigger: the new input and one triggering-information message per neighbour."""

    time: float
    control: np.ndarray
    infos: tuple[TriggerInfo, ...]


compiled.configure(gap_fraction=_GAP_FRACTION, trigger_output=TriggerOutput)


class _AgentHooks:
    """What ETA-1 and ETA-2 each supply to `_EventTriggeredAgent` (Eta1Agent, Eta2Agent): the
    base class calls these and never defines them."""

    _threshold: TriggerRule
    """The triggering threshold θ(t) and its bounds: α e^{-βt} (ETA-1), α_d e^{-β_d t} (ETA-2) by
    default, each with its speed scale and floor (`eta1_gains`, `eta2_gains`; the agent's
    `trigger_rule` picks another family, formation_agent.core.trigger)."""

    # The vector path's error and bounds (p > 3), and the plain-float path's bounds: each of
    # Eta1Agent and Eta2Agent defines them (declared here for the type checker only).
    _vector_error_and_rate: Callable[[float], tuple[np.ndarray, np.ndarray]]
    _vector_bounds: Callable[[float, float, float], tuple[float, float, float, float]]
    _fast_bounds: Callable[[float, float], tuple[float, float, float, float]]

    def _update(self, y: list[tuple[float, ...]], length: list[float], extra: Any) -> tuple[float, ...]:
        """At a triggering time, from the sensed relative states y_ij, their lengths and `extra`
        (ETA-2: the relative velocities; ETA-1: None): the new control (uxsingle) / (uxdouble)."""
        raise NotImplementedError

    def _row(self, k: int) -> tuple[float, ...]:
        """Edge k as the plain-float hot path reads it (its last event, the relative state there
        and what moves it until the edge's next event)."""
        raise NotImplementedError

    def _fast_probe(
        self, t: float, *, with_rate: bool = True
    ) -> tuple[float, float, float, float, float, float]:
        """The measurement error e(t) and, `with_rate`, ė(t), padded to three components, on the
        plain-float hot path."""
        raise NotImplementedError


class _SafetyHooks:
    """The collision layer's part of an agent (docs/SAFETY.md): off (None) unless Eta1Agent is given
    a `SafetyConfig`; its time caps the agent's certified search."""

    _safety: SafetyLayer | None = None
    _capped_search: CappedSearch | None = None
    # The agent's own (`_EventTriggeredAgent`), declared here for the type checker only.
    neighbour_ids: tuple[int, ...]
    last_event: float
    _edge_time: list[float]
    _edge_y: list[tuple[float, ...]]
    _offsets: list[tuple[float, ...]]
    _edge_u: list[tuple[float, ...]]
    _capacity: list[float]

    @property
    def safety(self) -> SafetyConfig | None:
        """The collision layer's configuration (docs/SAFETY.md), or None when it is off."""
        return None if self._safety is None else self._safety.config

    @property
    def safety_interventions(self) -> int:
        """Triggers at which the safety layer changed the nominal command (0 when it is off)."""
        return 0 if self._safety is None else self._safety.interventions

    @property
    def safety_last_intervention(self) -> float | None:
        """The latest trigger at which the safety layer changed the nominal command, or None."""
        return None if self._safety is None else self._safety.last_intervention

    def _capped(self, search: CrossingSearch) -> CappedSearch:
        """`search` with the safety layer's time as a cap (S6), made once per search."""
        held = self._capped_search
        if held is None or held.inner is not search:
            edges = [
                (self._edge_time[k], self._edge_y[k], self._offsets[k], self._edge_u[k], self._capacity[k])
                for k in range(len(self.neighbour_ids))
            ]
            cap = cast(SafetyLayer, self._safety).safety_time(now=self.last_event, edges=edges)  # it is on
            held = self._capped_search = CappedSearch(search, cap)
        return held


class _KnowledgeArrays:
    """An agent's knowledge as numpy arrays, for the numpy path (p > 3) and the tests: read-only views
    of its edge lists (`_edge_time`, `_edge_y`, `_edge_u`, ETA-2's `_edge_q`: the one record of the
    knowledge, which trigger and receive keep), built when read and kept until the knowledge changes;
    and whether every neighbour was heard."""

    neighbour_ids: tuple[int, ...]
    dimension: int
    triggers: int
    infos_received: int
    _heard: list[bool]

    _everyone_heard = False

    _edge_time: list[float]
    _edge_y: list[tuple[float, ...]]
    _edge_u: list[tuple[float, ...]]

    _mirror_key: tuple[int, int] | None = None
    _mirror: tuple[np.ndarray, ...] = ()

    def _mirrors(self) -> tuple[np.ndarray, ...]:
        """(anchor times, y_ij at the anchors, the neighbours' controls[, q_ij at the anchors]), read-only."""
        key = (self.triggers, self.infos_received)
        if self._mirror_key != key:
            m, p = len(self.neighbour_ids), self.dimension
            lists = [self._edge_y, self._edge_u, *([self._edge_q] if hasattr(self, '_edge_q') else [])]
            arrays = [np.array(self._edge_time, dtype=float)]
            arrays += [np.array([row[:p] for row in rows], dtype=float).reshape(m, p) for rows in lists]
            for array in arrays:
                array.flags.writeable = False
            self._mirror, self._mirror_key = tuple(arrays), key
        return self._mirror

    @property
    def _anchor_time(self) -> np.ndarray:
        """Each edge's anchor: its last event (its own trigger or the neighbour's)."""
        return self._mirrors()[0]

    @property
    def _anchor_y(self) -> np.ndarray:
        """y_ij = x_i - x_j - d_ij at each edge's anchor."""
        return self._mirrors()[1]

    @property
    def _neighbour_control(self) -> np.ndarray:
        """Each neighbour's latest control."""
        return self._mirrors()[2]

    def _heard_all(self) -> bool:
        """True once every neighbour was heard (it stays so: nothing unhears one)."""
        if not self._everyone_heard:
            self._everyone_heard = all(self._heard)
        return self._everyone_heard


class _EventTriggeredAgent(_AgentHooks, _SafetyHooks, _KnowledgeArrays):
    """Bookkeeping shared by ETA-1 and ETA-2: anchors, caching of the next time; its neighbours
    and the checks of what it is handed are its `Neighbourhood` (`formation_agent.core.neighbourhood`)."""

    algorithm = ''

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object] | Neighbourhood,
        delta: float,
        tolerance: float = DEFAULT_TOLERANCE,
    ) -> None:
        # Who the neighbours are, d_ij and Δ - ||d_ij|| (checked), and the checks of every input; or
        # the agent's Neighbourhood built already (`Neighbourhood.team`: a whole team's at once).
        if isinstance(neighbours, Neighbourhood):
            hood = self._hood = neighbours
            if hood.agent_id != agent_id or hood.delta != delta:
                raise AgentError(
                    f"agent {agent_id}: the neighbourhood given is agent {hood.agent_id}'s with Δ = "
                    f'{hood.delta!r}, not Δ = {delta!r}'
                )
        else:
            hood = self._hood = Neighbourhood(agent_id=agent_id, neighbours=neighbours, delta=delta)
        self.agent_id, self.delta, self.neighbour_ids = hood.agent_id, hood.delta, hood.ids
        offsets = self.offsets = hood.offsets  # d_ij, one row per neighbour
        self.capacity = hood.capacity  # Δ - ||d_ij||
        self.dimension = hood.dimension
        self.tolerance = _positive('tolerance', tolerance)
        m, p = offsets.shape
        self._heard = [False] * m
        self.control = np.zeros(p)  # the command: u_i (ETA-1) or u^d_i (ETA-2), broadcast and applied
        # The command's term in the error: e_i = sum_j ω_ij y_ij + offset (u_i / κ for ETA-1).
        self._offset = np.zeros(p)
        self.last_trigger: float | None = None
        self.last_event = 0.0
        self._search: CrossingSearch | None = None  # the plan from the current knowledge
        self.triggers = 0
        self.infos_received = 0
        self._interval: float | None = None  # between the last two triggers: the search's first span
        # Plain-float mirror of the knowledge (p <= 3, padded to three components), kept up to
        # date by trigger/receive, with one row of prediction constants per edge; and the
        # per-edge values of the latest evaluation, which `bounds` at the same time reuses.
        self._fast = p <= _FAST_DIMENSION
        zero = (0.0,) * max(p, _FAST_DIMENSION)
        # The neighbourhood's lists (never changed, by either)
        self._offsets = hood.offset_rows
        self._offsets3 = hood.offset_rows3  # padded as `_pad` pads
        self._capacity = hood._capacity
        self._edge_time = [0.0] * m
        self._edge_y = [zero] * m
        self._edge_u = [zero] * m
        self._u = zero  # the command, padded
        self._u_offset = zero  # the error's offset, padded
        self._control_norm = 0.0  # ||offset||
        self._rows: list[tuple[float, ...]] = [()] * m  # one per edge, laid out by `_row`
        self._probe_key: tuple[float, int, int] | None = None
        self._probe_value: tuple[float, float, float, float, float, float] = ()  # type: ignore[assignment]  # read only once _probe_key is set
        self._probe: Any = None  # the latest evaluation's per-edge values, laid out by each algorithm

    # -- inputs -------------------------------------------------------------------------------

    def receive(self, info: TriggerInfo) -> None:
        """Take a neighbour's triggering information (ETA-1 step 6, ETA-2 step 7: predict anew
        from its time). A plain-float agent takes it compiled where the compiled core runs
        (`compiled.receiver`: the same updates and floats; a message it does not accept as it is —
        one this method refuses, or not plain tuples of floats — comes here)."""
        fast = compiled.receiver() if self._fast else None
        if fast is not None and fast(self, info):
            return
        hood = self._hood
        k = hood.sender_slot(info)
        stamp = hood.time(info.stamp, 'information from agent {}', info.sender)
        if stamp < self._edge_time[k] or (self.last_trigger is not None and stamp < self.last_trigger):
            raise AgentError(
                f'agent {self.agent_id}: information from agent {info.sender} goes back in time '
                f'(t={stamp!r}, edge last updated at t={self._edge_time[k]!r})'
            )
        # The message carries x_j - x_i; this agent's edge state is x_i - x_j - d_ij.
        rel = hood.floats(info.rel_position, 'rel_position from agent {}', info.sender)
        control = hood.floats(info.control, 'control from agent {}', info.sender)
        self._receive_extra(k, info)
        y = tuple(-r - d for r, d in zip(rel, self._offsets3[k]))
        self._heard[k] = True
        self._edge_time[k] = stamp
        self._edge_y[k] = self._pad(y)
        self._edge_u[k] = self._pad(control)
        if self._fast:
            self._rows[k] = self._row(k)
        self.infos_received += 1
        self.last_event = max(self.last_event, stamp)
        search = self._search
        if search is not None and search.result is not None and search.result <= stamp:
            return  # already due at or before this time: its own trigger re-plans everything
        self._search = None

    def _receive_extra(self, k: int, info: TriggerInfo) -> None:
        """ETA-2 also takes the relative velocity."""

    def trigger(
        self, t: float, sensed: SensedState, *, nearby: Mapping[int, tuple[float, ...]] | None = None
    ) -> TriggerOutput:
        """ETA-1 step 8, ETA-2 step 9: sense, update the input, and produce the triggering
        information. `nearby`: x_i - x_j of the other robots within the safety layer's sensing
        radius (only read with the layer on, docs/SAFETY.md). A plain-float agent without the safety
        layer triggers compiled where the compiled core runs (`compiled.trigger`: the same updates,
        floats and output; sensing it does not take as it is, or refuses, comes here)."""
        fast = compiled.trigger() if self._fast and self._safety is None else None
        if fast is not None:
            out: TriggerOutput | None = fast(self, t, sensed)
            if out is not None:
                return out
        t = self._hood.time(t, 'trigger')
        if sensed.agent != self.agent_id:
            raise AgentError(f'agent {self.agent_id} was handed the sensing of agent {sensed.agent}')
        if self.last_trigger is not None and t < self.last_trigger:
            raise AgentError(
                f'agent {self.agent_id}: trigger at t={t!r} before its last one at t={self.last_trigger!r}'
            )
        rel = self._hood.rows(sensed.rel_positions, 'sensed rel_positions')
        # Edge by edge in plain floats (a handful of edges: numpy would cost more than it saves).
        y = [tuple(r - d for r, d in zip(row, offset)) for row, offset in zip(rel, self._offsets)]
        length = [math.sqrt(_sum_of_squares(row)) for row in y]
        self._hood.check_sensed_range(length)
        extra = self._sensed_extra(sensed)  # validated before anything changes
        if self._safety is not None:
            self._safety.check_nearby(nearby, neighbours=self.neighbour_ids)
        offset = self._update(y, length, extra)
        control = self._command(offset)
        if self._safety is not None:  # the applied command, broadcast; e_i keeps the nominal offset
            control = self._safety.filter(
                t=t, nominal=control, rel=rel, y=y, capacity=self._capacity, nearby=nearby
            )
        self.control = np.array(control)
        self._offset = np.array(offset)
        m = len(self.neighbour_ids)
        self._edge_time = [t] * m
        self._edge_y = [self._pad(row) for row in y]
        self._u = self._pad(control)
        self._u_offset = self._pad(offset)
        self._control_norm = math.sqrt(_sum_of_squares(self._u_offset))
        if self._fast:
            self._rows = [self._row(k) for k in range(m)]
        if self.last_trigger is not None and t > self.last_trigger:
            self._interval = t - self.last_trigger
        self.last_trigger = t
        self.last_event = max(self.last_event, t)
        self._search = None
        self.triggers += 1
        return TriggerOutput(time=t, control=np.array(control), infos=self._infos(t, rel, control))

    def _weighted_sum(self, vectors: list[tuple[float, ...]], length: list[float]) -> list[float]:
        """sum_j ω_ij(||y_ij||) v_j over the edges (eq. fij for ω), in plain floats (at triggers only)."""
        total = [0.0] * self.dimension
        for vector, r, c in zip(vectors, length, self._capacity):
            w = omega(r, c)
            for d, v in enumerate(vector):
                total[d] += w * v
        return total

    def _infos(
        self, t: float, rel: list[tuple[float, ...]], control: tuple[float, ...]
    ) -> tuple[TriggerInfo, ...]:
        return tuple(
            TriggerInfo(
                sender=self.agent_id,
                receiver=j,
                stamp=t,
                control=control,
                rel_position=rel[k],
                rel_velocity=self._info_velocity(k),
            )
            for k, j in enumerate(self.neighbour_ids)
        )

    def _info_velocity(self, k: int) -> tuple[float, ...] | None:
        return None

    def _command(self, offset: tuple[float, ...]) -> tuple[float, ...]:
        """The command from the error's offset (ETA-2: the same; ETA-1: times κ)."""
        return offset

    def _sensed_extra(self, sensed: SensedState) -> object:
        return None

    # -- planning -----------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        """True once the agent has triggered and heard from every neighbour."""
        return self.last_trigger is not None and self._heard_all()

    def next_trigger_time(self, limit: float = math.inf) -> float:
        """Next triggering time t^i_{k+1} (ETA-1 steps 3-4, ETA-2 steps 4-5); inf if it lies beyond `limit`.

        Before its first trigger the agent is due at t = 0 (t^i_1 = 0).
        """
        if self.last_trigger is None:
            return 0.0
        return self.trigger_search(limit).run()

    def trigger_search(self, limit: float = math.inf) -> CrossingSearch | CappedSearch:
        """The certified search behind `next_trigger_time`, for callers that advance it in pieces.

        `advance(until)` learns only as much as needed (its `frontier` is a certified lower bound
        on t^i_{k+1}); the answer is the float `next_trigger_time` returns. The agent replaces the
        search when its knowledge changes, so a caller holding an older one must drop it.
        """
        if self.last_trigger is None:
            raise AgentError(f'agent {self.agent_id} has not triggered yet: it is due at t = 0')
        search = self._search
        if search is not None and search.limit != limit:
            answer = search.result
            still_valid = answer is not None and (math.isfinite(answer) or search.limit >= limit)
            if not still_valid:
                search = None
        if search is None:
            if not self._heard_all():
                missing = [j for j, heard in zip(self.neighbour_ids, self._heard) if not heard]
                raise AgentError(f'agent {self.agent_id} has not heard from neighbours {missing} yet')
            # The first trial span only sets how fast the certified steps grow, never what they
            # certify; the agent's own last inter-event time is its natural scale. It depends on
            # the knowledge alone, so a robot and the simulator take the same steps.
            search = _new_search(
                self,
                fast=self._fast,
                start=self.last_event,
                limit=limit,
                initial_step=max(self._interval or 0.0, _FIRST_SPAN),
            )
            self._search = search
        return search if self._safety is None else self._capped(search)

    def threshold(self, t: float) -> float:
        """α e^{-βt} (eq. triggersingle) or α_d e^{-β_d t} (eq. triggerdouble) at real time t, with
        the floor c0 and the rates times κ (ETA-2: times κ², the units of the agent's error); or the
        agent's other `trigger_rule`."""
        return self._threshold(t)

    @property
    def trigger_rule(self) -> TriggerRule:
        """The threshold θ(t) the agent triggers on, in real time (formation_agent.core.trigger)."""
        return self._threshold

    # ErrorModel interface (formation_agent.core.crossing) -------------------------------------------

    _kind = 0  # 1: ETA-1, 2: ETA-2 (the compiled core's layout of `_row`)

    def error(self, t: float) -> np.ndarray:
        """The predicted triggering error e_i(t) (ETA-1) or E_i(t) (ETA-2), valid until the next event."""
        return self.error_and_rate(t)[0]

    def error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """e_i(t) and de_i/dt (ETA-1), or E_i(t) and dE_i/dt (ETA-2)."""
        if not self._fast:
            return self._vector_error_and_rate(t)
        e0, e1, e2, d0, d1, d2 = self._probe_at(t)
        p = self.dimension
        return np.array((e0, e1, e2)[:p]), np.array((d0, d1, d2)[:p])

    def error_terms(self, t: float) -> tuple[float, float]:
        """(||e||², e·ė) at t: all the search needs of e at a point."""
        if not self._fast:
            e, rate = self._vector_error_and_rate(t)
            return float(e @ e), float(e @ rate)
        e0, e1, e2, d0, d1, d2 = self._probe_at(t)
        return e0 * e0 + e1 * e1 + e2 * e2, e0 * d0 + e1 * d1 + e2 * d2

    def error_norm(self, t: float) -> float:
        """||e(t)||, for polishing a crossing."""
        if not self._fast:
            return float(np.linalg.norm(self._vector_error_and_rate(t)[0]))
        e0, e1, e2, _, _, _ = self._fast_probe(t, with_rate=False)
        return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)

    def bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
        """(H, E, E1, E2): bounds on ||e||, ||ė||, ||ë|| over [a, a+H], H <= span (crossing.ErrorModel)."""
        if not self._fast:
            return self._vector_bounds(a, span, size)
        self._probe_at(a)
        return self._fast_bounds(span, size)

    # Plain-float evaluation (p <= 3) ---------------------------------------------------------

    def _probe_at(self, t: float) -> tuple[float, float, float, float, float, float]:
        """e(t) and ė(t) padded to three components; keeps the per-edge values for `bounds`."""
        key = (t, self.triggers, self.infos_received)
        if self._probe_key != key:
            self._probe_value = self._fast_probe(t)
            self._probe_key = key
        return self._probe_value

    @staticmethod
    def _pad(values: Iterable[float]) -> tuple[float, ...]:
        values = tuple(values)
        return values + (0.0,) * (_FAST_DIMENSION - len(values))


class Eta1Agent(_EventTriggeredAgent):
    """Event-Triggered Algorithm 1: single integrators, Theorem 1."""

    algorithm = 'eta1'
    _kind = 1

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object] | Neighbourhood,
        delta: float,
        alpha: float,
        beta: float,
        tolerance: float = DEFAULT_TOLERANCE,
        speed_scale: float = DEFAULT_SPEED_SCALE,
        threshold_floor: float = DEFAULT_THRESHOLD_FLOOR,
        safety: SafetyConfig | None = None,
        trigger_rule: str = DEFAULT_RULE,
    ) -> None:
        super().__init__(agent_id=agent_id, neighbours=neighbours, delta=delta, tolerance=tolerance)
        if safety is not None:  # collision avoidance with connectivity (docs/SAFETY.md)
            if self.dimension != 2:
                raise AgentError(
                    f'agent {agent_id}: the safety layer is planar, got dimension {self.dimension}'
                )
            self._safety = SafetyLayer(safety, agent_id=agent_id)
        self.alpha = _positive('alpha', alpha)
        self.beta = _positive('beta', beta)
        try:
            self.speed_scale, self._threshold = eta1_gains(
                alpha=self.alpha,
                beta=self.beta,
                speed_scale=speed_scale,
                threshold_floor=threshold_floor,
                trigger_rule=trigger_rule,
            )
        except (ScaleError, RuleError) as error:
            raise AgentError(f'agent {agent_id}: {error}') from None

    def _update(self, y: list[tuple[float, ...]], length: list[float], extra: None) -> tuple[float, ...]:
        # u_i = -sum_j ω_ij(t_k) (x_i - x_j - d_ij)(t_k)   (eq. uxsingle), the paper's; the command is κ u_i
        return tuple(-v for v in self._weighted_sum(y, length))

    def _command(self, offset: tuple[float, ...]) -> tuple[float, ...]:
        kappa = self.speed_scale
        return tuple(kappa * v for v in offset)  # κ u_i (docs/SPEED_SCALE.md); exact at κ = 1

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Predicted y_ij(t) and its constant rate u_i - u_j (eq. statexixj)."""
        rate = self.control - self._neighbour_control
        return self._anchor_y + (t - self._anchor_time)[:, None] * rate, rate

    def _vector_error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        # e_i(t) = sum_j ω_ij(t) y_ij(t) - sum_j ω_ij(t_k) y_ij(t_k) = sum_j ω_ij(t) y_ij(t) + u_i
        # (u_i the paper's: the command over κ)
        y, v = self._state(t)
        r = np.linalg.norm(y, axis=1)
        w = omega(r, self.capacity)
        e = (w[:, None] * y).sum(axis=0) + self._offset
        # d/dt [ω(r) y] = ω'(r) (y·v / r) y + ω v   (eq. dotei); the first term vanishes at r = 0.
        radial = np.divide((y * v).sum(axis=1), r, out=np.zeros_like(r), where=r > 0.0)
        rate = ((omega_prime(r, self.capacity) * radial)[:, None] * y + w[:, None] * v).sum(axis=0)
        return e, rate

    def _vector_bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
        y, v = self._state(a)
        r = np.linalg.norm(y, axis=1)
        speed = np.linalg.norm(v, axis=1)
        span = _span_within_capacity(span, r, speed, self.capacity, self.agent_id, self.neighbour_ids)
        reach = r + span * speed  # ||y_ij|| <= reach on [a, a+span]: y is linear in t
        rate = float((weight_gain(reach, self.capacity) * speed).sum())  # (eq. dotnormei)
        curv = float((curvature_gain(reach, self.capacity) * speed * speed).sum())
        size = min(
            size + rate * span,
            float(np.linalg.norm(self._offset)) + float((omega(reach, self.capacity) * reach).sum()),
        )
        return span, size, rate, curv

    def _row(self, k: int) -> tuple[float, ...]:
        """Edge k as the plain-float path reads it, vectors padded to three components:
        (anchor, y0, y1, y2, v0, v1, v2, speed, capacity) — the edge's last event, y_ij there,
        its constant rate v = u_i - u_j until the edge's next event (statexixj), ||v||, and
        Δ - ||d_ij||. A plain tuple: unpacking one is faster than a named tuple in the hot loop."""
        u, u_j = self._u, self._edge_u[k]
        v0, v1, v2 = u[0] - u_j[0], u[1] - u_j[1], u[2] - u_j[2]
        y0, y1, y2 = self._edge_y[k]
        speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        return (self._edge_time[k], y0, y1, y2, v0, v1, v2, speed, self._capacity[k])

    def _fast_probe(
        self, t: float, *, with_rate: bool = True
    ) -> tuple[float, float, float, float, float, float]:
        """e(t) and, `with_rate`, ė(t), padded to three components (the formulas of
        _vector_error_and_rate, edge by edge; ω and dω/dr are eqs. fij, hij). With the rate it
        also keeps the radii and the span limit of _span_within_capacity, for _fast_bounds."""
        e0 = e1 = e2 = d0 = d1 = d2 = 0.0
        radii = []
        cap = math.inf
        for k, (anchor, ya0, ya1, ya2, v0, v1, v2, speed, c) in enumerate(self._rows):
            s = t - anchor
            y0 = ya0 + s * v0  # (statexixj): y_ij(t) = y_ij(anchor) + (t - anchor)(u_i - u_j)
            y1 = ya1 + s * v1
            y2 = ya2 + s * v2
            r = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
            gap = c - r
            if gap <= 0.0:
                raise self._hood.out_of_range(k, r, c)
            w = (2.0 * c - r) / (gap * gap)  # ω_ij (fij)
            e0 += w * y0
            e1 += w * y1
            e2 += w * y2
            if not with_rate:
                continue
            radial = (y0 * v0 + y1 * v1 + y2 * v2) / r if r > 0.0 else 0.0
            f = (3.0 * c - r) / (gap * gap * gap) * radial  # dω/dr (hij) times dr/dt
            d0 += f * y0 + w * v0
            d1 += f * y1 + w * v1
            d2 += f * y2 + w * v2
            radii.append(r)
            if speed > 0.0:
                limit = _GAP_FRACTION * gap / speed  # _span_within_capacity
                cap = min(cap, limit)
        if with_rate:
            self._probe = (radii, cap)
        u0, u1, u2 = self._u_offset
        return e0 + u0, e1 + u1, e2 + u2, d0, d1, d2

    def _fast_bounds(self, span: float, size: float) -> tuple[float, float, float, float]:
        # The formulas of _vector_bounds, edge by edge (tension.py: weight_gain, curvature_gain).
        radii, cap = self._probe
        span = min(span, cap)
        rate = curv = reach_sum = 0.0
        for r, row in zip(radii, self._rows):
            speed, c = row[7], row[8]
            reach = r + span * speed  # ||y_ij|| <= reach on [a, a+span]: y is linear in t
            gap = c - reach
            gap3 = gap * gap * gap
            rate += 2.0 * c * c / gap3 * speed  # g_ij (eq. gij), (eq. dotnormei)
            curv += (
                (reach * ((8.0 * c - 2.0 * reach) / (gap3 * gap)) + 3.0 * ((3.0 * c - reach) / gap3))
                * speed
                * speed
            )
            reach_sum += (2.0 * c - reach) / (gap * gap) * reach
        return span, min(size + rate * span, self._control_norm + reach_sum), rate, curv


class Eta2Agent(_EventTriggeredAgent):
    """Event-Triggered Algorithm 2: double integrators, Theorem 2.

    `control` is u^d_i(t_k) = -k1 sum ω (x_i-x_j-d_ij) - k2 sum ω (q_i-q_j) at t_k; the applied input
    is u^d_i - k3 q_i(t) (eq. uxdouble), whose velocity feedback the plant closes continuously.
    """

    algorithm = 'eta2'
    _kind = 2

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object] | Neighbourhood,
        delta: float,
        alpha_d: float,
        beta_d: float,
        k1: float,
        k2: float,
        k3: float,
        tolerance: float = DEFAULT_TOLERANCE,
        speed_scale: float = DEFAULT_SPEED_SCALE,
        threshold_floor: float = DEFAULT_THRESHOLD_FLOOR,
        trigger_rule: str = DEFAULT_RULE,
    ) -> None:
        super().__init__(agent_id=agent_id, neighbours=neighbours, delta=delta, tolerance=tolerance)
        self.alpha_d = _positive('alpha_d', alpha_d)
        self.beta_d = _positive('beta_d', beta_d)
        paper = {name: _positive(name, value) for name, value in (('k1', k1), ('k2', k2), ('k3', k3))}
        try:
            # k1, k2, k3 below are the real-time gains (κ²k1, κk2, κk3); the threshold is κ² that of
            # (triggerdouble), decaying at κβ_d (formation_agent.core.speed_scale).
            (self.k1, self.k2, self.k3), self._threshold = eta2_gains(
                alpha_d=self.alpha_d,
                beta_d=self.beta_d,
                speed_scale=speed_scale,
                threshold_floor=threshold_floor,
                trigger_rule=trigger_rule,
                **paper,
            )
        except (ScaleError, RuleError) as error:
            raise AgentError(f'agent {agent_id}: {error}') from None
        self.speed_scale = float(speed_scale)
        self._edge_q = [(0.0,) * max(self.dimension, _FAST_DIMENSION)] * len(self.neighbour_ids)

    def _receive_extra(self, k: int, info: TriggerInfo) -> None:
        if info.rel_velocity is None:
            raise AgentError(
                f'agent {self.agent_id}: ETA-2 information from agent {info.sender} lacks rel_velocity'
            )
        q = tuple(-v for v in self._hood.floats(info.rel_velocity, 'rel_velocity from agent {}', info.sender))
        self._edge_q[k] = self._pad(q)

    @property
    def _anchor_q(self) -> np.ndarray:
        """q_i - q_j at each edge's anchor."""
        return self._mirrors()[3]

    def _info_velocity(self, k: int) -> tuple[float, ...] | None:
        return self._sensed_q[k]

    def _sensed_extra(self, sensed: SensedState) -> list[tuple[float, ...]]:
        return self._hood.rows(sensed.rel_velocities, 'sensed rel_velocities')

    def _update(
        self, y: list[tuple[float, ...]], length: list[float], extra: list[tuple[float, ...]]
    ) -> tuple[float, ...]:
        self._sensed_q = extra
        self._edge_q = [self._pad(row) for row in extra]
        k1, k2 = self.k1, self.k2
        mix = [tuple(k1 * a + k2 * b for a, b in zip(y_row, q_row)) for y_row, q_row in zip(y, extra)]
        # u^d_i = -k1 sum_j ω_ij y_ij - k2 sum_j ω_ij q_ij at t_k  (eq. uxdouble without -k3 q_i)
        return tuple(-v for v in self._weighted_sum(mix, length))

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted y_ij(t), q_ij(t) (eqs. statexixjd with x_ij(s) restored, stateqiqj) and u^d_i - u^d_j."""
        key = (t, self.triggers, self.infos_received)  # the prediction changes only with these
        if self._cached_key != key:
            du = self.control - self._neighbour_control
            y, q = advance_double(self._anchor_y, self._anchor_q, du, self.k3, t - self._anchor_time)
            self._cached_key, self._cached_state = key, (y, q, du)
        return self._cached_state

    _cached_key: tuple[float, int, int] | None = None

    def _vector_error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        # E_i(t) = k1 e_i + k2 e_qi = sum_j ω_ij(t) (k1 y_ij + k2 q_ij)(t) + u^d_i  (eq. triggerdouble)
        y, q, du = self._state(t)
        r = np.linalg.norm(y, axis=1)
        w = omega(r, self.capacity)
        mix = self.k1 * y + self.k2 * q
        e = (w[:, None] * mix).sum(axis=0) + self.control
        accel = du - self.k3 * q  # d(q_i - q_j)/dt
        radial = np.divide((y * q).sum(axis=1), r, out=np.zeros_like(r), where=r > 0.0)
        rate = (
            (omega_prime(r, self.capacity) * radial)[:, None] * mix
            + w[:, None] * (self.k1 * q + self.k2 * accel)
        ).sum(axis=0)  # (eqs. doteidouble, doteqi)
        return e, rate

    def _vector_bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
        y, q, du = self._state(a)
        c = self.capacity
        r = np.linalg.norm(y, axis=1)
        # By (stateqiqj), q_ij(a+h) = q_ij(a) + (1 - e^{-k3 h}) (du - k3 q_ij(a)) / k3, and
        # dq_ij/dt = e^{-k3 h} (du - k3 q_ij(a)) shrinks in norm. The speed bound depends on the
        # span, which in turn is limited by it; one pass with the trial span is enough since
        # shrinking the span only tightens the bound.
        accel = np.linalg.norm(du - self.k3 * q, axis=1)
        q_now = np.linalg.norm(q, axis=1)
        speed = q_now + (one_minus_exp(self.k3 * span) / self.k3) * accel
        span = _span_within_capacity(span, r, speed, c, self.agent_id, self.neighbour_ids)
        reach = r + span * speed
        low = r - span * speed
        w, h, g = omega(reach, c), omega_prime(reach, c), weight_gain(reach, c)
        k1, k2, k3 = self.k1, self.k2, self.k3
        rate = float((k1 * g * speed + k2 * (h * speed * speed + w * accel)).sum())
        # d²/dt² [ω(r) y] <= curvature_gain ||ẏ||² + g ||ÿ||; d²/dt² [ω(r) q] needs 1/r, so it is
        # only bounded where r stays away from 0 (ω(||y||) has a kink at y = 0).
        curv_y = (curvature_gain(reach, c) * speed * speed + g * accel).sum()
        moving = speed > 0.0
        if np.any(low[moving] <= 0.0):
            curv = math.inf
        else:
            inv_low = np.divide(1.0, low, out=np.zeros_like(low), where=moving)
            omega_ddot = omega_second(reach, c) * speed * speed + h * (speed * speed * inv_low + accel)
            curv_q = (omega_ddot * speed + 2.0 * h * speed * accel + w * k3 * accel).sum()
            curv = float(k1 * curv_y + k2 * curv_q)
        size = min(
            size + rate * span,
            float(np.linalg.norm(self.control)) + float((w * (k1 * reach + k2 * speed)).sum()),
        )
        return span, size, rate, curv

    def _row(self, k: int) -> tuple[float, ...]:
        """Edge k as the plain-float path reads it, vectors padded to three components:
        (anchor, y0, y1, y2, q0, q1, q2, u0, u1, u2, capacity) — the edge's last event, y_ij and
        q_i - q_j there, u^d_i - u^d_j (constant until the edge's next event), Δ - ||d_ij||."""
        u, u_j = self._u, self._edge_u[k]
        y0, y1, y2 = self._edge_y[k]
        q0, q1, q2 = self._edge_q[k]
        return (
            self._edge_time[k],
            y0,
            y1,
            y2,
            q0,
            q1,
            q2,
            u[0] - u_j[0],
            u[1] - u_j[1],
            u[2] - u_j[2],
            self._capacity[k],
        )

    def _closed_form(self, t: float, anchor: float) -> tuple[float, float, float]:
        """(lag, ramp, fade): the factors of the closed-loop motion q' = u^d - k3 q from `anchor`
        to `t`, z = k3 (t - anchor): y(t) = y + lag q + ramp du (statexixjd) and
        q(t) = fade q + lag du (stateqiqj), with lag = (1 - e^{-z}) / k3,
        ramp = (z - 1 + e^{-z}) / k3² and fade = e^{-z} (a plain tuple: this is the hot path)."""
        k3 = self.k3
        z = k3 * (t - anchor)
        decay = -math.expm1(-z)  # 1 - e^{-z}
        ramp = z_minus_one_plus_exp_float(z) if abs(z) < _SERIES_LIMIT else z - decay  # = z + expm1(-z)
        return decay / k3, ramp / (k3 * k3), 1.0 - decay

    def _fast_probe(
        self, t: float, *, with_rate: bool = True
    ) -> tuple[float, float, float, float, float, float]:
        """E(t) and, `with_rate`, its rate, padded to three components: the closed form
        (statexixjd, stateqiqj) from each edge's anchor, then E_i and its rate (doteidouble,
        doteqi), edge by edge (the formulas of _state and _vector_error_and_rate). Edges anchored
        at the same time (all of them after a trigger) share the factors. With the rate it also
        keeps each edge's radius, speeds and capacity for _fast_bounds."""
        k1, k2, k3 = self.k1, self.k2, self.k3
        e0 = e1 = e2 = d0 = d1 = d2 = 0.0
        probe = []
        last_anchor = None
        for k, (anchor, ya0, ya1, ya2, qa0, qa1, qa2, u0, u1, u2, c) in enumerate(self._rows):
            if anchor != last_anchor:
                lag, ramp, fade = self._closed_form(t, anchor)
                last_anchor = anchor
            y0 = ya0 + lag * qa0 + ramp * u0  # (statexixjd)
            y1 = ya1 + lag * qa1 + ramp * u1
            y2 = ya2 + lag * qa2 + ramp * u2
            q0 = fade * qa0 + lag * u0  # (stateqiqj)
            q1 = fade * qa1 + lag * u1
            q2 = fade * qa2 + lag * u2
            r = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
            gap = c - r
            if gap <= 0.0:
                raise self._hood.out_of_range(k, r, c)
            w = (2.0 * c - r) / (gap * gap)  # ω_ij (fij)
            m0 = k1 * y0 + k2 * q0
            m1 = k1 * y1 + k2 * q1
            m2 = k1 * y2 + k2 * q2
            e0 += w * m0
            e1 += w * m1
            e2 += w * m2
            if not with_rate:
                continue
            a0 = u0 - k3 * q0  # d(q_i - q_j)/dt
            a1 = u1 - k3 * q1
            a2 = u2 - k3 * q2
            radial = (y0 * q0 + y1 * q1 + y2 * q2) / r if r > 0.0 else 0.0
            f = (3.0 * c - r) / (gap * gap * gap) * radial  # dω/dr (hij) times dr/dt
            d0 += f * m0 + w * (k1 * q0 + k2 * a0)
            d1 += f * m1 + w * (k1 * q1 + k2 * a1)
            d2 += f * m2 + w * (k1 * q2 + k2 * a2)
            probe.append(
                (r, math.sqrt(q0 * q0 + q1 * q1 + q2 * q2), math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), c)
            )
        if with_rate:
            self._probe = probe
        v0, v1, v2 = self._u_offset
        return e0 + v0, e1 + v1, e2 + v2, d0, d1, d2

    def _fast_bounds(self, span: float, size: float) -> tuple[float, float, float, float]:
        # The formulas of _vector_bounds, edge by edge (tension.py for ω and its derivatives).
        k1, k2, k3 = self.k1, self.k2, self.k3
        growth = -math.expm1(-k3 * span) / k3  # speed bound from the trial span, as there
        probe = self._probe
        speeds = []
        for r, q_now, accel, c in probe:
            speed = q_now + growth * accel
            if speed > 0.0:
                span = min(span, _GAP_FRACTION * (c - r) / speed)  # _span_within_capacity
            speeds.append(speed)
        rate = curv_y = curv_q = reach_sum = 0.0
        kink = False
        for (r, _, accel, c), speed in zip(probe, speeds):
            reach = r + span * speed
            gap = c - reach
            gap3 = gap * gap * gap
            w = (2.0 * c - reach) / (gap * gap)
            h = (3.0 * c - reach) / gap3
            g = 2.0 * c * c / gap3
            second = (8.0 * c - 2.0 * reach) / (gap3 * gap)
            speed_sq = speed * speed
            rate += k1 * g * speed + k2 * (h * speed_sq + w * accel)
            curv_y += (reach * second + 3.0 * h) * speed_sq + g * accel
            if speed > 0.0:
                low = r - span * speed
                if low <= 0.0:
                    kink = True  # ω(||y||) has a kink at y = 0: no second-order bound
                else:
                    omega_ddot = second * speed_sq + h * (speed_sq / low + accel)
                    curv_q += omega_ddot * speed + 2.0 * h * speed * accel + w * k3 * accel
            else:
                curv_q += w * k3 * accel
            reach_sum += w * (k1 * reach + k2 * speed)
        curv = math.inf if kink else k1 * curv_y + k2 * curv_q
        return span, min(size + rate * span, self._control_norm + reach_sum), rate, curv


def make_agent(
    *,
    algorithm: str,
    agent_id: int,
    neighbours: Mapping[int, object] | Neighbourhood,
    delta: float,
    gains: Mapping[str, float],
    tolerance: float = DEFAULT_TOLERANCE,
    safety: SafetyConfig | None = None,
    trigger_rule: str = DEFAULT_RULE,
) -> Eta1Agent | Eta2Agent:
    """The agent of `algorithm` ('eta1' or 'eta2') with `gains` by name (extra names are ignored;
    speed_scale and threshold_floor are optional, SCALE_GAINS); `safety`: the collision layer
    (ETA-1 only, docs/SAFETY.md); `trigger_rule`: the threshold's family by name
    (formation_agent.core.trigger)."""
    kind, chosen = _kind_and_gains(algorithm=algorithm, agent_id=agent_id, gains=gains, safety=safety)
    return kind(
        agent_id=agent_id,
        neighbours=neighbours,
        delta=delta,
        tolerance=tolerance,
        trigger_rule=trigger_rule,
        **chosen,
    )


def make_agents(
    *,
    algorithm: str,
    neighbours: Mapping[int, Mapping[int, object] | Neighbourhood],
    delta: float,
    gains: Mapping[str, float],
    tolerance: float = DEFAULT_TOLERANCE,
    safety: SafetyConfig | None = None,
    trigger_rule: str = DEFAULT_RULE,
) -> dict[int, Eta1Agent | Eta2Agent]:
    """`make_agent` for every agent of `neighbours` (agent id -> its neighbours, or its Neighbourhood
    built already: `Neighbourhood.team`), in that order, the algorithm and gains chosen once: the same
    agents, and the same error as `make_agent` raises for the first agent."""
    agents: dict[int, Eta1Agent | Eta2Agent] = {}
    for agent_id, hood in neighbours.items():
        if not agents:
            kind, chosen = _kind_and_gains(algorithm=algorithm, agent_id=agent_id, gains=gains, safety=safety)
        agents[agent_id] = kind(
            agent_id=agent_id,
            neighbours=hood,
            delta=delta,
            tolerance=tolerance,
            trigger_rule=trigger_rule,
            **chosen,
        )
    return agents


def _kind_and_gains(
    *, algorithm: str, agent_id: int, gains: Mapping[str, float], safety: SafetyConfig | None
) -> tuple[type[Eta1Agent] | type[Eta2Agent], dict[str, Any]]:
    """`make_agent`'s agent type and its keyword arguments from `gains` (and `safety`), checked."""
    if algorithm not in ALGORITHM_GAINS:
        raise AgentError(f'algorithm must be one of {sorted(ALGORITHM_GAINS)}, got {algorithm!r}')
    missing = [name for name in ALGORITHM_GAINS[algorithm] if name not in gains]
    if missing:
        raise AgentError(f'agent {agent_id}: {algorithm} needs the gains {missing}')
    kind = Eta1Agent if algorithm == 'eta1' else Eta2Agent
    chosen: dict[str, Any] = {name: gains[name] for name in ALGORITHM_GAINS[algorithm]}
    chosen.update({name: gains.get(name, default) for name, default in SCALE_GAINS.items()})
    if safety is not None:
        if algorithm != 'eta1':
            raise AgentError(f'agent {agent_id}: the safety layer runs with eta1 only, got {algorithm!r}')
        chosen['safety'] = safety
    return kind, chosen


def _new_search(
    agent: _EventTriggeredAgent, *, fast: bool, start: float, limit: float, initial_step: float
) -> CrossingSearch:
    """The agent's search from `start`: compiled (`_fastcore.Search`) for the plain-float path (`fast`,
    p <= 3) and the exponential rule only (`compiled.search_type`), else `CrossingSearch`, which calls
    the agent's ErrorModel methods and its rule's (the same floats)."""
    rule = agent.trigger_rule
    search_type = compiled.search_type(rule) if fast else None
    if search_type is None:
        return CrossingSearch(
            agent, start=start, rule=rule, limit=limit, tolerance=agent.tolerance, initial_step=initial_step
        )
    exponential = cast(ExponentialRule, rule)  # search_type knows no other
    return search_type(
        agent,
        start=start,
        alpha=exponential.alpha,
        beta=exponential.beta,
        floor=exponential.floor,
        limit=limit,
        tolerance=agent.tolerance,
        initial_step=initial_step,
    )


def _sum_of_squares(values: Iterable[float]) -> float:
    """v0² + v1² + ... left to right, as the compiled trigger adds them: not `sum()`, which from
    Python 3.12 on (ROS Jazzy's) compensates its rounding and would round differently."""
    total = 0.0
    for v in values:
        total += v * v
    return total


def _span_within_capacity(
    span: float,
    r: np.ndarray,
    speed: np.ndarray,
    capacity: np.ndarray,
    agent_id: int,
    neighbour_ids: Sequence[int],
) -> float:
    """Shrink `span` so that every predicted edge uses at most `_GAP_FRACTION` of its gap."""
    gap = capacity - r
    if np.any(gap <= 0.0):
        k = int(np.flatnonzero(gap <= 0.0)[0])
        raise AgentError(
            f'agent {agent_id}: predicted edge to agent {neighbour_ids[k]} left its range '
            f'(||y_ij|| = {float(r[k])!r} >= Δ-||d_ij|| = {float(capacity[k])!r})'
        )
    moving = speed > 0.0
    if np.any(moving):
        span = min(span, float((_GAP_FRACTION * gap[moving] / speed[moving]).min()))
    return span
