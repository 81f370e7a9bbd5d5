"""A toy triggering rule, plugged in through one module of the tests
(formation_agent/core/toy_trigger_rule.py), in a distributed lock-step run: its name reaches every
agent process as the parameter trigger_rule and the run equals the in-process engine bit for bit
(real processes, private ROS domain 141)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import yaml

from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]

TOY_FOLDER = Path(__file__).resolve().parents[2] / 'formation_agent' / 'core'
RULE = 'toy_trigger_rule:Polynomial'


@pytest.mark.timeout(300)
def test_a_toy_rule_runs_lockstep_in_every_agent_process_and_equals_the_engine(tmp_path, monkeypatch):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    # The rule's module is importable here and in every child (they inherit this environment).
    monkeypatch.syspath_prepend(str(TOY_FOLDER))
    monkeypatch.setenv(
        'PYTHONPATH', os.pathsep.join(filter(None, (str(TOY_FOLDER), os.environ.get('PYTHONPATH'))))
    )
    scenario = load_scenario('paper_single').replace(trigger_rule=RULE)
    horizon = 3.0
    reference = simulate(scenario, horizon=horizon)
    paper = simulate(load_scenario('paper_single'), horizon=horizon)
    assert reference.trigger_times != paper.trigger_times  # the toy's threshold, not the paper's
    assert reference.total_events > 3 * scenario.n

    result = FormationRun(
        scenario, out_dir=tmp_path / 'run', horizon=horizon, domain_id=141, progress=False, timeout=240.0
    ).run()
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    assert summary['mode'] == 'distributed'
    got = {int(agent): times for agent, times in summary['trigger_times'].items()}
    assert got == reference.trigger_times  # the same floats
    assert summary['messages_sent'] == reference.messages_sent
    agents = yaml.safe_load((result.out_dir / 'agents.params.yaml').read_text())
    assert {node['ros__parameters']['trigger_rule'] for node in agents.values()} == {RULE}
