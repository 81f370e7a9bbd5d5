"""Baselines for the event-triggered controllers: the continuous controller they sample.

`simulate_continuous` integrates the controllers of the paper with the weights and states taken
at every instant instead of at triggering times:

    single (eq. single):  x_i' = u_i = -sum_j ω_ij(t) y_ij(t)                    (uxsingle at t)
    double (eq. double):  x_i' = q_i,
                          q_i' = -k1 sum_j ω_ij(t) y_ij(t) - k2 sum_j ω_ij(t) q_ij(t) - k3 q_i(t)
                                                                                 (uxdouble at t)

with y_ij = x_i - x_j - d_ij, q_ij = q_i - q_j and ω_ij = (2c - r) / (c - r)², c = Δ - ||d_ij||,
r = ||y_ij|| (eq. fij). The single-integrator controller is the gradient flow of the tension
ν = Σ_edges r² / (c - r), whose gradient in y_i is Σ_j ω_ij y_ij; for double integrators
k1 ν + ½ Σ ||q_i||² does not grow. Both facts are what the tests check.

The periodic-sampling baseline is `formation_sim.sim.engine.simulate(..., period=...)`.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.integrate import solve_ivp

from formation_agent.core.speed_scale import eta2_gains, initial_velocities
from formation_sim.sim.engine import check_sample_dt
from formation_sim.sim.errors import BaselineError, EngineError
from formation_sim.sim.record import RunRecord
from formation_sim.sim.samples import Samples

METHOD = 'DOP853'  # 8th-order Runge-Kutta: tight tolerances at a moderate number of evaluations


class _EdgeSums:
    """Σ_j ω_ij v_ij for every agent i over edge arrays (edge (i, j) adds +ω v to i, -ω v to j)."""

    def __init__(self, scenario) -> None:
        index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
        self.ids = tuple(scenario.agent_ids)
        self.n = len(self.ids)
        self.heads = np.array([index[e.i] for e in scenario.edges], dtype=np.intp)
        self.tails = np.array([index[e.j] for e in scenario.edges], dtype=np.intp)
        self.offsets = np.array([np.asarray(e.d, dtype=float) for e in scenario.edges])
        self.capacity = scenario.delta - np.linalg.norm(self.offsets, axis=1)  # Δ - ||d_ij||

    def weights(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(y_ij per edge, ω_ij per edge) at positions x; ω is NaN on an edge out of its range."""
        y = x[self.heads] - x[self.tails] - self.offsets
        r = np.linalg.norm(y, axis=1)
        gap = self.capacity - r
        gap[gap <= 0.0] = np.nan  # outside ω's domain: the integrator rejects such a trial step
        return y, (2.0 * self.capacity - r) / (gap * gap)  # (fij)

    def check_range(self, x: np.ndarray) -> None:
        """Raise if an edge is out of its range at positions x."""
        r = np.linalg.norm(x[self.heads] - x[self.tails] - self.offsets, axis=1)
        broken = np.flatnonzero(~(r < self.capacity))
        if broken.size:
            k = int(broken[0])
            i, j = self.ids[self.heads[k]], self.ids[self.tails[k]]
            raise BaselineError(
                f'continuous controller: edge ({i},{j}) left its range: ||x_i-x_j-d_ij|| = {float(r[k])!r} '
                f'>= Δ-||d_ij|| = {float(self.capacity[k])!r}'
            )

    def accumulate(self, per_edge: np.ndarray) -> np.ndarray:
        total = np.zeros((self.n, per_edge.shape[1]))
        np.add.at(total, self.heads, per_edge)
        np.add.at(total, self.tails, -per_edge)
        return total


def _checked_horizon(scenario, *, horizon: float | None, sample_dt: float) -> float:
    """The run's horizon (the scenario's by default), once it and `sample_dt` are valid."""
    horizon = float(scenario.horizon if horizon is None else horizon)
    if not (math.isfinite(horizon) and horizon > 0.0):
        raise BaselineError(f'horizon must be a finite number > 0, got {horizon!r}')
    if not (math.isfinite(sample_dt) and sample_dt > 0.0):
        raise BaselineError(f'sample_dt must be a finite number > 0, got {sample_dt!r}')
    try:
        check_sample_dt(sample_dt, horizon=horizon, scenario=scenario)
    except EngineError as error:
        raise BaselineError(str(error)) from None
    return horizon


def simulate_continuous(
    scenario,
    *,
    horizon: float | None = None,
    sample_dt: float = 0.01,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> RunRecord:
    """Integrate the continuous controller (see the module docstring) up to `horizon`.

    The record samples the state every `sample_dt` (and at the horizon). Continuous control has
    no triggers and sends no triggering information; `sensing_calls` counts, per agent, the
    controller evaluations the integrator needed (n per right-hand-side evaluation), a lower
    bound on what sampling this controller at this accuracy would cost; `extra` has the details.
    """
    horizon = _checked_horizon(scenario, horizon=horizon, sample_dt=sample_dt)
    started = time.perf_counter()
    sums = _EdgeSums(scenario)
    n, p = np.asarray(scenario.positions).shape
    double = scenario.dynamics == 'double'
    gains = scenario.gains

    kappa = gains.speed_scale  # the paper's controller in the time s = κt (docs/SPEED_SCALE.md)
    if double:
        (k1, k2, k3), _ = eta2_gains(
            alpha_d=gains.alpha_d,
            beta_d=gains.beta_d,
            k1=gains.k1,
            k2=gains.k2,
            k3=gains.k3,
            speed_scale=kappa,
            threshold_floor=gains.threshold_floor,
        )

        def rhs(_t: float, state: np.ndarray) -> np.ndarray:
            x, q = state[: n * p].reshape(n, p), state[n * p :].reshape(n, p)
            y, w = sums.weights(x)
            q_rel = q[sums.heads] - q[sums.tails]
            # u_i = -k1 Σ ω y_ij - k2 Σ ω q_ij - k3 q_i   (uxdouble, all at t)
            u = -sums.accumulate(w[:, None] * (k1 * y + k2 * q_rel)) - k3 * q
            return np.concatenate([q.ravel(), u.ravel()])

        velocities = initial_velocities(scenario.velocities, kappa)
        initial = np.concatenate([np.asarray(scenario.positions, float).ravel(), velocities.ravel()])
    else:

        def rhs(_t: float, state: np.ndarray) -> np.ndarray:
            y, w = sums.weights(state.reshape(n, p))
            return (-kappa * sums.accumulate(w[:, None] * y)).ravel()  # u_i = -κ Σ ω y_ij  (uxsingle at t)

        initial = np.asarray(scenario.positions, dtype=float).ravel()

    grid = np.arange(0.0, horizon, sample_dt)
    grid = np.append(grid[grid < horizon], horizon)
    sums.check_range(np.asarray(scenario.positions, dtype=float))
    # A trial step that crosses a range limit sees NaN weights, has a NaN error estimate and is
    # rejected; the first step is kept small since the weights can start steep (paper_single).
    solution = solve_ivp(
        rhs, (0.0, horizon), initial, method=METHOD, t_eval=grid, rtol=rtol, atol=atol, first_step=1e-9
    )
    if not solution.success:
        raise BaselineError(f'continuous controller: integration failed: {solution.message}')
    states = solution.y.T
    positions = states[:, : n * p].reshape(-1, n, p)
    for x in positions:
        sums.check_range(x)
    velocities = states[:, n * p :].reshape(-1, n, p) if double else None
    return RunRecord(
        scenario=scenario,
        horizon=horizon,
        mode='continuous',
        trigger_times={agent: [] for agent in scenario.agent_ids},
        samples=Samples(times=solution.t, positions=positions, velocities=velocities),
        messages_sent=0,
        sensing_calls=n * int(solution.nfev),
        wall_time=time.perf_counter() - started,
        extra={'method': METHOD, 'rtol': rtol, 'atol': atol, 'rhs_evaluations': int(solution.nfev)},
    )
