"""The largest command a scenario will ask for: the proofs' bound where it settles the question,
else the largest in an exact in-process run (`formation validate --max-speed`); and the speed scale
κ that keeps the commands within a robot's limits (`choose_speed_scale`, `--speed-scale auto`).

`largest_command(scenario, max_speed=V)` returns the bound of `formation_sim.model.command_bound`
when the theorems' hypotheses hold and it is within V (a guarantee); otherwise it runs the exact
engine to the horizon and returns the largest command of that run (what this run asks for, not a
guarantee: other starting points may ask for more), saying which.

`choose_speed_scale(scenario, limits=...)` runs the exact engine once at κ = 1 and hands its
largest commands, its settling time and the proofs' bound to the pure arithmetic of
`formation_sim.model.speed_choice` (which explains both values of κ).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from formation_agent.core.safety import DEFAULT_TURN
from formation_sim.model.command_bound import CommandBound, command_bound
from formation_sim.model.errors import JamError, TheoryError
from formation_sim.model.scenario import Scenario
from formation_sim.model.speed_choice import (
    OBSERVED_MARGIN,
    SETTLE_FRACTION,
    RobotLimits,
    Settling,
    SpeedScaleChoice,
    check_limits_apply,
    linear_crossing,
    scale_choice,
    settling_time,
)
from formation_sim.model.warp_choice import (
    WARP_CAP,
    WARP_EVENT_RATE,
    WARP_WINDOW,
    WarpChoice,
    guaranteed_warp,
    observed_warp,
    warp_limit,
)
from formation_sim.sim.engine import simulate
from formation_sim.sim.record import RunRecord

DOUBLE_GRID = 0.01
"""ETA-2 moves along curves between events: its settling time is known to this sample spacing [s, κ = 1]."""


def measured_command(scenario: Scenario, *, horizon: float | None = None) -> CommandBound:
    """The largest command of each agent in an exact run (`measured_run`)."""
    return measured_run(scenario, horizon=horizon)[0]


def measured_run(scenario: Scenario, *, horizon: float | None = None) -> tuple[CommandBound, RunRecord]:
    """(the largest command of each agent in an exact run (ETA-1: ||u_i(t_k)|| over its triggers;
    ETA-2: ||q_i|| and ||u^d_i - k3 q_i|| over the run).

    Exact, not sampled: ETA-1 commands change only at events; between events an ETA-2 velocity
    moves on the segment from q_i(t_k) towards u^d_i / k3 and its derivative shrinks as e^{-k3 τ},
    so both norms are largest at event times, where the engine stops anyway.  The record samples
    every event time and the horizon (ETA-2: also a 0.01 s grid, for its settling time)."""
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
            np.maximum(
                acceleration,
                np.linalg.norm(world.controls - world.damping * velocity, axis=1),
                out=acceleration,
            )  # κ k3 at κ

    record = simulate(scenario, horizon=horizon, sample_dt=DOUBLE_GRID if double else None, on_event=on_event)
    note(seen['world'], seen.get('velocity'))  # the controls set at the last event
    if double:  # the record samples every event time and the horizon
        speed = np.linalg.norm(record.sample_velocities, axis=2).max(axis=0)
    ids = scenario.agent_ids
    return CommandBound(
        source='exact run',
        speed=dict(zip(ids, speed.tolist())),
        acceleration=dict(zip(ids, acceleration.tolist())) if double else None,
        reference=(
            f'the exact in-process run to t = {record.horizon:g} ({record.total_events} events): what this '
            'run asks for, not a guarantee'
        ),
    ), record


def largest_command(
    scenario: Scenario,
    *,
    max_speed: float = math.inf,
    max_acceleration: float = math.inf,
    horizon: float | None = None,
) -> tuple[CommandBound, CommandBound | None]:
    """(the answer, the theory's bound if it was looked at and did not settle it).

    The theory's bound answers when it exists and is within the limits; else the exact run does."""
    try:
        bound = command_bound(scenario)
    except TheoryError:
        return measured_command(scenario, horizon=horizon), None
    within = bound.max_speed <= max_speed and (
        bound.max_acceleration is None or bound.max_acceleration <= max_acceleration
    )
    if within:
        return bound, None
    return measured_command(scenario, horizon=horizon), bound


def unit_scale(scenario: Scenario) -> Scenario:
    """The scenario at κ = 1 (the paper's time); itself when it is already."""
    return scenario.with_scale(speed_scale=1.0) if scenario.gains.speed_scale != 1.0 else scenario


def settling(scenario: Scenario, record: RunRecord, *, fraction: float = SETTLE_FRACTION) -> Settling:
    """When the run of `record` reached `fraction` of its initial formation error for good (exact for
    ETA-1, whose positions are linear between the event samples; to the grid for ETA-2)."""
    times = np.asarray(record.sample_times, dtype=float)
    positions = np.asarray(record.sample_positions, dtype=float)
    heads, tails, d = scenario.edge_indices()
    edge_errors = positions[:, heads, :] - positions[:, tails, :] - d  # (K, m, p)
    errors = np.linalg.norm(edge_errors, axis=2).max(axis=1)
    threshold = fraction * float(errors[0])

    def crossing(k: int) -> float:
        return linear_crossing(
            edge_errors[k],
            edge_errors[k + 1],
            t0=float(times[k]),
            t1=float(times[k + 1]),
            threshold=threshold,
        )

    single = scenario.dynamics == 'single'
    return Settling(
        initial_error=float(errors[0]),
        time=settling_time(times, errors, threshold=threshold, segment_crossing=crossing if single else None),
        run_horizon=float(record.horizon),
        fraction=fraction,
        resolution='exact' if single else f'the {DOUBLE_GRID:g} s sample grid and the events (κ = 1)',
    )


def choose_speed_scale(
    scenario: Scenario,
    *,
    limits: RobotLimits,
    margin: float = OBSERVED_MARGIN,
    paper_horizon: float | None = None,
) -> SpeedScaleChoice:
    """Both speed scales κ for `limits` (`formation_sim.model.speed_choice`): the guaranteed one from
    the proofs' bound, the observed one from the exact run at κ = 1 to `paper_horizon` (default
    the scenario's horizon: all a run at any κ <= 1 covers of the paper's time), with the time each
    needs to settle.  LimitsError if the limits do not apply to this scenario."""
    check_limits_apply(limits, scenario.dynamics)
    paper = unit_scale(scenario)
    run_horizon = float(scenario.horizon if paper_horizon is None else paper_horizon)
    observed, record = measured_run(paper, horizon=run_horizon)
    try:
        bound = command_bound(paper)
        theory_speeds: tuple[float, float | None] | str = (bound.max_speed, bound.max_acceleration)
    except TheoryError as error:
        theory_speeds = str(error)
    return scale_choice(
        limits=limits,
        dynamics=scenario.dynamics,
        theory=theory_speeds,
        observed=(observed.max_speed, observed.max_acceleration),
        settling=settling(paper, record),
        horizon=scenario.horizon,
        margin=margin,
    )


def command_steps(scenario: Scenario, *, horizon: float) -> tuple[np.ndarray, np.ndarray, RunRecord]:
    """ETA-1: (the event times, the largest ||u_i|| in force from each to the next, the record) of
    the exact run of `scenario` to `horizon`: the team's largest command as a step function of time
    (exact: ETA-1's commands change at events only)."""
    times: list[float] = []
    largest: list[float] = []
    seen: dict = {}

    def note(t_from: float, world) -> None:
        times.append(t_from)
        largest.append(float(np.linalg.norm(world.controls, axis=1).max()))

    def on_event(t: float, world, due) -> None:
        # Called before the agents due at t trigger: the controls in force since the previous event
        # (rounds at one instant: only the last round's controls are ever in force).
        last = seen.get('t')
        if last is not None and t > last:
            note(last, world)
        seen['t'], seen['world'] = t, world

    jam = None if scenario.safety is None else JAM_EVENTS_PER_AGENT * len(scenario.agent_ids)
    turn = None if scenario.safety is None else scenario.safety.turn

    def watch(t: float, events: int) -> None:  # the engine reports every 1000 steps
        if jam is not None and turn is not None and events > jam:
            raise JamError(
                f'the exact run the speed is chosen from triggers {events} times by t = {t:.4g} s of the '
                f"paper's time (more than {JAM_EVENTS_PER_AGENT} per agent): the safety layer's robots "
                f'jam, three or more blocking each other at the tie-break turn λ = {turn:g} '
                '(docs/SAFETY.md, "Ties")',
                jams=((turn, events, t),),
            )

    record = simulate(scenario, horizon=horizon, sample_dt=None, on_event=on_event, progress=watch)
    note(seen['t'], seen['world'])  # the controls set at the last event
    return np.asarray(times), np.asarray(largest), record


def untangled(
    scenario: Scenario, *, horizon: float
) -> tuple[Scenario, tuple[np.ndarray, np.ndarray, RunRecord], tuple[tuple[float, int, float], ...]]:
    """(the scenario, its `command_steps` to `horizon`, the jams met on the way): with the safety
    layer at the default tie-break turn, the first of `TIE_BREAK_TURNS` whose exact run does not jam
    (the scenario then carries that λ, and every agent turns by it: a choice made before step 0, like
    the warp's); a scenario with another turn, or no layer, is run as it is.  JamError when every
    turn tried jams, naming each."""
    safety = scenario.safety
    turns = TIE_BREAK_TURNS if safety is not None and safety.turn == DEFAULT_TURN else (None,)
    jams: list[tuple[float, int, float]] = []
    for turn in turns:
        trial = (
            scenario
            if turn is None or safety is None
            else scenario.replace(safety=replace(safety, turn=turn))
        )
        try:
            return trial, command_steps(trial, horizon=horizon), tuple(jams)
        except JamError as error:
            jams.extend(error.jams)
            last = str(error)
    if len(jams) > 1:
        tried = ', '.join(f'λ = {turn:g} ({events} events by t = {t:.4g} s)' for turn, events, t in jams)
        last = f'{last}; it jams at every tie-break turn tried: {tried}'
    raise JamError(
        f'{last}: nothing was run: place the robots otherwise, choose another --min-separation, or set '
        "the scenario's safety.turn",
        jams=tuple(jams),
    )


TIE_BREAK_TURNS = (DEFAULT_TURN, 2.0, 3.0)
"""The tie-break turns λ the exact run before a warped run tries, in this order, while the robots
jam (docs/SAFETY.md, "Ties"): 1.5 forms every Burgers placement measured (50 of 50) and 37 of the
38 teams of the stress sweep; 2.0 frees the stress sweep's seed 19 and the three cars' jams, but
costs about 30 % more time where 1.5 forms; 3.0 frees seed 19 too but jams placements 1.5 forms."""

JAM_EVENTS_PER_AGENT = 5000
"""With the safety layer, an exact run that triggers more than this many times per agent is a jam
(docs/SAFETY.md, "Stress sweep": the intervals shrink with h): the speed's choice tries the next
tie-break turn (`untangled`), or refuses, rather than run on for minutes (random_square(204,
side=2.2) at D = 0.45 m: 4000 events by 13.6 s)."""

LAYER_ROUNDING = 1.0 + 1e-9
"""The safety layer's cap κ <= L / (v̄ × this): its filter's ||v|| <= v̄ holds up to rounding."""


def choose_time_warp(
    scenario: Scenario,
    *,
    limits: RobotLimits,
    margin: float = OBSERVED_MARGIN,
    cap: float = WARP_CAP,
    window: float = WARP_WINDOW,
    event_rate: float = WARP_EVENT_RATE,
) -> WarpChoice:
    """The time warps for `limits` (`formation_sim.model.warp_choice`, ETA-1): the observed one from
    the exact run at κ = 1 to cap × the scenario's horizon (all the warped run can reach of the
    paper's time), the guaranteed one from the proofs' decaying bound.  With the safety layer every
    applied command is within v̄ whatever the run does, so κ <= L / v̄ is a guarantee: the cap (a
    wall-clock run that strays from the exact one, as the layer's ties make likely, then asks no
    more than the robots can do).  LimitsError where no warp applies (ETA-2, no speed limit)."""
    limit = warp_limit(limits, scenario.dynamics, cap=cap, window=window)
    if scenario.safety is not None:  # the layer's filter keeps every applied command within v̄
        cap = min(cap, limit / (scenario.safety.max_speed * LAYER_ROUNDING))
    paper = unit_scale(scenario)
    horizons = (cap * float(scenario.horizon), float(scenario.horizon))
    paper, (times, largest, record), jams = untangled(paper, horizon=horizons[0])
    observed = observed_warp(
        times=times,
        largest=largest,
        limits=limits,
        horizons=horizons,
        margin=margin,
        cap=cap,
        window=window,
        events=np.concatenate([np.asarray(when, dtype=float) for when in record.trigger_times.values()]),
        agents=len(scenario.agent_ids),
        event_rate=event_rate,
    )
    guaranteed, missing = None, None
    try:
        bound = command_bound(paper)
        guaranteed = guaranteed_warp(
            speed=bound.max_speed,
            dotyi=max(bound.dotyi.values()),
            beta=paper.gains.beta,
            limits=limits,
            horizons=horizons,
            cap=cap,
            window=window,
        )
    except TheoryError as error:
        missing = str(error)
    return WarpChoice(
        turn=paper.safety.turn if jams and paper.safety is not None else None,
        jams=jams,
        limits=limits,
        observed=observed,
        guaranteed=guaranteed,
        guaranteed_missing=missing,
        settling=settling(paper, record),
        margin=margin,
        cap=cap,
        window=window,
        event_rate=event_rate,
    )
