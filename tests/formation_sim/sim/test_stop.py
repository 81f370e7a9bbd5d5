"""How an exact run ends (formation_sim.sim.stop through formation_sim.sim.engine.simulate):
`until_error` at the first event below the fraction of the initial formation error, the horizon,
and the rounding floor as a stop (`stop_at_floor`) instead of an EngineError.

The expected values come from runs without the stop: their trigger chains, and the formation error
recomputed here from their samples at every event time."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError
from formation_sim.sim.stop import STOP_REASONS
from formation_sim.sim.summary import build_summary


def _errors(scenario, record) -> np.ndarray:
    """max over edges of ||x_i - x_j - d_ij|| at every sample of `record` (computed edge by edge)."""
    index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
    x = np.asarray(record.sample_positions)
    per_edge = [
        np.linalg.norm(x[:, index[edge.i]] - x[:, index[edge.j]] - edge.d, axis=1) for edge in scenario.edges
    ]
    return np.max(per_edge, axis=0)


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_until_error_stops_at_the_first_event_below_the_fraction_of_the_initial_error(name):
    scenario = load_scenario(name)
    full = simulate(scenario, horizon=20.0, sample_dt=None)  # samples: t = 0, every event, the horizon
    errors = _errors(scenario, full)
    below = np.nonzero((errors < 0.01 * errors[0]) & (full.sample_times > 0))[0]
    expected = float(full.sample_times[below[0]])
    assert expected < 20.0  # the paper's examples reach 1 % within 20 s (4.3 s and 6.8 s)

    record = simulate(scenario, horizon=20.0, sample_dt=None, until_error=0.01)
    stop = record.extra['stop']
    assert stop['reason'] == 'error_reached' and stop['time'] == expected == record.horizon
    assert stop['initial_error'] == pytest.approx(errors[0], rel=1e-15)
    assert stop['error'] == pytest.approx(errors[below[0]], rel=1e-15)
    assert stop['error'] < 0.01 * stop['initial_error'] and stop['horizon'] == 20.0
    # The run is the full run up to the stop: the same triggers before it, none at or after it.
    for agent, times in full.trigger_times.items():
        assert record.trigger_times[agent] == [t for t in times if t < expected]
    assert record.sample_times[-1] == expected
    summary = build_summary(record)
    assert summary['horizon'] == expected and summary['extra']['stop']['reason'] == 'error_reached'
    assert summary['final_formation_error'] == pytest.approx(stop['error'], rel=1e-12)


def test_the_horizon_is_the_upper_bound_and_says_so():
    scenario = load_scenario('paper_single')
    record = simulate(scenario, horizon=2.0, sample_dt=None, until_error=0.01)
    stop = record.extra['stop']
    assert stop['reason'] == 'horizon' and stop['time'] == 2.0 == record.horizon
    assert stop['error'] == pytest.approx(build_summary(record)['final_formation_error'], rel=1e-12)
    assert stop['error'] >= 0.01 * stop['initial_error']
    plain = simulate(scenario, horizon=2.0, sample_dt=None)
    assert plain.trigger_times == record.trigger_times and 'stop' not in plain.extra


def test_the_rounding_floor_ends_the_run_where_it_would_have_failed():
    scenario = load_scenario('paper_double')
    worlds = []
    with pytest.raises(EngineError, match='from here on rounding') as failure:
        simulate(scenario, horizon=60.0, sample_dt=None, on_event=lambda t, world, due: worlds.append(t))
    record = simulate(scenario, horizon=60.0, sample_dt=None, stop_at_floor=True)
    stop = record.extra['stop']
    assert stop['reason'] == 'rounding_floor' and stop['message'] == str(failure.value)
    # The failing run called on_event at every event before the floor's; the stop is the next one.
    assert worlds[-1] < stop['time'] == record.horizon == record.sample_times[-1] < 60.0
    assert f'at t={stop["time"]!r}' in stop['message']
    assert max(max(times) for times in record.trigger_times.values()) == worlds[-1]


def test_until_error_also_stops_on_the_floor_with_the_error_there():
    scenario = load_scenario('paper_single')
    floor = simulate(scenario, horizon=60.0, sample_dt=None, stop_at_floor=True)
    errors = _errors(scenario, floor)
    fraction = 0.5 * float(errors[1:].min()) / float(errors[0])  # never reached before the floor
    record = simulate(scenario, horizon=60.0, sample_dt=None, until_error=fraction, stop_at_floor=True)
    stop = record.extra['stop']
    assert stop['reason'] == 'rounding_floor' and stop['reason'] in STOP_REASONS
    assert stop['time'] == floor.extra['stop']['time'] and record.trigger_times == floor.trigger_times
    assert stop['error'] == pytest.approx(errors[-1], rel=1e-12)
    assert stop['error'] >= fraction * stop['initial_error']


@pytest.mark.parametrize('value', [0, 0.0, 1.0, 1.5, -0.1, math.nan, math.inf, True, '0.1'])
def test_a_bad_fraction_is_refused_with_the_rule_and_the_value(value):
    with pytest.raises(EngineError, match=r'until_error must be a (number|fraction) in \(0, 1\)') as bad:
        simulate(load_scenario('paper_single'), horizon=1.0, until_error=value)
    assert repr(value) in str(bad.value)
