"""The paper's quantities along a run and the guarantees of Theorems 1 and 2 they must respect.

`run_series` evaluates, at every sample of a `RunRecord`, the edge lengths, the formation error,
the tension ν (or ν_d) and the Lyapunov function V (or V_d); `theory_bounds` the proofs' bounds
(k_ij, k_V, ξ_i and their Theorem 2 counterparts); `theorem_checks` checks the run against them
and `inter_event_stats` the inter-event times against ξ_i. Each check is a `Check` with its numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from formation_agent.core.speed_scale import paper_velocities, real_duration, real_rate
from formation_sim.model import theory
from formation_sim.model.scenario import Scenario
from formation_sim.model.threshold_floor import FloorBounds, floor_bounds
from formation_sim.sim.record import RunRecord

ProgressCallback = Callable[[int, int | None], None]


@dataclass(frozen=True, kw_only=True)
class Check:
    """One consistency or theorem check: what was checked, whether it held, the numbers.

    A check that is not `binding` is reported but does not fail the analysis: on robots the
    theorems' decay and inter-event bounds are not guaranteed (README, "Running on robots": they
    assume exact integrators, exact sensing, no latency and no saturation)."""

    name: str
    ok: bool
    detail: str
    binding: bool = True

    def to_dict(self) -> dict[str, Any]:
        return {'name': self.name, 'ok': self.ok, 'detail': self.detail, 'binding': self.binding}


ROBOT_BOUNDS_NOTE = (
    "robots: reported, not guaranteed (noise, latency, saturation and the robots' dynamics are outside the "
    'theorems)'
)


@dataclass(frozen=True, kw_only=True)
class Series:
    """The paper's quantities at every sample of a run (rows = samples, columns = scenario edges)."""

    times: np.ndarray  # (K,)
    edge_lengths: np.ndarray  # (K, m) ||x_i - x_j||, must stay < Δ (Theorem 1/2 (i))
    edge_errors: np.ndarray  # (K, m) ||x_i - x_j - d_ij|| = ||y_i - y_j||
    formation_error: np.ndarray  # (K,) max over edges
    tension: np.ndarray  # (K,) ν (single) or ν_d = k1 ν + ½ Σ||q_i||² (double)
    lyapunov: np.ndarray  # (K,) V = ½ δᵀδ or V_d (double)


SERIES_CHUNK = 4096  # samples evaluated at once by run_series (bounds its temporaries)


def run_series(record: RunRecord, *, progress: ProgressCallback | None = None) -> Series:
    """The paper's quantities at every sample of `record` (a `BagRun` holds one: `bag_run.record`)."""
    if not isinstance(record, RunRecord):
        hint = ' (a BagRun holds it: pass bag_run.record)' if hasattr(record, 'record') else ''
        raise TypeError(f'run_series takes a RunRecord{hint}, got {type(record).__name__}')
    scenario = record.scenario
    heads, tails, d = scenario.edge_indices()
    x = record.sample_positions
    relative = x[:, heads] - x[:, tails]
    lengths = np.linalg.norm(relative, axis=2)
    errors = np.linalg.norm(relative - d, axis=2)
    tau = theory.formation_feasibility(scenario).tau
    double = scenario.dynamics == 'double'
    q = record.sample_velocities
    if double and scenario.speed_scale != 1.0:
        q = paper_velocities(q, scenario.speed_scale)  # ν_d, V_d of the paper's time (docs/SPEED_SCALE.md)
    count = len(record.sample_times)
    tension = np.empty(count)
    lyapunov = np.empty(count)
    for k in range(0, count, SERIES_CHUNK):  # (K, n, p) at a time: each sample's float as its own
        part = slice(k, min(k + SERIES_CHUNK, count))
        if double:
            tension[part] = theory.tensions_double(scenario, x[part], q[part])
            lyapunov[part] = theory.lyapunovs_double(scenario, x[part], q[part], tau=tau)
        else:
            tension[part] = theory.tensions(scenario, x[part])
            lyapunov[part] = theory.lyapunovs(scenario, x[part], tau=tau)
        if progress is not None:
            progress(k, count)
    if progress is not None:
        progress(count, count)
    return Series(
        times=np.asarray(record.sample_times, dtype=float),
        edge_lengths=lengths,
        edge_errors=errors,
        formation_error=errors.max(axis=1),
        tension=tension,
        lyapunov=lyapunov,
    )


@dataclass(frozen=True, kw_only=True)
class TheoryBounds:
    """What Theorem 1 (single) or Theorem 2 (double, corrected chain) guarantees for a scenario, in
    real time: at a speed scale κ the rates are κβ (κβ_d) and ξ_i/κ (docs/SPEED_SCALE.md). With a
    threshold floor c0 > 0 the guarantees are the floor's (`floor`, formation_sim.model.threshold_floor)."""

    theorem: int
    rate: float  # κβ (Theorem 1) or κβ_d (Theorem 2), per real second
    k_nu: float | None  # ν(t) <= k_ν (kν), or ν_d(t) <= k^d_ν (None: no bound, ETA-2 with a floor)
    k_V: float | None  # V(t) < k_V e^{-2 rate t} (kV), or V_d < k^d_V e^{-2 β_d t} (kVd, corrected)
    error_gain: float | None  # ||y_i - y_j|| < error_gain e^{-rate t} (lengthysV) / (yiyj)
    edge_bounds: dict[tuple[int, int], float] | None  # ||x_i - x_j|| <= k_ij + ||d_ij|| < Δ
    xi: dict[int, float] | None  # (xi) / (xid): t_{k+1} - t_k >= ξ_i (seconds)
    note: str
    speed_scale: float = 1.0
    floor: FloorBounds | None = None  # with a threshold floor c0 > 0: its bounds, in the paper's time
    # Theorem 2 only: k^d_V and the error gain of the chain as printed (rate (2-k4)ρ2(P)), drawn
    # for comparison; docs/THEOREM2.md shows where the paper's example leaves them.
    printed_k_V: float | None = None
    printed_error_gain: float | None = None


def theory_bounds(scenario: Scenario) -> TheoryBounds:
    """The proof constants as bounds; raises TheoryError outside the theorems' hypotheses."""
    constants = theory.theorem_constants(scenario)
    norms = {edge.pair: float(np.linalg.norm(edge.d)) for edge in scenario.edges}
    kappa = scenario.speed_scale
    if (floor := floor_bounds(scenario)) is not None:
        return _floor_bounds(scenario, floor, norms)
    edge_bounds = {pair: k + norms[pair] for pair, k in constants.k_edge.items()}
    xi = (
        None
        if constants.xi is None
        else {agent: real_duration(v, kappa) for agent, v in constants.xi.items()}
    )
    if constants.theorem == 1:
        return TheoryBounds(
            theorem=1,
            speed_scale=kappa,
            rate=real_rate(scenario.gains.beta, kappa),
            k_nu=constants.k_nu,
            k_V=constants.k_V,
            error_gain=2.0 * math.sqrt(constants.k_V),  # (lengthysV): ||y_i-y_j||² < 4 k_V e^{-2βt}
            edge_bounds=edge_bounds,
            xi=xi,
            note='Theorem 1' + _scale_note(kappa),
        )
    chain = constants.corrected_chain
    gain = None if chain.k_V is None else 2.0 * math.sqrt(chain.z_gain * chain.k_V)  # (yiyj), corrected
    printed = constants.paper_chain
    printed_gain = None if printed.k_V is None else 2.0 * math.sqrt(printed.z_gain * printed.k_V)
    return TheoryBounds(
        theorem=2,
        speed_scale=kappa,
        rate=real_rate(scenario.gains.beta_d, kappa),
        k_nu=constants.k_nu,
        k_V=chain.k_V,
        error_gain=gain,
        edge_bounds=edge_bounds,
        xi=xi,
        note='Theorem 2, corrected chain (docs/THEOREM2.md)'
        + ('' if chain.holds else ': β_d is not below (2-k4)/λmax(P), no decay bound')
        + _scale_note(kappa),
        printed_k_V=printed.k_V,
        printed_error_gain=printed_gain,
    )


def _scale_note(kappa: float) -> str:
    return '' if kappa == 1.0 else f'; speed scale κ = {kappa:g}: rates × κ, ξ_i / κ (docs/SPEED_SCALE.md)'


def _floor_bounds(scenario: Scenario, floor: FloorBounds, norms: dict) -> TheoryBounds:
    """The threshold floor's guarantees as TheoryBounds (docs/SPEED_SCALE.md, "The threshold floor")."""
    kappa = scenario.speed_scale
    proven = floor.proven
    note = (
        f'Theorem {floor.theorem} with the threshold floor c0 = {floor.floor:g}: '
        + (
            f'connectivity proven ({floor.condition})'
            if proven
            else f'connectivity not proven ({floor.condition} fails): checked on the run only'
        )
        + f'; V ultimately <= {floor.ultimate:.4g}, formation error <= {floor.ball:.4g}'
        + _scale_note(kappa)
    )
    return TheoryBounds(
        theorem=floor.theorem,
        speed_scale=kappa,
        rate=real_rate(floor.rate, kappa),
        k_nu=floor.k_nu,
        k_V=None,
        error_gain=None,
        edge_bounds=None
        if floor.k_edge is None
        else {pair: k + norms[pair] for pair, k in floor.k_edge.items()},
        xi=None if floor.xi is None else {agent: real_duration(v, kappa) for agent, v in floor.xi.items()},
        note=note,
        floor=floor,
    )


def printed_chain_ratios(series: Series, bounds: TheoryBounds) -> dict[str, Any] | None:
    """Theorem 2: the largest V_d / (printed k^d_V e^{-2β_d t}) and the first time it reaches 1."""
    if bounds.printed_k_V is None:
        return None
    ratio = series.lyapunov / (bounds.printed_k_V * np.exp(-2.0 * bounds.rate * series.times))
    worst = int(np.argmax(ratio))
    above = np.flatnonzero(ratio >= 1.0)
    return {
        'max_ratio': float(ratio[worst]),
        'at_time': float(series.times[worst]),
        'first_time_above': float(series.times[above[0]]) if above.size else None,
    }


def theorem_checks(record: RunRecord, series: Series, bounds: TheoryBounds | None) -> list[Check]:
    """The theorems' guarantees checked at every sample (and every inter-event time).

    On a robot run only connectivity binds; the proofs' bounds are reported (`Check.binding`)."""
    checks = _theorem_checks(record, series, bounds)
    if record.mode != 'robots':
        return checks
    return [checks[0]] + [
        Check(name=c.name, ok=c.ok, detail=f'{c.detail} ({ROBOT_BOUNDS_NOTE})', binding=False)
        for c in checks[1:]
    ]


def _theorem_checks(record: RunRecord, series: Series, bounds: TheoryBounds | None) -> list[Check]:
    scenario = record.scenario
    delta = scenario.delta
    longest = float(series.edge_lengths.max())
    checks = [
        Check(
            name='connectivity: ||x_i - x_j|| < Δ',
            ok=longest < delta,
            detail=f'max edge length {longest!r} vs Δ = {delta!r}',
        )
    ]
    if bounds is None:
        return checks
    if bounds.edge_bounds is not None:
        over = []
        for column, edge in enumerate(scenario.edges):
            top = float(series.edge_lengths[:, column].max())
            if not top <= bounds.edge_bounds[edge.pair]:
                over.append(f'{edge.i}-{edge.j}: {top!r} > {bounds.edge_bounds[edge.pair]!r}')
        checks.append(
            Check(
                name='edge lengths <= k_ij + ||d_ij|| (kij)',
                ok=not over,
                detail='; '.join(over) or 'every edge within its bound',
            )
        )
    if bounds.k_nu is not None:
        top_nu = float(series.tension.max())
        checks.append(
            Check(
                name='tension <= k_nu (knu)',
                ok=top_nu <= bounds.k_nu,
                detail=f'max {top_nu!r} vs k_nu = {bounds.k_nu!r}',
            )
        )
    t = series.times
    if bounds.floor is not None:
        return checks + _floor_checks(record, series, bounds)
    if bounds.k_V is not None:
        ratio = series.lyapunov / (bounds.k_V * np.exp(-2.0 * bounds.rate * t))
        worst = int(np.argmax(ratio))
        checks.append(
            Check(
                name='V < k_V e^{-2 beta t} (kV)',
                ok=bool(ratio[worst] < 1.0),
                detail=f'largest V / bound {ratio[worst]:.3g} at t = {float(t[worst])!r}',
            )
        )
    if bounds.error_gain is not None:
        ratio = series.formation_error / (bounds.error_gain * np.exp(-bounds.rate * t))
        worst = int(np.argmax(ratio))
        checks.append(
            Check(
                name='formation error < 2 sqrt(k_V) e^{-beta t}',
                ok=bool(ratio[worst] < 1.0),
                detail=f'largest error / bound {ratio[worst]:.3g} at t = {float(t[worst])!r}',
            )
        )
    if bounds.xi is not None:
        checks.append(_inter_event_check(record, bounds.xi, name='inter-event times >= xi_i (xi)'))
    return checks


def _floor_checks(record: RunRecord, series: Series, bounds: TheoryBounds) -> list[Check]:
    """With a threshold floor: V <= B(κt), the error within 2 sqrt(z B(κt)), inter-event times >= ξ_i.

    B bounds V wherever the edges stay within their capacities (ω_ij >= 2/Δ0 needs nothing else),
    which the connectivity check verifies on the run when the floor's condition does not prove it."""
    floor, t = bounds.floor, series.times
    envelope = floor.lyapunov_bound(bounds.speed_scale * t)
    # B is a bound on the exact V; the samples' V carries the rounding of the states.
    ratio = series.lyapunov / (envelope * (1.0 + 1e-9) + 1e-300)
    worst = int(np.argmax(ratio))
    checks = [
        Check(
            name='V <= B(κt) (threshold floor, docs/SPEED_SCALE.md)',
            ok=bool(ratio[worst] <= 1.0),
            detail=f'largest V / B {ratio[worst]:.3g} at t = {float(t[worst])!r}; B -> {floor.ultimate:.4g}',
        )
    ]
    error_bound = 2.0 * np.sqrt(floor.z_gain * envelope)
    ratio = series.formation_error / (error_bound * (1.0 + 1e-9) + 1e-300)
    worst = int(np.argmax(ratio))
    checks.append(
        Check(
            name='formation error <= 2 sqrt(z B(κt)) (threshold floor)',
            ok=bool(ratio[worst] <= 1.0),
            detail=(
                f'largest error / bound {ratio[worst]:.3g} at t = {float(t[worst])!r}; ultimately <= '
                f'{floor.ball:.4g}'
            ),
        )
    )
    if bounds.xi is not None:
        checks.append(
            _inter_event_check(record, bounds.xi, name='inter-event times >= c0 / c_i (threshold floor)')
        )
    return checks


def _inter_event_check(record, xi, *, name: str) -> Check:
    """Every agent's least inter-event time against its lower bound xi[agent] (no Zeno behaviour)."""
    below = []
    for agent, times in record.trigger_times.items():
        if len(times) > 1:
            gap = float(np.diff(times).min())
            if not gap >= xi[agent]:
                below.append(f'agent {agent}: {gap!r} < {xi[agent]!r}')
    return Check(name=name, ok=not below, detail='; '.join(below) or 'every agent')


def inter_event_stats(record: RunRecord, xi: dict[int, float] | None) -> dict[str, dict[str, Any]]:
    result = {}
    for agent, times in record.trigger_times.items():
        gaps = np.diff(np.asarray(times, dtype=float))
        result[str(agent)] = {
            'events': len(times),
            'min': float(gaps.min()) if gaps.size else None,
            'median': float(np.median(gaps)) if gaps.size else None,
            'max': float(gaps.max()) if gaps.size else None,
            'xi': None if xi is None else xi.get(agent),
        }
    return result
