"""A time warp in the exact engine (docs/SPEED_SCALE.md, "A time warp"): the warped run is the
κ = 1 run in the time s(t).

The warp identity: every triggering time of the warped run is the warp's label t(s) of the κ = 1
run's, bit for bit (the agents run in s), and maps back to it within rounding; the positions at
real times t are the κ = 1 run's at s(t); the commands κ(t) u_p stay within the limits the warp
was chosen for; what does not apply is refused with the rule and the value.
"""

from __future__ import annotations

import numpy as np
import pytest

from formation_agent.core.time_warp import TimeWarp
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.model.speed_choice import RobotLimits
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError
from formation_sim.sim.largest_command import choose_time_warp

WARP = TimeWarp(paper_starts=(0.0, 0.3, 1.0, 2.5), rates=(0.1, 0.37, 1.0, 2.0))
HORIZON = 9.0  # real: s(9) = 7.72, within the κ = 1 run
PAPER_HORIZON = 12.0
SCENARIOS = {
    'robots_lab': load_scenario('robots_lab'),
    'paper_single': load_scenario('paper_single'),
    'random_single': random_scenario(n=7, seed=18, dynamics='single'),
}


@pytest.fixture(scope='module')
def runs():
    out = {}
    for name, scenario in SCENARIOS.items():
        reference = simulate(scenario, horizon=PAPER_HORIZON, sample_dt=None)
        warped = simulate(scenario, horizon=HORIZON, sample_dt=0.05, time_warp=WARP)
        out[name] = reference, warped
    return out


@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_triggering_times_are_the_kappa_one_run_under_the_warp(runs, name):
    reference, warped = runs[name]
    end = WARP.paper(HORIZON)
    assert end < PAPER_HORIZON
    assert warped.total_events > 5 * SCENARIOS[name].n
    for agent, times in reference.trigger_times.items():
        expected = [s for s in times if s <= end]
        got = warped.trigger_times[agent]
        assert got == [WARP.real(s) for s in expected]  # bit for bit: the same events, relabelled
        back = np.array([WARP.paper(t) for t in got])
        np.testing.assert_allclose(back, expected, rtol=1e-13, atol=1e-15)
    assert warped.horizon == HORIZON and warped.sample_times[-1] == HORIZON
    assert warped.extra['time_warp']['rates'] == list(WARP.rates)


@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_positions_at_t_are_the_kappa_one_positions_at_s_of_t(runs, name):
    reference, warped = runs[name]
    s_ref = np.asarray(reference.sample_times)  # every event of the κ = 1 run: x linear in between
    x_ref = np.asarray(reference.sample_positions)
    t = np.asarray(warped.sample_times)
    x = np.asarray(warped.sample_positions)
    assert np.all(np.diff(t) > 0.0)
    scale = np.abs(x_ref).max()
    for k in range(0, t.size, 7):
        s = WARP.paper(float(t[k]))
        j = min(int(np.searchsorted(s_ref, s, side='right')) - 1, s_ref.size - 2)
        w = (s - s_ref[j]) / (s_ref[j + 1] - s_ref[j])
        expected = x_ref[j] + w * (x_ref[j + 1] - x_ref[j])
        np.testing.assert_allclose(x[k], expected, rtol=0.0, atol=1e-9 * scale)


def test_chosen_warp_keeps_every_command_within_the_limits():
    limits = RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1)
    scenario = load_scenario('robots_lab').replace(horizon=30.0)
    choice = choose_time_warp(scenario, limits=limits)
    warp = choice.warp
    seen = []

    def on_event(s, world, due):
        seen.append((s, np.linalg.norm(world.controls, axis=1).max()))  # in force until s

    record = simulate(scenario, horizon=30.0, sample_dt=None, time_warp=warp, on_event=on_event)
    worst = 0.0
    for (s0, _), (s1, command) in zip(seen, seen[1:]):
        # the command in force on [s0, s1) meets every rate of the warp over that interval
        inside = [k for start, k in zip(warp.paper_starts, warp.rates) if s0 < start < s1]
        worst = max(worst, max([warp.paper_rate(s0), *inside]) * command)
    assert worst <= 0.22 / 1.25 * (1.0 + 1e-12)
    assert worst >= 0.9 * 0.22 / 1.25  # the warp uses the room it has
    assert warp.max_rate == 1.0 and warp.rates[0] < 0.2
    # the constant κ of today: the same run settles 3× later
    assert choice.settle_time(warp) < choice.settling.at(warp.rates[0]) / 2.5
    assert record.total_events > 0


@pytest.mark.parametrize(
    ('scenario', 'kwargs', 'words'),
    [
        (load_scenario('paper_double'), {}, "dynamics 'double'"),
        (load_scenario('robots_lab').with_scale(speed_scale=0.5), {}, 'speed_scale 0.5'),
        (load_scenario('robots_lab'), {'period': 0.1}, 'period 0.1'),
    ],
)
def test_warp_refused_where_it_does_not_apply(scenario, kwargs, words):
    with pytest.raises(EngineError, match='time_warp: applies to ETA-1 event-triggered runs') as caught:
        simulate(scenario, horizon=1.0, time_warp=WARP, **kwargs)
    assert words in str(caught.value)


def test_with_the_safety_layer_the_warp_never_asks_more_than_the_limit_whatever_the_run_does():
    """The layer's filter keeps every applied command within v̄ = 0.5 m/s, so a warp capped at
    κ <= 0.22 / 0.5 cannot ask a robot for more than 0.22 m/s, on any run: the pieces that the
    exact run alone would allow up to κ = 1 (where its commands are small) are held at 0.44."""
    from formation_agent.core.safety import SafetyConfig

    limits = RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1)
    scenario = load_scenario('robots_anywhere')
    plain = choose_time_warp(scenario, limits=limits).warp
    assert plain.max_rate == 1.0  # without the layer: the exact run's commands decay, κ rises to 1
    safe = scenario.replace(safety=SafetyConfig(min_separation=0.46))
    choice = choose_time_warp(safe, limits=limits)
    assert choice.cap == choice.warp.max_rate < 0.44 and choice.cap == pytest.approx(0.44, rel=1e-8)
    assert choice.cap * 0.5 <= 0.22
    assert choice.warp.rates[0] == pytest.approx(0.22 / (1.25 * 0.5), rel=1e-12)  # the observed start
    assert choice.to_dict()['cap'] == choice.cap
