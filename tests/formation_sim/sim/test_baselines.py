"""The continuous-controller baseline: it solves the closed loop, and the closed loop's own laws hold."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.model import theory
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.baselines import simulate_continuous
from formation_sim.sim.errors import BaselineError


def _controls(scenario, x, q=None):
    """u_i of (uxsingle) / (uxdouble) with every quantity at t, written out again edge by edge."""
    row = {a: k for k, a in enumerate(scenario.agent_ids)}
    u = np.zeros_like(x)
    for edge in scenario.edges:
        a, b = row[edge.i], row[edge.j]
        y = x[a] - x[b] - edge.d
        c = scenario.delta - np.linalg.norm(edge.d)
        r = np.linalg.norm(y)
        w = (2 * c - r) / (c - r) ** 2
        term = w * y if q is None else w * (scenario.gains.k1 * y + scenario.gains.k2 * (q[a] - q[b]))
        u[a] -= term
        u[b] += term
    if q is not None:
        u -= scenario.gains.k3 * q
    return u


@pytest.fixture(scope='module', params=['paper_single', 'paper_double'])
def paper_run(request):
    scenario = load_scenario(request.param)
    return scenario, simulate_continuous(scenario, horizon=4.0, sample_dt=1e-3)


def test_samples_solve_the_closed_loop(paper_run):
    # Five-point centred differences of the samples (error ~ dt^4) against the controller:
    # x' = u (single); x' = q and q' = u (double).
    scenario, record = paper_run
    t, x, q = record.sample_times, record.sample_positions, record.sample_velocities
    assert record.mode == 'continuous'
    assert t[0] == 0.0 and t[-1] == 4.0 and np.allclose(np.diff(t)[:-1], 1e-3)

    def rate(samples, k):
        h = t[k + 1] - t[k]
        return (-samples[k + 2] + 8 * samples[k + 1] - 8 * samples[k - 1] + samples[k - 2]) / (12 * h)

    # From past the steep start of paper_single to where the inputs are still above 1e-3; the
    # dense output's interpolation noise (~1e-9) sets the absolute tolerance.
    for k in range(200, 2000, 97):
        if q is None:
            expected = _controls(scenario, x[k])
            assert np.allclose(rate(x, k), expected, rtol=1e-6, atol=5e-8)
        else:
            assert np.allclose(rate(x, k), q[k], rtol=1e-6, atol=5e-8)
            assert np.allclose(rate(q, k), _controls(scenario, x[k], q[k]), rtol=1e-6, atol=5e-8)


def test_tension_never_grows_and_connectivity_holds(paper_run):
    # Single: the controller is the gradient flow of ν; double: k1 ν + ½ Σ ||q||² is non-increasing.
    scenario, record = paper_run
    if record.sample_velocities is None:
        values = [theory.tension(scenario, x) for x in record.sample_positions]
    else:
        values = [
            theory.tension_double(scenario, x, q)
            for x, q in zip(record.sample_positions, record.sample_velocities)
        ]
    assert all(math.isfinite(v) for v in values)
    assert np.all(np.diff(values) <= 1e-9 * values[0])
    for x in record.sample_positions:
        assert np.all(theory.edge_errors(scenario, x) < theory.edge_capacities(scenario))


def test_centroid_laws(paper_run):
    # Σ u_i = 0 over an undirected graph: the centroid of single integrators stands still, and
    # the mean velocity of double integrators decays as e^{-k3 t}.
    scenario, record = paper_run
    x, q, t = record.sample_positions, record.sample_velocities, record.sample_times
    if q is None:
        assert np.allclose(x.mean(axis=1), x[0].mean(axis=0), rtol=0, atol=1e-9)
    else:
        expected = q[0].mean(axis=0)[None, :] * np.exp(-scenario.gains.k3 * t)[:, None]
        assert np.allclose(q.mean(axis=1), expected, rtol=1e-8, atol=1e-10)


def test_random_team_converges_to_its_formation():
    scenario = random_scenario(n=20, seed=4, slack=0.3)
    record = simulate_continuous(scenario, horizon=30.0, sample_dt=0.5)
    first = theory.formation_error(scenario, record.sample_positions[0])
    last = theory.formation_error(scenario, record.sample_positions[-1])
    assert last < 1e-3 * first
    assert record.sensing_calls == scenario.n * record.extra['rhs_evaluations']
    assert record.messages_sent == 0 and record.total_events == 0


@pytest.mark.parametrize(
    ('kwargs', 'message'), [(dict(horizon=0.0), 'horizon'), (dict(horizon=1.0, sample_dt=-0.1), 'sample_dt')]
)
def test_bad_arguments_are_named(kwargs, message):
    with pytest.raises(BaselineError, match=message):
        simulate_continuous(load_scenario('paper_single'), **kwargs)


def test_simulate_command_runs_the_continuous_baseline(tmp_path, capsys):
    import json

    from formation_sim.cli import main

    out = tmp_path / 'run'
    assert (
        main(
            [
                'simulate',
                'paper_single',
                '--continuous',
                '--horizon',
                '2',
                '--out',
                str(out),
                '--no-plot',
                '--quiet',
            ]
        )
        == 0
    )
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['mode'] == 'continuous'
    assert summary['total_events'] == 0 and summary['messages_sent'] == 0
    assert summary['sensing_calls'] == 3 * summary['extra']['rhs_evaluations']
    assert summary['max_edge_length'] < summary['delta']
    assert main(['simulate', 'paper_single', '--continuous', '--period', '0.1']) == 2  # bad input
    assert 'not allowed with' in capsys.readouterr().err
