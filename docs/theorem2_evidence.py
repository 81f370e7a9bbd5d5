"""Numerical evidence for docs/THEOREM2.md: decay rates of the paper's double-integrator example.

Run:  python docs/theorem2_evidence.py [--horizon 30] [--no-engine]

1. Linearisation of the closed loop (uxdouble) with E = 0 at the formation: slowest decay rate.
2. The continuous controller (E ≡ 0, which meets (triggerdouble) trivially) integrated with
   scipy solve_ivp (DOP853, rtol 1e-12) in deviation coordinates δ_i = y_i - ȳ, so the decaying
   error is never a difference of large numbers.
3. The exact event-triggered run (ETA-2) of `formation_sim.sim.engine.simulate`.

For each, the log slope of the formation error max_edge ||x_i - x_j - d_ij|| and of V_d is fitted
over windows and compared with the rates the theorem claims.
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp

from formation_sim.model import theory
from formation_sim.model.gains import k4_value
from formation_sim.model.scenario import load_scenario


def window_slopes(times, values, windows):
    """Least-squares slope of log(values) over each [start, end) window."""
    rows = []
    log_values = np.log(values)
    for start, end in windows:
        mask = (times >= start) & (times < end) & np.isfinite(log_values)
        slope = np.polyfit(times[mask], log_values[mask], 1)[0] if mask.sum() >= 2 else math.nan
        rows.append((start, end, slope))
    return rows


def linear_rates(scenario):
    """Eigenvalues of the E = 0 closed loop linearised at the formation (ω_ij = 2/(Δ-||d_ij||))."""
    gains = scenario.gains
    weights = 2.0 / theory.edge_capacities(scenario)  # f_ij(0), (fij)
    lap = theory.laplacian(scenario, weights)
    n = scenario.n
    top = np.hstack([np.zeros((n, n)), np.eye(n)])
    bottom = np.hstack([-gains.k1 * lap, -gains.k2 * lap - gains.k3 * np.eye(n)])
    eigenvalues = np.linalg.eigvals(np.vstack([top, bottom]))
    # Drop the modes of the centroid (ȳ, q̄), which do not enter formation error or V_d.
    centroid = np.ones(n) / math.sqrt(n)
    projector = np.eye(n) - np.outer(centroid, centroid)
    lap_eigs = np.linalg.eigvalsh(projector @ lap @ projector)[1:]
    rates = []
    for lam in lap_eigs:
        roots = np.roots([1.0, gains.k2 * lam + gains.k3, gains.k1 * lam])
        rates.append(float(-roots.real.max()))
    return lap_eigs, rates, eigenvalues


def continuous_run(scenario, horizon):
    heads, tails, _d = scenario.edge_indices()
    capacities = theory.edge_capacities(scenario)
    gains = scenario.gains
    n, p = scenario.n, scenario.dimension
    tau = theory.formation_feasibility(scenario).tau
    y0 = scenario.positions - tau
    q0 = scenario.velocities
    state0 = np.concatenate([(y0 - y0.mean(axis=0)).ravel(), (q0 - q0.mean(axis=0)).ravel()])

    def rhs(_t, state):
        dy = state[: n * p].reshape(n, p)
        dq = state[n * p :].reshape(n, p)
        rel = dy[heads] - dy[tails]  # y_i - y_j = x_i - x_j - d_ij
        length = np.linalg.norm(rel, axis=1)
        omega = (2.0 * capacities - length) / (capacities - length) ** 2  # (fij)
        coupling = np.zeros((n, p))
        term = omega[:, None] * (gains.k1 * rel + gains.k2 * (dq[heads] - dq[tails]))
        np.add.at(coupling, heads, term)
        np.add.at(coupling, tails, -term)
        return np.concatenate([dq.ravel(), (-coupling - gains.k3 * dq).ravel()])

    times = np.linspace(0.0, horizon, int(horizon * 20) + 1)
    solution = solve_ivp(rhs, (0.0, horizon), state0, method='DOP853', rtol=1e-12, atol=1e-30, t_eval=times)
    dys = solution.y[: n * p].T.reshape(-1, n, p)
    dqs = solution.y[n * p :].T.reshape(-1, n, p)
    # Rounding leaves a non-decaying mean of order 1e-16 (the centroid mode is neutral); V_d sees
    # only deviations from the mean, (K_n⊗P⊗I_p), so remove it again.
    dys = dys - dys.mean(axis=1, keepdims=True)
    dqs = dqs - dqs.mean(axis=1, keepdims=True)
    errors = np.array([np.linalg.norm(dy[heads] - dy[tails], axis=1).max() for dy in dys])
    P = gains.P
    lyap = 0.5 * np.array(
        [
            P[0, 0] * np.sum(a * a) + 2 * P[0, 1] * np.sum(a * b) + P[1, 1] * np.sum(b * b)
            for a, b in zip(dys, dqs)
        ]
    )
    return times, errors, lyap


def engine_run(scenario, horizon):
    from formation_sim.sim.engine import simulate

    record = simulate(scenario, horizon=horizon, sample_dt=0.05)
    times = record.sample_times
    errors = np.array([theory.formation_error(scenario, x) for x in record.sample_positions])
    tau = theory.formation_feasibility(scenario).tau
    lyap = np.array(
        [
            theory.lyapunov_double(scenario, x, q, tau=tau)
            for x, q in zip(record.sample_positions, record.sample_velocities)
        ]
    )
    return record, times, errors, lyap


def first_violations(times, errors, lyap, k_v, beta_d):
    """First sample times at which the conclusions (kVd) and (yiyj) of Theorem 2 (ii) fail."""
    bound_v = k_v * np.exp(-2.0 * beta_d * times)  # V_d < k^d_V e^{-2 β_d t}
    bound_e = 2.0 * np.sqrt(k_v) * np.exp(-beta_d * times)  # ||y_i - y_j|| < 2 sqrt(k^d_V) e^{-β_d t}
    over_v = np.flatnonzero(lyap >= bound_v)
    over_e = np.flatnonzero(errors >= bound_e)
    return (times[over_v[0]] if over_v.size else None, times[over_e[0]] if over_e.size else None)


def report(label, times, errors, lyap, windows, beta_d, claimed_v_rate, k_v=None):
    print(f'\n{label}')
    print('  window      slope log(max edge error)   slope log(V_d)')
    for (s, e, se), (_, _, sv) in zip(
        window_slopes(times, errors, windows), window_slopes(times, lyap, windows)
    ):
        print(f'  [{s:4.0f},{e:4.0f})   {se:10.4f}                 {sv:10.4f}')
    growth = lyap * np.exp(2.0 * beta_d * times)
    marks = [t for t in (0, 5, 10, 15, 20, 25, 30, 40) if t <= times[-1]]
    print('  V_d(t) e^{2 β_d t}: ' + ', '.join(f't={t}: {np.interp(t, times, growth):.4g}' for t in marks))
    implied = lyap[0] * np.exp(-claimed_v_rate * times)
    over = np.flatnonzero(lyap > implied)
    if claimed_v_rate > 0 and over.size:
        print(f'  V_d(t) > V_d(0) e^{{-{claimed_v_rate:.4f} t}} first at t = {times[over[0]]:.2f}')
    if k_v is not None:
        t_v, t_e = first_violations(times, errors, lyap, k_v, beta_d)
        print(
            f'  with the printed k^d_V = {k_v:.6g}: V_d >= k^d_V e^(-2 β_d t) first at t = {t_v}, '
            f'max ||y_i-y_j|| >= 2 sqrt(k^d_V) e^(-β_d t) first at t = {t_e}'
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--horizon', type=float, default=30.0)
    parser.add_argument('--no-engine', action='store_true')
    parser.add_argument('--beta-d', type=float, default=None, help="replace the paper's β_d = 1")
    args = parser.parse_args()
    scenario = load_scenario('paper_double')
    if args.beta_d is not None:
        scenario = scenario.replace(gains=dataclasses.replace(scenario.gains, beta_d=args.beta_d))
    gains = scenario.gains
    k4 = k4_value(gains.k1, gains.k2, gains.k3)
    eig = np.linalg.eigvalsh(gains.P)
    printed, corrected = (2 - k4) * eig[0], (2 - k4) / eig[1]
    print(f'k1 = {gains.k1:.6f}, k2 = {gains.k2:.6f}, k3 = {gains.k3:.10f}, k4 = {k4:.6f}')
    print(f'P eigenvalues: ρ2(P) = {eig[0]:.6f}, λmax(P) = {eig[1]:.6f}')
    print(
        f'β_d = {gains.beta_d}; printed bound (2-k4)ρ2(P) = {printed:.6f}; corrected (2-k4)/λmax(P) '
        f'= {corrected:.6f}'
    )
    lap_eigs, rates, _ = linear_rates(scenario)
    print(
        f'L_ω at the formation: eigenvalues {np.round(lap_eigs, 6).tolist()}, mode decay rates '
        f'{np.round(rates, 6).tolist()}'
    )
    print(
        f'slowest linear rate σ = {min(rates):.6f}: formation error ~ e^(-σt), V_d ~ e^(-2σt) = '
        f'e^(-{2 * min(rates):.6f} t)'
    )

    paper_k_v = theory.theorem_constants(scenario).paper_chain.k_V
    print(f'k^d_V as printed (kVd): {paper_k_v:.6g}')
    windows = [(t, t + 5.0) for t in np.arange(5.0, args.horizon, 5.0)]
    times, errors, lyap = continuous_run(scenario, args.horizon)
    # With E = 0 the printed proof gives V_d' <= -2 (2-k4) ρ2(P) V_d, i.e. V_d <= V_d(0) e^{-2(2-k4)ρ2(P) t}.
    report(
        'continuous controller (E = 0), solve_ivp DOP853 rtol 1e-12',
        times,
        errors,
        lyap,
        windows,
        gains.beta_d,
        2 * printed,
        paper_k_v,
    )
    if not args.no_engine:
        record, times, errors, lyap = engine_run(scenario, args.horizon)
        report(
            f'ETA-2, formation_sim.sim.engine.simulate ({record.total_events} events)',
            times,
            errors,
            lyap,
            windows,
            gains.beta_d,
            0.0,
            paper_k_v,
        )
        print(
            '  events per 5 s window: '
            + ', '.join(
                f'[{s:.0f},{s + 5:.0f}): '
                f'{sum(1 for ts in record.trigger_times.values() for t in ts if s <= t < s + 5)}'
                for s in np.arange(0.0, args.horizon, 5.0)
            )
        )


if __name__ == '__main__':
    main()
