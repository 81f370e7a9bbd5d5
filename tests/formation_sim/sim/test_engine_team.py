"""The engine's compiled step at an event time (`_fastcore.Team` through `engine._team`, issue 31).

The bit-equality of whole runs on both paths is tests/formation_agent/core/test_compiled.py's
(`test_engine_runs_are_bit_equal_on_both_paths`: with the compiled core on, those runs go through the
team). Here: that the team really takes the plain agents' triggers (no silent fall-back to the Python
step), that an agent it does not take is left untouched for the Python path, which then raises its
error, and that arrays of another shape are refused by rule and value.
"""

from __future__ import annotations

import numpy as np
import pytest

from formation_agent.core import compiled
from formation_agent.core.trigger import ExponentialRule
from formation_msgs_py.types import TriggerInfo
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim import engine
from formation_sim.sim.engine import build_agent
from formation_sim.sim.errors import EngineError
from formation_sim.sim.world import World

pytestmark = pytest.mark.skipif(not compiled.AVAILABLE, reason='compiled core not built')


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


def _watch_plans(monkeypatch) -> tuple[list, list[int]]:
    """The compiled queue of the next run, and how many new searches each of its plans made."""
    queues: list = []
    made: list[int] = []
    link, plan = engine._Agenda.link, engine._Agenda.plan

    def kept(self, team):
        queues.append(self.queue)
        link(self, team)

    def counted(self, agents, changed, due, t):
        before = {i: agents[i]._search for i in changed}
        plan(self, agents, changed, due, t)
        made.append(sum(agents[i]._search is not search for i, search in before.items()))

    monkeypatch.setattr(engine._Agenda, 'link', kept)
    monkeypatch.setattr(engine._Agenda, 'plan', counted)
    return queues, made


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_new_searches_start_from_the_teams_copy_and_give_the_python_chain(on_path, monkeypatch, dynamics):
    scenario = random_scenario(n=12, seed=2, dynamics=dynamics)
    horizon = 6.0 if dynamics == 'single' else 0.05
    on_path(False)
    pure = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    on_path(True)
    queues, made = _watch_plans(monkeypatch)
    fast = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    events = sum(map(len, pure.trigger_times.values()))
    assert fast.trigger_times == pure.trigger_times and events > 100
    # Each agent's first search (t = 0, before it had heard every neighbour) is trigger_search's; every
    # later new one is made right after the team updated the agent, from the team's copy.
    (queue,) = queues
    assert made[0] == scenario.n and queue.from_team == sum(made) - scenario.n > events


def test_a_change_the_team_did_not_make_is_read_from_the_agent(on_path):
    """A message the Python receive takes (here a numpy vector, which the compiled receive leaves to it)
    moves the agent's counter: its next search reads the agent, not the team's older copy."""
    on_path(True)
    scenario, world, agents, team = _team_and_agents('paper_single')
    plain = (type(agents[1]),)
    queue = compiled.agenda()(
        agent_ids=scenario.agent_ids,
        horizon=100.0,
        first_span=engine._FIRST_SPAN,
        plain=plain,
        rule=ExponentialRule,
    )
    queue.link(team)
    due = list(scenario.agent_ids)
    team.trigger(due, 0, 0.0, *world.arrays())
    team.deliver()
    queue.plan(agents, due)  # the first searches: trigger_search's (no neighbour heard before t = 0)
    assert queue.from_team == 0
    world.advance(0.001)
    team.trigger([1], 0, 0.001, *world.arrays())
    changed = sorted({1, *team.deliver()})
    queue.plan(agents, changed)
    assert queue.from_team == len(changed) == 3  # the trigger's and the receivers' copies
    first = agents[1]._search.run()
    sender = agents[1].neighbour_ids[0]
    rel = -np.asarray(agents[1]._edge_y[0][: scenario.dimension]) * 1.5  # a neighbour farther away
    agents[1].receive(
        TriggerInfo(sender=sender, receiver=1, stamp=0.002, control=(0.0, 0.0), rel_position=rel)
    )
    queue.plan(agents, [1])
    assert queue.from_team == 3  # this search read the agent
    replanned = agents[1]._search.run()
    on_path(False)
    agents[1]._search = None
    assert replanned == agents[1].next_trigger_time(100.0) != first  # the Python search of the new knowledge


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_a_message_after_a_trigger_the_team_did_not_make_uses_the_agents_own_command(on_path, name):
    """The team delivers from its copy of the receiver's d_ij, capacity and command only while the
    receiver's counters say the copy is its knowledge; after a trigger elsewhere (here `_trigger_one`,
    the engine's Python step) it reads the agent: every row stays the agent's `_row` of its knowledge."""
    on_path(True)
    scenario, world, agents, team = _team_and_agents(name)
    due = list(scenario.agent_ids)
    times: dict[int, list[float]] = {i: [] for i in due}
    team.trigger(due, 0, 0.0, *world.arrays())
    team.deliver()
    world.advance(1e-4)
    engine._trigger_one(agents[1], world, 1e-4, times)  # agent 1's new command, not through the team
    world.advance(2e-4)
    assert team.trigger([2, 3], 0, 2e-4, *world.arrays()) == 2
    assert sorted(team.deliver()) == [1, 1, 2, 3]
    for agent in agents.values():
        assert agent._rows == [agent._row(k) for k in range(len(agent.neighbour_ids))]
    assert agents[1]._u[: scenario.dimension] == tuple(agents[1].control)
