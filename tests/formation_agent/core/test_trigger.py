"""Triggering rules (formation_agent.core.trigger): the bounds each rule promises the certified search,
the registry, and a toy rule plugged in through one module (toy_trigger_rule.py) run by the engine."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from formation_agent.core import compiled
from formation_agent.core.crossing import CrossingSearch
from formation_agent.core.errors import AgentError, RuleError
from formation_agent.core.eta import Eta1Agent
from formation_agent.core.trigger import (
    DEFAULT_RULE,
    ExponentialRule,
    make_rule,
    register_rule,
    rule_factory,
    rule_names,
    unregister_rule,
)
from formation_msgs_py.types import SensedState, TriggerInfo
from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import load_scenario, scenario_from_dict, scenario_to_dict
from formation_sim.sim.engine import simulate

HERE = Path(__file__).resolve().parent
TOY = 'toy_trigger_rule'


@pytest.fixture
def toy(monkeypatch):
    """The toy module importable by its path (this folder on sys.path and PYTHONPATH), as a user's
    own rule module would be."""
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(filter(None, (str(HERE), os.environ.get('PYTHONPATH')))))
    yield f'{TOY}:Polynomial'
    for name in ('polynomial', 'exponential_again', f'{TOY}:Polynomial', f'{TOY}:Exponential'):
        unregister_rule(name)
    sys.modules.pop(TOY, None)


def _rules(toy_name):
    return [
        ExponentialRule(floor=0.0, alpha=2.0, beta=0.7),
        ExponentialRule(floor=0.3, alpha=2.0, beta=0.7),
        make_rule(toy_name, floor=0.0, alpha=2.0, beta=0.7),
        make_rule(toy_name, floor=0.3, alpha=2.0, beta=0.7),
    ]


def test_each_rule_keeps_the_promises_the_search_relies_on(toy):
    # On t >= a: r = θ(t)/θ(a) from the rule's value alone, its derivatives by central differences;
    # (r²)'' in [0, K], |(r²)'| <= G, ratio = r, scale = 1/θ(a), (r²)'(a) as given.
    for rule in _rules(toy):
        for a in (0.0, 0.4, 3.0, 12.0):
            scale = rule.scale(a)
            assert scale == pytest.approx(1.0 / rule(a), rel=1e-14)
            rate_a, slope = rule.margin_terms(a, scale)
            curvature = rule.curvature(a, scale)
            h = 1e-4

            def r2(t, a=a, rule=rule):
                return (rule(t) / rule(a)) ** 2

            assert (r2(a + h) - r2(a)) / h == pytest.approx(rate_a, rel=1e-3, abs=1e-9)
            for t in a + np.linspace(h, 20.0, 400):
                first = (r2(t + h) - r2(t - h)) / (2 * h)
                second = (r2(t + h) - 2 * r2(t) + r2(t - h)) / (h * h)
                assert abs(first) <= slope * (1 + 1e-6) + 1e-9, (rule, a, t)
                assert -1e-6 <= second <= curvature * (1 + 1e-6) + 1e-6, (rule, a, t)
                assert rule.ratio(t, a, scale) == pytest.approx(rule(t) / rule(a), rel=1e-13)


def test_the_exponential_rule_is_the_papers_threshold():
    rule = make_rule(DEFAULT_RULE, floor=0.25, alpha=10.0, beta=1.5)
    assert isinstance(rule, ExponentialRule)
    for t in (0.0, 0.5, 7.0):
        assert rule(t) == 0.25 + 10.0 * math.exp(-1.5 * t)
    assert DEFAULT_RULE in rule_names()


def test_an_unknown_rule_is_refused_with_the_rule_and_the_value():
    with pytest.raises(RuleError, match=r"trigger_rule: must be one of \[.*'exponential'.*\].*got 'cubic'"):
        rule_factory('cubic')
    with pytest.raises(RuleError, match="trigger_rule: cannot import 'no_such_module_here'"):
        rule_factory('no_such_module_here:Rule')
    with pytest.raises(RuleError, match="trigger_rule: 'math' has no rule 'Nothing'"):
        rule_factory('math:Nothing')
    with pytest.raises(AgentError, match="agent 1: trigger_rule: must be one of .* got 'cubic'"):
        Eta1Agent(
            agent_id=1, neighbours={2: (1.0, 0.0)}, delta=2.0, alpha=1.0, beta=1.0, trigger_rule='cubic'
        )
    with pytest.raises(ScenarioError, match="trigger_rule: .* got 'cubic'"):
        load_scenario('paper_single').replace(trigger_rule='cubic')


def test_a_rule_is_registered_once_under_its_name_and_refused_numbers_name_the_rule(toy):
    family = rule_factory(toy)
    assert rule_factory('polynomial') is family  # importing the module registered it by name
    register_rule(family)  # the same family again: nothing changes
    clash = type('Clash', (), {'name': 'polynomial'})
    with pytest.raises(RuleError, match="trigger_rule: 'polynomial' is registered already"):
        register_rule(clash)
    with pytest.raises(RuleError, match=r"trigger_rule: 'polynomial' refused floor=0.0, alpha=-1.0"):
        make_rule('polynomial', floor=0.0, alpha=-1.0, beta=1.0)


def test_a_rule_without_the_members_of_trigger_rule_is_refused_every_time():
    lacking = type('Lacking', (), {'name': 'lacking', '__init__': lambda self, **numbers: None})
    register_rule(lacking)
    try:
        for _ in range(2):  # the protocol check is remembered only for types that pass it
            with pytest.raises(
                RuleError, match=r"trigger_rule: 'lacking' built .*lacks the methods of TriggerRule"
            ):
                make_rule('lacking', floor=0.0, alpha=1.0, beta=1.0)
    finally:
        unregister_rule('lacking')
    rule = make_rule(DEFAULT_RULE, floor=0.0, alpha=2.0, beta=0.5)
    assert make_rule(DEFAULT_RULE, floor=0.0, alpha=2.0, beta=0.5) == rule


def _single_error_ratios(scenario, record, threshold):
    """||e_i|| / θ at each agent's triggers after t = 0, and the largest between them, from the
    record's positions alone: e_i(t) = Σ_j ω_ij y_ij (t) − the same at agent i's last trigger,
    ω = (2c − r)/(c − r)² (eq. fij), y_ij = x_i − x_j − d_ij."""
    samples = record.samples
    times, positions = samples.times, np.asarray(samples.positions)
    row = {a: k for k, a in enumerate(scenario.agent_ids)}

    def sums(x):
        total = np.zeros((scenario.n, scenario.dimension))
        for edge in scenario.edges:
            y = x[row[edge.i]] - x[row[edge.j]] - edge.d
            c = scenario.delta - np.linalg.norm(edge.d)
            r = np.linalg.norm(y)
            w = (2 * c - r) / (c - r) ** 2
            total[row[edge.i]] += w * y
            total[row[edge.j]] -= w * y
        return total

    at_triggers, inside = [], 0.0
    for agent, triggers in record.trigger_times.items():
        k = row[agent]
        for start, end in zip(triggers, [*triggers[1:], record.horizon]):
            anchor = sums(positions[np.searchsorted(times, start)])[k]
            for s in np.flatnonzero((times > start) & (times <= end)):
                ratio = np.linalg.norm(sums(positions[s])[k] - anchor) / threshold(times[s])
                if times[s] == end and end < record.horizon:
                    at_triggers.append(ratio)
                else:
                    inside = max(inside, ratio)
    return np.array(at_triggers), inside


def test_a_toy_rule_from_its_own_module_runs_in_the_engine_and_triggers_on_its_threshold(toy):
    base = load_scenario('paper_single')
    scenario = base.replace(trigger_rule=toy)
    record = simulate(scenario, horizon=6.0)
    paper = simulate(base, horizon=6.0)
    assert record.trigger_times != paper.trigger_times  # the rule is the toy's, not the paper's
    gains = scenario.gains
    threshold = make_rule(toy, floor=gains.threshold_floor, alpha=gains.alpha, beta=gains.beta)
    at_triggers, inside = _single_error_ratios(scenario, record, threshold)
    assert len(at_triggers) == record.total_events - scenario.n > 20
    assert np.abs(at_triggers - 1.0).max() < 1e-9  # every trigger on c0 + α/(1 + βt)²
    assert inside <= 1.0 + 1e-9  # and the error below it in between
    # The scenario says which rule, in its file as well.
    assert scenario_to_dict(scenario)['trigger_rule'] == toy
    assert scenario_from_dict(scenario_to_dict(scenario)) == scenario
    assert 'trigger_rule' not in scenario_to_dict(base)  # the paper's files are unchanged


def test_another_rule_runs_in_pure_python_even_where_the_compiled_core_runs(toy):
    if not compiled.AVAILABLE:
        pytest.skip('compiled core not built')
    previous = compiled.use_compiled(True)
    try:
        agent = Eta1Agent(
            agent_id=1, neighbours={2: (1.0, 0.0)}, delta=2.0, alpha=1.0, beta=1.0, trigger_rule=toy
        )
        paper = Eta1Agent(agent_id=1, neighbours={2: (1.0, 0.0)}, delta=2.0, alpha=1.0, beta=1.0)
        for one in (agent, paper):
            one.trigger(0.0, SensedState(agent=1, stamp=0.0, rel_positions={2: (1.5, 0.0)}))
            info = TriggerInfo(sender=2, receiver=1, stamp=0.0, control=(0.0, 0.0), rel_position=(-1.5, 0.0))
            one.receive(info)
        assert type(agent.trigger_search(10.0)) is CrossingSearch
        assert type(paper.trigger_search(10.0)) is not CrossingSearch  # the C search
    finally:
        compiled.use_compiled(previous)


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
@pytest.mark.parametrize(('kappa', 'floor'), [(1.0, 0.0), (1.7, 1e-3)])
def test_the_exponential_written_outside_the_package_gives_the_same_floats(toy, name, kappa, floor):
    # The generic path (any rule, pure Python) against the built-in rule (compiled where built):
    # every triggering time equal, float for float, at κ = 1 and c0 = 0 and with both.
    base = load_scenario(name).with_scale(speed_scale=kappa, threshold_floor=floor)
    again = base.replace(trigger_rule=f'{TOY}:Exponential')
    assert simulate(again, horizon=6.0).trigger_times == simulate(base, horizon=6.0).trigger_times
