"""The threshold floor c0 (docs/SPEED_SCALE.md, "The threshold floor"): its guarantees, checked on
exact runs of both ETAs, and the validate rule that refuses a c0 breaking its condition."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.analysis.checks import run_series, theorem_checks, theory_bounds
from formation_sim.model import theory
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import DoubleGains, load_scenario
from formation_sim.model.threshold_floor import floor_bounds
from formation_sim.model.validate import validate_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError


def _near_formation_double(c0: float):
    """paper_double's graph started near its formation at rest, α_d = 0.02: ETA-2's condition holds."""
    base = load_scenario('paper_double')
    tau = theory.formation_feasibility(base).tau
    x = tau + np.array([[0.05, 0.0], [0.0, -0.04], [-0.03, 0.03]])
    gains = DoubleGains.from_riccati(
        alpha_d=0.02, beta_d=0.1, beta1=base.gains.beta1, k3='paper', threshold_floor=c0
    )
    return base.replace(name='near_double', positions=x, velocities=np.zeros_like(x), gains=gains)


CASES = {
    # name: (scenario, κ, horizon of the paper's time)
    'paper_single c0=0.1': (load_scenario('paper_single').with_scale(threshold_floor=0.1), 1.0, 20.0),
    'paper_single c0=0.5 κ=0.37': (
        load_scenario('paper_single').with_scale(threshold_floor=0.5, speed_scale=0.37),
        0.37,
        20.0,
    ),
    'robots_square c0=5mm': (load_scenario('robots_square').with_scale(threshold_floor=0.005), 1.0, 30.0),
    'random single c0=0.02': (random_scenario(n=7, seed=18).with_scale(threshold_floor=0.02), 1.0, 30.0),
    'near double c0=5mm': (_near_formation_double(0.005), 1.0, 30.0),
    'near double c0=5mm κ=2': (_near_formation_double(0.005).with_scale(speed_scale=2.0), 2.0, 30.0),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_the_floors_guarantees_hold_on_exact_runs(case):
    scenario, kappa, horizon = CASES[case]
    floor = floor_bounds(scenario)
    assert floor.proven, floor.condition
    record = simulate(scenario, horizon=horizon / kappa, sample_dt=0.01 / kappa)
    series = run_series(record)
    # A positive minimum inter-event time: at least c0 / c_i (paper time), ξ_i / κ seconds.
    for agent, times in record.trigger_times.items():
        assert len(times) > 3
        assert float(np.diff(times).min()) >= floor.xi[agent] / kappa, agent
    # Connectivity: every edge within k_ij + ||d_ij|| < Δ at every sample.
    for column, edge in enumerate(scenario.edges):
        bound = floor.k_edge[edge.pair] + float(np.linalg.norm(edge.d))
        assert bound < scenario.delta
        assert float(series.edge_lengths[:, column].max()) <= bound
    # Practical convergence: V <= B(κt) throughout; the final error within 2 sqrt(z B), which tends
    # to the ball 2 sqrt(z V_∞) = O(c0).
    envelope = floor.lyapunov_bound(kappa * series.times)
    assert np.all(series.lyapunov <= envelope * (1.0 + 1e-9))
    end = float(floor.lyapunov_bound(kappa * series.times[-1]))
    assert series.formation_error[-1] <= 2.0 * math.sqrt(floor.z_gain * end) * (1.0 + 1e-9)
    assert float(floor.lyapunov_bound(1e6)) == pytest.approx(floor.ultimate, rel=1e-9)
    # The analysis' checks say the same, all of them.
    checks = theorem_checks(record, series, theory_bounds(scenario))
    assert all(check.ok for check in checks), [c for c in checks if not c.ok]
    assert {c.name for c in checks} >= {
        'V <= B(κt) (threshold floor, docs/SPEED_SCALE.md)',
        'inter-event times >= c0 / c_i (threshold floor)',
    }


def test_the_floor_lets_a_run_outlast_the_rounding_of_the_vanishing_threshold():
    scenario = load_scenario('paper_single')
    with pytest.raises(EngineError, match='ulps'):
        simulate(
            scenario, horizon=60.0, sample_dt=0.0
        )  # the paper's threshold reaches rounding near t = 34.4
    floored = scenario.with_scale(threshold_floor=1e-3)
    record = simulate(floored, horizon=60.0, sample_dt=0.0)
    xi = floor_bounds(floored).xi
    assert all(float(np.diff(t).min()) >= xi[a] for a, t in record.trigger_times.items())
    late = sum(1 for t in record.trigger_times.values() for s in t if s > 40.0)
    assert (
        late < 1000
    )  # ~3.6 a second in the last 20 s; the paper's threshold had 19 000 in one second near t = 44


def test_a_zero_floor_is_the_paper():
    scenario = load_scenario('paper_single').with_scale(threshold_floor=0.0)
    assert floor_bounds(scenario) is None
    assert not _floor_findings(scenario)[1]


def _floor_findings(scenario):
    """The report and its threshold_floor findings as (level, finding)."""
    report = validate_scenario(scenario)
    levels = (('error', report.errors), ('warning', report.warnings), ('note', report.notes))
    return report, [(level, f) for level, found in levels for f in found if f.rule == 'threshold_floor']


def test_validate_refuses_an_eta1_floor_beyond_its_condition_and_names_it():
    base = load_scenario('paper_single')
    limit = theory.beta0(base) * float(theory.edge_capacities(base).min()) * math.sqrt(2.0 / base.n)
    report, found = _floor_findings(base.with_scale(threshold_floor=limit * 1.001))
    assert not report.ok
    (error,) = [f for level, f in found if level == 'error']
    assert f'{limit:.6g}' in error.message and 'c0 < β0 min(Δ-||d_ij||) sqrt(2/n)' in error.message
    report, found = _floor_findings(base.with_scale(threshold_floor=limit * 0.999))
    assert report.ok and not [f for level, f in found if level == 'error']


def test_validate_refuses_an_eta2_floor_whose_ball_leaves_the_capacity_and_warns_where_unproven():
    base = load_scenario('paper_double')
    report, found = _floor_findings(base.with_scale(threshold_floor=1.0))
    assert not report.ok
    assert 'ultimate ball' in next(f for level, f in found if level == 'error').message
    report, found = _floor_findings(base.with_scale(threshold_floor=0.01))
    assert report.ok  # the paper's example: proven only where sup V_d fits, which it does not
    assert [f for level, f in found if level == 'warning' and 'checked on runs only' in f.message]
    report, found = _floor_findings(_near_formation_double(0.005))
    assert report.ok and not [f for level, f in found if level != 'note']


def test_eta2_where_the_condition_fails_the_run_is_still_checked_and_holds():
    """The paper's example with c0 = 0.01: connectivity is not proven (its V_d(0) is too large), so
    the analysis checks it on the run, and V_d <= B_d(κt), which needs only the edges in range."""
    scenario = load_scenario('paper_double').with_scale(threshold_floor=0.01, speed_scale=2.0)
    floor = floor_bounds(scenario)
    assert not floor.proven and floor.xi is None
    record = simulate(scenario, horizon=10.0, sample_dt=0.005)
    series = run_series(record)
    checks = theorem_checks(record, series, theory_bounds(scenario))
    assert all(check.ok for check in checks), [c for c in checks if not c.ok]
    assert [c.name for c in checks][:2] == [
        'connectivity: ||x_i - x_j|| < Δ',
        'V <= B(κt) (threshold floor, docs/SPEED_SCALE.md)',
    ]
