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
from formation_agent.core.eta import Eta1Agent, Eta2Agent
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
    compiled.configure(gap_fraction=0.125)  # hands the compiled core the patched limit
    try:
        pure, fast = both(attempt)
    finally:
        monkeypatch.undo()
        compiled.configure(gap_fraction=0.125)
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
