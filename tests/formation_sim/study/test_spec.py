"""A study's SPEC: grids and draws expanded deterministically, every rule named with its value."""

from __future__ import annotations

import pytest

from formation_sim.study.errors import StudyError
from formation_sim.study.spec import PARAMETERS, build_study, load_study


def _spec(*blocks, **top):
    return {'name': 't', 'seed': 3, 'cases': list(blocks), **top}


def test_a_grid_is_the_product_of_its_axes_and_draws_multiply_it():
    study = build_study(
        _spec(
            {'n': [3, 4], 'graph': ['star', 'path', 'cycle']},
            {'draws': 4, 'n': 5, 'slack': {'log_uniform': [0.01, 0.5]}, 'p': [1, 2]},
        )
    )
    assert len(study.cases) == 6 + 8
    first = [c.params for c in study.cases[:6]]
    assert {(p['n'], p['graph']) for p in first} == {
        (n, g) for n in (3, 4) for g in ('star', 'path', 'cycle')
    }
    drawn = [c.params['slack'] for c in study.cases[6:]]
    assert all(0.01 <= s <= 0.5 for s in drawn)
    assert drawn[0] == drawn[1] and drawn[0] != drawn[2]  # one draw, then the grid over p
    assert len({c.key for c in study.cases}) == len(study.cases)
    assert [c.index for c in study.cases] == list(range(14))


def test_the_same_spec_gives_the_same_cases_and_another_seed_other_draws():
    blocks = ({'draws': 5, 'n': {'integers': [2, 50]}, 'graph': {'choice': ['star', 'path']}},)
    a, b = build_study(_spec(*blocks)), build_study(_spec(*blocks))
    assert [c.params for c in a.cases] == [c.params for c in b.cases] and a.digest == b.digest
    other = build_study(_spec(*blocks, seed=4))
    assert [c.params for c in other.cases] != [c.params for c in a.cases] and other.digest != a.digest


def test_what_does_not_apply_is_dropped_and_equal_cases_run_once():
    study = build_study(
        _spec(
            {
                'n': 4,
                'sampling': ['event', 'periodic'],
                'period': [0.1, 0.2],
                'graph': 'star',
                'degree': [3, 6],
            }
        )
    )
    # event x 2 periods x 2 degrees is one case (no period, no degree for a star); periodic: 2.
    assert len(study.cases) == 3
    event = study.cases[0].params
    assert (
        event['period'] is None
        and event['degree'] is None
        and event['beta1'] is None
        and event['beta'] == 0.5
    )
    double = build_study(_spec({'n': 4, 'algorithm': 'eta2'})).cases[0].params
    assert double['beta'] is None and double['beta1'] == 1.0 and double['max_speed'] == 1.0
    assert set(event) == set(PARAMETERS)


def test_defaults_apply_to_every_block_and_a_block_wins():
    study = build_study(_spec({'n': 3}, {'n': 3, 'horizon': 7}, defaults={'horizon': 2}))
    assert [c.params['horizon'] for c in study.cases] == [2.0, 7.0]


@pytest.mark.parametrize(
    ('spec', 'complaint'),
    [
        (_spec({'n': 3, 'slak': 0.5}), "cases[0]: unknown key 'slak'"),
        (_spec({'n': 3}, {'n': 1}), 'cases[1].n: must be an integer >= 2 (agents), got 1'),
        (_spec({'n': 3, 'slack': 1.5}), 'cases[0].slack: must be a number in (0, 1]'),
        (_spec({'n': 3, 'beta': 1.0}), 'cases[0].beta: must be a number in (0, 1): β as a fraction of β0'),
        (
            _spec({'n': 3, 'graph': 'tree'}),
            'cases[0].graph: must be one of geometric, star, path, cycle, complete',
        ),
        (_spec({'n': 2, 'graph': 'cycle'}), 'a cycle needs n >= 3 agents, got n = 2'),
        (_spec({'n': 3, 'sampling': 'periodic'}), 'cases[0].period: sampling: periodic needs a period'),
        (_spec({'n': {'integers': [2, 5]}}), 'cases[0]: draws: K is needed with distributions (n)'),
        (_spec({'draws': 2, 'n': {'normal': [2, 5]}}), 'cases[0].n: a distribution is one of'),
        (
            _spec({'draws': 2, 'slack': {'log_uniform': [0, 0.5]}, 'n': 3}),
            'cases[0].slack.log_uniform: low must be > 0',
        ),
        (_spec({'draws': 0, 'n': 3}), 'cases[0].draws: must be an integer >= 1, got 0'),
        (_spec({'n': []}), 'cases[0].n: a grid axis needs at least one value'),
        (_spec({'n': 3}, sed=1), "unknown key 'sed'"),
        ({'name': 't', 'cases': []}, 'cases: must be a non-empty list of blocks'),
        (_spec({'n': 3}, defaults={'hroizon': 1}), "defaults: unknown key 'hroizon'"),
    ],
)
def test_bad_specs_are_refused_with_the_rule_and_the_value(spec, complaint):
    with pytest.raises(StudyError) as caught:
        build_study(spec)
    assert complaint in str(caught.value)


def test_shipped_studies_expand(tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[3] / 'studies'
    smoke, audit = load_study(root / 'smoke.yaml'), load_study(root / 'audit.yaml')
    assert 15 <= len(smoke.cases) <= 30
    assert len(audit.cases) >= 2000
    params = [c.params for c in audit.cases]
    assert {p['graph'] for p in params} == {'geometric', 'star', 'path', 'cycle', 'complete'}
    assert {p['algorithm'] for p in params} == {'eta1', 'eta2'}
    assert min(p['n'] for p in params) == 2 and max(p['n'] for p in params) >= 24
    assert {p['p'] for p in params} == {1, 2, 3}
    # To convergence (issue 31): every run to 1 % of its initial error (or the rounding floor), and
    # at least 500 ETA-2 teams with β_d a fraction of the corrected bound, so below it.
    assert {p['until_error'] for p in params} == {0.01}
    corrected = [p for p in params if p['beta_d_bound'] == 'corrected']
    assert len(corrected) >= 500 and all(0 < p['beta_d'] < 1 for p in corrected)
    # ... and ETA-1's threshold rate from half of β0 up, so every team can reach 1 % in the horizon
    assert all(p['beta'] >= 0.5 for p in params if p['algorithm'] == 'eta1' and p['n'] > 2)
    # ETA-2 below the corrected bound wherever the printed rate is not the point (two agents, the
    # paper's α_d = 10, complete graphs): there the team can follow its threshold to 1 %
    eta2 = [p for p in params if p['algorithm'] == 'eta2']
    assert len(eta2) >= 1000 and len(corrected) >= 1000
    (tmp_path / 'bad.yaml').write_text('name: x\ncases: [{n: 3, p: 0}]\n')
    with pytest.raises(StudyError, match=r'bad.yaml: cases\[0\].p: must be an integer in \[1, 10\]'):
        load_study(tmp_path / 'bad.yaml')


def test_the_speed_scale_and_the_threshold_floor_are_parameters_that_keep_old_keys():
    plain = build_study(_spec({'n': 4}))
    scaled = build_study(_spec({'n': 4, 'speed_scale': [1.0, 0.5], 'threshold_floor': [0.0, 0.01]}))
    assert len(scaled.cases) == 4
    assert scaled.cases[0].key == plain.cases[0].key  # κ = 1, c0 = 0: the key of a SPEC without them
    assert len({c.key for c in scaled.cases}) == 4
    with pytest.raises(StudyError, match=r'cases\[0\].speed_scale: must be a number > 0 \(the speed scale κ'):
        build_study(_spec({'n': 4, 'speed_scale': 0}))
    with pytest.raises(StudyError, match=r'cases\[0\].threshold_floor: must be a number >= 0'):
        build_study(_spec({'n': 4, 'threshold_floor': -1.0}))


def test_until_error_and_the_beta_d_bound_are_parameters_that_keep_old_keys():
    plain = build_study(_spec({'n': 4}, {'n': 4, 'algorithm': 'eta2', 'beta_d': 0.5}))
    more = build_study(
        _spec(
            {'n': 4, 'until_error': [None, 0.01]},
            {'n': 4, 'algorithm': 'eta2', 'beta_d': 0.5, 'beta_d_bound': ['printed', 'corrected']},
        )
    )
    assert len(more.cases) == 4
    assert more.cases[0].key == plain.cases[0].key and more.cases[2].key == plain.cases[1].key
    assert len({c.key for c in more.cases}) == 4
    assert more.cases[1].params['until_error'] == 0.01 and more.cases[3].params['beta_d_bound'] == 'corrected'
    assert more.cases[0].params['beta_d_bound'] is None  # ETA-1: no β_d, no bound
    with pytest.raises(StudyError, match=r'cases\[0\].until_error: must be a number in \(0, 1\).*got 1.0'):
        build_study(_spec({'n': 4, 'until_error': 1.0}))
    bound = r"cases\[0\].beta_d_bound: must be one of printed, corrected.*'λmax'"
    with pytest.raises(StudyError, match=bound):
        build_study(_spec({'n': 4, 'algorithm': 'eta2', 'beta_d_bound': 'λmax'}))
