"""One case: its team, its row, and the audit's event-by-event numbers against independent ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from formation_sim.analysis.checks import run_series, theorem_checks, theory_bounds
from formation_sim.model import theory
from formation_sim.sim.engine import simulate
from formation_sim.study.audit import TOLERANCE, EdgeWatch, theorem_audit
from formation_sim.study.case import COLUMNS, check_case, run_case, scenario_of
from formation_sim.study.spec import build_study


def _cases(*blocks):
    return build_study(
        {'name': 't', 'seed': 5, 'defaults': {'horizon': 1.0, 'alpha': 10.0}, 'cases': list(blocks)}
    ).cases


def test_a_case_is_its_random_team_with_the_gains_as_fractions_of_their_bounds():
    single, double = _cases(
        {'n': 7, 'graph': 'cycle', 'beta': 0.9, 'p': 3},
        {'n': 9, 'algorithm': 'eta2', 'graph': 'star', 'beta1': 0.5, 'k3': 0.3, 'beta_d': 0.8},
    )
    s = scenario_of(single)
    assert s.dynamics == 'single' and s.n == 7 and s.dimension == 3 and len(s.edges) == 7
    assert s.gains.beta == pytest.approx(0.9 * theory.beta0(s), rel=1e-12)
    d = scenario_of(double)
    constants = theory.theorem_constants(d)
    assert {e.i for e in d.edges} == {1} and len(d.edges) == 8  # a star around agent 1
    assert d.gains.beta1 == pytest.approx(0.5 * constants.beta0, rel=1e-12)
    assert d.gains.k3 == pytest.approx(0.3 * constants.k3_upper_bound, rel=1e-12)
    assert d.gains.beta_d == pytest.approx(0.8 * constants.beta_d_bound_paper, rel=1e-12)
    assert check_case(single) is None and check_case(double) is None


def test_a_case_breaking_a_hypothesis_is_named_with_the_rule():
    (case,) = _cases({'n': 30, 'graph': 'path', 'slack': 0.001, 'alpha': 0.01})
    problem = check_case(case)
    assert (
        problem.startswith('case 0 (cases[0]: eta1 event n=30 p=2 path seed=0)') and '[precision]' in problem
    )


@pytest.mark.parametrize('algorithm', ['eta1', 'eta2'])
def test_the_row_agrees_with_the_summary_and_the_analysis_checks(algorithm):
    (case,) = _cases({'n': 6, 'algorithm': algorithm, 'graph': 'geometric', 'slack': 0.2})
    row = run_case(case)
    assert tuple(row) == COLUMNS and row['status'] == 'ok' and row['error'] is None
    scenario = scenario_of(case)
    record = simulate(scenario, horizon=1.0, sample_dt=0.0)
    assert row['total_events'] == record.total_events and row['messages_sent'] == record.messages_sent
    # The exact largest edge is at least the one at the events, and holds the margin it reports.
    assert row['max_edge_exact'] >= row['max_edge_length'] == pytest.approx(row['max_edge_exact'], rel=0.05)
    # (ETA-1: exact at the events, a length is convex between them; ETA-2: within TOLERANCE Δ.)
    exact = 1.0 - row['max_edge_exact'] / scenario.delta
    assert exact - TOLERANCE - 1e-15 <= row['conn_margin'] <= exact
    # Every guarantee holds, as analysis.checks finds too (its checks at the same samples).
    checks = theorem_checks(record, run_series(record), theory_bounds(scenario))
    assert all(check.ok for check in checks)
    assert row['conn_violations'] == row['conv_violations'] == row['zeno_violations'] == 0
    assert row['conv_margin'] > 0 and row['zeno_margin'] >= 0
    gaps = sum(len(t) - 1 for t in record.trigger_times.values())
    assert row['zeno_checks'] == gaps and row['conv_checks'] == 2 * len(record.sample_times)
    if algorithm == 'eta2':
        assert row['printed_checks'] == row['conv_checks']


def test_the_edge_watch_finds_the_largest_length_between_events_to_its_tolerance():
    """ETA-2 moves along exponentials between events: the watch's maximum against a fine grid."""
    (case,) = _cases(
        {'n': 5, 'algorithm': 'eta2', 'graph': 'path', 'slack': 0.05, 'max_speed': 2.0, 'horizon': 0.5}
    )
    scenario = scenario_of(case)
    watch = EdgeWatch(scenario)
    record = simulate(scenario, horizon=0.5, sample_dt=1e-4, on_event=watch.on_event)
    watch.finish(0.5)
    heads, tails, _ = scenario.edge_indices()
    x = np.asarray(record.sample_positions)
    dense = float(np.linalg.norm(x[:, heads] - x[:, tails], axis=2).max())
    result = watch.result()
    # The grid (every event and every 0.1 ms) never sees more than the watch, and sees nearly as much.
    assert dense <= result['max_edge_exact'] + TOLERANCE * scenario.delta
    assert result['max_edge_exact'] - dense < 1e-6
    assert result['conn_checks'] > len(record.sample_times)


def test_the_audit_counts_a_violated_bound():
    """Bounds far below the proof's are violated, and the margins say so."""
    (case,) = _cases({'n': 4, 'graph': 'star', 'slack': 0.3})
    scenario = scenario_of(case)
    record = simulate(scenario, horizon=1.0, sample_dt=0.0)
    series = run_series(record)
    bounds = theory_bounds(scenario)
    honest = theorem_audit(record, series, bounds)
    tight = dataclasses.replace(
        bounds, k_V=bounds.k_V * 1e-12, xi=dict.fromkeys(bounds.xi, 1.0)
    )  # every gap of a 1 s run is below 1 s
    broken = theorem_audit(record, series, tight)
    assert honest['conv_violations'] == honest['zeno_violations'] == 0
    assert broken['conv_violations'] > 0 and broken['conv_margin'] < 0
    assert broken['zeno_violations'] > 0 and broken['zeno_margin'] < 0


def test_a_failed_case_is_a_row_with_its_error():
    (case,) = _cases({'n': 4})
    bad = dataclasses.replace(case, params={**case.params, 'slack': 2.0})  # past the SPEC's checks
    row = run_case(bad)
    assert row['status'] == 'failed' and 'slack must lie in (0, 1], got 2.0' in row['error']
    assert row['total_events'] is None and row['wall_time'] >= 0 and tuple(row) == COLUMNS


@pytest.mark.parametrize('sampling', ['periodic', 'continuous'])
def test_baselines_have_rows_without_an_audit(sampling):
    (case,) = _cases({'n': 5, 'sampling': sampling, 'period': 0.1})
    row = run_case(case)
    assert row['status'] == 'ok' and row['conn_checks'] is None
    if sampling == 'periodic':
        assert row['total_events'] == 5 * 11  # every agent at t = 0, 0.1, ..., 1.0 (the horizon)
    else:
        assert row['total_events'] == 0 and row['sensing_calls'] > 0


def test_a_case_at_a_speed_scale_runs_the_same_events_in_scaled_time():
    """κ = 0.5: the paper's run, every triggering time / κ (docs/SPEED_SCALE.md), audited the same."""
    plain, scaled = _cases({'n': 5, 'graph': 'path', 'speed_scale': [1.0, 0.5]})
    assert scenario_of(scaled).gains.speed_scale == 0.5 and scenario_of(plain).gains.speed_scale == 1.0
    slow = dataclasses.replace(scaled, params={**scaled.params, 'horizon': 2.0})
    a, b = run_case(plain), run_case(slow)
    assert b['status'] == 'ok' and b['total_events'] == a['total_events']
    assert b['min_inter_event_time'] == pytest.approx(2.0 * a['min_inter_event_time'], rel=1e-9)
    assert b['conn_violations'] == b['conv_violations'] == b['zeno_violations'] == 0


def test_beta_d_drawn_as_a_fraction_of_the_corrected_bound():
    block = {'n': 6, 'algorithm': 'eta2', 'graph': 'path', 'beta1': 0.4, 'beta_d': 0.7}
    printed, corrected = _cases(block, {**block, 'beta_d_bound': 'corrected'})
    a, b = scenario_of(printed), scenario_of(corrected)
    constants = theory.theorem_constants(b)
    assert b.gains.beta_d == pytest.approx(0.7 * constants.beta_d_bound_corrected, rel=1e-12)
    assert a.gains.beta_d == pytest.approx(0.7 * constants.beta_d_bound_paper, rel=1e-12)
    # The same team and gains but β_d: P (so both bounds) does not depend on β_d.
    assert np.array_equal(a.gains.P, b.gains.P) and a.gains.k3 == b.gains.k3
    assert np.array_equal(a.positions, b.positions)
    assert b.gains.beta_d < constants.beta_d_bound_corrected < a.gains.beta_d  # here corrected < printed
    row = run_case(corrected)
    assert row['status'] == 'ok' and row['rate'] == b.gains.beta_d and row['beta_d_bound'] == 'corrected'
    assert row['conv_checks'] > 0 and row['conv_violations'] == 0  # Theorem 2 (ii) checked: below the bound


def test_until_error_runs_a_case_to_its_first_event_below_the_fraction():
    (case,) = _cases({'n': 5, 'graph': 'cycle', 'slack': 0.3, 'horizon': 60.0, 'until_error': 0.01})
    row = run_case(case)
    assert row['status'] == 'ok' and row['stop'] == 'error_reached' and row['stop_time'] < 60.0
    scenario = scenario_of(case)
    heads, tails, d = scenario.edge_indices()
    x = scenario.positions
    initial = np.linalg.norm(x[heads] - x[tails] - d, axis=1).max()
    assert row['initial_formation_error'] == pytest.approx(initial, rel=1e-15)
    assert row['final_formation_error'] < 0.01 * row['initial_formation_error']
    # The run without the stop has the same events before the stop time, and one at it (the stop
    # comes before that event's agents trigger).
    full = simulate(scenario, horizon=row['stop_time'], sample_dt=0.0)
    times = [t for chain in full.trigger_times.values() for t in chain]
    assert sum(t < row['stop_time'] for t in times) == row['total_events'] and max(times) == row['stop_time']
    assert row['conv_checks'] > 0 and row['conv_violations'] == 0
    (plain,) = _cases({'n': 5, 'graph': 'cycle', 'slack': 0.3, 'horizon': 1.0})
    assert run_case(plain)['stop'] is None
