"""The engine's numpy steps done compiled (issue 31, its fourth step): the world's closed-form step
(`World.advance`, `World.state_at`), the rounding floor's largest |component| and the edge watch of a
run without event samples (`EdgeLengths.add_rows`) give numpy's very floats.

Whole runs on both paths are tests/formation_agent/core/test_compiled.py's (every sample and trigger
time equal); here each piece is compared with its numpy twin over random states far beyond what one
run visits (tiny and large k3 tau, both sides of the series limit, NaN), and the fall-backs: an array
the compiled pass does not take is left to numpy, nothing written.
"""

from __future__ import annotations

import numpy as np
import pytest

from formation_agent.core import _fastcore, compiled
from formation_agent.core.closed_form import SERIES_LIMIT
from formation_sim.model.generate import random_scenario
from formation_sim.sim import engine, world
from formation_sim.sim.errors import WorldError
from formation_sim.sim.samples import EdgeLengths
from formation_sim.sim.world import World

pytestmark = pytest.mark.skipif(not compiled.AVAILABLE, reason='compiled core not built')


def _bits(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array).view(np.int64)


def _random_world(rng, *, double: bool) -> World:
    n, p = int(rng.integers(1, 40)), int(rng.integers(1, 4))
    scale = 10.0 ** rng.integers(-4, 5)
    out = World(
        agent_ids=tuple(range(n)),
        positions=rng.normal(size=(n, p)) * scale,
        velocities=rng.normal(size=(n, p)) * scale if double else None,
        damping=float(10.0 ** rng.uniform(-3, 3)) if double else None,
    )
    out.arrays()[2][:] = rng.normal(size=(n, p)) * scale
    return out


@pytest.mark.parametrize('double', [False, True])
def test_the_compiled_world_step_is_numpys_bit_for_bit(on_path, monkeypatch, double) -> None:
    rng = np.random.default_rng(31 + double)
    small = 0
    for _ in range(400):
        w = _random_world(rng, double=double)
        tau = float(10.0 ** rng.uniform(-12, 1))
        small += double and w.damping * tau < SERIES_LIMIT
        on_path(False)
        want = w.state_at(tau)
        on_path(True)
        with monkeypatch.context() as patch:  # the compiled step, not numpy, computes it
            patch.setattr(world, 'advance_double', None)
            got = w.state_at(tau)
        for a, b in zip(got, want):
            assert (a is None) == (b is None)
            if a is not None:
                assert np.array_equal(_bits(a), _bits(b))
    assert not double or 50 < small < 350  # both branches of z - 1 + e^{-z} were compared


def test_world_advance_on_both_paths_keeps_the_same_state(on_path) -> None:
    rng = np.random.default_rng(7)
    worlds = {}
    for on in (False, True):
        on_path(on)
        w = worlds[on] = _random_world(np.random.default_rng(3), double=True)
        t = 0.0
        for _ in range(200):
            t += float(10.0 ** rng.uniform(-9, -1))
            w.advance(t)
        rng = np.random.default_rng(7)
    for a, b in zip(worlds[False].arrays(), worlds[True].arrays()):
        assert np.array_equal(_bits(a), _bits(b))


def test_the_compiled_step_leaves_arrays_it_does_not_take_to_numpy() -> None:
    x = np.arange(6.0).reshape(3, 2)
    out = np.full_like(x, 7.0)
    for bad in (x.astype(np.float32), np.asfortranarray(np.arange(12.0).reshape(3, 4))[:, :2], [[1.0, 2.0]]):
        assert _fastcore.advance(bad, None, x, out, None, 0.0, 1.0) is False
        assert _fastcore.advance(x, None, bad, out, None, 0.0, 1.0) is False
    assert _fastcore.advance(x, None, x, np.zeros(5), None, 0.0, 1.0) is False  # another size
    assert (out == 7.0).all()
    with pytest.raises(TypeError, match='q and q_out must both be arrays or both None'):
        _fastcore.advance(x, x, x, out, None, 1.0, 1.0)


def test_the_largest_component_is_numpys(on_path) -> None:
    rng = np.random.default_rng(5)
    for _ in range(200):
        x = rng.normal(size=(int(rng.integers(1, 30)), 3)) * 10.0 ** rng.integers(-300, 300)
        assert _fastcore.abs_max(x) == float(np.abs(x).max())
    nan = np.array([[1.0, -5.0], [np.nan, 2.0]])
    assert np.isnan(_fastcore.abs_max(nan)) and np.isnan(np.abs(nan).max())
    assert _fastcore.abs_max(np.zeros((0, 2))) is None  # numpy raises its error for an empty array
    assert _fastcore.abs_max(np.zeros((3, 2))[:, 0]) is None  # not contiguous: numpy does it
    on_path(True)
    assert engine._abs_max(np.array([[3.0, -8.5]])) == 8.5
    assert engine._abs_max(np.array([[3.0, -8.5]], dtype=np.float32)) == 8.5  # numpy's fall-back


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_the_compiled_edge_watch_is_numpys(on_path, dynamics) -> None:
    scenario = random_scenario(n=40, seed=3, dynamics=dynamics)
    watches = {on: EdgeLengths(scenario) for on in (False, True)}
    rng = np.random.default_rng(11)
    for step in range(300):
        x = rng.normal(size=(scenario.n, scenario.dimension)) * 10.0 ** rng.integers(-3, 4)
        if step == 150:
            x[:, 0] = np.nan  # every edge measured from here on keeps NaN, as numpy.maximum does
        rows = sorted({int(k) for k in rng.integers(0, scenario.n, size=int(rng.integers(1, 5)))})
        for on, watch in watches.items():
            on_path(on)
            watch.add_rows(rows, x)
    assert np.isnan(watches[True].squared).any() and not np.isnan(watches[True].squared).all()
    assert np.array_equal(watches[False].squared, watches[True].squared, equal_nan=True)


def test_the_edge_watch_refuses_what_it_cannot_take(on_path) -> None:
    scenario = random_scenario(n=10, seed=1, dynamics='single')
    watch = EdgeLengths(scenario)
    on_path(True)
    watch.add_rows([0], np.ones((scenario.n, scenario.dimension)))  # builds the compiled tables
    start, incident, heads, tails = watch._csr
    x = np.ones((scenario.n, scenario.dimension))
    assert _fastcore.watch_edges(x, [scenario.n], start, incident, heads, tails, watch.squared) is False
    assert _fastcore.watch_edges(x[:-1], [0], start, incident, heads, tails, watch.squared) is False
    assert (
        _fastcore.watch_edges(x, [0], start.astype(np.int32), incident, heads, tails, watch.squared) is False
    )
    assert (watch.squared == 0.0).all()
    with pytest.raises(IndexError):  # numpy's path then raises its error for the unknown row
        watch.add_rows([scenario.n], x)


def test_the_rows_of_agents_are_their_indices_and_a_stranger_is_named():
    world = World(agent_ids=(7, 3, 5), positions=np.zeros((3, 2)))
    assert world.rows([5, 7, 5]) == [world.index(5), world.index(7), world.index(5)] == [2, 0, 2]
    assert world.rows(()) == []
    with pytest.raises(WorldError, match=r'^unknown agent 4; agents are \[7, 3, 5\]$'):
        world.rows([3, 4])
    with pytest.raises(WorldError, match=r'^unknown agent 4; agents are \[7, 3, 5\]$'):
        world.index(4)
