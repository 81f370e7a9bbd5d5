"""The proofs' bound on the commands holds on exact runs, and is what robots_square is built on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.model.command_bound import command_bound
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.largest_command import measured_command


@pytest.mark.parametrize('name', ['robots_square', 'paper_single', 'paper_double'])
def test_no_exact_run_asks_for_more_than_the_bound(name):
    scenario = load_scenario(name)
    bound = command_bound(scenario)
    run = measured_command(scenario, horizon=min(scenario.horizon, 10.0))
    for agent in scenario.agent_ids:
        assert 0.0 < run.speed[agent] <= bound.speed[agent], agent
        if bound.acceleration is not None:
            assert 0.0 < run.acceleration[agent] <= bound.acceleration[agent], agent


@pytest.mark.parametrize('seed', range(4))
def test_the_bound_holds_on_random_teams(seed):
    scenario = random_scenario(n=5, seed=seed)
    bound = command_bound(scenario)
    run = measured_command(scenario, horizon=3.0)
    assert all(run.speed[i] <= bound.speed[i] for i in scenario.agent_ids)


def test_the_sampled_bound_is_tighter_than_dotyi_by_at_least_alpha():
    scenario = load_scenario('robots_square')
    bound = command_bound(scenario)
    for agent in scenario.agent_ids:
        assert bound.speed[agent] <= bound.dotyi[agent] - scenario.gains.alpha + 1e-15


def test_robots_square_fits_a_turtlebot3_by_the_bound_alone():
    bound = command_bound(load_scenario('robots_square'))
    assert bound.max_speed < 0.22 and max(bound.dotyi.values()) < 0.22
    assert bound.max_turn_rate(0.1) < 2.84
    assert math.isclose(bound.max_speed, 0.19448, rel_tol=1e-4)


def test_an_eta2_velocity_bound_is_the_tension_bound():
    from formation_sim.model import theory

    scenario = load_scenario('paper_double')
    bound = command_bound(scenario)
    k_nu = theory.theorem_constants(scenario).k_nu
    assert all(value == math.sqrt(2.0 * k_nu) for value in bound.speed.values())
    assert np.isfinite(bound.max_acceleration)
