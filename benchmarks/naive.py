"""The naive alternative to the exact engine: a fixed-step simulation of the same controllers.

At every step k dt the true state is advanced exactly (the inputs are piecewise constant, so no
integration error enters), every agent's triggering error is computed from its definition on the
true state (Theorem 1: e_i = sum_j ω_ij y_ij - [the same at t^i_k]; Theorem 2: E_i = k1 e_i +
k2 e_qi), and the agents with ||e_i|| >= α e^{-βt} trigger. Detection is the only thing the step
changes: an agent triggers up to dt late, with its error above the threshold, and a crossing
that comes and goes within one step is missed. `NaiveResult` measures exactly that.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from formation_agent.core.closed_form import advance_double


@dataclass(kw_only=True)
class NaiveResult:
    dt: float
    horizon: float
    reached: float  # the time the run got to (< horizon if an edge left its range)
    connectivity_lost: str | None  # which edge and when, if it happened
    trigger_times: dict[int, list[float]]
    overshoot: list[float] = field(default_factory=list)  # ||e_i|| / threshold - 1 at each detection
    wall_time: float = 0.0
    steps: int = 0
    messages: int = 0  # one per trigger per neighbour

    @property
    def total_events(self) -> int:
        return sum(len(times) for times in self.trigger_times.values())


def simulate_fixed_step(scenario, *, horizon: float, dt: float = 1e-4) -> NaiveResult:
    """Run ETA-1/ETA-2 with the triggering condition checked every `dt` on the true state."""
    started = time.perf_counter()
    ids = list(scenario.agent_ids)
    row = {a: k for k, a in enumerate(ids)}
    heads = np.array([row[e.i] for e in scenario.edges])
    tails = np.array([row[e.j] for e in scenario.edges])
    d = np.array([np.asarray(e.d, dtype=float) for e in scenario.edges])
    c = scenario.delta - np.linalg.norm(d, axis=1)
    n = len(ids)
    double = scenario.dynamics == 'double'
    g = scenario.gains
    alpha, beta = (g.alpha_d, g.beta_d) if double else (g.alpha, g.beta)
    degree = np.bincount(heads, minlength=n) + np.bincount(tails, minlength=n)

    def combined(x, q):
        """sum_j ω_ij y_ij (single) or sum_j ω_ij (k1 y_ij + k2 q_ij) (double), per agent; edge slack."""
        y = x[heads] - x[tails] - d
        r = np.linalg.norm(y, axis=1)
        gap = c - r
        w = (2.0 * c - r) / (gap * gap)  # (fij)
        term = w[:, None] * (y if q is None else g.k1 * y + g.k2 * (q[heads] - q[tails]))
        total = np.zeros_like(x)
        np.add.at(total, heads, term)
        np.add.at(total, tails, -term)
        return total, gap

    x = np.array(scenario.positions, dtype=float)
    q = np.array(scenario.velocities, dtype=float) if double else None
    anchor, _ = combined(x, q)
    u = -anchor  # t_1 = 0: every agent triggers (uxsingle / the event-triggered part of uxdouble)
    times = {a: [0.0] for a in ids}
    result = NaiveResult(dt=dt, horizon=horizon, reached=horizon, connectivity_lost=None, trigger_times=times)
    steps = math.floor(horizon / dt + 1e-9)
    for k in range(1, steps + 1):
        t = k * dt
        if double:
            x, q = advance_double(x, q, u, g.k3, dt)
        else:
            x = x + dt * u
        now, gap = combined(x, q)
        if np.any(gap <= 0.0):
            e = int(np.flatnonzero(gap <= 0.0)[0])
            result.connectivity_lost = f'edge ({ids[heads[e]]},{ids[tails[e]]}) left its range at t={t:.6g}'
            result.reached = t
            break
        threshold = alpha * math.exp(-beta * t)
        size = np.linalg.norm(now + u, axis=1)  # e_i = sum ω y (now) - sum ω y (t^i_k), and u_i = -the latter
        due = np.flatnonzero(size >= threshold)
        if due.size:
            result.overshoot.extend((size[due] / threshold - 1.0).tolist())
            u[due] = -now[due]
            for i in due:
                times[ids[i]].append(t)
        result.steps = k
    result.wall_time = time.perf_counter() - started
    result.messages = int(sum(degree[row[a]] * len(v) for a, v in times.items()))
    return result
