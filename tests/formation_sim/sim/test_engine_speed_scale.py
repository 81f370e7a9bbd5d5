"""The speed scale κ (docs/SPEED_SCALE.md) in the exact engine: the run at κ is the paper's in the
time s = κt.

The engine runs the very agents the nodes run: the triggering times at κ are the κ = 1 run's divided
by κ, the positions at t/κ are the κ = 1 positions at t and the velocities κ times theirs, for both
ETAs; κ = 1 and c0 = 0 given explicitly are the paper's run bit for bit; bad values are refused.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.model.errors import ScenarioError
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate

KAPPAS = (0.1, 0.37, 3.0)
REL = 1e-9
HORIZON = 3.0  # of the κ = 1 run (paper time)
DT = 0.05


def _scenarios():
    return {
        'paper_single': load_scenario('paper_single'),
        'paper_double': load_scenario('paper_double'),
        'random_single': random_scenario(n=7, seed=18, dynamics='single'),
        'random_double': random_scenario(n=6, seed=18, dynamics='double'),
    }


SCENARIOS = _scenarios()


@pytest.fixture(scope='module')
def reference_runs():
    return {
        name: simulate(s, horizon=HORIZON, sample_dt=DT, sample_events=False) for name, s in SCENARIOS.items()
    }


@pytest.mark.parametrize('kappa', KAPPAS)
@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_triggering_times_are_divided_by_kappa_and_paths_kept(reference_runs, name, kappa):
    base = SCENARIOS[name]
    reference = reference_runs[name]
    scaled = simulate(
        base.with_scale(speed_scale=kappa), horizon=HORIZON / kappa, sample_dt=DT / kappa, sample_events=False
    )
    assert reference.total_events > 3 * base.n  # the runs hold real event chains
    for agent, times in reference.trigger_times.items():
        # Events within rounding of the horizon may fall on either side of it.
        expected = np.array([t for t in times if t < HORIZON * (1.0 - 1e-6)])
        got = np.array(scaled.trigger_times[agent][: expected.size]) * kappa
        assert got.size == expected.size
        assert got[0] == expected[0] == 0.0
        np.testing.assert_allclose(got[1:], expected[1:], rtol=REL, atol=0.0, err_msg=f'agent {agent}')
    # Grid samples k·DT/κ against k·DT: positions equal, velocities κ times the paper's.
    count = min(len(reference.sample_times), len(scaled.sample_times)) - 1  # the horizon's sample aside
    np.testing.assert_allclose(
        np.asarray(scaled.sample_times[:count]) * kappa, reference.sample_times[:count], rtol=1e-12
    )
    scale = float(np.abs(reference.sample_positions).max())
    np.testing.assert_allclose(
        scaled.sample_positions[:count], reference.sample_positions[:count], rtol=0.0, atol=REL * scale
    )
    if base.dynamics == 'double':
        speeds = float(np.abs(reference.sample_velocities).max())
        np.testing.assert_allclose(
            scaled.sample_velocities[:count],
            kappa * reference.sample_velocities[:count],
            rtol=0.0,
            atol=REL * kappa * speeds,
        )
        np.testing.assert_array_equal(
            scaled.sample_velocities[0], kappa * base.velocities
        )  # the run starts at κ q(0)


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_kappa_one_and_floor_zero_given_explicitly_are_the_paper_bit_for_bit(name):
    base = load_scenario(name)
    given = base.with_scale(speed_scale=1.0, threshold_floor=0.0)
    assert given.gains.speed_scale == 1.0 and given.gains.threshold_floor == 0.0
    a = simulate(base, horizon=2.0, sample_dt=0.1)
    b = simulate(given.replace(name='given'), horizon=2.0, sample_dt=0.1)
    assert a.trigger_times == b.trigger_times
    np.testing.assert_array_equal(a.sample_positions, b.sample_positions)


@pytest.mark.parametrize('bad', [0.0, -1.0, math.nan, math.inf, 1e-7, 2e6])
def test_a_scenario_with_a_bad_speed_scale_is_refused_with_its_rule_and_value(bad):
    with pytest.raises(ScenarioError, match=r'gains\.speed_scale: must') as caught:
        load_scenario('paper_single').with_scale(speed_scale=bad)
    assert repr(float(bad)) in str(caught.value)


@pytest.mark.parametrize('kappa', [0.37, 3.0])
@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_the_theorems_checks_hold_on_a_scaled_run_in_real_time(reference_runs, name, kappa):
    """The analysis' bounds at κ: rates κβ, ξ_i/κ, V_d of the paper's velocities q/κ; every check
    that holds for the paper's run holds for the scaled one, and the ratios to the bounds agree."""
    from formation_sim.analysis.checks import run_series, theorem_checks, theory_bounds
    from formation_sim.sim.summary import build_summary

    base = SCENARIOS[name]
    scaled_scenario = base.with_scale(speed_scale=kappa)
    reference = reference_runs[name]
    scaled = simulate(scaled_scenario, horizon=HORIZON / kappa, sample_dt=DT / kappa, sample_events=False)
    bounds = theory_bounds(scaled_scenario)
    paper = theory_bounds(base)
    assert bounds.rate == kappa * paper.rate
    assert bounds.xi == (None if paper.xi is None else {agent: xi / kappa for agent, xi in paper.xi.items()})
    series, paper_series = run_series(scaled), run_series(reference)
    count = min(len(series.times), len(paper_series.times)) - 1
    np.testing.assert_allclose(series.lyapunov[:count], paper_series.lyapunov[:count], rtol=1e-7)
    got = {c.name: c.ok for c in theorem_checks(scaled, series, bounds)}
    assert got == {c.name: c.ok for c in theorem_checks(reference, paper_series, paper)}
    assert all(got.values()), got
    summary = build_summary(scaled)
    assert all(entry['holds'] in (True, None) for entry in summary['xi_check'].values())
    assert summary['theorem_constants']['speed_scale'] == kappa


def test_a_robots_velocity_reference_at_kappa_follows_the_scaled_world():
    """ETA-2 on a velocity-commanded robot: the reference q_i(t) with damping κk3 (what the agent
    node gives its RobotCommander), started at κ q(0) and fed the agent's u^d, is the exact world's."""
    from formation_agent.core.speed_scale import damping
    from formation_agent.core.velocity_reference import VelocityReference

    kappa = 2.5
    scenario = load_scenario('paper_double').with_scale(speed_scale=kappa)
    events = []  # (t, velocities, controls): the hook runs before the agents due at t trigger
    simulate(
        scenario,
        horizon=0.4,
        sample_dt=0.0,
        on_event=lambda t, world, due: events.append((t, world.velocities, world.controls)),
    )
    k = scenario.index(1)
    reference = VelocityReference(
        k3=damping(scenario.gains.k3, kappa), velocity=kappa * scenario.velocities[k], time=0.0
    )
    assert len(events) > 20
    for (before, _, _), (t, velocities, controls) in zip(events, events[1:]):
        reference.update(before, controls[k])  # the command in force on (before, t]
        np.testing.assert_allclose(reference.velocity(t), velocities[k], rtol=1e-9, atol=1e-12)
