"""ETA-1 and ETA-2 as run by one agent: only what that agent knows, no global state, no ROS.

An agent knows its neighbours' desired displacements d_ij, the radius Δ and its gains. At its own
triggering times it is handed what it senses and returns its new input and the triggering
information for each neighbour; in between it is handed its neighbours' triggering information.
From these it predicts every relative state in closed form (eqs. statexixj, statexixjd,
stateqiqj) and finds its next triggering time as the first crossing of ||e_i(t)|| = α e^{-βt}
(resp. ||E_i(t)|| = α_d e^{-β_d t}), certified by `formation_agent.crossing`.

Per edge the agent keeps an anchor: the time of the edge's last event (its own trigger or the
neighbour's) and the relative state then, plus the neighbour's current input. Since both inputs
are constant between the edge's events, the closed form from the anchor is exact.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from formation_agent.closed_form import advance_double, one_minus_exp
from formation_agent.crossing import first_crossing
from formation_agent.tension import (
    curvature_gain,
    edge_capacity,
    omega,
    omega_prime,
    omega_second,
    weight_gain,
)
from formation_msgs_py.types import SensedState, TriggerInfo


class AgentError(ValueError):
    """Input the agent cannot accept: bad parameters, malformed or inconsistent information."""


@dataclass(frozen=True, kw_only=True, slots=True)
class TriggerOutput:
    """Result of a trigger: the new input and one triggering-information message per neighbour."""

    time: float
    control: np.ndarray
    infos: tuple[TriggerInfo, ...]


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise AgentError(f'{name} must be a finite number > 0, got {value!r}')
    return value


class _EventTriggeredAgent:
    """Bookkeeping shared by ETA-1 and ETA-2: neighbours, anchors, caching of the next time."""

    algorithm = ''

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object],
        delta: float,
        tolerance: float = 1e-12,
    ) -> None:
        if not neighbours:
            raise AgentError(f'agent {agent_id} has no neighbours: the graph must be connected')
        if agent_id in neighbours:
            raise AgentError(f'agent {agent_id} lists itself as a neighbour (self-loop)')
        self.agent_id = int(agent_id)
        self.delta = _positive('delta (communication radius Δ)', delta)
        self.neighbour_ids = tuple(int(j) for j in neighbours)
        self._slot = {j: k for k, j in enumerate(self.neighbour_ids)}
        offsets = np.array([np.asarray(neighbours[j], dtype=float) for j in self.neighbour_ids])
        if offsets.ndim != 2 or offsets.shape[1] < 1:
            raise AgentError(f'agent {agent_id}: desired displacements must be vectors of one dimension p >= 1')
        if not np.all(np.isfinite(offsets)):
            raise AgentError(f'agent {agent_id}: desired displacements are not finite')
        self.offsets = offsets  # d_ij, one row per neighbour
        self.capacity = edge_capacity(self.delta, offsets)  # Δ - ||d_ij||
        for j, c in zip(self.neighbour_ids, self.capacity):
            if c <= 0.0:
                raise AgentError(
                    f'edge ({agent_id},{j}): ||d_ij|| = {float(self.delta - c)!r} is not below Δ = {self.delta!r} '
                    '(Assumption 1)'
                )
        self.dimension = offsets.shape[1]
        self.tolerance = _positive('tolerance', tolerance)
        m, p = offsets.shape
        self._anchor_time = np.zeros(m)
        self._anchor_y = np.zeros((m, p))  # y_i - y_j = x_i - x_j - d_ij at the anchor
        self._neighbour_control = np.zeros((m, p))
        self._heard = np.zeros(m, dtype=bool)
        self.control = np.zeros(p)
        self.last_trigger: float | None = None
        self.last_event = 0.0
        self._next: float | None = None
        self.triggers = 0
        self.infos_received = 0

    # -- inputs -------------------------------------------------------------------------------

    def _vector(self, value, what: str) -> np.ndarray:
        array = np.asarray(value, dtype=float)
        if array.shape != (self.dimension,):
            raise AgentError(
                f'agent {self.agent_id}: {what} has shape {array.shape}, expected ({self.dimension},)'
            )
        if not np.all(np.isfinite(array)):
            raise AgentError(f'agent {self.agent_id}: {what} is not finite: {array.tolist()}')
        return array

    def _check_time(self, stamp: float, what: str) -> float:
        stamp = float(stamp)
        if not math.isfinite(stamp):
            raise AgentError(f'agent {self.agent_id}: {what} has a non-finite time {stamp!r}')
        return stamp

    def _relative_rows(self, values: Mapping[int, object] | None, what: str) -> np.ndarray:
        if values is None or set(values) != set(self.neighbour_ids):
            got = None if values is None else sorted(values)
            raise AgentError(
                f'agent {self.agent_id}: {what} must cover exactly its neighbours {sorted(self.neighbour_ids)}, got {got}'
            )
        return np.array([self._vector(values[j], f'{what}[{j}]') for j in self.neighbour_ids])

    def receive(self, info: TriggerInfo) -> None:
        """Take a neighbour's triggering information (ETA step 6: re-predict from its time)."""
        if info.receiver != self.agent_id:
            raise AgentError(f'agent {self.agent_id} got information addressed to agent {info.receiver}')
        k = self._slot.get(info.sender)
        if k is None:
            raise AgentError(
                f'agent {self.agent_id} got information from agent {info.sender}, '
                f'which is not a neighbour {sorted(self.neighbour_ids)}'
            )
        stamp = self._check_time(info.stamp, f'information from agent {info.sender}')
        if stamp < self._anchor_time[k] or (self.last_trigger is not None and stamp < self.last_trigger):
            raise AgentError(
                f'agent {self.agent_id}: information from agent {info.sender} goes back in time '
                f'(t={stamp!r}, edge last updated at t={float(self._anchor_time[k])!r})'
            )
        # The message carries x_j - x_i; this agent's edge state is x_i - x_j - d_ij.
        rel = self._vector(info.rel_position, f'rel_position from agent {info.sender}')
        control = self._vector(info.control, f'control from agent {info.sender}')
        self._receive_extra(k, info)
        self._anchor_time[k] = stamp
        self._anchor_y[k] = -rel - self.offsets[k]
        self._neighbour_control[k] = control
        self._heard[k] = True
        self.infos_received += 1
        self.last_event = max(self.last_event, stamp)
        if self._next is not None and self._next <= stamp:
            return  # already due at or before this time: its own trigger re-plans everything
        self._next = None

    def _receive_extra(self, k: int, info: TriggerInfo) -> None:
        """ETA-2 also takes the relative velocity."""

    def trigger(self, t: float, sensed: SensedState) -> TriggerOutput:
        """ETA step 9: sense, update the input, and produce the triggering information."""
        t = self._check_time(t, 'trigger')
        if sensed.agent != self.agent_id:
            raise AgentError(f'agent {self.agent_id} was handed the sensing of agent {sensed.agent}')
        if self.last_trigger is not None and t < self.last_trigger:
            raise AgentError(f'agent {self.agent_id}: trigger at t={t!r} before its last one at t={self.last_trigger!r}')
        rel = self._relative_rows(sensed.rel_positions, 'sensed rel_positions')
        y = rel - self.offsets
        length = np.linalg.norm(y, axis=1)
        broken = np.flatnonzero(length >= self.capacity)
        if broken.size:
            k = int(broken[0])
            raise AgentError(
                f'agent {self.agent_id}: edge to agent {self.neighbour_ids[k]} is out of its range: '
                f'||x_i-x_j-d_ij|| = {float(length[k])!r} >= Δ-||d_ij|| = {float(self.capacity[k])!r}'
            )
        extra = self._sensed_extra(sensed)  # validated before anything changes
        self._anchor_time[:] = t
        self._anchor_y[:] = y
        control = self._update(y, length, extra)
        self.control = control
        self.last_trigger = t
        self.last_event = max(self.last_event, t)
        self._next = None
        self.triggers += 1
        return TriggerOutput(time=t, control=control.copy(), infos=self._infos(t, rel))

    def _infos(self, t: float, rel: np.ndarray) -> tuple[TriggerInfo, ...]:
        control = tuple(self.control.tolist())
        return tuple(
            TriggerInfo(
                sender=self.agent_id,
                receiver=j,
                stamp=t,
                control=control,
                rel_position=tuple(rel[k].tolist()),
                rel_velocity=self._info_velocity(k),
            )
            for k, j in enumerate(self.neighbour_ids)
        )

    def _info_velocity(self, k: int):
        return None

    def _sensed_extra(self, sensed: SensedState):
        return None

    # -- planning -----------------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        """True once the agent has triggered and heard from every neighbour."""
        return self.last_trigger is not None and bool(self._heard.all())

    def next_trigger_time(self, limit: float = math.inf) -> float:
        """Next triggering time t^i_{k+1} (ETA steps 3-5); inf if it lies beyond `limit`.

        Before its first trigger the agent is due at t = 0 (t^i_1 = 0).
        """
        if self.last_trigger is None:
            return 0.0
        if self._next is None or (math.isinf(self._next) and self._searched_to < limit):
            if not self._heard.all():
                missing = [j for j, heard in zip(self.neighbour_ids, self._heard) if not heard]
                raise AgentError(f'agent {self.agent_id} has not heard from neighbours {missing} yet')
            alpha, beta = self._threshold
            self._next = first_crossing(
                self,
                start=self.last_event,
                alpha=alpha,
                beta=beta,
                limit=limit,
                tolerance=self.tolerance,
            )
            self._searched_to = limit
        return self._next

    _searched_to = math.inf

    def threshold(self, t: float) -> float:
        """α e^{-βt} (eq. triggersingle) or α_d e^{-β_d t} (eq. triggerdouble)."""
        alpha, beta = self._threshold
        return alpha * math.exp(-beta * t)

    # ErrorModel interface (formation_agent.crossing) -------------------------------------------

    def error(self, t: float) -> np.ndarray:
        """The predicted triggering error e_i(t) (ETA-1) or E_i(t) (ETA-2), valid until the next event."""
        return self.error_and_rate(t)[0]


class Eta1Agent(_EventTriggeredAgent):
    """Event-Triggered Algorithm 1: single integrators, Theorem 1."""

    algorithm = 'eta1'

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object],
        delta: float,
        alpha: float,
        beta: float,
        tolerance: float = 1e-12,
    ) -> None:
        super().__init__(agent_id=agent_id, neighbours=neighbours, delta=delta, tolerance=tolerance)
        self.alpha = _positive('alpha', alpha)
        self.beta = _positive('beta', beta)
        self._threshold = (self.alpha, self.beta)

    def _update(self, y: np.ndarray, length: np.ndarray, extra: None) -> np.ndarray:
        # u_i = -sum_j ω_ij(t_k) (x_i - x_j - d_ij)(t_k)   (eq. uxsingle)
        return -(omega(length, self.capacity)[:, None] * y).sum(axis=0)

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Predicted y_ij(t) and its constant rate u_i - u_j (eq. statexixj)."""
        rate = self.control - self._neighbour_control
        return self._anchor_y + (t - self._anchor_time)[:, None] * rate, rate

    def error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        # e_i(t) = sum_j ω_ij(t) y_ij(t) - sum_j ω_ij(t_k) y_ij(t_k) = sum_j ω_ij(t) y_ij(t) + u_i
        y, v = self._state(t)
        r = np.linalg.norm(y, axis=1)
        w = omega(r, self.capacity)
        e = (w[:, None] * y).sum(axis=0) + self.control
        # d/dt [ω(r) y] = ω'(r) (y·v / r) y + ω v   (eq. dotei); the first term vanishes at r = 0.
        radial = np.divide((y * v).sum(axis=1), r, out=np.zeros_like(r), where=r > 0.0)
        rate = ((omega_prime(r, self.capacity) * radial)[:, None] * y + w[:, None] * v).sum(axis=0)
        return e, rate

    def bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
        y, v = self._state(a)
        r = np.linalg.norm(y, axis=1)
        speed = np.linalg.norm(v, axis=1)
        span = _span_within_capacity(span, r, speed, self.capacity, self.agent_id, self.neighbour_ids)
        reach = r + span * speed  # ||y_ij|| <= reach on [a, a+span]: y is linear in t
        rate = float((weight_gain(reach, self.capacity) * speed).sum())  # (eq. dotnormei)
        curv = float((curvature_gain(reach, self.capacity) * speed * speed).sum())
        size = min(
            size + rate * span,
            float(np.linalg.norm(self.control)) + float((omega(reach, self.capacity) * reach).sum()),
        )
        return span, size, rate, curv


class Eta2Agent(_EventTriggeredAgent):
    """Event-Triggered Algorithm 2: double integrators, Theorem 2.

    `control` is u^d_i(t_k) = -k1 sum ω (x_i-x_j-d_ij) - k2 sum ω (q_i-q_j) at t_k; the applied input
    is u^d_i - k3 q_i(t) (eq. uxdouble), whose velocity feedback the plant closes continuously.
    """

    algorithm = 'eta2'

    def __init__(
        self,
        *,
        agent_id: int,
        neighbours: Mapping[int, object],
        delta: float,
        alpha_d: float,
        beta_d: float,
        k1: float,
        k2: float,
        k3: float,
        tolerance: float = 1e-12,
    ) -> None:
        super().__init__(agent_id=agent_id, neighbours=neighbours, delta=delta, tolerance=tolerance)
        self.alpha_d = _positive('alpha_d', alpha_d)
        self.beta_d = _positive('beta_d', beta_d)
        self.k1 = _positive('k1', k1)
        self.k2 = _positive('k2', k2)
        self.k3 = _positive('k3', k3)
        self._threshold = (self.alpha_d, self.beta_d)
        self._anchor_q = np.zeros_like(self._anchor_y)  # q_i - q_j at the anchor

    def _receive_extra(self, k: int, info: TriggerInfo) -> None:
        if info.rel_velocity is None:
            raise AgentError(f'agent {self.agent_id}: ETA-2 information from agent {info.sender} lacks rel_velocity')
        self._anchor_q[k] = -self._vector(info.rel_velocity, f'rel_velocity from agent {info.sender}')

    def _info_velocity(self, k: int):
        return tuple(self._anchor_q[k].tolist())

    def _sensed_extra(self, sensed: SensedState) -> np.ndarray:
        return self._relative_rows(sensed.rel_velocities, 'sensed rel_velocities')

    def _update(self, y: np.ndarray, length: np.ndarray, extra: np.ndarray) -> np.ndarray:
        self._anchor_q[:] = extra
        w = omega(length, self.capacity)[:, None]
        # u^d_i = -k1 sum_j ω_ij y_ij - k2 sum_j ω_ij q_ij at t_k  (eq. uxdouble without -k3 q_i)
        return -(w * (self.k1 * y + self.k2 * self._anchor_q)).sum(axis=0)

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted y_ij(t), q_ij(t) (eqs. statexixjd with x_ij(s) restored, stateqiqj) and u^d_i - u^d_j."""
        key = (t, self.triggers, self.infos_received)  # the prediction changes only with these
        if self._cached_key != key:
            du = self.control - self._neighbour_control
            y, q = advance_double(self._anchor_y, self._anchor_q, du, self.k3, t - self._anchor_time)
            self._cached_key, self._cached_state = key, (y, q, du)
        return self._cached_state

    _cached_key = None

    def error_and_rate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
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

    def bounds(self, a: float, span: float, size: float) -> tuple[float, float, float, float]:
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


# A step may use at most this fraction of an edge's remaining room, so that the bounds, which
# are evaluated at the far end of the step, stay within a small factor of the local values.
_ROOM_FRACTION = 0.125


def _span_within_capacity(span, r, speed, capacity, agent_id, neighbour_ids) -> float:
    """Shrink `span` so that every predicted edge uses at most `_ROOM_FRACTION` of its room."""
    room = capacity - r
    if np.any(room <= 0.0):
        k = int(np.flatnonzero(room <= 0.0)[0])
        raise AgentError(
            f'agent {agent_id}: predicted edge to agent {neighbour_ids[k]} left its range '
            f'(||y_ij|| = {float(r[k])!r} >= Δ-||d_ij|| = {float(capacity[k])!r})'
        )
    moving = speed > 0.0
    if np.any(moving):
        span = min(span, float((_ROOM_FRACTION * room[moving] / speed[moving]).min()))
    return span
