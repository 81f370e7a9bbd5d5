"""Random scenarios: valid by construction, seeded, fast enough for 10 000 agents."""

from __future__ import annotations

import numpy as np
import pytest

from formation_sim.model import gains, theory
from formation_sim.model.errors import GenerateError
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import scenario_from_dict, scenario_to_dict
from formation_sim.model.validate import validate_scenario

CASES = [
    dict(
        n=2 + (seed * 7) % 60,
        seed=seed,
        dynamics=('single', 'double')[seed % 2],
        dimension=1 + seed % 3,
        slack=(0.5, 0.2, 0.9, 0.04)[seed % 4],
    )
    for seed in range(50)
]


@pytest.mark.parametrize('case', CASES, ids=[f'seed{c["seed"]}' for c in CASES])
def test_random_scenarios_satisfy_every_hypothesis(case):
    s = random_scenario(**case)
    assert s.n == case['n'] and s.dynamics == case['dynamics'] and s.dimension == case['dimension']
    report = validate_scenario(s)
    assert report.ok, [f.format() for f in report.errors]
    assert theory.is_connected(s)
    # Feasible by construction, ||d_ij|| <= 0.75 Δ.
    assert theory.formation_feasibility(s).residual < 1e-9
    capacities = theory.edge_capacities(s)
    assert np.all(capacities >= 0.25 * s.delta - 1e-12)
    # (initial) with the requested slack on every edge, attained on the tightest one.
    errors = theory.edge_errors(s, s.positions)
    assert np.all(errors <= (1.0 - case['slack']) * capacities * (1 + 1e-12) + 1e-12)
    assert np.max(errors / capacities) == pytest.approx(1.0 - case['slack'], rel=1e-9)
    beta0 = theory.beta0(s)
    if s.dynamics == 'single':
        assert s.gains.beta == pytest.approx(0.5 * beta0)
    else:
        g = s.gains
        assert g.beta1 == pytest.approx(beta0)
        assert g.k3 == pytest.approx(0.5 * gains.k3_upper_bound(g.k1, g.k2))
        assert 0.0 < g.beta_d < min(gains.beta_d_bound_paper(g), gains.beta_d_bound_corrected(g))
        assert np.all(np.linalg.norm(s.velocities, axis=1) <= 1.0)
    # Below 5 % relative slack (initial) warns; β (β1) above Remark 3.2's 4/(n(n-1)Δ) warns;
    # nothing else is near an edge.
    rate = s.gains.beta if s.dynamics == 'single' else s.gains.beta1
    expected = {'initial'} if case['slack'] < 0.05 else set()
    if rate > 4.0 / (s.n * (s.n - 1) * s.delta):
        expected.add('remark')
    assert {w.rule for w in report.warnings} == expected
    # The constants of the proofs exist (the corrected chain of Theorem 2 included).
    constants = theory.theorem_constants(s)
    assert all(value > 0 for value in constants.xi.values())


def test_same_seed_same_scenario_other_seed_other_scenario():
    a = random_scenario(n=40, seed=7, dynamics='double')
    assert a == random_scenario(n=40, seed=7, dynamics='double')
    assert a != random_scenario(n=40, seed=8, dynamics='double')
    assert scenario_from_dict(scenario_to_dict(a)) == a


def test_slack_one_starts_in_formation():
    s = random_scenario(n=20, seed=3, slack=1.0)
    assert np.max(theory.edge_errors(s, s.positions)) < 1e-12


def test_ten_thousand_agents():
    s = random_scenario(n=10_000, seed=1)
    assert s.n == 10_000 and theory.is_connected(s)
    degree = 2 * len(s.edges) / s.n
    assert 3.0 < degree < 12.0  # a sparse geometric graph around the requested mean degree 6
    assert 0.0 < s.gains.beta < theory.beta0(s)


@pytest.mark.parametrize(
    'kwargs, fragment',
    [
        (dict(n=1, seed=0), 'n must be an integer >= 2'),
        (dict(n=5, seed=0, slack=0.0), 'slack'),
        (dict(n=5, seed=0, slack=1.5), 'slack'),
        (dict(n=5, seed=0, dynamics='triple'), 'dynamics'),
        (dict(n=5, seed=0, dimension=0), 'dimension'),
        (dict(n=5, seed=0, delta=-1.0), 'delta'),
        (dict(n=5, seed=0, alpha=0.0), 'alpha'),
    ],
)
def test_bad_parameters(kwargs, fragment):
    with pytest.raises(GenerateError, match=fragment):
        random_scenario(**kwargs)


@pytest.mark.parametrize('graph', ['star', 'path', 'cycle', 'complete'])
@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_graph_families_are_valid_teams_of_their_shape(graph, dynamics):
    n = 9
    s = random_scenario(n=n, seed=3, dynamics=dynamics, dimension=2, slack=0.3, graph=graph)
    pairs = {e.pair for e in s.edges}
    expected = {
        'star': {(1, j) for j in range(2, n + 1)},
        'path': {(i, i + 1) for i in range(1, n)},
        'cycle': {(i, i + 1) for i in range(1, n)} | {(1, n)},
        'complete': {(i, j) for i in range(1, n + 1) for j in range(i + 1, n + 1)},
    }[graph]
    assert pairs == expected
    report = validate_scenario(s)
    assert report.ok, [f.format() for f in report.errors]
    assert np.all(np.linalg.norm([e.d for e in s.edges], axis=1) <= 0.75 * s.delta * (1 + 1e-12))
    errors, capacities = theory.edge_errors(s, s.positions), theory.edge_capacities(s)
    assert np.max(errors / capacities) == pytest.approx(0.7, rel=1e-9)


def test_gain_fractions_and_their_defaults():
    default = random_scenario(n=12, seed=4, dynamics='double')
    assert (
        random_scenario(n=12, seed=4, dynamics='double', graph='geometric', beta1=1.0) == default
    )  # the rule, bit for bit
    s = random_scenario(n=12, seed=4, dynamics='double', beta1=0.5, k3=0.25, beta_d=0.9)
    beta0 = theory.beta0(s)
    assert s.gains.beta1 == pytest.approx(0.5 * beta0) and s.gains.k3 == pytest.approx(
        0.25 * gains.k3_upper_bound(s.gains.k1, s.gains.k2)
    )
    assert s.gains.beta_d == pytest.approx(0.9 * gains.beta_d_bound_paper(s.gains))
    single = random_scenario(n=12, seed=4, beta=0.99)
    assert single.gains.beta == pytest.approx(0.99 * theory.beta0(single))
    with pytest.raises(GenerateError, match=r'a cycle needs n >= 3 agents, got n = 2'):
        random_scenario(n=2, seed=0, graph='cycle')
    with pytest.raises(
        GenerateError, match=r"graph must be one of geometric, star, path, cycle, complete, got 'tree'"
    ):
        random_scenario(n=4, seed=0, graph='tree')
    with pytest.raises(GenerateError, match=r'beta is a fraction of its bound in \(0, 1\), got 1.0'):
        random_scenario(n=4, seed=0, beta=1.0)
