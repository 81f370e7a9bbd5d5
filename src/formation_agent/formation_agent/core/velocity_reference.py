"""ETA-2 on a robot that takes velocity commands: the velocity reference q_i(t), ROS-free.

Under (uxdouble) the agent's velocity obeys dq_i/dt = u^d_i - k3 q_i(t): the event-triggered
part u^d_i is constant between the agent's triggers, the damping -k3 q_i(t) acts continuously.
A robot that takes velocity commands gets q_i(t) itself, integrated here in closed form between
updates (`formation_agent.core.closed_form`, (stateqiqj)); the command adapter samples it at its
command rate.

An acceleration limit a (a robot's `max_linear_acceleration`) holds the reference's acceleration
w = u^d - k3 q to ||w|| <= a, still exactly: while ||w|| > a the reference accelerates at a
along w's direction, which does not turn (dw/dt = -k3 a w/||w||), so ||w|| falls linearly at rate
k3 a; once it reaches a, the unlimited closed form takes over and ||w|| decays as e^{-k3 t}.
So the limit can only start to act at an update, which is where it is counted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from formation_agent.core.closed_form import advance_double


class VelocityReference:
    """q(t) under dq/dt = sat_a(u^d - k3 q), u^d piecewise constant; exact between updates."""

    def __init__(
        self, *, k3: float, velocity: Sequence[float], time: float, max_acceleration: float = math.inf
    ) -> None:
        if not (math.isfinite(k3) and k3 > 0.0):
            raise ValueError(f'k3 must be a finite number > 0, got {k3!r}')
        if not max_acceleration > 0.0:
            raise ValueError(f'max_acceleration must be > 0, got {max_acceleration!r}')
        self.k3 = float(k3)
        self.max_acceleration = float(max_acceleration)
        self._time = float(time)  # anchor: the state is exact here
        self._velocity = np.array(velocity, dtype=float)
        self._control = np.zeros_like(self._velocity)
        self._limited_until = self._time  # end of the phase held at the acceleration limit

    def update(self, time: float, control: Sequence[float]) -> float:
        """The agent's new u^d from `time` on; returns ||u^d - k3 q(time)||, the acceleration it asks for."""
        self._velocity = self.velocity(time)
        self._time = float(time)
        self._control = np.array(control, dtype=float)
        requested = float(np.linalg.norm(self._control - self.k3 * self._velocity))
        a = self.max_acceleration
        # While ||w|| > a it falls at rate k3 a: the limited phase lasts (||w|| - a) / (k3 a).
        self._limited_until = self._time + (requested - a) / (self.k3 * a) if requested > a else self._time
        return requested

    def velocity(self, time: float) -> np.ndarray:
        """q(time), time >= the last update."""
        tau = float(time) - self._time
        if tau < 0.0:
            raise ValueError(
                f'velocity reference asked for t={time!r}, before its last update at t={self._time!r}'
            )
        q, u, k3 = self._velocity, self._control, self.k3
        if self._limited_until > self._time:
            w = u - k3 * q
            direction = w / np.linalg.norm(w)
            limited = min(tau, self._limited_until - self._time)
            q = q + (self.max_acceleration * limited) * direction
            tau -= limited
            if tau <= 0.0:
                return q
        return advance_double(np.zeros_like(q), q, u, k3, tau)[1]
