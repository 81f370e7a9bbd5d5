"""The engine's compiled step at an event time (`_fastcore.Team` through `engine._team`, issue 31).

The bit-equality of whole runs on both paths is tests/formation_agent/core/test_compiled.py's
(`test_engine_runs_are_bit_equal_on_both_paths`: with the compiled core on, those runs go through the
team). Here: that the team really takes the plain agents' triggers (no silent fall-back to the Python
step), that an agent it does not take is left untouched for the Python path, which then raises its
error, and that arrays of another shape are refused by rule and value.
"""

from __future__ import annotations

import pytest

from formation_agent.core import compiled
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim import engine
from formation_sim.sim.engine import build_agent
from formation_sim.sim.errors import EngineError
from formation_sim.sim.world import World

pytestmark = pytest.mark.skipif(not compiled.AVAILABLE, reason='compiled core not built')


@pytest.fixture
def on_path():
    previous = compiled.active()
    yield compiled.use_compiled
    compiled.use_compiled(previous)


def _count_python_triggers(monkeypatch) -> list[int]:
    calls: list[int] = []
    python_step = engine._trigger_one

    def counted(agent, *args, **kwargs):
        calls.append(agent.agent_id)
        return python_step(agent, *args, **kwargs)

    monkeypatch.setattr(engine, '_trigger_one', counted)
    return calls


@pytest.mark.parametrize('case', ['paper_single', 'paper_double', 'random_double'])
def test_the_team_takes_every_plain_trigger_and_gives_the_python_chain(on_path, monkeypatch, case):
    scenario = (
        random_scenario(n=10, seed=1, dynamics='double') if case == 'random_double' else load_scenario(case)
    )
    horizon = 0.3 if case == 'random_double' else 5.0
    calls = _count_python_triggers(monkeypatch)
    on_path(False)
    pure = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    python_calls = len(calls)
    on_path(True)
    fast = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    triggers = sum(map(len, pure.trigger_times.values()))
    assert python_calls == triggers > 20  # the pure path triggers every agent in Python
    assert len(calls) == python_calls  # the compiled run triggered none there: the team took them all
    assert fast.trigger_times == pure.trigger_times
    assert fast.messages_sent == pure.messages_sent


def _team_and_agents(name: str):
    scenario = load_scenario(name)
    world = World.from_scenario(scenario)
    agents = {i: build_agent(scenario, i) for i in scenario.agent_ids}
    team = engine._team(agents, world)
    assert team is not None
    return scenario, world, agents, team


def test_an_agent_the_team_does_not_take_is_left_to_the_python_path(on_path):
    on_path(True)
    scenario, world, agents, team = _team_and_agents('paper_single')
    due = list(scenario.agent_ids)
    assert team.trigger(due, 0, 0.0, *world.arrays()) == len(due)  # t = 0: every agent taken
    assert team.deliver() == [j for i in due for j in agents[i].neighbour_ids]  # receivers, in order sent
    late = due[2]
    agents[late].last_trigger = 2.0  # a trigger at t = 1 would go back in time: refused
    controls, counts = world.controls, [agents[i].triggers for i in due]
    assert team.trigger(due, 0, 1.0, *world.arrays()) == 2  # the first two taken, the third left
    assert [agents[i].triggers for i in due] == [c + (k < 2) for k, c in enumerate(counts)]
    assert (world.controls[2:] == controls[2:]).all()  # nothing written for the agent left
    times: dict[int, list[float]] = {i: [] for i in due}
    refused = r'at t=1\.0: agent 3: trigger at t=1\.0 before its last one at t=2\.0'
    with pytest.raises(EngineError, match=refused):
        engine._trigger_and_deliver(agents, world, [late], 1.0, times, team=team)


def test_the_team_refuses_arrays_of_another_shape_by_rule_and_value(on_path):
    on_path(True)
    scenario, world, _, team = _team_and_agents('paper_double')
    x, q, u = world.arrays()
    with pytest.raises(ValueError, match=r"the world's arrays must be \(3, 2\) float64"):
        team.trigger(list(scenario.agent_ids), 0, 0.0, x[:2], q, u)
    with pytest.raises(ValueError, match=r"the world's arrays must be \(3, 2\) float64"):
        team.trigger(list(scenario.agent_ids), 0, 0.0, x, q, u.astype('float32'))
