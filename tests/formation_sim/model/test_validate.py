"""Validation: each broken hypothesis gives its named error, near-edge cases warn, numbers are shown."""

from __future__ import annotations

import json

import numpy as np
import pytest

from formation_sim.model.scenario import DoubleGains, Edge, SingleGains, load_scenario, scenario_from_dict
from formation_sim.model.validate import ValidationError, require_valid, validate_scenario

# k3 = 0.6 (k4 ≈ 0.99), β_d = 0.1: below both the printed and the corrected bound.
BELOW_BOTH_BOUNDS = {'beta_d': 0.1}


def rules(findings):
    return {(f.rule, f.subject) for f in findings}


def test_paper_single_is_valid_with_two_warnings():
    report = validate_scenario(load_scenario('paper_single'))
    assert report.ok
    # Edge (2,3): ||x_2-x_3-d_23|| = ||(1, -0.5)|| = 1.1180 < 4 - 2√2 = 1.1716, slack 4.6 %.
    # β = 1 > 4/(3·2·4) = 1/6: the Remark's bound cannot certify β.
    assert rules(report.warnings) == {('initial', 'edge (2, 3)'), ('remark', 'gains')}
    text = report.format()
    assert 'β0 = ρ2/Δ0 = 1.5' in text and 'ρ2(DD^T) = 3' in text
    for edge in ('edge (1, 2)', 'edge (1, 3)', 'edge (2, 3)'):
        assert edge in text  # the slack of every edge is listed
    assert '0.0535389' in text  # 4 - 2√2 - √1.25


def test_paper_double_warns_about_the_corrected_beta_d_bound():
    report = validate_scenario(load_scenario('paper_double'))
    assert report.ok
    assert ('beta_d_corrected', 'gains') in rules(report.warnings)
    warning = next(w for w in report.warnings if w.rule == 'beta_d_corrected')
    assert warning.values['beta_d'] == 1.0
    assert warning.values['bound_corrected'] == pytest.approx(1 / 5.3644, rel=1e-4)
    assert warning.values['bound_paper'] == pytest.approx(1.1096, abs=1e-4)
    assert 'P = [[5.0237, 1.1547], [1.1547, 1.45022]]' in report.format()


def test_double_below_both_bounds_has_no_beta_d_warning(paper_scenario_dict):
    report = validate_scenario(scenario_from_dict(paper_scenario_dict('double', **BELOW_BOTH_BOUNDS)))
    assert report.ok
    assert not {w.rule for w in report.warnings} & {'beta_d', 'beta_d_corrected', 'k3'}


def _edit(paper_scenario_dict, dynamics, change):
    """The paper's example (double integrators below both β_d bounds), changed by `change`."""
    data = paper_scenario_dict(dynamics, **(BELOW_BOTH_BOUNDS if dynamics == 'double' else {}))
    change(data)
    return scenario_from_dict(data)


def _gain(key, value):
    return lambda data: data['gains'].__setitem__(key, value)


def _position(agent, value):
    return lambda data: data['agents'][agent].__setitem__('position', value)


def _edge_d(k, value):
    return lambda data: data['edges'][k].__setitem__('d', value)


BROKEN = [
    # (label, dynamics, change, rule, subject, fragments of the message)
    (
        'disconnected',
        'single',
        lambda d: (
            d['edges'].__delitem__(slice(1, 3))
            or d['edges'].__setitem__(0, {'i': 1, 'j': 2, 'd': [0.0, -2.0]})
        ),
        'connected',
        'graph',
        ['2 connected components', 'agent 3'],
    ),
    ('infeasible', 'single', _edge_d(2, [-2.0, 2.5]), 'feasible', 'formation', ['residual', 'Assumption 1']),
    (
        'too long d',
        'single',
        lambda d: (
            d['edges'][0].__setitem__('d', [0.0, -4.5]),
            d['edges'][1].__setitem__('d', [-2.0, 0.0]),
            d['edges'][2].__setitem__('d', [-2.0, 4.5]),
            d['agents'][2].__setitem__('position', [2.0, 8.5]),
        ),
        'edge_length',
        'edge (1, 2)',
        ['||d_ij|| = 4.5', 'Δ = 4'],
    ),
    (
        'initial broken',
        'single',
        _position(3, [4.3, 5.5]),
        'initial',
        'edge (2, 3)',
        ['(initial)', 'Δ-||d_ij|| = 1.17157'],
    ),
    ('alpha zero', 'single', _gain('alpha', 0.0), 'alpha', 'gains', ['α = 0']),
    ('beta above beta0', 'single', _gain('beta', 1.6), 'beta', 'gains', ['β0 = 1.5', 'β = 1.6']),
    ('beta negative', 'single', _gain('beta', -0.1), 'beta', 'gains', ['β = -0.1']),
    ('alpha_d negative', 'double', _gain('alpha_d', -1.0), 'alpha_d', 'gains', ['α_d = -1']),
    ('beta1 above beta0', 'double', _gain('beta1', 1.6), 'beta1', 'gains', ['β0 = 1.5', 'β1 = 1.6']),
    ('k3 too large', 'double', _gain('k3', 1.3), 'k3', 'gains', ['k3 = 1.3', '1.21066']),
    ('k3 zero', 'double', _gain('k3', 0.0), 'k3', 'gains', ['k3 = 0']),
    ('beta_d above printed bound', 'double', _gain('beta_d', 1.2), 'beta_d', 'gains', ['β_d = 1.2', 'ρ2(P)']),
    (
        'riccati broken',
        'double',
        lambda d: d['gains'].update(k1=0.5, k2=0.5),
        'riccati',
        'gains',
        ['riccatti', 'β1 = 1.5'],
    ),
    ('k2 negative', 'double', lambda d: d['gains'].update(k1=1.2, k2=-1.5), 'k1_k2', 'gains', ['k2 = -1.5']),
]


@pytest.mark.parametrize(
    'label, dynamics, change, rule, subject, fragments', BROKEN, ids=[b[0] for b in BROKEN]
)
def test_broken_hypotheses_give_named_errors(
    label, dynamics, change, rule, subject, fragments, paper_scenario_dict
):
    report = validate_scenario(_edit(paper_scenario_dict, dynamics, change))
    assert not report.ok
    matching = [f for f in report.errors if f.rule == rule and f.subject == subject]
    assert matching, (label, [f.format() for f in report.errors])
    for fragment in fragments:
        assert any(fragment in f.message for f in matching), (label, fragment, matching[0].message)
    with pytest.raises(ValidationError) as caught:
        require_valid(_edit(paper_scenario_dict, dynamics, change))
    assert caught.value.report.errors == report.errors
    assert f'[{report.errors[0].rule}]' in str(caught.value)
    json.dumps(report.to_dict(), allow_nan=False)


NEAR_EDGE = [
    ('beta near beta0', 'single', _gain('beta', 1.45), 'beta'),
    # β < β0 with β = β0 as computed: equal up to the bound's rounding, accepted with a warning.
    ('beta at beta0', 'single', _gain('beta', 1.5), 'rounding'),
    ('k3 near its bound', 'double', lambda d: d['gains'].update(k3=1.2, beta_d=0.001), 'k3'),
    ('beta_d near printed bound', 'double', lambda d: d['gains'].update(k3=0.6053, beta_d=1.08), 'beta_d'),
    ('beta_d above corrected bound', 'double', _gain('beta_d', 0.5), 'beta_d_corrected'),
]


@pytest.mark.parametrize('label, dynamics, change, rule', NEAR_EDGE, ids=[n[0] for n in NEAR_EDGE])
def test_near_edge_conditions_warn_but_pass(label, dynamics, change, rule, paper_scenario_dict):
    report = validate_scenario(_edit(paper_scenario_dict, dynamics, change))
    assert report.ok, [f.format() for f in report.errors]
    assert rule in {w.rule for w in report.warnings}
    assert require_valid(_edit(paper_scenario_dict, dynamics, change)).ok


def test_generous_slack_gives_no_initial_warning():
    s = load_scenario('paper_single')
    report = validate_scenario(s.replace(positions=np.array([[2.0, 4.0], [2.0, 6.0], [4.0, 4.0]])))
    assert report.ok
    assert 'initial' not in {w.rule for w in report.warnings}  # already in formation: 100 % slack


REMARK_BOUND_N3 = 4.0 / (3 * 2 * 4.0)  # Remark 3.2: 4/(n(n-1)Δ) for the paper's n = 3, Δ = 4


def _remark_warnings(report):
    return [w for w in report.warnings if w.rule == 'remark']


def test_remark_warns_above_its_bound_and_only_there():
    s = load_scenario('paper_single')
    above = _remark_warnings(validate_scenario(s))  # β = 1 > 1/6
    assert len(above) == 1
    assert above[0].values == {'value': 1.0, 'remark_bound': pytest.approx(REMARK_BOUND_N3, rel=1e-15)}
    assert 'β = 1 exceeds 4/(n(n-1)Δ) = 0.166667' in above[0].message
    assert _remark_warnings(validate_scenario(s.replace(gains=SingleGains(alpha=10.0, beta=0.1)))) == []


def test_double_remark_applies_to_beta1():
    s = load_scenario('paper_double')
    above = _remark_warnings(validate_scenario(s))  # β1 = 1.5 > 1/6
    assert len(above) == 1
    assert above[0].values == {'value': 1.5, 'remark_bound': pytest.approx(REMARK_BOUND_N3, rel=1e-15)}
    assert 'β1 = 1.5 exceeds 4/(n(n-1)Δ) = 0.166667' in above[0].message
    gains = DoubleGains.from_riccati(alpha_d=10.0, beta_d=0.05, beta1=0.1, k3='paper')
    report = validate_scenario(s.replace(gains=gains))
    assert report.ok and _remark_warnings(report) == []


def test_report_dict_lists_every_edge_slack():
    report = validate_scenario(load_scenario('paper_single'))
    data = json.loads(json.dumps(report.to_dict(), allow_nan=False))
    note = next(n for n in data['notes'] if n['rule'] == 'initial')
    slacks = {(e['i'], e['j']): e['slack'] for e in note['values']['edges']}
    assert slacks[(1, 2)] == pytest.approx(2.0 - np.hypot(1.5, 1.0))
    assert slacks[(1, 3)] == pytest.approx(2.0 - np.hypot(0.5, 1.5))
    assert slacks[(2, 3)] == pytest.approx(4.0 - 2.0 * np.sqrt(2.0) - np.hypot(1.0, 0.5))


def test_zero_capacity_edge_reports_without_nan():
    s = load_scenario('paper_single')
    edges = (Edge(i=1, j=2, d=np.array([0.0, -4.0])),) + s.edges[1:]
    report = validate_scenario(s.replace(edges=edges))
    assert ('edge_length', 'edge (1, 2)') in rules(report.errors)
    json.dumps(report.to_dict(), allow_nan=False)


# -- strict inequalities are shown with the digits that break them -------------------------------


@pytest.mark.parametrize(
    ('edits', 'expected'),
    [
        # β a hair above β0 = 1.5 and its rounding margin (5 ulps): 6 digits would read
        # "β0 = 1.5 required, got β = 1.5".
        ({'beta': 1.500000000000001}, '0 < β < β0 = 1.5 required, got β = 1.500000000000001'),
        # ||d_ij|| a hair above Δ = 4: "||d_ij|| = 4 is not below Δ = 4" before.
        (
            {'d12': [0.0, -4.000000000000001]},
            '||d_ij|| = 4.000000000000001 is not below Δ = 4 (Assumption 1)',
        ),
        # ||d_ij|| = Δ exactly: equal values print alike, and rightly so.
        ({'d12': [0.0, -4.0]}, '||d_ij|| = 4 is not below Δ = 4 (Assumption 1)'),
    ],
    ids=['beta', 'edge length above', 'edge length equal'],
)
def test_a_broken_strict_inequality_prints_enough_digits(paper_scenario_dict, edits, expected):
    data = paper_scenario_dict()
    if 'beta' in edits:
        data['gains']['beta'] = edits['beta']
    if 'd12' in edits:
        data['edges'][0]['d'] = edits['d12']
    messages = [finding.message for finding in validate_scenario(scenario_from_dict(data)).errors]
    assert expected in messages, messages


# -- what the agents receive as ROS parameters -------------------------------------------------------

SUBNORMAL = 5e-324


@pytest.mark.parametrize(
    ('dynamics', 'where', 'subject', 'key'),
    [
        ('single', ('gains', 'alpha'), 'gains', 'gains.alpha'),
        ('single', ('gains', 'beta'), 'gains', 'gains.beta'),
        ('single', ('horizon',), 'scenario', 'horizon'),
        ('single', ('edges', 1, 'd', 0), 'edge (1, 3)', 'd[0]'),
        ('double', ('gains', 'alpha_d'), 'gains', 'gains.alpha_d'),
        ('double', ('gains', 'beta_d'), 'gains', 'gains.beta_d'),
        ('double', ('gains', 'k3'), 'gains', 'gains.k3'),
    ],
)
def test_a_subnormal_parameter_is_refused_naming_its_key(paper_scenario_dict, dynamics, where, subject, key):
    data = paper_scenario_dict(dynamics)
    target = data
    for step in where[:-1]:
        target = target[step]
    target[where[-1]] = SUBNORMAL
    report = validate_scenario(scenario_from_dict(data))
    found = [f for f in report.errors if f.rule == 'parameters']
    assert [(f.subject, f.values['key']) for f in found] == [(subject, key)]
    assert f'{key} = 5e-324 is a subnormal double' in found[0].message


def test_zero_and_the_smallest_normal_double_are_carried(paper_scenario_dict):
    data = paper_scenario_dict()
    data['edges'][1]['d'] = [-2.0, 2.2250738585072014e-308]
    data['edges'][0]['d'] = [-0.0, -2.0]
    assert not [f for f in validate_scenario(scenario_from_dict(data)).errors if f.rule == 'parameters']


# Doubles that a decimal round trip through YAML could lose, all normal: the parameter file must
# carry each bit for bit.
AWKWARD_NORMAL = [
    0.1,
    1.0 / 3.0,
    -0.0,
    2.2250738585072014e-308,
    1.7976931348623157e308,
    np.nextafter(1.0, 2.0),
    1e22,
    -7.5e-300,
    123456789.12345679,
]


@pytest.mark.ros
@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_agent_parameters_survive_the_parameter_file_bit_for_bit(tmp_path, paper_scenario_dict, dynamics):
    """The file FormationRun writes, read by rcl's own parser as an agent node reads it; and a
    subnormal value, which validate refuses, indeed does not survive it."""
    import struct

    from formation_sim.runtime.launch.orchestrate import FormationRun

    data = paper_scenario_dict(dynamics)
    data['edges'][0]['d'] = [float(AWKWARD_NORMAL[0]), float(AWKWARD_NORMAL[1])]
    data['edges'][1]['d'] = [float(v) for v in AWKWARD_NORMAL[2:4]]
    data['edges'][2]['d'] = [float(v) for v in AWKWARD_NORMAL[4:6]]
    gains = ('alpha', 'beta') if dynamics == 'single' else ('alpha_d', 'beta_d')
    data['gains'][gains[0]], data['gains'][gains[1]] = float(AWKWARD_NORMAL[7] * -1), float(AWKWARD_NORMAL[8])
    data['communication_radius'] = float(AWKWARD_NORMAL[6])
    data['horizon'] = 0.1 + 0.2
    scenario = scenario_from_dict(data)
    assert not [f for f in validate_scenario(scenario).errors if f.rule == 'parameters']
    run = FormationRun(scenario, out_dir=tmp_path / 'run', validate=False, progress=False)
    run.out_dir.mkdir()
    path = run.plan.write_inputs()['agents']
    read = _read_with_rcl(path, scenario.agent_ids)

    from formation_sim.runtime.contract import agent_parameters

    def bits(value):
        return struct.pack('<d', value) if isinstance(value, float) else value

    for agent in scenario.agent_ids:
        expected = agent_parameters(scenario, agent, horizon=scenario.horizon, extra_subscribers=1)
        for name, value in expected.items():
            got = read[agent][name]
            if isinstance(value, list):
                assert [bits(v) for v in got] == [bits(v) for v in value], (agent, name)
            else:
                assert bits(got) == bits(value), (agent, name, got, value)

    # The rule is needed: a subnormal gain is read back as text.
    data['gains'][gains[0]] = SUBNORMAL
    broken = FormationRun(
        scenario_from_dict(data), out_dir=tmp_path / 'broken', validate=False, progress=False
    )
    broken.out_dir.mkdir()
    assert isinstance(
        _read_with_rcl(broken.plan.write_inputs()['agents'], scenario.agent_ids)[1][gains[0]], str
    )


def _read_with_rcl(path, agent_ids):
    """{agent: {name: value}} as rcl parses `path` for the node /agent_<i>/formation_agent."""
    import os

    import rclpy
    from rclpy.node import Node

    from formation_agent.ros.node import NODE_NAME

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = rclpy.Context()
    rclpy.init(context=context, args=['test', '--ros-args', '--params-file', str(path)], domain_id=65)
    try:
        read = {}
        for agent in agent_ids:
            node = Node(
                NODE_NAME,
                namespace=f'/agent_{agent}',
                context=context,
                automatically_declare_parameters_from_overrides=True,
                start_parameter_services=False,
                enable_rosout=False,
            )
            read[agent] = {name: parameter.value for name, parameter in node._parameters.items()}
            node.destroy_node()
        return read
    finally:
        rclpy.shutdown(context=context)


# Double precision and the initial slack (rule `precision`): one ulp of y_ij moves the triggering
# error by g_ij ulp (gij), g_ij = 2c²/σ³ for capacity c and slack σ; the certified search gets
# through the plateaus that leaves if that step is at most 1e-12 × 200 000 / 4 = 5e-8 of α.
SEARCH_LIMIT = 1e-12 * 200_000 / 4


def _precision_errors(report):
    return [f for f in report.errors if f.rule == 'precision']


@pytest.mark.parametrize('fraction', [1e-12, 1e-6, 8e-4])
def test_initial_slack_below_double_precision_is_refused_with_the_floor(fraction, tight_edge):
    s = tight_edge('paper_single', fraction)
    report = validate_scenario(s)
    (finding,) = _precision_errors(report)
    assert finding.subject == 'edge (2, 3)'
    c = 4.0 - 2.0 * np.sqrt(2.0)
    y = s.positions[1] - s.positions[2] - np.array([-2.0, 2.0])
    slack = c - np.linalg.norm(y)
    ulp = np.spacing(np.abs(y).max())
    step = 2 * c * c / slack**3 * ulp
    floor = (2 * c * c * ulp / (SEARCH_LIMIT * 10.0)) ** (1 / 3)  # g_ij(floor) ulp = 5e-8 α
    assert finding.values['slack'] == pytest.approx(slack, rel=1e-9)
    assert finding.values['error_step'] == pytest.approx(step, rel=1e-9)
    assert finding.values['floor'] == pytest.approx(floor, rel=1e-9)
    assert floor == pytest.approx(9.1e-4 * c, rel=0.01)  # relative slack 9.1e-4 and up resolve
    for number in (slack, floor, step, step / 10.0):
        assert f'{number:.6g}' in finding.message
    assert 'α = 10' in finding.message and '5e-08' in finding.message
    with pytest.raises(ValidationError, match=r'\[precision\] edge \(2, 3\)'):
        require_valid(s)


def test_initial_slack_above_the_floor_is_accepted(tight_edge):
    # Relative slack 1e-3 runs (200 084 events to t = 10; tests/formation_sim/test_engine.py runs its start).
    report = validate_scenario(tight_edge('paper_single', 1e-3))
    assert report.ok and not _precision_errors(report)
    assert ('initial', 'edge (2, 3)') in rules(report.warnings)  # still the generic 5 % warning


def _paper_single_in_units(power: int):
    """paper_single with lengths × s = 2^power, β / s and the horizon × s (α unchanged): ω_ij scales
    as 1/s and the commands not at all, so it is the same run with its times × s."""
    paper = load_scenario('paper_single')
    s = 2.0**power
    return paper.replace(
        positions=paper.positions * s,
        edges=tuple(Edge(i=e.i, j=e.j, d=np.asarray(e.d) * s) for e in paper.edges),
        delta=paper.delta * s,
        gains=SingleGains(alpha=paper.gains.alpha, beta=paper.gains.beta / s),
        horizon=paper.horizon * s,
    )


@pytest.mark.parametrize('power', [-200, -40, -3, 3])
def test_the_same_run_in_other_length_units_is_accepted_and_runs_alike(power):
    from formation_sim.sim.engine import simulate

    reference = simulate(load_scenario('paper_single'), sample_dt=None, sample_events=False)
    scaled = _paper_single_in_units(power)
    assert validate_scenario(scaled).ok
    record = simulate(scaled, sample_dt=None, sample_events=False)
    assert record.total_events == reference.total_events == 187
    for agent in reference.trigger_times:
        back = np.asarray(record.trigger_times[agent]) / 2.0**power  # exact: a power of two
        assert np.allclose(back, reference.trigger_times[agent], rtol=0.0, atol=1e-9)


@pytest.mark.parametrize('power', [-330, -251, 251, 600])
def test_lengths_outside_what_double_precision_computes_with_are_refused_by_rule_scale(power):
    """2^-300: the engine's curvature bound divided by an underflowed gap⁴ (ZeroDivisionError
    after validate had accepted it); 2^300: the fourth powers overflow and the bound is silently
    lost. Only the scale findings are reported: the other rules' numbers would be inf or 0."""
    with np.errstate(all='ignore'):
        report = validate_scenario(_paper_single_in_units(power))
    assert report.errors and {finding.rule for finding in report.errors} == {'scale'}
    finding = report.errors[0]
    if power < 0:
        # Edge (1, 2) of paper_single: Δ = 4, d = (0, -2), x1 - x2 = (-1.5, -3): slack 2 - ||(-1.5, -1)||.
        # Its capacity Δ - ||d|| = 2 is named when it is itself too small, else the slack.
        capacity, slack = 2.0 * 2.0**power, (2.0 - np.hypot(1.5, 1.0)) * 2.0**power
        name, value = (
            ('Δ-||d_ij||', capacity)
            if capacity < 2.0**-250
            else ('the initial slack Δ-||d_ij||-||x_i(0)-x_j(0)-d_ij||', slack)
        )
        assert finding.subject == 'edge (1, 2)'
        assert finding.message.startswith(
            f'{name} = {value:.6g} is below {2.0**-250:.6g} (2^-250): the certified search divides by '
            'the fourth power of the distance to Δ'
        ), finding.message
    else:
        assert finding.subject == 'scenario'
        assert finding.message.startswith(f'Δ = {4.0 * 2.0**power:.6g} is above {2.0**250:.6g} (2^250): '), (
            finding.message
        )
    assert finding.message.endswith(
        'state the scenario in other length units (ETA-1 runs the same with lengths × s, '
        'β / s and time × s: ω_ij scales as 1/s, the commands not at all)'
    )


def test_double_integrator_slack_floor_counts_velocities(tight_edge):
    # E_i = k1 e_i + k2 e_qi: one ulp of y moves it by (k1 g + k2 h ||q_i-q_j||) ulp, one ulp of
    # q_i - q_j by k2 f ulp(q); f = (c+σ)/σ², g = 2c²/σ³, h = (2c+σ)/σ³.
    from scipy.optimize import brentq

    s = tight_edge('paper_double', 1e-3)
    (finding,) = _precision_errors(validate_scenario(s))
    g = s.gains
    c = 4.0 - 2.0 * np.sqrt(2.0)
    y = s.positions[1] - s.positions[2] - np.array([-2.0, 2.0])
    q = s.velocities[1] - s.velocities[2]
    ulp_y, ulp_q = np.spacing(np.abs(y).max()), np.spacing(np.abs(q).max())

    def step(sigma):
        return (
            g.k1 * 2 * c * c / sigma**3 + g.k2 * (2 * c + sigma) / sigma**3 * np.linalg.norm(q)
        ) * ulp_y + (g.k2 * (c + sigma) / sigma**2 * ulp_q)

    floor = brentq(lambda sigma: step(sigma) - SEARCH_LIMIT * g.alpha_d, 1e-6, c, xtol=1e-15, rtol=1e-13)
    assert finding.values['error_step'] == pytest.approx(step(c - np.linalg.norm(y)), rel=1e-9)
    assert finding.values['floor'] == pytest.approx(floor, rel=1e-9)
    assert 'α_d = 10' in finding.message
    assert not _precision_errors(validate_scenario(tight_edge('paper_double', 3e-3)))


# -- gains on a computed bound: its rounding is not a reason to refuse ------------------------------


def _held_out_team(beta1_of):
    """A random ETA-2 team (not the paper's round numbers) with β1 = beta1_of(β0 as computed)."""
    import math

    from formation_sim.model import theory
    from formation_sim.model.generate import random_scenario
    from formation_sim.model.scenario import scenario_to_dict

    base = random_scenario(n=5, seed=2, dynamics='double', horizon=0.5)
    beta0 = theory.beta0(base)
    data = scenario_to_dict(base)
    data['gains'] = {**data['gains'], 'beta1': beta1_of(beta0, math), 'k3': 'paper'}
    return scenario_from_dict(data), beta0


@pytest.mark.parametrize('ulps', [0, 1, 2])
def test_beta1_on_beta0_up_to_rounding_is_accepted_with_a_warning_naming_the_margin(ulps):
    from formation_sim.model.gains import ROUNDING_ULPS

    def nudged(beta0, math):
        for _ in range(ulps):
            beta0 = math.nextafter(beta0, math.inf)
        return beta0

    scenario, beta0 = _held_out_team(nudged)
    assert scenario.gains.beta1 > beta0 or ulps == 0
    report = validate_scenario(scenario)
    assert report.ok, [f.message for f in report.errors]
    rounding = [w for w in report.warnings if w.rule == 'rounding']
    if ulps == 0:
        assert rounding == []  # β1 <= β0 holds as computed
        return
    assert len(rounding) == 1, rounding
    message = rounding[0].message
    assert f'β1 = {scenario.gains.beta1!r} is {ulps} ulp(s) above β0 = {beta0!r}' in message
    assert f'rounding margin of {ROUNDING_ULPS} ulps' in message
    assert rounding[0].values['margin_ulps'] == ROUNDING_ULPS
    from formation_sim.model import theory

    assert theory.theorem_constants(scenario).k_V is not None  # the proof's chain goes through


def test_beta1_above_beta0_by_more_than_rounding_is_refused():
    scenario, beta0 = _held_out_team(lambda beta0, math: beta0 * (1.0 + 1e-9))
    report = validate_scenario(scenario)
    assert [(f.rule, f.subject) for f in report.errors] == [('beta1', 'gains')]
    assert report.errors[0].values == {'beta1': scenario.gains.beta1, 'beta0': beta0}


def test_beta1_one_ulp_above_beta0_simulates(tmp_path, capsys):
    import math

    from formation_sim.cli import main
    from formation_sim.model.scenario import dump_scenario

    scenario, _ = _held_out_team(lambda beta0, m: math.nextafter(beta0, math.inf))
    path = tmp_path / 'team.yaml'
    dump_scenario(scenario, path)
    assert main(['simulate', str(path), '--out', str(tmp_path / 'run'), '--no-plot']) == 0, (
        capsys.readouterr()
    )
    summary = json.loads((tmp_path / 'run' / 'summary.json').read_text())
    assert summary['total_events'] > 0 and summary['theorem_constants'].get('error') is None, summary
    # One ulp of β1 moves P by rounding only: the same events as with β1 = β0, at the same times
    # to rounding (the run is 0.5 s long).
    from formation_sim.sim.engine import simulate

    at_beta0, _ = _held_out_team(lambda beta0, m: beta0)
    nudged, on_beta0 = simulate(scenario, sample_dt=None), simulate(at_beta0, sample_dt=None)
    assert nudged.total_events == on_beta0.total_events > 0
    for agent, times in on_beta0.trigger_times.items():
        assert np.allclose(nudged.trigger_times[agent], times, rtol=0.0, atol=1e-12), agent


def test_a_strict_bound_met_up_to_rounding_is_accepted_and_beyond_it_refused(paper_scenario_dict):
    import math

    from formation_sim.model import theory
    from formation_sim.model.errors import TheoryError

    beta0 = 1.5  # the paper's example, exactly
    accepted = scenario_from_dict(paper_scenario_dict('single', beta=math.nextafter(beta0, math.inf)))
    report = validate_scenario(accepted)
    assert report.ok and 'rounding' in {w.rule for w in report.warnings}
    with pytest.raises(TheoryError, match=r'unbounded'):  # β = β0: the proof's constants do not exist
        theory.theorem_constants(accepted)
    refused = scenario_from_dict(paper_scenario_dict('single', beta=beta0 * (1.0 + 1e-9)))
    assert [f.rule for f in validate_scenario(refused).errors] == ['beta']


def test_a_triggering_rule_the_theorems_do_not_cover_is_a_warning_and_the_paper_rule_none(monkeypatch):
    import sys
    from pathlib import Path

    from formation_agent.core.trigger import unregister_rule

    toy = Path(__file__).resolve().parents[2] / 'formation_agent' / 'core'  # toy_trigger_rule.py
    monkeypatch.syspath_prepend(str(toy))
    monkeypatch.delitem(sys.modules, 'toy_trigger_rule', raising=False)
    base = load_scenario('paper_single')
    try:
        report = validate_scenario(base.replace(trigger_rule='toy_trigger_rule:Polynomial'))
    finally:
        for name in ('polynomial', 'exponential_again', 'toy_trigger_rule:Polynomial'):
            unregister_rule(name)
    assert ('trigger_rule', 'gains') in rules(report.warnings)
    warning = next(w for w in report.warnings if w.rule == 'trigger_rule')
    assert "trigger_rule 'toy_trigger_rule:Polynomial': Theorems 1 and 2 are proven for" in warning.message
    assert 'trigger_rule' not in {w.rule for w in validate_scenario(base).warnings}
    # The package's own exponential rule by its import path is the paper's rule: no warning.
    same = base.replace(trigger_rule='formation_agent.core.trigger:ExponentialRule')
    assert 'trigger_rule' not in {w.rule for w in validate_scenario(same).warnings}
