"""The engine's compiled step at an event time (`_fastcore.Team` through `engine._team`, issue 31).

The bit-equality of whole runs on both paths is tests/formation_agent/core/test_compiled.py's
(`test_engine_runs_are_bit_equal_on_both_paths`: with the compiled core on, those runs go through the
team). Here: that the team really takes the plain agents' triggers (no silent fall-back to the Python
step), that an agent it does not take is left untouched for the Python path, which then raises its
error, and that arrays of another shape are refused by rule and value.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from formation_agent.core import compiled
from formation_agent.core.eta import Eta1Agent, Eta2Agent
from formation_agent.core.trigger import ExponentialRule
from formation_msgs_py.types import TriggerInfo
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim import engine
from formation_sim.sim.engine import build_agent, build_agents
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
    team.release()  # the agents' attributes are their knowledge again: a change there is read by the team
    late = due[2]
    agents[late].last_trigger = 2.0  # a trigger at t = 1 would go back in time: refused
    controls = world.controls
    assert team.trigger(due, 0, 1.0, *world.arrays()) == 2  # the first two taken, the third left
    team.release()
    assert [agents[i].triggers for i in due] == [2, 2, 1]
    assert agents[late].last_trigger == 2.0  # handed back as it was
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


def _watch_team(monkeypatch) -> tuple[list, list, list[int]]:
    """The compiled queue and team of the next run, and every agent whose trigger_search (the Python way to a
    new search) was called."""
    queues: list = []
    teams: list = []
    searched: list[int] = []
    link, make_team = engine._Agenda.link, engine._team

    def kept(self, team):
        queues.append(self.queue)
        link(self, team)

    def made(agents, world):
        teams.append(make_team(agents, world))
        return teams[-1]

    def counted(kind):
        method = kind.trigger_search

        def trigger_search(self, limit=math.inf):
            searched.append(self.agent_id)
            return method(self, limit)

        monkeypatch.setattr(kind, 'trigger_search', trigger_search)

    monkeypatch.setattr(engine._Agenda, 'link', kept)
    monkeypatch.setattr(engine, '_team', made)
    counted(Eta1Agent)
    counted(Eta2Agent)
    return queues, teams, searched


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_new_searches_start_from_the_teams_ledger_and_give_the_python_chain(on_path, monkeypatch, dynamics):
    scenario = random_scenario(n=12, seed=2, dynamics=dynamics)
    horizon = 6.0 if dynamics == 'single' else 0.05
    on_path(False)
    pure = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    on_path(True)
    queues, teams, searched = _watch_team(monkeypatch)
    fast = engine.simulate(scenario, horizon=horizon, sample_dt=None)
    events = sum(map(len, pure.trigger_times.values()))
    assert fast.trigger_times == pure.trigger_times and events > 100
    # Every new search was made from the team's ledger, none by trigger_search (the Python way); the team
    # read each agent's attributes once (at its first trigger) and wrote them once (at the end of the run).
    ((queue,), (team,)) = queues, teams
    assert searched == [] and queue.from_team > events
    assert team.loads == team.stores == scenario.n


def test_a_change_the_team_did_not_make_is_read_from_the_agent(on_path):
    """A message the Python receive takes (here a numpy vector, which the compiled receive leaves to it)
    after the team handed the agent back: the team reads the agent again, and its next search is the
    Python search of the new knowledge."""
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
    queue.plan(agents, due)  # the first searches, from the team's ledger
    assert queue.from_team == 3 and team.loads == 3
    world.advance(0.001)
    team.trigger([1], 0, 0.001, *world.arrays())
    changed = sorted({1, *team.deliver()})
    queue.plan(agents, changed)
    assert queue.from_team == 3 + len(changed) == 6  # the trigger's and the receivers' searches
    team.release(1)  # handed back: its attributes are its knowledge, its search the ledger's
    first = agents[1]._search.run()
    sender = agents[1].neighbour_ids[0]
    rel = -np.asarray(agents[1]._edge_y[0][: scenario.dimension]) * 1.5  # a neighbour farther away
    agents[1].receive(
        TriggerInfo(sender=sender, receiver=1, stamp=0.002, control=(0.0, 0.0), rel_position=rel)
    )
    queue.plan(agents, [1])
    assert team.loads == 4 and queue.from_team == 7  # agent 1 read again, its search made from that
    team.release(1)
    replanned = agents[1]._search.run()
    on_path(False)
    agents[1]._search = None
    assert replanned == agents[1].next_trigger_time(100.0) != first  # the Python search of the new knowledge


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_a_message_after_a_trigger_the_team_did_not_make_uses_the_agents_own_command(on_path, name):
    """An agent handed back for the engine's Python step (`_trigger_one`) is read again by the team at its
    next message: every row stays the agent's `_row` of its knowledge, with its new command."""
    on_path(True)
    scenario, world, agents, team = _team_and_agents(name)
    due = list(scenario.agent_ids)
    times: dict[int, list[float]] = {i: [] for i in due}
    team.trigger(due, 0, 0.0, *world.arrays())
    team.deliver()
    world.advance(1e-4)
    team.release(1)  # as the engine hands an agent back before its Python step
    engine._trigger_one(agents[1], world, 1e-4, times)  # agent 1's new command, not through the team
    world.advance(2e-4)
    assert team.trigger([2, 3], 0, 2e-4, *world.arrays()) == 2
    assert sorted(team.deliver()) == [1, 1, 2, 3]
    team.release()
    assert team.loads == 4  # agent 1 read again
    for agent in agents.values():
        assert agent._rows == [agent._row(k) for k in range(len(agent.neighbour_ids))]
    assert agents[1]._u[: scenario.dimension] == tuple(agents[1].control)
    assert [agent.triggers for agent in agents.values()] == [2, 2, 2]


def _bits(value):
    """`value` with every float as its bit pattern (so that -0.0, 0.0 and NaN count as different floats)."""
    if isinstance(value, float):
        return struct.pack('<d', value).hex()
    if isinstance(value, (list, tuple)):
        return [_bits(v) for v in value]
    return value


def _knowledge(agent) -> list:
    """Everything trigger and receive keep of an agent (the attributes the team writes back), by bits, and
    where its search stands."""
    values = [
        *(agent._edge_time, agent._edge_y, agent._edge_u, agent._rows, agent._heard),
        *(agent._u, agent._u_offset, agent._control_norm, agent.control.tolist(), agent._offset.tolist()),
        *(agent.last_trigger, agent.last_event, agent._interval, agent.triggers, agent.infos_received),
    ]
    if isinstance(agent, Eta2Agent):
        values += [agent._edge_q, agent._sensed_q]
    search = agent._search
    values.append(None if search is None else (search.start, search.frontier, search.result, search.steps))
    return _bits(values)


def _run_keeping_agents(monkeypatch, scenario, horizon, *, python_agent=None):
    """A run and its agents (`python_agent`: that one on the numpy path, which the team leaves to Python)."""
    agents = {}

    def build(scenario, **kwargs):
        agents.update(build_agents(scenario, **kwargs))
        if python_agent is not None:
            agents[python_agent]._fast = False
        return agents

    monkeypatch.setattr(engine, 'build_agents', build)
    return engine.simulate(scenario, horizon=horizon, sample_dt=None), agents


TEAMS = [
    ('paper_single', 5.0),
    ('paper_double', 5.0),
    ((9, 3, 'double', 3), 0.2),
    ((12, 5, 'single', 2), 2.0),
]


@pytest.mark.parametrize('case, horizon', TEAMS, ids=[str(c[0]) for c in TEAMS])
def test_after_a_run_every_agent_holds_the_pure_python_knowledge(on_path, monkeypatch, case, horizon):
    """The team's ledger written back at the end of the run: every agent's edges, rows, command, counters and
    search are the pure-Python run's, bit for bit (a write-back skipped or stale leaves them elsewhere)."""
    n, seed, dynamics, dimension = case if isinstance(case, tuple) else (0, 0, '', 0)
    scenario = (
        load_scenario(case)
        if isinstance(case, str)
        else random_scenario(n=n, seed=seed, dynamics=dynamics, dimension=dimension)
    )
    on_path(False)
    pure, pure_agents = _run_keeping_agents(monkeypatch, scenario, horizon)
    on_path(True)
    fast, fast_agents = _run_keeping_agents(monkeypatch, scenario, horizon)
    assert fast.trigger_times == pure.trigger_times and sum(map(len, pure.trigger_times.values())) > 20
    for i in scenario.agent_ids:
        assert _knowledge(fast_agents[i]) == _knowledge(pure_agents[i]), f'agent {i}'
        assert pure_agents[i].triggers > 1 and fast_agents[i]._search is not None


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_an_agent_on_the_python_path_among_the_teams_gives_the_pure_python_run(
    on_path, monkeypatch, dynamics
):
    """One agent the team leaves to Python (the numpy path): its triggers are `_trigger_one`'s, its messages
    reach the team's agents through their Python receive (the team hands each back and reads it again), and
    the team's messages reach it through its receive; the event chain and every agent's knowledge after the
    run are the pure-Python run's."""
    scenario = random_scenario(n=8, seed=4, dynamics=dynamics)
    horizon = 2.0 if dynamics == 'single' else 0.05
    on_path(False)
    pure, pure_agents = _run_keeping_agents(monkeypatch, scenario, horizon, python_agent=3)
    on_path(True)
    teams: list = []
    make_team = engine._team
    monkeypatch.setattr(
        engine, '_team', lambda agents, world: teams.append(make_team(agents, world)) or teams[-1]
    )
    fast, fast_agents = _run_keeping_agents(monkeypatch, scenario, horizon, python_agent=3)
    assert fast.trigger_times == pure.trigger_times and len(pure.trigger_times[3]) > 5
    assert fast.messages_sent == pure.messages_sent
    (team,) = teams
    assert team.loads > 2 * scenario.n  # agent 3's receivers handed back and read again, event after event
    for i in scenario.agent_ids:
        assert _knowledge(fast_agents[i]) == _knowledge(pure_agents[i]), f'agent {i}'


def _python_edges(agents: dict, ids: tuple) -> tuple | None:
    """The team's edges as `engine._team` computed them before `_fastcore.team_edges` (the reference)."""
    position = {i: k for k, i in enumerate(ids)}
    if any(i not in agents[j].neighbour_ids for i in ids for j in agents[i].neighbour_ids):
        return None
    neighbours = tuple(tuple(position[j] for j in agents[i].neighbour_ids) for i in ids)
    back = tuple(tuple(agents[j].neighbour_ids.index(i) for j in agents[i].neighbour_ids) for i in ids)
    return neighbours, back


class _Listed:
    def __init__(self, neighbour_ids: tuple) -> None:
        self.neighbour_ids = neighbour_ids


@pytest.mark.parametrize('seed', range(6))
def test_the_teams_edges_are_those_of_the_python_construction(seed):
    rng = np.random.default_rng(seed)
    scenario = random_scenario(n=int(rng.integers(2, 60)), seed=seed, dynamics=('single', 'double')[seed % 2])
    agents = build_agents(scenario)
    ids = tuple(int(i) for i in rng.permutation(scenario.agent_ids))  # any order of the world
    edges = compiled._fastcore.team_edges(tuple(agents[i] for i in ids), ids)
    assert edges is not None and edges == _python_edges(agents, ids)
    # An agent listed twice (its first slot is taken, as tuple.index finds it); a neighbour that does not
    # list the agent back (None, as before); a stranger (None: the Python construction raised KeyError).
    listed = {1: _Listed((2, 3)), 2: _Listed((1, 3)), 3: _Listed((2, 1, 1))}
    found = compiled._fastcore.team_edges(tuple(listed.values()), tuple(listed))
    assert (
        found
        == _python_edges(listed, tuple(listed))
        == (((1, 2), (0, 2), (1, 0, 0)), ((0, 1), (0, 0), (1, 1, 1)))
    )
    unlisted = {**listed, 2: _Listed((3,))}  # 1 lists 2, which does not list 1
    assert _python_edges(unlisted, tuple(unlisted)) is None
    assert compiled._fastcore.team_edges(tuple(unlisted.values()), tuple(unlisted)) is None
    stranger = {**listed, 1: _Listed((2, 4))}
    assert compiled._fastcore.team_edges(tuple(stranger.values()), tuple(stranger)) is None
