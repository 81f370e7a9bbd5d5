"""The largest command a scenario will ask for: the proofs' bound where it settles the question,
else the largest in an exact in-process run (`formation validate --max-speed`).

`largest_command(scenario, max_speed=V)` returns the bound of `formation_sim.model.command_bound`
when the theorems' hypotheses hold and it is within V (a guarantee); otherwise it runs the exact
engine to the horizon and returns the largest command of that run (what this run asks for, not a
guarantee: other starting points may ask for more), saying which.
"""

from __future__ import annotations

import math

import numpy as np

from formation_sim.model import theory
from formation_sim.model.command_bound import CommandBound, command_bound
from formation_sim.model.scenario import Scenario
from formation_sim.sim.engine import simulate


def measured_command(scenario: Scenario, *, horizon: float | None = None) -> CommandBound:
    """The largest command of each agent in an exact run (ETA-1: ||u_i(t_k)|| over its triggers;
    ETA-2: ||q_i|| and ||u^d_i - k3 q_i|| over the run).

    Exact, not sampled: ETA-1 commands change only at events; between events an ETA-2 velocity
    moves on the segment from q_i(t_k) towards u^d_i / k3 and its derivative shrinks as e^{-k3 τ},
    so both norms are largest at event times, where the engine stops anyway."""
    double = scenario.dynamics == 'double'
    n = scenario.n
    speed = np.zeros(n)
    acceleration = np.zeros(n)
    seen = {}

    def on_event(t: float, world, due) -> None:
        # Called before the agents due at t trigger: the controls set at the previous event.
        seen['world'] = world
        note(world, seen.get('velocity'))
        seen['velocity'] = None if world.velocities is None else world.velocities.copy()

    def note(world, velocity) -> None:
        controls = np.linalg.norm(world.controls, axis=1)
        if not double:
            np.maximum(speed, controls, out=speed)
        elif velocity is not None:  # the segment that began at the previous event
            np.maximum(acceleration, np.linalg.norm(world.controls - scenario.gains.k3 * velocity, axis=1), out=acceleration)

    record = simulate(scenario, horizon=horizon, sample_dt=None, on_event=on_event)
    note(seen['world'], seen.get('velocity'))  # the controls set at the last event
    if double:  # the record samples every event time and the horizon
        speed = np.linalg.norm(record.sample_velocities, axis=2).max(axis=0)
    ids = scenario.agent_ids
    return CommandBound(
        source='exact run',
        speed=dict(zip(ids, speed.tolist())),
        acceleration=dict(zip(ids, acceleration.tolist())) if double else None,
        reference=f'the exact in-process run to t = {record.horizon:g} ({record.total_events} events): what this run asks for, not a guarantee',
    )


def largest_command(scenario: Scenario, *, max_speed: float = math.inf, max_acceleration: float = math.inf, horizon: float | None = None) -> tuple[CommandBound, CommandBound | None]:
    """(the answer, the theory's bound if it was looked at and did not settle it).

    The theory's bound answers when it exists and is within the limits; else the exact run does."""
    try:
        bound = command_bound(scenario)
    except theory.TheoryError:
        return measured_command(scenario, horizon=horizon), None
    within = bound.max_speed <= max_speed and (bound.max_acceleration is None or bound.max_acceleration <= max_acceleration)
    if within:
        return bound, None
    return measured_command(scenario, horizon=horizon), bound
