"""The engine's rounding floor (`engine.rounding_floor`) in other length units.

The same run stated in units of 2^k (every length × 2^k: positions, d_ij, Δ) is the same run:
ETA-1 with times × 2^k and β / 2^k (e_i = Σ ω_ij y_ij has no unit, nor have α and the commands),
ETA-2 with k1, k2, α_d and the velocities × 2^k and time kept (E_i has the units of an
acceleration). The floor compares the threshold with the triggering error's rounding step
(`theory.rounding_step`), in the threshold's units, so a run stops, or runs to its horizon, at the
same event in every unit. The former rule, the threshold against 8 ulps of the lengths, did not:
recomputed here on the run's own samples, it stops paper_single in units of 2^40 at t/2^40 ≈ 7.4.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from formation_sim.model import theory
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import FloorEdges, simulate
from formation_sim.sim.errors import EngineError

UNITS = (-40, -20, 0, 20, 40)
REL = 1e-9


def in_units(scenario, k: int):
    """`scenario` with every length × 2^k and the gains that make it the same run; and its time unit."""
    s = 2.0**k
    edges = tuple(dataclasses.replace(edge, d=edge.d * s) for edge in scenario.edges)
    gains = scenario.gains
    lengths = dict(delta=scenario.delta * s, positions=scenario.positions * s, edges=edges)
    if scenario.dynamics == 'single':
        gains = dataclasses.replace(gains, beta=gains.beta / s)
        return scenario.replace(gains=gains, horizon=scenario.horizon * s, **lengths), s
    P = gains.P * s  # B^T P = [k1, k2] (P's first entry is not used by a run)
    gains = dataclasses.replace(gains, k1=gains.k1 * s, k2=gains.k2 * s, alpha_d=gains.alpha_d * s, P=P)
    return scenario.replace(gains=gains, velocities=scenario.velocities * s, **lengths), 1.0


def _stop_time(error: EngineError) -> float:
    return float(str(error).split('at t=')[1].split()[0])


def _old_rule_stop(record, scenario) -> float | None:
    """Where the former floor, α e^{-βt} < 8 ulp(largest |x_i|), would have stopped a recorded run."""
    threshold = scenario.gains.alpha * np.exp(-scenario.gains.beta * record.sample_times)
    ulps = 8.0 * np.spacing(np.abs(record.sample_positions).max(axis=(1, 2)))
    below = np.nonzero(threshold < ulps)[0]
    return float(record.sample_times[below[0]]) if below.size else None


def test_paper_single_runs_to_its_horizon_alike_in_every_unit_where_the_old_rule_stopped_at_7_4():
    reference = None
    for k in UNITS:
        scenario, unit = in_units(load_scenario('paper_single'), k)
        record = simulate(scenario, sample_dt=None)  # its horizon, 10 × 2^k: no stop in any unit
        times = {agent: np.array(t) / unit for agent, t in record.trigger_times.items()}
        if reference is None:
            reference = times
        assert {a: len(t) for a, t in times.items()} == {a: len(t) for a, t in reference.items()}
        for agent, t in times.items():
            np.testing.assert_allclose(t, reference[agent], rtol=REL, atol=0.0)
        old = _old_rule_stop(record, scenario)
        if k <= 0:
            assert old is None
        elif k == 40:
            # 8 ulps of positions ~ 7.5 × 2^40 are 0.0078, which α e^{-t} = 10 e^{-t} passes near 7.
            assert old is not None and 7.0 < old / unit < 8.0


def test_paper_double_stops_at_the_same_event_in_every_unit():
    stops, chains = [], []
    for k in UNITS:
        scenario, _ = in_units(load_scenario('paper_double'), k)
        chain, worlds = [], []

        def on_event(t, world, due, chain=chain, worlds=worlds):
            chain.append((t, tuple(due)))
            worlds[:] = [world]

        with pytest.raises(EngineError, match='from here on rounding, not the dynamics, decides the events'):
            simulate(scenario, horizon=60.0, sample_dt=None, on_event=on_event)
        (world,) = worlds  # the engine's world, left at the stop
        stops.append(world.time)
        chains.append(chain)
        _check_the_formation_step_is_the_states(scenario, world)
    assert len({len(chain) for chain in chains}) == 1
    for chain in chains[1:]:
        assert [due for _, due in chain] == [due for _, due in chains[0]]
        np.testing.assert_allclose([t for t, _ in chain], [t for t, _ in chains[0]], rtol=REL, atol=0.0)
    assert stops == pytest.approx([stops[0]] * len(stops), rel=REL)


def test_paper_single_stops_near_the_same_time_in_every_unit():
    # ETA-1's chain in other units is the same up to rounding, which the dynamics amplify as the
    # threshold shrinks (the search's first trial span, 1e-3 s, is not stated in the run's time
    # unit: its certified steps differ by rounding); at the stop, t ≈ 34, the chains are apart by
    # about one event, no longer by orders of magnitude (2^40 units: 7.4 with 8 ulps of lengths).
    stops = []
    for k in (-40, 0, 40):
        scenario, unit = in_units(load_scenario('paper_single'), k)
        with pytest.raises(EngineError, match='ulps of the triggering error') as stop:
            simulate(scenario, horizon=60.0 * unit, sample_dt=None)
        stops.append(_stop_time(stop.value) / unit)
    assert max(stops) - min(stops) < 0.01 * min(stops)


def _check_the_formation_step_is_the_states(scenario, world):
    """At the stop, the step taken at the formation is the step at the true states (rel 1e-9)."""
    edges = FloorEdges.of(scenario)
    heads, tails, d = scenario.edge_indices()
    x, q = world.positions, world.velocities
    capacities = theory.edge_capacities(scenario)
    slack = capacities - np.linalg.norm(x[heads] - x[tails] - d, axis=1)
    speed = np.linalg.norm(q[heads] - q[tails], axis=1)
    ulp_y, ulp_q = np.spacing(max(np.abs(x).max(), edges.offset)), np.spacing(np.abs(q).max())
    gains = scenario.gains
    at_states = theory.rounding_step(
        capacities, slack, ulp_y, k1=gains.k1, k2=gains.k2, speed=speed, ulp_q=ulp_q
    )
    at_formation = theory.rounding_step(
        edges.capacity, edges.capacity, ulp_y, k1=gains.k1, k2=gains.k2, ulp_q=ulp_q
    )
    assert float(at_states.max()) == pytest.approx(at_formation, rel=REL)


def test_the_floors_spacing_is_numpys_for_every_value_it_meets():
    # rounding_floor takes ulps of max |x| (>= 0, or NaN) with math.ulp where it agrees with np.spacing.
    from formation_sim.sim.engine import _spacing

    rng = np.random.default_rng(2)
    values = [0.0, 5e-324, 2.2e-308, 1.0, 1e300, 1.5e300, 1.7976931348623157e308, math.inf, math.nan]
    values += list(10.0 ** rng.uniform(-320, 308, size=2000))
    for value in values:
        assert np.float64(_spacing(value)).tobytes() == np.float64(np.spacing(value)).tobytes(), value
