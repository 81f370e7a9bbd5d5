"""The simulator's exact world without a node: moved and sampled as the engine moves and samples
its world, and stopped by the engine's rule once the threshold reaches the rounding of the states."""

from __future__ import annotations

import numpy as np

from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.nodes.exact_world import ExactWorld
from formation_sim.sim.world import World


def test_an_event_samples_the_grid_before_it_and_the_state_at_it_in_closed_form():
    scenario = load_scenario('paper_double')
    seen = []
    exact = ExactWorld(scenario, sample_period=0.25, on_sample=lambda t, x, q: seen.append(t))
    exact.sampler.event()  # t = 0
    reference = World.from_scenario(scenario)  # the same world, moved on its own
    for world in (exact.world, reference):
        world.set_control(2, [0.5, -1.25])
    exact.advance(0.6)
    assert exact.time == 0.6 and exact.sampler.times == [0.0, 0.25, 0.5, 0.6] and seen == exact.sampler.times
    for t, x, q in zip(exact.sampler.times[1:], exact.sampler.positions[1:], exact.sampler.velocities[1:]):
        x_ref, q_ref = reference.state_at(t)
        assert np.array_equal(x, x_ref) and np.array_equal(q, q_ref)  # bit for bit
    exact.advance(0.75)  # an event on the grid: sampled once
    assert exact.sampler.times == [0.0, 0.25, 0.5, 0.6, 0.75]


def test_the_run_stops_where_the_threshold_reaches_the_rounding_of_the_states():
    scenario = load_scenario('paper_single')
    exact = ExactWorld(scenario, sample_period=0.0)
    assert exact.floor_problem() is None
    exact.advance(10.0)  # threshold 10 e^-10 = 4.5e-4: far above the rounding of positions ~ 5
    assert exact.floor_problem() is None and exact.sampler.times == [10.0]
    exact.advance(40.0)  # 10 e^-40 = 4.2e-17: below one ulp of the positions
    problem = exact.floor_problem()
    assert problem.startswith(
        'at t=40.0 the triggering threshold 4.25e-17 is below 8 ulps of the triggering error'
    )
    assert 'shorten the horizon or lower beta' in problem
