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

from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import ScenarioError, load_scenario
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
    return {name: simulate(s, horizon=HORIZON, sample_dt=DT, sample_events=False) for name, s in SCENARIOS.items()}


@pytest.mark.parametrize('kappa', KAPPAS)
@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_triggering_times_are_divided_by_kappa_and_paths_kept(reference_runs, name, kappa):
    base = SCENARIOS[name]
    reference = reference_runs[name]
    scaled = simulate(base.with_scale(speed_scale=kappa), horizon=HORIZON / kappa, sample_dt=DT / kappa, sample_events=False)
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
    np.testing.assert_allclose(np.asarray(scaled.sample_times[:count]) * kappa, reference.sample_times[:count], rtol=1e-12)
    scale = float(np.abs(reference.sample_positions).max())
    np.testing.assert_allclose(scaled.sample_positions[:count], reference.sample_positions[:count], rtol=0.0, atol=REL * scale)
    if base.dynamics == 'double':
        speeds = float(np.abs(reference.sample_velocities).max())
        np.testing.assert_allclose(
            scaled.sample_velocities[:count], kappa * reference.sample_velocities[:count], rtol=0.0, atol=REL * kappa * speeds
        )
        np.testing.assert_array_equal(scaled.sample_velocities[0], kappa * base.velocities)  # the run starts at κ q(0)


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
