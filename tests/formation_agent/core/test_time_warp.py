"""The time warp s(t) (formation_agent.core.time_warp): its pieces, its two maps and their
inverse, its parameter form, and the refusals naming the rule time_warp and the value."""

from __future__ import annotations

import math
import random

import pytest

from formation_agent.core.errors import WarpError
from formation_agent.core.time_warp import MAX_PIECES, TimeWarp

WARP = TimeWarp(paper_starts=(0.0, 0.3, 1.0), rates=(0.1, 0.4, 1.0))


def test_real_starts_are_the_integral_of_one_over_kappa():
    # t_1 = 0.3 / 0.1 = 3, t_2 = 3 + 0.7 / 0.4 = 4.75 (by hand)
    assert WARP.real_starts[0] == 0.0
    assert WARP.real_starts[1] == pytest.approx(3.0, abs=1e-15)
    assert WARP.real_starts[2] == pytest.approx(4.75, abs=1e-15)


@pytest.mark.parametrize(
    ('t', 's', 'kappa'),
    [(0.0, 0.0, 0.1), (1.0, 0.1, 0.1), (3.5, 0.5, 0.4), (4.75, 1.0, 1.0), (10.0, 6.25, 1.0)],
)
def test_paper_time_and_rate_by_hand(t, s, kappa):
    assert WARP.paper(t) == pytest.approx(s, abs=1e-14)
    assert WARP.rate(t) == kappa
    assert WARP.paper_rate(s) == kappa
    assert WARP.real(s) == pytest.approx(t, abs=1e-13)


def test_maps_are_monotone_inverse_and_continuous():
    rng = random.Random(7)
    starts = [0.0]
    for _ in range(40):
        starts.append(starts[-1] + rng.uniform(1e-3, 2.0))
    warp = TimeWarp(paper_starts=tuple(starts), rates=tuple(rng.uniform(1e-3, 3.0) for _ in starts))
    ts = sorted(rng.uniform(0.0, 2.0 * warp.real_starts[-1]) for _ in range(20_000)) + list(warp.real_starts)
    ts.sort()
    ss = [warp.paper(t) for t in ts]
    assert all(b >= a for a, b in zip(ss, ss[1:]))  # monotone in floats, breakpoints included
    for t, s in zip(ts, ss):
        assert abs(warp.real(s) - t) <= 1e-12 * max(1.0, t) / warp.min_rate
    # Continuous: each breakpoint maps onto its paper start, and just before it nearly so.
    for t_m, s_m in zip(warp.real_starts, warp.paper_starts):
        assert warp.paper(t_m) == s_m
        assert warp.real(s_m) == t_m
        assert abs(warp.paper(math.nextafter(t_m, -math.inf)) - s_m) <= 1e-12 * max(1.0, s_m)


def test_constant_warp_is_the_speed_scale():
    warp = TimeWarp.constant(0.37)
    for t in (0.0, 0.5, 7.0, 1e3):
        assert warp.paper(t) == 0.37 * t
        assert warp.real(0.37 * t) == pytest.approx(t, rel=1e-15)
    assert warp.pieces == 1 and warp.max_rate == warp.min_rate == 0.37


def test_parameter_round_trip():
    values = WARP.to_parameter()
    assert values == [0.0, 0.1, 0.3, 0.4, 1.0, 1.0]
    assert TimeWarp.from_parameter(values) == WARP
    assert WARP.to_dict()['rates'] == [0.1, 0.4, 1.0]


@pytest.mark.parametrize(
    ('values', 'words'),
    [
        ([], 'an even, non-zero count), got 0 numbers'),
        ([0.0, 1.0, 2.0], 'got 3 numbers'),
        ([0.5, 1.0], 'the first piece starts at s = 0, got 0.5'),
        ([0.0, 1.0, 0.0, 2.0], 'piece starts must increase, got 0.0 then 0.0'),
        ([0.0, 0.0], 'every rate must lie in [1e-06, 1e+06] (the rule speed_scale), got 0.0'),
        ([0.0, 2e6], 'got 2000000.0'),
        ([0.0, math.nan], 'rates must be finite numbers, got nan'),
        ([0.0, 'fast'], "rates must be finite numbers, got 'fast'"),
        ([0.0, 1.0, math.inf, 1.0], 'paper_starts must be finite numbers, got inf'),
    ],
)
def test_bad_warps_are_refused_with_rule_and_value(values, words):
    with pytest.raises(WarpError) as caught:
        TimeWarp.from_parameter(values)
    assert str(caught.value).startswith('time_warp: ')
    assert words in str(caught.value)


def test_too_many_pieces_refused():
    n = MAX_PIECES + 1
    with pytest.raises(WarpError, match=f'at most {MAX_PIECES} pieces, got {n}'):
        TimeWarp(paper_starts=tuple(float(k) for k in range(n)), rates=(1.0,) * n)


def _robots_lab():
    from formation_sim.model.scenario import load_scenario

    return load_scenario('robots_lab')


def _swap_square_safe():
    from formation_agent.core.safety import SafetyConfig
    from formation_sim.sim.safety_cases import swap_square

    return swap_square(safety=SafetyConfig(min_separation=0.45))


@pytest.mark.parametrize('make', [_robots_lab, _swap_square_safe])
def test_warped_agents_in_real_time_trigger_when_the_engine_s_warped_run_does(make):
    """A team of `WarpedAgent`s driven in real time, as agent nodes on the wall clock drive them
    (the world moving in the paper's time), triggers at the engine's warped triggering times; with
    the safety layer too (the other robots within R handed on at each trigger, as an agent node
    hands them), its interventions counted and the latest one in real time."""
    import numpy as np

    from formation_agent.core.time_warp import WarpedAgent
    from formation_sim.sim.engine import build_agent, simulate
    from formation_sim.sim.world import World

    scenario = make()
    horizon = 8.0
    record = simulate(scenario, horizon=horizon, sample_dt=None, time_warp=WARP)
    expected = record.trigger_times
    agents = {i: WarpedAgent(build_agent(scenario, i), WARP) for i in scenario.agent_ids}
    world = World.from_scenario(scenario)
    got = {i: [] for i in agents}
    due, t = list(agents), 0.0
    while True:
        world.advance(max(world.time, agents[due[0]].paper(t)))  # the world in s
        outbox = []
        for i in due:
            core = agents[i].core
            sensed = world.sense(i, core.neighbour_ids)
            if scenario.safety is None:
                out = agents[i].trigger(t, sensed)
            else:
                nearby = world.nearby(i, scenario.safety.sensing_radius, exclude=core.neighbour_ids)
                out = agents[i].trigger(t, sensed, nearby=nearby)
            assert out.time == t and all(info.stamp == t for info in out.infos)
            world.set_control(i, out.control)  # u_p: the world moves in s
            got[i].append(t)
            outbox.extend(out.infos)
        for info in outbox:
            agents[info.receiver].receive(info)
        plan = {i: agent.next_trigger_time(horizon) for i, agent in agents.items()}
        t = min(plan.values())
        if not t <= horizon:
            break
        due = sorted(i for i, ti in plan.items() if ti == t)
    for i, times in expected.items():
        assert len(got[i]) == len(times) > 5
        np.testing.assert_allclose(got[i], times, rtol=1e-12, atol=1e-14)
    assert np.array_equal(agents[1].control, agents[1].core.control)  # the paper's u_p
    if scenario.safety is not None:
        counts = {i: agent.safety_interventions for i, agent in agents.items()}
        assert counts == {int(i): n for i, n in record.extra['safety']['interventions'].items()}
        assert sum(counts.values()) > 0
        last = max(agent.safety_last_intervention or 0.0 for agent in agents.values())
        assert last == pytest.approx(record.extra['safety']['last_intervention'], rel=1e-12)
        assert last > WARP.real_starts[-1]  # in real time: beyond s = 1.0, where t = s/κ differs


@pytest.mark.parametrize(
    ('values', 'words'),
    [
        ({'time_warp': [0.0, 0.5, 1.0]}, 'time_warp: must be the pairs [s_0, κ_0, s_1, κ_1, ...]'),
        ({'time_warp': [0.0, 0.5], 'algorithm': 'eta2'}, 'time_warp: eta1 only'),
        (
            {'time_warp': [0.0, 0.5], 'speed_scale': 0.5},
            'time_warp: replaces speed_scale, which must then be 1',
        ),
        ({'time_warp': [0.0, 0.5], 'robot': 'none'}, 'time_warp: applies to robots (wall clock) only so far'),
    ],
)
def test_the_agents_parameter_is_checked_with_rule_and_value(values, words):
    from formation_agent.ros.config import AGENT_PARAMETERS, _warp_problems

    assert next(spec for spec in AGENT_PARAMETERS if spec.name == 'time_warp').default == []
    problems = _warp_problems({'algorithm': 'eta1', 'speed_scale': 1.0, 'robot': 'unicycle', **values})
    assert len(problems) == 1 and words in problems[0]
    assert (
        _warp_problems(
            {'algorithm': 'eta1', 'speed_scale': 1.0, 'robot': 'unicycle', 'time_warp': [0.0, 1.0]}
        )
        == []
    )


def test_the_safety_layer_takes_a_time_warp():
    """Issue 27: the agent's safety rules no longer refuse a warp (every robot follows the same
    one, so the layer holds in the paper's time); its own rules still apply."""
    from formation_agent.ros.config import _safety_problems

    values = {
        'min_separation': 0.45,
        'sensing_radius': 2.0,
        'safety_gamma': 2.0,
        'safety_max_speed': 0.5,
        'safety_turn': 1.0,
        'algorithm': 'eta1',
        'dimension': 2,
        'agent_id': 1,
        'neighbour_ids': [2, 4],
        'other_robot_ids': [3],
        'time_warp': [0.0, 0.352, 1.0, 0.44],
    }
    assert _safety_problems(values) == []
    assert _safety_problems({**values, 'dimension': 3}) == [
        'min_separation: the safety layer is planar, got dimension 3'
    ]
