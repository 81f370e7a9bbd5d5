"""A lock-step distributed run whose agents use one implementation of the core (compiled or pure
Python, formation_agent.core.compiled) equals the in-process engine using the other, bit for bit:
the same trigger times as floats (max difference 0), the same messages (private ROS domains 204-206)."""

from __future__ import annotations

import json

import pytest

from formation_agent.core import compiled
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_compiled_agents')]


def _scenario(name: str):
    if name == 'random':
        return random_scenario(n=6, seed=2, dynamics='single')
    return load_scenario(name)


@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    ('name', 'horizon', 'agents_compiled', 'domain_id'),
    [('paper_single', 10.0, True, 204), ('paper_double', 8.0, False, 205), ('random', 1.0, True, 206)],
)
def test_agents_on_one_path_equal_the_engine_on_the_other(
    tmp_path, monkeypatch, name, horizon, agents_compiled, domain_id
):
    if not compiled.AVAILABLE:
        pytest.skip('compiled core not built')
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = _scenario(name)
    previous = compiled.use_compiled(not agents_compiled)
    try:
        reference = simulate(scenario, horizon=horizon)
    finally:
        compiled.use_compiled(previous)
    # The agent processes inherit the environment: '1' makes them pure Python.
    monkeypatch.setenv(compiled.ENVIRONMENT, '0' if agents_compiled else '1')
    result = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=domain_id,
        progress=False,
        timeout=240.0,
        record=False,
    ).run()
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    got = {int(agent): times for agent, times in summary['trigger_times'].items()}
    assert got == reference.trigger_times  # every trigger time, float for float
    assert summary['messages_sent'] == reference.messages_sent
    assert reference.total_events > 3 * scenario.n
