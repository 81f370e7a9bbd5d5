"""The speed scale κ from a robot's limits, the settling time, and the threshold floor a pose noise asks
for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.eta import Eta1Agent
from formation_msgs_py.types import SensedState, TriggerInfo
from formation_sim.model.errors import LimitsError
from formation_sim.model.scenario import load_scenario
from formation_sim.model.speed_choice import (
    NOISE_QUANTILE,
    RobotLimits,
    Settling,
    check_limits_apply,
    linear_crossing,
    scale_choice,
    scenario_noise_floor,
    settling_time,
)


def _choice(limits, *, observed=(2.0, None), theory=(8.0, None), dynamics='single', settle=3.0, margin=1.25):
    settling = Settling(initial_error=0.5, time=settle, run_horizon=60.0)
    return scale_choice(
        limits=limits,
        dynamics=dynamics,
        theory=theory,
        observed=observed,
        settling=settling,
        horizon=60.0,
        margin=margin,
    )


def test_each_kappa_puts_the_binding_command_exactly_at_its_limit_over_the_margin():
    choice = _choice(RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1))
    assert (
        choice.observed.value * 2.0 * 1.25 == pytest.approx(0.22) and 'speed 0.22' in choice.observed.binding
    )
    assert choice.guaranteed.value * 8.0 == pytest.approx(0.22) and choice.guaranteed.margin == 1.0
    # the time to settle is the κ = 1 time over κ: the slower run takes longer
    assert choice.observed.settle_time == pytest.approx(3.0 / choice.observed.value)
    assert choice.guaranteed.settle_time > choice.observed.settle_time
    assert choice.value == choice.observed.value and choice.source == 'observed'
    # a slow turn rate binds through ||u|| <= W l
    turn = _choice(RobotLimits(max_speed=0.22, max_angular_speed=1.0, control_point_distance=0.1))
    assert (
        turn.observed.value * 2.0 * 1.25 / 0.1 == pytest.approx(1.0)
        and 'turn rate 1 rad/s' in turn.observed.binding
    )


def test_eta2_acceleration_scales_with_kappa_squared():
    limits = RobotLimits(max_speed=0.5, max_acceleration=1.0)
    choice = _choice(limits, observed=(0.3, 50.0), theory=(2.0, 900.0), dynamics='double')
    kappa = choice.observed.value
    assert kappa * kappa * 50.0 * 1.25 == pytest.approx(1.0) and 'acceleration' in choice.observed.binding
    assert kappa * 0.3 * 1.25 < 0.5
    assert choice.guaranteed.value == pytest.approx(math.sqrt(1.0 / 900.0))


def test_no_motion_needs_no_scale_and_auto_keeps_the_papers_time():
    choice = _choice(RobotLimits(max_speed=0.22), observed=(0.0, None), settle=0.0)
    assert math.isinf(choice.observed.value) and choice.value == 1.0
    assert 'no limit binds' in choice.source


def test_a_slow_scale_is_reported_beyond_the_horizon_not_refused():
    choice = _choice(RobotLimits(max_speed=0.001), observed=(2.0, None), settle=3.0)
    assert choice.observed.settle_time > 60.0
    assert any('beyond the horizon 60 s' in line for line in choice.lines())


def test_guaranteed_is_missing_with_its_reason_outside_the_proofs():
    choice = _choice(RobotLimits(max_speed=0.22), theory='rule beta: β >= β0')
    assert choice.guaranteed is None and any('guaranteed: none: rule beta' in line for line in choice.lines())


@pytest.mark.parametrize(
    ('limits', 'dynamics', 'complaint'),
    [
        (RobotLimits(), 'single', 'needs at least one of --max-speed'),
        (
            RobotLimits(max_speed=0.22, max_acceleration=1.0),
            'single',
            'ETA-1 commands velocities (uxsingle) that jump at every event',
        ),
    ],
)
def test_limits_no_kappa_can_meet_are_refused(limits, dynamics, complaint):
    with pytest.raises(LimitsError, match=re_escape(complaint)):
        check_limits_apply(limits, dynamics)
    check_limits_apply(RobotLimits(max_speed=0.5, max_acceleration=1.0), 'double')  # ETA-2 takes both


def re_escape(text: str) -> str:
    import re

    return re.escape(text)


@pytest.mark.parametrize('value', [0.0, -1.0, math.nan])
def test_bad_limits_name_the_rule(value):
    with pytest.raises(LimitsError, match='max_speed: must be a number > 0'):
        RobotLimits(max_speed=value)


def test_linear_crossing_is_where_the_largest_edge_error_comes_down_to_the_threshold():
    rng = np.random.default_rng(3)
    for _ in range(50):
        start = rng.normal(size=(4, 2))
        end = 0.05 * rng.normal(size=(4, 2))
        threshold = 0.5 * (np.linalg.norm(start, axis=1).max() + np.linalg.norm(end, axis=1).max())
        if np.linalg.norm(end, axis=1).max() > threshold:
            continue
        t = linear_crossing(start, end, t0=1.0, t1=2.0, threshold=threshold)
        grid = np.linspace(1.0, 2.0, 20001)
        path = start[None] + (grid - 1.0)[:, None, None] * (end - start)[None]
        errors = np.linalg.norm(path, axis=2).max(axis=1)
        # by brute force: the last grid point above the threshold lies just before t
        last_above = grid[np.flatnonzero(errors > threshold)[-1]]
        assert last_above <= t <= last_above + 1e-4 + 1e-12
        assert np.linalg.norm(start + (t - 1.0) * (end - start), axis=1).max() == pytest.approx(
            threshold, rel=1e-9
        )


def test_settling_time_waits_for_the_last_time_above():
    times = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    errors = np.array([1.0, 0.01, 0.2, 0.04, 0.03])  # below, above again, then below for good
    assert settling_time(times, errors, threshold=0.05) == 3.0
    assert math.isinf(settling_time(times, np.array([1.0, 0.5, 0.4, 0.3, 0.2]), threshold=0.05))
    assert settling_time(times, np.zeros(5), threshold=0.0) == 0.0


def test_the_noise_floor_is_what_noisy_senses_put_into_e_i_by_the_agent_itself():
    """Monte Carlo through the agent core: agent 1 of robots_lab at the formation senses its edges
    with noise σ, each neighbour sends its own noisy sense of the same edge; e_1 just after is what
    the derivation says: σ sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²) = √10 σ per axis (ω_ij = 1), and its
    norm exceeds c0 = 3 s with probability e^{-9/2} in the plane."""
    scenario = load_scenario('robots_lab')
    sigma = 0.005
    floor, per_agent, formula = scenario_noise_floor(scenario, pose_noise=sigma)
    assert 'q = 3' in formula and floor == pytest.approx(NOISE_QUANTILE * max(per_agent.values()))
    assert per_agent[1] == pytest.approx(math.sqrt(10.0) * sigma)
    target = {1: np.zeros(2), 2: np.array([1.0, 0.0]), 4: np.array([0.0, 1.0])}
    rng = np.random.default_rng(7)
    samples = []
    for _ in range(3000):
        agent = Eta1Agent(
            agent_id=1, neighbours=scenario.neighbours(1), delta=scenario.delta, alpha=1.0, beta=0.1
        )
        pose = {k: v + rng.normal(0.0, sigma, 2) for k, v in target.items()}
        agent.trigger(
            0.0, SensedState(agent=1, stamp=0.0, rel_positions={j: tuple(pose[1] - pose[j]) for j in (2, 4)})
        )
        for j in (2, 4):  # the neighbour's own sense, of fresh poses
            mine, theirs = target[1] + rng.normal(0.0, sigma, 2), target[j] + rng.normal(0.0, sigma, 2)
            agent.receive(
                TriggerInfo(
                    sender=j, receiver=1, stamp=0.0, control=(0.0, 0.0), rel_position=tuple(theirs - mine)
                )
            )
        samples.append(agent.error(0.0))
    samples = np.array(samples)
    assert samples.std(axis=0) == pytest.approx([per_agent[1]] * 2, rel=0.06)
    beyond = np.mean(np.linalg.norm(samples, axis=1) > floor)
    assert 0.004 < beyond < 0.02  # e^{-9/2} = 0.011: the norm of two Gaussian components beyond 3 s


def test_eta2_noise_floor_adds_the_velocity_noise_of_pose_differences():
    scenario = load_scenario('robots_lab_double')
    single, _, _ = scenario_noise_floor(load_scenario('robots_lab'), pose_noise=0.005)
    floor, per_agent, formula = scenario_noise_floor(
        scenario, pose_noise=0.005, pose_period=0.01, speed_scale=0.5
    )
    gains = scenario.gains
    w = 2.0 / (scenario.delta - 1.0)
    assert per_agent[1] == pytest.approx(
        0.005 * math.sqrt(10) * w * (gains.k1 + gains.k2 * math.sqrt(2) / (0.5 * 0.01))
    )
    assert 'Δt = 0.01 s' in formula and floor > single
    with pytest.raises(LimitsError, match='pose_period'):
        scenario_noise_floor(scenario, pose_noise=0.005)
