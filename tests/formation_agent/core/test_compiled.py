"""The compiled core against the pure-Python path: the same floats, bit for bit, and the same errors.

Both paths run in one process (`compiled.use_compiled`); every trigger time, every sample (positions
and velocities), every message count and every search's state must be equal, not close: the
compiled core is only correct if it is the pure-Python path's arithmetic.
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from formation_agent.core import compiled
from formation_agent.core.crossing import CrossingSearch
from formation_agent.core.errors import AgentError, CrossingError
from formation_agent.core.eta import Eta1Agent, Eta2Agent, TriggerOutput
from formation_msgs_py.types import SensedState, TriggerInfo
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate


def test_the_compiled_core_is_built_by_make_venv():
    # `make venv` and colcon build it; a silent fall-back to pure Python would hide the speed-up.
    assert compiled.AVAILABLE, 'formation_agent.core._fastcore is not built: run `make venv` again'


@pytest.fixture
def both():
    """Run `make(...)` on each path; the pair (pure Python, compiled)."""
    if not compiled.AVAILABLE:
        pytest.skip('compiled core not built')
    previous = compiled.active()

    def run(make):
        out = []
        for on in (False, True):
            compiled.use_compiled(on)
            out.append(make())
        return out

    yield run
    compiled.use_compiled(previous)


def _assert_same_run(pure, fast):
    assert pure.trigger_times == fast.trigger_times  # every trigger time, float for float
    assert pure.messages_sent == fast.messages_sent
    a, b = pure.samples, fast.samples
    assert np.array_equal(a.times, b.times)
    assert np.array_equal(a.positions, b.positions)  # every sample
    if a.velocities is not None:
        assert np.array_equal(a.velocities, b.velocities)
    assert sum(map(len, pure.trigger_times.values())) > 20


def _scenario(case):
    if isinstance(case, str):
        return load_scenario(case)
    n, seed, dynamics, dimension = case
    return random_scenario(n=n, seed=seed, dynamics=dynamics, dimension=dimension)


CASES = [
    ('paper_single', 10.0),
    ('paper_double', 10.0),
    ((10, 1, 'single', 2), 2.0),
    ((12, 7, 'single', 3), 1.0),
    ((10, 1, 'double', 2), 0.5),
    ((8, 3, 'double', 3), 0.2),
]


@pytest.mark.parametrize('case, horizon', CASES, ids=[str(c[0]) for c in CASES])
def test_engine_runs_are_bit_equal_on_both_paths(both, case, horizon):
    scenario = _scenario(case)
    pure, fast = both(lambda: simulate(scenario, horizon=horizon, sample_dt=0.01))
    _assert_same_run(pure, fast)


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_speed_scale_and_threshold_floor_runs_are_bit_equal(both, dynamics):
    # The floor c0 > 0 takes the other branch of the threshold's scale S (crossing._scale).
    scenario = random_scenario(n=6, seed=4, dynamics=dynamics)
    gains = scenario.gains.__class__(
        **{
            **{k: getattr(scenario.gains, k) for k in scenario.gains.__dataclass_fields__},
            'speed_scale': 2.0,
            'threshold_floor': 1e-3,
        }
    )
    scenario = scenario.replace(gains=gains)
    horizon = 0.5 if dynamics == 'single' else 0.1
    pure, fast = both(lambda: simulate(scenario, horizon=horizon, sample_dt=0.01))
    _assert_same_run(pure, fast)


def _drive(agent, rng, *, double: bool):
    """Random knowledge: a trigger, then information from each neighbour at later times."""
    ids = agent.neighbour_ids
    rel = [tuple(rng.uniform(-0.4, 0.4, 2) + np.array(agent.offsets[k])) for k in range(len(ids))]
    vel = [tuple(rng.uniform(-0.3, 0.3, 2)) for _ in ids] if double else None
    sensed = SensedState(
        agent=agent.agent_id,
        stamp=0.0,
        rel_positions=dict(zip(ids, rel)),
        rel_velocities=dict(zip(ids, vel)) if double else None,
        velocity=(0.0, 0.0) if double else None,
    )
    agent.trigger(0.0, sensed)
    for k, j in enumerate(ids):
        agent.receive(
            TriggerInfo(
                sender=j,
                receiver=agent.agent_id,
                stamp=float(rng.uniform(0.0, 1e-3)) * k,
                control=tuple(rng.uniform(-1.0, 1.0, 2)),
                rel_position=tuple(-np.array(rel[k])),
                rel_velocity=tuple(-np.array(vel[k])) if double else None,
            )
        )


def _bits(value):
    """A float by its bits (NaN equals NaN, -0.0 differs from 0.0), other values as they are."""
    return struct.pack('<d', value).hex() if isinstance(value, float) else value


def _search_state(search: CrossingSearch):
    values = (search.result, search.frontier, search.steps, search._span, *search._cover)
    return tuple(_bits(v) for v in values)


@pytest.mark.parametrize('seed', range(40))
def test_searches_from_random_knowledge_end_in_the_same_state(both, seed):
    # Search by search, in pieces (as the engine advances them) and to the end: result, frontier,
    # step count, next span and the last step's bounds all equal.
    def make_pair():
        rng = np.random.default_rng(seed)
        double = seed % 2 == 1
        neighbours = {2: (1.0, 0.0), 3: (0.0, 1.0), 4: (-1.0, 0.5)}
        if double:
            agent = Eta2Agent(
                agent_id=1, neighbours=neighbours, delta=3.0, alpha_d=0.5, beta_d=0.05, k1=1.0, k2=2.0, k3=1.5
            )
        else:
            agent = Eta1Agent(agent_id=1, neighbours=neighbours, delta=3.0, alpha=0.5, beta=0.3)
        _drive(agent, rng, double=double)
        search = agent.trigger_search(50.0)
        states = []
        for until in (1e-4, 1e-3, 0.01, math.inf):
            search.advance(until)
            states.append(_search_state(search))
        return states

    pure, fast = both(make_pair)
    assert pure == fast
    assert pure[-1][0] is not None


def _outside_agent():
    agent = Eta1Agent(agent_id=1, neighbours={2: (1.0, 0.0)}, delta=2.0, alpha=1.0, beta=0.1)
    agent.trigger(0.0, SensedState(agent=1, stamp=0.0, rel_positions={2: (1.0, 0.0)}))
    # Agent 2 reports a relative state y = (1.5, 0) beyond the edge's capacity Δ - ||d|| = 1.
    agent.receive(TriggerInfo(sender=2, receiver=1, stamp=0.0, control=(0.0, 0.0), rel_position=(-2.5, 0.0)))
    return agent


def test_an_edge_predicted_out_of_range_is_the_same_error_on_both_paths(both):
    def attempt():
        agent = _outside_agent()
        search = agent.trigger_search(10.0)
        with pytest.raises(AgentError) as caught:
            search.advance(1.0)
        return str(caught.value), search.steps

    pure, fast = both(attempt)
    assert pure == fast
    assert pure[1] == 1
    assert 'agent 2' in pure[0]


def test_the_step_limit_is_the_same_error_on_both_paths(both, monkeypatch):
    from formation_agent.core import crossing

    def attempt():
        neighbours = {2: (1.0, 0.0), 3: (0.0, 1.0)}
        agent = Eta1Agent(agent_id=1, neighbours=neighbours, delta=3.0, alpha=0.5, beta=0.3)
        _drive(agent, np.random.default_rng(5), double=False)
        search = agent.trigger_search(50.0)
        with pytest.raises(CrossingError) as caught:
            search.advance(1.0)
        return str(caught.value), search.steps

    monkeypatch.setattr(crossing, 'MAX_STEPS', 3)
    compiled.configure(
        gap_fraction=0.125, trigger_output=TriggerOutput
    )  # hands the compiled core the patched limit
    try:
        pure, fast = both(attempt)
    finally:
        monkeypatch.undo()
        compiled.configure(gap_fraction=0.125, trigger_output=TriggerOutput)
    assert pure == fast
    assert pure[0].startswith('no convergence after 3 certified steps (t=')


def _python(code: str, **env) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, '-c', code], env={**os.environ, **env}, capture_output=True, text=True, timeout=120
    )


def test_formation_pure_python_1_forces_the_pure_python_path():
    code = 'from formation_agent.core import compiled; print(compiled.implementation())'
    assert _python(code, FORMATION_PURE_PYTHON='1').stdout.split() == ['python']
    assert _python(code, FORMATION_PURE_PYTHON='0').stdout.split() == [
        'compiled' if compiled.AVAILABLE else 'python'
    ]


def test_a_bad_formation_pure_python_value_is_refused_by_name():
    run = _python('import formation_agent.core.compiled', FORMATION_PURE_PYTHON='yes')
    assert run.returncode != 0
    assert "FORMATION_PURE_PYTHON must be 0 or 1 (1: the pure-Python core), got 'yes'" in run.stderr


def test_without_the_extension_the_pure_python_path_runs_and_says_so():
    # As on a machine where it was not built: the import of _fastcore fails.
    code = (
        'import sys; sys.modules["formation_agent.core._fastcore"] = None\n'
        'from formation_agent.core import compiled\n'
        'from formation_sim.model.scenario import load_scenario\n'
        'from formation_sim.sim.engine import simulate\n'
        'r = simulate(load_scenario("paper_single"), horizon=1.0, sample_dt=None)\n'
        'print(compiled.AVAILABLE, compiled.implementation(), sum(map(len, r.trigger_times.values())))\n'
        'try:\n'
        '    compiled.use_compiled(True)\n'
        'except RuntimeError as error:\n'
        '    print(error)\n'
    )
    run = _python(code)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    first = lines[0].split()
    assert first[:2] == ['False', 'python']
    assert int(first[2]) > 10
    assert 'the compiled core formation_agent.core._fastcore is not built' in lines[1]


def _knowledge(agent):
    """Everything `receive` and `trigger` change, by bits."""
    arrays = [agent._anchor_time, agent._anchor_y, agent._neighbour_control, agent._heard, agent.control]
    if isinstance(agent, Eta2Agent):
        arrays += [agent._anchor_q]
    lists = [agent._edge_time, agent._edge_y, agent._edge_u, agent._rows, [agent._u, agent._u_offset]]
    if isinstance(agent, Eta2Agent):
        lists.append(agent._edge_q)
    flat = [v for a in arrays for v in np.asarray(a, dtype=float).ravel().tolist()]
    flat += [v for rows in lists for row in rows for v in (row if isinstance(row, tuple) else (row,))]
    counts = (agent.infos_received, agent.triggers, agent.last_event, agent.last_trigger)
    counts += (agent._search is None,)
    return [_bits(v) for v in flat], counts


def _random_agent(rng, *, double: bool, dimension: int):
    ids = [int(j) for j in rng.choice(np.arange(2, 40), size=int(rng.integers(1, 8)), replace=False)]
    neighbours = {j: tuple(rng.uniform(-1.0, 1.0, dimension)) for j in ids}
    if double:
        return Eta2Agent(
            agent_id=1, neighbours=neighbours, delta=4.0, alpha_d=0.5, beta_d=0.05, k1=1.0, k2=2.0, k3=1.5
        )
    return Eta1Agent(agent_id=1, neighbours=neighbours, delta=4.0, alpha=0.5, beta=0.3, speed_scale=1.5)


def _message(rng, agent, j, stamp, *, double: bool):
    """Information from neighbour j at `stamp`, its vectors in the forms a node may hand over."""
    p = agent.dimension
    form = rng.choice(['tuple', 'list', 'ints', 'numpy'])
    rel, control, velocity = (rng.uniform(-0.5, 0.5, p) for _ in range(3))
    rel = rel - agent.offsets[agent.neighbour_ids.index(j)]

    def shape(v):
        if form == 'list':
            return [float(x) for x in v]
        if form == 'ints':
            return tuple(int(x * 4) for x in v)
        if form == 'numpy':
            return v
        return tuple(float(x) for x in v)

    return TriggerInfo(
        sender=j,
        receiver=1,
        stamp=stamp,
        control=shape(control),
        rel_position=shape(rel),
        rel_velocity=shape(velocity) if double else None,
    )


@pytest.mark.parametrize('seed', range(24))
def test_receive_and_trigger_leave_the_same_knowledge_on_both_paths(both, seed):
    # Random agents (ETA-1/ETA-2, p = 1..3), random triggers and messages (tuples, lists, ints, numpy
    # arrays: the compiled receive takes the plain ones, the Python path the others), bad messages
    # among them: after every call the knowledge is equal bit for bit, and so are the errors.
    def make():
        rng = np.random.default_rng(seed)
        double = seed % 2 == 1
        agent = _random_agent(rng, double=double, dimension=1 + seed % 3)
        ids, p = agent.neighbour_ids, agent.dimension
        states, t = [], 0.0
        for _ in range(6):
            rel = {j: tuple(rng.uniform(-0.4, 0.4, p) + agent.offsets[k]) for k, j in enumerate(ids)}
            vel = {j: tuple(rng.uniform(-0.3, 0.3, p)) for j in ids}
            sensed = SensedState(
                agent=1,
                stamp=t,
                rel_positions=rel,
                rel_velocities=vel if double else None,
                velocity=(0.0,) * p if double else None,
            )
            bad = rng.integers(0, 8)
            if bad == 0:  # a neighbour missing
                sensed = SensedState(**{**_fields(sensed), 'rel_positions': dict(list(rel.items())[1:])})
            elif bad == 1:  # an edge out of its range
                far = {**rel, ids[0]: tuple(v + 10.0 for v in rel[ids[0]])}
                sensed = SensedState(**{**_fields(sensed), 'rel_positions': far})
            elif bad == 2:  # another agent's sensing
                sensed = SensedState(**{**_fields(sensed), 'agent': 2})
            try:
                out = agent.trigger(t - (bad == 3) * 0.5, sensed)  # 3: before the last trigger
                states.append((_knowledge(agent), _output(out)))
            except AgentError as error:
                states.append(str(error))
            for _ in range(int(rng.integers(1, 3 * len(ids)))):
                t += float(rng.choice([0.0, rng.uniform(0.0, 1e-2)]))
                info = _message(rng, agent, int(rng.choice(ids)), t, double=double)
                bad = rng.integers(0, 6)
                if bad == 0:
                    info = TriggerInfo(**{**_fields(info), 'stamp': t - 1.0})  # back in time
                elif bad == 1:
                    info = TriggerInfo(**{**_fields(info), 'rel_position': (math.nan,) * p})
                elif bad == 2:
                    info = TriggerInfo(**{**_fields(info), 'sender': 99})
                try:
                    agent.receive(info)
                    states.append(_knowledge(agent))
                except AgentError as error:
                    states.append(str(error))
                if rng.integers(0, 3) == 0 and agent.ready:
                    try:  # the search reads the rows the compiled receive wrote
                        states.append(_bits(agent.trigger_search(10.0).advance(t + 1e-3)))
                    except AgentError as error:  # a message put an edge out of its range
                        states.append(str(error))
            t += 1e-3
        return states

    pure, fast = both(make)
    assert pure == fast
    assert sum(isinstance(s, str) for s in pure) >= 1 or seed % 4 != 0


def _fields(info):
    return {name: getattr(info, name) for name in info.__slots__}


def _output(out):
    """A TriggerOutput by bits: its time, command and every message."""
    infos = [
        (i.sender, i.receiver, _bits(i.stamp), [_bits(v) for v in (*i.control, *i.rel_position)])
        + (None if i.rel_velocity is None else tuple(_bits(v) for v in i.rel_velocity),)
        for i in out.infos
    ]
    assert all(type(v) is float for i in out.infos for v in (*i.control, *i.rel_position))
    return _bits(out.time), [_bits(v) for v in out.control.tolist()], out.control.shape, infos


@pytest.mark.parametrize('double', [False, True])
def test_plain_messages_and_sensing_are_taken_compiled(both, double):
    # The compiled receive and trigger do take plain input (else the test above compares Python with Python).
    rng = np.random.default_rng(3)
    agent = _random_agent(rng, double=double, dimension=2)
    ids = agent.neighbour_ids
    sensed = SensedState(
        agent=1,
        stamp=0.0,
        rel_positions={j: tuple(agent.offsets[k]) for k, j in enumerate(ids)},
        rel_velocities=dict.fromkeys(ids, (0.1, 0.0)) if double else None,
        velocity=(0.0, 0.0) if double else None,
    )
    compiled.use_compiled(True)
    out = compiled.trigger()(agent, 0.0, sensed)
    assert out is not None and len(out.infos) == len(ids) and agent.triggers == 1
    info = _message(np.random.default_rng(1), agent, ids[0], 0.5, double=double)
    info = TriggerInfo(**{**_fields(info), 'control': (0.5, -0.25), 'rel_position': (0.25, 0.5)})
    assert compiled.receiver()(agent, info) is True and agent.infos_received == 1
    assert (
        compiled.receiver()(agent, TriggerInfo(**{**_fields(info), 'stamp': 0.25})) is False
    )  # back in time
    assert agent.infos_received == 1


class _StubSearch:
    """A search whose frontier walks to a drawn crossing time in drawn steps (a CrossingError at `bad`)."""

    def __init__(self, rng, start):
        self.frontier, self.result = start, None
        self.crossing = start + float(rng.choice([0.0, rng.exponential(0.05), math.inf]))
        self.step = float(rng.choice([1e-3, 1e-2, 0.05]))
        self.bad = start + 0.3 if rng.integers(0, 40) == 0 else math.inf

    def advance(self, until):
        while self.result is None and self.frontier <= until:
            if self.frontier >= self.bad:
                raise CrossingError(f'stub at t={self.frontier!r}')
            if self.frontier + self.step >= self.crossing:
                self.result = self.crossing
            else:
                self.frontier += self.step
        return self.result


class _StubAgent:
    def __init__(self, rng):
        self.rng, self.start = rng, 0.0

    def trigger_search(self, limit):
        return _StubSearch(self.rng, self.start)


@pytest.mark.parametrize('seed', range(12))
def test_the_compiled_agenda_gives_the_engines_order_and_times(both, seed):
    # formation_sim.sim.engine._Agenda on its Python heap and on _fastcore.Agenda: the same times,
    # the same agents due, the same agent named when a search fails, on random plans and ties.
    from formation_sim.sim.engine import EngineError, _Agenda

    def make():
        rng = np.random.default_rng(seed)
        ids = tuple(sorted(int(i) for i in rng.choice(np.arange(100), size=12, replace=False)))
        agents = {i: _StubAgent(np.random.default_rng([seed, i])) for i in ids}
        agenda = _Agenda(horizon=2.0, period=None, agent_ids=ids)
        assert (agenda.queue is not None) == compiled.active()
        due, receivers, seen, t = list(ids), [], [], 0.0
        for _ in range(60):
            for i in set(due) | set(receivers):
                agents[i].start = t
            agenda.plan(agents, due, receivers, t)  # the union, in the ids' order
            try:
                t_next = agenda.next_time()
            except EngineError as error:
                seen.append(str(error))
                break
            if t_next > 2.0:
                break
            t = t_next
            due = agenda.pop_due(t)
            seen.append((_bits(t), due))
            receivers = [int(i) for i in rng.choice(ids, size=int(rng.integers(0, 6)))]  # repeats, due ones
        return seen

    pure, fast = both(make)
    assert pure == fast
    assert len(pure) > 3


def test_sums_of_squares_add_left_to_right_as_the_compiled_trigger():
    # Not sum(): from Python 3.12 on (ROS Jazzy's) it compensates its rounding, the compiled core
    # does not. 1 + 3 × 2^-54 left to right stays 1; compensated it rounds up to 1 + 2^-52.
    from formation_agent.core.eta import _sum_of_squares

    values = (1.0, 2.0**-27, 2.0**-27, 2.0**-27)
    assert _sum_of_squares(values) == 1.0
    assert math.fsum(v * v for v in values) == 1.0 + 2.0**-52
