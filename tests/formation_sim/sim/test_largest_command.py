"""The largest command: the theory answers when its bound is within the limits, an exact run otherwise."""

from __future__ import annotations

import math

import numpy as np

from formation_agent.core.tension import omega
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.largest_command import largest_command, measured_command


def test_the_theory_answers_within_the_limits_and_an_exact_run_beyond():
    scenario = load_scenario('robots_square')
    answer, loose = largest_command(scenario, max_speed=0.22)
    assert answer.source == 'theory' and loose is None
    answer, loose = largest_command(scenario, max_speed=0.15, horizon=5.0)  # the bound, 0.194, says nothing
    assert answer.source == 'exact run' and loose.source == 'theory'
    assert answer.max_speed < 0.15 < loose.max_speed


def test_the_measured_eta1_command_is_the_largest_u_i_at_the_triggers():
    # Independently: u_i(t_k) = -Σ ω_ij (x_i - x_j - d_ij) at every trigger, from the record's event samples.
    scenario = load_scenario('paper_single')
    horizon = 2.0
    record = simulate(scenario, horizon=horizon, sample_dt=None)
    largest = {}
    for agent, times in record.trigger_times.items():
        k = scenario.index(agent)
        for t in times:
            x = record.sample_positions[int(np.flatnonzero(record.sample_times == t)[0])]
            u = np.zeros(scenario.dimension)
            for j, d in scenario.neighbours(agent).items():
                y = x[k] - x[scenario.index(j)] - d
                u -= omega(np.linalg.norm(y), scenario.delta - np.linalg.norm(d)) * y
            largest[agent] = max(largest.get(agent, 0.0), float(np.linalg.norm(u)))
    measured = measured_command(scenario, horizon=horizon)
    for agent in scenario.agent_ids:
        assert math.isclose(measured.speed[agent], largest[agent], rel_tol=1e-9), agent
