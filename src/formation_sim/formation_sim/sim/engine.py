"""Exact event-driven simulation of a whole team in one process.

The engine is only a router and a physical world: the agents are the same `formation_agent.core.eta`
objects a robot would run. It moves the world from event to event in closed form; there is no
time step anywhere. At each event time it lets every due agent sense and trigger, delivers all
triggering information, and asks every agent whose knowledge changed for its next time once.

Speed (BENCHMARKS.md): that question is answered lazily. Each agent's certified search
(`Eta1Agent/Eta2Agent.trigger_search`) only advances while its frontier, a certified lower bound on
the agent's time, is at or before the team's earliest known next event; a search overtaken by new
information is dropped after the steps that were needed. The steps are those of an uninterrupted
search, so the triggering times are the floats `next_trigger_time` gives, as in the agent nodes.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from formation_agent.core import compiled
from formation_agent.core.crossing import DEFAULT_TOLERANCE, PRECISION_HINT, CrossingSearch
from formation_agent.core.errors import CrossingError
from formation_agent.core.eta import (
    _FIRST_SPAN,
    ALGORITHM_GAINS,
    SCALE_GAINS,
    Eta1Agent,
    Eta2Agent,
    make_agent,
    make_agents,
)
from formation_agent.core.neighbourhood import Neighbourhood
from formation_agent.core.time_warp import TimeWarp
from formation_agent.core.trigger import ExponentialRule
from formation_msgs_py.types import TriggerInfo
from formation_sim.model import theory
from formation_sim.sim.errors import EngineError
from formation_sim.sim.record import RunRecord
from formation_sim.sim.samples import EdgeLengths, Samples, TrajectoryWriter
from formation_sim.sim.stop import RunStop
from formation_sim.sim.world import World

if TYPE_CHECKING:
    from formation_agent.core import _fastcore


# Numbers the sampling grid of one run may hold (positions, and velocities for double
# integrators, at every grid point): 400 MB as doubles.  A smaller spacing would exhaust memory
# (or, in the simulator node, publish for hours) instead of failing at once.
MAX_GRID_VALUES = 50_000_000


def check_sample_dt(sample_dt: float | None, *, horizon: float, scenario) -> None:
    """Refuse a grid spacing that is negative, not finite, or too fine for the horizon (MAX_GRID_VALUES).

    0 and None mean no grid (samples at events only).
    """
    if sample_dt is None or sample_dt == 0.0:
        return
    if not (isinstance(sample_dt, (int, float)) and math.isfinite(sample_dt) and sample_dt > 0.0):
        raise EngineError(
            f'the sample spacing must be a finite number >= 0 (0: samples at events only), got {sample_dt!r}'
        )
    per_sample = scenario.n * scenario.dimension * (2 if scenario.dynamics == 'double' else 1)
    values = horizon / sample_dt * per_sample
    if values > MAX_GRID_VALUES:
        raise EngineError(
            f'the sample spacing {sample_dt!r} s asks for {horizon / sample_dt:.3g} samples of '
            f'{per_sample} numbers over the horizon {horizon:g} s ({values:.3g} numbers; at most '
            f'{MAX_GRID_VALUES:.0e}): use a spacing of at least {horizon * per_sample / MAX_GRID_VALUES:.3g} '
            's, or 0 (samples at events only)'
        )


def build_agent(
    scenario,
    agent_id: int,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    neighbourhood: Neighbourhood | None = None,
) -> Eta1Agent | Eta2Agent:
    """The ROS-free agent object for `agent_id`, holding only what that agent knows; `neighbourhood`: its
    neighbours and d_ij built already (`Neighbourhood.team`), else from `scenario.neighbours(agent_id)`."""
    return make_agent(
        agent_id=agent_id,
        neighbours=scenario.neighbours(agent_id) if neighbourhood is None else neighbourhood,
        tolerance=tolerance,
        **_agent_settings(scenario),
    )


def build_agents(scenario, *, tolerance: float = DEFAULT_TOLERANCE) -> dict[int, Eta1Agent | Eta2Agent]:
    """`build_agent` for every agent of the scenario, their neighbourhoods built for the whole team at once
    (`Neighbourhood.team`: one numpy call for all d_ij, one for all capacities; the same floats) and the
    gains chosen once (`make_agents`): the same agents. A neighbourhood it would refuse is built by its
    agent, which raises the error."""
    ids = scenario.agent_ids
    hoods = Neighbourhood.team(neighbours={i: scenario.neighbours(i) for i in ids}, delta=scenario.delta)
    if hoods is None:
        return {i: build_agent(scenario, i, tolerance=tolerance) for i in ids}
    return make_agents(neighbours=hoods, tolerance=tolerance, **_agent_settings(scenario))


def _agent_settings(scenario) -> dict:
    """What every agent of the scenario is made with (`make_agent`), but its id and neighbours."""
    algorithm = 'eta1' if scenario.dynamics == 'single' else 'eta2'
    return {
        'algorithm': algorithm,
        'delta': scenario.delta,
        'gains': {
            name: getattr(scenario.gains, name) for name in (*ALGORITHM_GAINS[algorithm], *SCALE_GAINS)
        },
        'safety': scenario.safety,
        'trigger_rule': scenario.trigger_rule,
    }


class Sampler:
    """Collects the state at every event and on a regular grid, by pure evaluation.

    Shared by the engine and the simulator node; `on_sample(t, x, q)` is called after each
    sample is added (the simulator checks connectivity and queues it for its tools there). The
    states stay in memory (`positions`, `velocities`) unless a `writer` streams them to disk.
    Without event samples, `watch` keeps each edge's largest length at its agents' triggering
    times (`EdgeLengths`), so the summary's edge maxima stay exact for single integrators.
    """

    def __init__(
        self,
        world: World,
        sample_dt: float | None,
        *,
        events: bool = True,
        on_sample: Callable[[float, np.ndarray, np.ndarray | None], None] | None = None,
        writer: TrajectoryWriter | None = None,
        watch: EdgeLengths | None = None,
        clock: _WarpClock | None = None,
    ) -> None:
        self.world = world
        self.clock = clock  # a time warp: the world runs in the paper's time, the samples in real time
        self.dt = sample_dt
        self.events = events
        self.on_sample = on_sample
        self.writer = writer
        self.watch = watch
        self.times: list[float] = []
        self.positions: list[np.ndarray] = []
        self.velocities: list[np.ndarray] = []
        self._next_grid = 1

    def grid_until(self, t_end: float) -> None:
        """Sample grid points after the world's time and before t_end (at t_end too without event samples)."""
        if not self.dt:
            return
        while True:
            tg = real = self._next_grid * self.dt
            if self.clock is not None:
                tg = self.clock.paper(real)  # the grid is in real time, the world in the paper's
            if tg > t_end or (tg == t_end and self.events):
                return
            self._next_grid += 1
            if tg > self.world.time:
                x, q = self.world.state_at(tg)
                self._add(real, x, q)

    def event(self, *, due=(), force: bool = False) -> None:
        """The world's present state as a sample (with event samples, or `force`); `due`: the agents
        about to trigger now, whose edges the watch measures."""
        if self.watch is not None and due:
            self.watch.add_rows(self.world.rows(due), self.world.arrays()[0])
        now = self.world.time if self.clock is None else self.clock.real(self.world.time)
        if not (self.events or force) or (self.times and self.times[-1] == now):
            return
        self._add(now, self.world.positions, self.world.velocities)

    def _add(self, t: float, x: np.ndarray, q: np.ndarray | None) -> None:
        self.times.append(t)
        if self.writer is not None:
            self.writer.append(x, q)
        else:
            self.positions.append(x)
            if q is not None:
                self.velocities.append(q)
        if self.on_sample is not None:
            self.on_sample(t, x, q)

    def samples(self) -> Samples:
        """What was sampled: in memory, or the writer's trajectory, completed and memory-mapped."""
        maxima = None if self.watch is None else self.watch.maxima
        if self.writer is not None:
            return self.writer.close(self.times, edge_maxima=maxima)
        return Samples.from_rows(self.times, self.positions, self.velocities or None, edge_maxima=maxima)


@dataclass(frozen=True)
class _WarpClock:
    """A time warp as the engine applies it (ETA-1 at κ = 1; docs/SPEED_SCALE.md, "A time warp"):
    the world and the agents run in the paper's time s to s(horizon), exactly the κ = 1 run; the
    record is in real time (t(s) for the events, the grid in real time), the real horizon and its
    paper time mapping onto each other exactly; `on_event` and `progress` get the paper's time."""

    warp: TimeWarp
    horizon: float  # real
    paper_horizon: float

    @classmethod
    def of(cls, warp: TimeWarp, scenario, *, horizon: float, period: float | None) -> _WarpClock:
        if scenario.dynamics != 'single' or scenario.gains.speed_scale != 1.0 or period is not None:
            raise EngineError(
                'time_warp: applies to ETA-1 event-triggered runs at speed scale 1 (the warp replaces κ), '
                f'got dynamics {scenario.dynamics!r}, speed_scale {scenario.gains.speed_scale!r}, period '
                f'{period!r}'
            )
        return cls(warp=warp, horizon=horizon, paper_horizon=warp.paper(horizon))

    def paper(self, t: float) -> float:
        return self.paper_horizon if t == self.horizon else self.warp.paper(t)

    def real(self, s: float) -> float:
        return self.horizon if s == self.paper_horizon else self.warp.real(s)

    def relabel(self, trigger_times: dict[int, list[float]]) -> dict[int, list[float]]:
        return {i: [self.real(s) for s in times] for i, times in trigger_times.items()}


def _next_event_time(heap, serial, searches, horizon: float) -> float:
    """The earliest planned time of the team, advancing unfinished searches only as needed.

    A search whose frontier is at or before the earliest known time might still cross there or
    earlier, so it takes certified steps until its frontier passes the next entry; ties put
    searches first (kind 0), so a planned time on top is the team's minimum. The steps are those
    `next_trigger_time` would take, so the times are the same floats, but a search overtaken by
    new information before it finishes costs only the steps up to that moment.
    """
    while heap:
        key, kind, i, number = heap[0]
        if serial[i] != number:
            heapq.heappop(heap)
            continue
        if kind == 1 or key > horizon:
            return key
        heapq.heappop(heap)
        search = searches[i]
        until = heap[0][0] if heap else math.inf
        try:
            result = search.advance(min(until, horizon))
        except CrossingError as error:
            raise EngineError(f'agent {i}: {error}; {PRECISION_HINT}') from error
        if result is None:
            heapq.heappush(heap, (search.frontier, 0, i, number))
        elif result <= horizon:
            heapq.heappush(heap, (result, 1, i, number))
    return math.inf


ROUNDING_FLOOR_ULPS = 8.0
"""A run stops once the threshold is below this many rounding steps of the triggering error
(`rounding_floor`)."""


@dataclass(frozen=True)
class FloorEdges:
    """What `rounding_floor` needs of the team's edges, computed once per run (`of`): the least
    capacity Δ - ||d_ij|| (and its edge (i, j)) and the largest |component| of the d_ij."""

    capacity: float
    pair: tuple[int, int]
    offset: float
    _factors: dict = field(default_factory=dict, compare=False, repr=False)  # by (k1, k2): rounding_factors

    @classmethod
    def of(cls, scenario) -> FloorEdges:
        capacities = theory.edge_capacities(scenario)
        k = int(np.argmin(capacities))
        _, _, d = scenario.edge_indices()
        return cls(capacity=float(capacities[k]), pair=scenario.edges[k].pair, offset=float(np.abs(d).max()))

    def factors(self, gains: tuple[float, float] | None) -> tuple:
        """`theory.rounding_factors` at the formation of the least-capacity edge (y_ij = 0: slack = c), for
        ETA-1 (`gains` None) or ETA-2's (k1, k2); made once per run and gains."""
        found = self._factors.get(gains)
        if found is None:
            c = self.capacity
            found = self._factors[gains] = (
                theory.rounding_factors(c, c)
                if gains is None
                else theory.rounding_factors(c, c, k1=gains[0], k2=gains[1])
            )
        return found


def rounding_floor(agent, world: World, edges: FloorEdges) -> str | None:
    """Why the event chain can no longer be trusted at `world.time`, or None.

    The threshold α e^{-βt} (α_d e^{-β_d t}) decays without end, the rounding of the states does
    not. A relative state y_ij = x_i - x_j - d_ij is computed from the positions, so it is rounded
    at about u = ulp(max |x_i|, |d_ij|) (largest components over the team) however small it gets,
    and one such step moves the triggering error by ρ = g_ij u ((gij); ETA-2: (k1 g_ij + k2 h_ij
    ||q_ij||) u + k2 f_ij ulp(max |q_i|), with the agent's real-time k1, k2): the rounding step the
    `precision` rule bounds at t = 0 (`theory.rounding_step`), in the units of the threshold. Once
    the threshold is below ROUNDING_FLOOR_ULPS such steps, whether an agent triggers is decided by
    rounding, and the events come ever faster (paper_single with β = 1: 6-7 events per second
    until t ≈ 37, then 19 000 in its 45th second). Both the engine and the distributed simulator
    stop there, with this message, at the same event.

    ρ is taken at the formation (y_ij = 0, q_ij = 0: g_ij = f_ij = 2/(Δ - ||d_ij||), largest on the
    edge of least capacity), which is where the threshold reaches rounding: it bounds the
    formation error, so by then ||y_ij|| is at rounding level too and g_ij(||y_ij||) = g_ij(0)
    to 1e-9 (tests/formation_sim/sim/test_engine_rounding_floor.py checks it at paper_double's
    stop). That keeps the rule O(n) at every event, like the lengths' ulps it replaces (~1 µs more
    a call, measured).

    ρ and the threshold have the same units, so the stop does not move when the run is stated in
    other length units (lengths × 2^k; ETA-1 times × 2^k and β / 2^k, e_i having no unit; ETA-2
    k1, k2, α_d and the velocities × 2^k). Comparing the threshold with ulps of the states, as
    before, stopped paper_single in units of 2^40 at t/2^40 = 7.42 instead of its horizon 10.
    Measured on the paper's examples, before → now: paper_single and paper_double with their
    horizons (10 s) run to the end, as before; with a horizon of 60 s paper_single stops at
    t = 35.245 → 34.364 (threshold 1.19e-14 < 8 × 1.52e-15 on edge (2, 3)), paper_double at
    t = 34.898 → 34.241 (1.35e-14 < 8 × 1.75e-15).
    """
    x, q, _ = world.arrays()  # the world's own arrays (read, not copied: this runs at every event)
    ulp_y = _spacing(max(_abs_max(x), edges.offset))
    if q is None:  # theory.rounding_step(c, c, ulp_y), its factors made once (edges.factors)
        step = theory.rounding_step_of(edges.factors(None), ulp_y)
    else:
        ulp_q = _spacing(_abs_max(q))
        step = theory.rounding_step_of(edges.factors((agent.k1, agent.k2)), ulp_y, ulp_q=ulp_q)
    floor = ROUNDING_FLOOR_ULPS * step
    t = world.time
    threshold = agent.threshold(t)
    if threshold >= floor:
        return None
    i, j = edges.pair
    how = 'g_ij × ulp, (gij)' if q is None else 'k1 g_ij × ulp + k2 f_ij × ulp(q), (gij) (fij)'
    return (
        f'at t={t!r} the triggering threshold {threshold:.3g} is below {ROUNDING_FLOOR_ULPS:g} ulps of the '
        f'triggering error ({floor:.3g}): one ulp of the states ({ulp_y:.3g}) moves it by up to {step:.3g} '
        f'({how} at the formation, on edge ({i}, {j})); from here on rounding, not the dynamics, decides '
        'the events; shorten the horizon or lower beta'
    )


def _spacing(value: float) -> float:
    """float(np.spacing(value)) for a value >= 0 or NaN: math.ulp where they agree (finite, below the
    largest double, whose spacing numpy calls inf), without numpy's call."""
    return math.ulp(value) if value < 1e300 else float(np.spacing(value))


def _abs_max(array: np.ndarray) -> float:
    """float(np.abs(array).max()), compiled where the compiled core runs (one pass, no temporary)."""
    fast = compiled.abs_max()
    top = None if fast is None else fast(array)
    return float(np.abs(array).max()) if top is None else top


def due_twice(agent_id: int, threshold_model, t: float) -> str:
    """Why an agent due again at the instant it has just triggered at stops the run (engine and
    simulator alike); `threshold_model` is any agent of the team (they share the threshold)."""
    return (
        f'agent {agent_id} reached its threshold again at t={t!r}, the instant it has just triggered at '
        f'(threshold {threshold_model.threshold(t):.3g}): the threshold has fallen to the rounding '
        'level of the relative states, or the gains are outside what the theorem guarantees '
        '(see `formation validate`); shorten the horizon or lower beta'
    )


def _pop_due(heap: list[tuple[float, int, int, int]], serial: dict[int, int], t: float) -> list[int]:
    """The agents planned for exactly `t` (live entries), taken off the heap, sorted."""
    due = []
    while heap and heap[0][0] == t:
        _, kind, i, number = heapq.heappop(heap)
        if kind == 1 and serial[i] == number:
            due.append(i)
    return sorted(due)


def _check_period(period: float | None, scenario) -> None:
    if period is not None and not (math.isfinite(period) and period > 0.0):
        raise EngineError(f'period must be a finite number > 0, got {period!r}')
    if period is not None and scenario.safety is not None:
        raise EngineError(
            'the safety layer runs with event triggering only (its own triggers), not with a period'
        )


def simulate(
    scenario,
    *,
    horizon: float | None = None,
    sample_dt: float | None = 0.01,
    tolerance: float = DEFAULT_TOLERANCE,
    period: float | None = None,
    sample_events: bool = True,
    trajectory_dir: str | Path | None = None,
    progress: Callable[[float, int], None] | None = None,
    on_event: Callable[[float, World, list[int]], None] | None = None,
    time_warp: TimeWarp | None = None,
    until_error: float | None = None,
    stop_at_floor: bool = False,
) -> RunRecord:
    """Run ETA-1/ETA-2 (or periodic sampling with `period`) exactly up to `horizon`.

    With `period`, every agent samples and broadcasts at k * period instead of at its own
    triggering times (the periodic baseline); everything else is the same. `on_event(t, world,
    due)` is called at every event time before the due agents trigger (for checkers). `time_warp`:
    the κ = 1 run in the time s(t) of the warp (`_WarpClock`).

    The record samples the state at every event time and every `sample_dt` (0 or None: no grid).
    `sample_events=False` samples only the grid, t = 0 and the horizon; each edge's largest length
    is then also measured at its two agents' triggering times (`Samples.edge_maxima`), which for
    single integrators is still the exact maximum. Samples are kept in memory (O(samples x agents)),
    or, with `trajectory_dir` (a run folder), written into its `trajectory/` as they are produced
    (memory O(agents + samples)) and memory-mapped in the record (`formation_sim.sim.samples`).

    `until_error` (0 < f < 1) ends the run at its first event t > 0 with formation error < f × the initial,
    `stop_at_floor` on the rounding floor instead of an EngineError; either sets the record's horizon to
    the run's end and `extra['stop']` (horizon, error_reached or rounding_floor: `formation_sim.sim.stop`).
    """
    horizon = float(scenario.horizon if horizon is None else horizon)
    if not (math.isfinite(horizon) and horizon > 0.0):
        raise EngineError(f'horizon must be a finite number > 0, got {horizon!r}')
    _check_period(period, scenario)
    check_sample_dt(sample_dt, horizon=horizon, scenario=scenario)
    clock = None if time_warp is None else _WarpClock.of(time_warp, scenario, horizon=horizon, period=period)
    started = time.perf_counter()
    world = World.from_scenario(scenario)
    stop = RunStop.of(scenario, world, horizon=horizon, until_error=until_error, at_floor=stop_at_floor)
    agents = build_agents(scenario, tolerance=tolerance)
    trigger_times: dict[int, list[float]] = {i: [] for i in scenario.agent_ids}
    writer = None if trajectory_dir is None else _writer(trajectory_dir, scenario)
    watch = None if sample_events else EdgeLengths(scenario)
    sampler = Sampler(world, sample_dt, events=sample_events, writer=writer, watch=watch, clock=clock)
    try:
        messages = _run(
            scenario,
            world,
            agents,
            sampler,
            trigger_times,
            horizon=horizon,
            period=period,
            progress=progress,
            on_event=on_event,
            stop=stop,
        )
    except BaseException:
        if writer is not None:
            writer.abandon()  # what was written stays, named trajectory.incomplete
        raise
    wall_time = time.perf_counter() - started
    asked = until_error is not None or stop_at_floor  # else no extra['stop']
    return RunRecord(
        scenario=scenario,
        horizon=horizon if stop.time is None else stop.time,  # the horizon unless a stop came first
        mode='in_process' if period is None else 'periodic',
        trigger_times=trigger_times,
        samples=sampler.samples(),
        messages_sent=messages,
        sensing_calls=sum(len(v) for v in trigger_times.values()),
        wall_time=wall_time,
        extra={
            'samples': 'events' if sample_events else 'grid' if sample_dt else 'none',
            **_run_extra(scenario, agents, clock=clock, period=period, stop=stop if asked else None),
        },
    )


def _writer(trajectory_dir: str | Path, scenario) -> TrajectoryWriter:
    return TrajectoryWriter(
        trajectory_dir,
        agent_ids=scenario.agent_ids,
        dimension=scenario.dimension,
        velocities=scenario.dynamics == 'double',
    )


def _run_extra(scenario, agents: dict, *, clock, period: float | None, stop: RunStop | None) -> dict:
    """The record's extra after its samples' kind: the period, the safety layer, the warp, the stop."""
    return {
        **({'period': period} if period is not None else {}),
        **({'safety': _safety_extra(scenario, agents, clock)} if scenario.safety is not None else {}),
        **({} if clock is None else {'time_warp': clock.warp.to_dict()}),
        **({'stop': stop.extra()} if stop is not None else {}),
    }


def _safety_extra(scenario, agents: dict, clock) -> dict:
    """The safety layer's settings and how often it changed a command (docs/SAFETY.md); under a
    warp the agents run in s, so their latest intervention is labelled t(s) as their triggers are."""
    last = {i: agent.safety_last_intervention for i, agent in agents.items()}
    if clock is not None:
        last = {i: None if s is None else clock.real(s) for i, s in last.items()}
    return safety_extra(
        scenario.safety,
        interventions={i: agent.safety_interventions for i, agent in agents.items()},
        last_interventions=last,
    )


def safety_extra(safety, *, interventions: dict, last_interventions: dict) -> dict:
    """summary.json's `extra.safety`: the layer's settings, per agent the triggers at which it
    changed the nominal command, and the latest such time over the team (0.0: none); the engine's
    and a distributed run's (from the agents' reports) alike."""
    return {
        **safety.as_dict(),
        'interventions': {str(i): n for i, n in interventions.items()},
        'last_intervention': max((t or 0.0 for t in last_interventions.values()), default=0.0),
    }


def _run(
    scenario,
    world: World,
    agents: dict,
    sampler: Sampler,
    trigger_times: dict[int, list[float]],
    *,
    horizon,
    period,
    progress,
    on_event,
    stop: RunStop,
) -> int:
    """The event loop of `simulate`; fills `trigger_times` and the sampler, returns the messages sent.
    With the sampler's warp clock it runs in the paper's time and labels the triggering times in real time."""
    clock = sampler.clock
    if clock is not None:
        horizon = clock.paper_horizon
    messages = 0
    agenda = _Agenda(horizon=horizon, period=period, agent_ids=scenario.agent_ids)
    due = list(scenario.agent_ids)  # t^i_1 = 0 for every agent
    t = 0.0
    steps = 0
    sampler.event(force=True)  # t = 0
    some_agent = agents[scenario.agent_ids[0]]  # the threshold is the same for every agent
    floor_edges = FloorEdges.of(scenario)
    team = _team(agents, world) if period is None else None
    if team is not None:
        agenda.link(team)
    try:
        while True:
            sampler.event(due=due)
            real_t = t if clock is None else clock.real(t)
            if period is None and (problem := rounding_floor(some_agent, world, floor_edges)) is not None:
                if not stop.at_floor:
                    raise EngineError(problem)
                stop.end('rounding_floor', real_t, problem, world=world)
            if stop.reason is not None or stop.error_reached(world, t, real_t):
                sampler.event(force=True)
                break
            if on_event is not None:
                on_event(t, world, due)
            receivers = _trigger_and_deliver(agents, world, due, t, trigger_times, team=team)
            messages += len(receivers)
            agenda.plan(agents, due, receivers, t)
            t_next = agenda.next_time()
            if t_next == t and period is None:
                # News at this instant put an agent on its threshold already (it would have crossed
                # within rounding of its neighbour): it triggers at this very instant, in a further
                # round. An agent due twice at one instant means the threshold is at rounding level.
                due = agenda.pop_due(t)
                twice = [i for i in due if trigger_times[i][-1] == t]
                if twice:
                    raise EngineError(due_twice(twice[0], some_agent, t))
                continue
            steps += 1
            if progress is not None and steps % 1000 == 0:
                progress(t, sum(map(len, trigger_times.values())))
            if t_next > horizon:
                sampler.grid_until(horizon)
                world.advance(horizon)
                sampler.event(force=True)
                stop.at_horizon(world)
                break
            sampler.grid_until(t_next)
            world.advance(t_next)
            t = t_next
            due = agenda.pop_due(t)
    finally:
        if team is not None:  # the agents' attributes are their knowledge again (the team's ledger written)
            team.release()
    if clock is not None:
        trigger_times.update(clock.relabel(trigger_times))
    return messages


def _team(agents: dict, world: World) -> _fastcore.Team | None:
    """The compiled step of `_trigger_and_deliver` over this team (`compiled.team`), or None (the
    pure-Python path, p > 3, or a neighbour that does not list the agent back): the agents in the
    world's order, each one's neighbours by their position there and its slot among their edges."""
    team_type, team_edges = compiled.team(), compiled.team_edges()
    ids = world.agent_ids
    if team_type is None or team_edges is None or world.dimension > 3:
        return None
    ordered = tuple(agents[i] for i in ids)
    edges = team_edges(ordered, ids)  # (neighbours by position, the agent's slot at each), compiled
    if edges is None:
        return None
    return team_type(
        plain=(Eta1Agent, Eta2Agent),
        rule=ExponentialRule,
        agents=ordered,
        ids=ids,
        neighbours=edges[0],
        back=edges[1],
        dimension=world.dimension,
        set_control=world.set_control,
    )


def _trigger_and_deliver(
    agents: dict,
    world: World,
    due: list[int],
    t: float,
    trigger_times: dict[int, list[float]],
    *,
    team: _fastcore.Team | None = None,
) -> list[int]:
    """Every due agent triggers at `t` (it senses, and its new control acts on the world), then
    their triggering information reaches its receivers; the receivers of the messages, in the order
    sent. With the compiled `team`, the agents it takes trigger there from the world's arrays and
    their messages are delivered there (the same updates and floats); any other goes the Python way."""
    outbox: list[TriggerInfo] = []
    start = 0
    while start < len(due):
        stop = start if team is None else team.trigger(due, start, t, *world.arrays())
        for i in due[start:stop]:
            trigger_times[i].append(t)
        if stop < len(due):
            outbox.extend(_trigger_one(agents[due[stop]], world, t, trigger_times))
        start = stop + 1
    receivers = [] if team is None else team.deliver()
    for info in outbox:
        if team is not None:
            team.release(info.receiver)  # its attributes its knowledge, for its Python receive
        agents[info.receiver].receive(info)
        receivers.append(info.receiver)
    return receivers


def _trigger_one(
    agent, world: World, t: float, trigger_times: dict[int, list[float]]
) -> tuple[TriggerInfo, ...]:
    """One agent's trigger at `t` the Python way (it senses, its new control acts on the world); its
    messages."""
    i = agent.agent_id
    try:
        sensed = world.sense(i, agent.neighbour_ids)
        if agent.safety is None:
            out = agent.trigger(t, sensed)
        else:  # the other robots its range sensor sees (docs/SAFETY.md)
            nearby = world.nearby(i, agent.safety.sensing_radius, exclude=agent.neighbour_ids)
            out = agent.trigger(t, sensed, nearby=nearby)
    except ValueError as err:
        raise EngineError(f'at t={t!r}: {err}') from err
    world.set_control(i, out.control)
    trigger_times[i].append(t)
    return out.infos


@dataclass(kw_only=True)
class _Agenda:
    """When each agent triggers next, as `_run` learns it.

    A heap of (time, kind, agent, serial): kind 1 = a planned triggering time, kind 0 = the
    frontier of a search still under way (a certified lower bound on the agent's time). Only
    the entry with the agent's latest serial is live; older ones are skipped when they surface.
    With `period`, every agent's next time is its next multiple of the period instead.
    """

    horizon: float
    period: float | None
    agent_ids: tuple[int, ...] = ()
    heap: list[tuple[float, int, int, int]] = field(default_factory=list)
    serial: dict[int, int] = field(default_factory=dict)
    searches: dict[int, CrossingSearch] = field(default_factory=dict)
    planned_period: dict[int, float] = field(default_factory=dict)
    counter: int = 0
    queue: _fastcore.Agenda | None = None

    def __post_init__(self) -> None:
        # Without a period, where the compiled core runs, the queue is its compiled twin
        # (`_fastcore.Agenda`: this heap, its serials and searches in C; the same order and times).
        # It makes the searches of Eta1Agent/Eta2Agent on the exponential rule as their trigger_search
        # does (_FIRST_SPAN); any other rule's search is the method's.
        if self.period is None and self.agent_ids and (queue := compiled.agenda()) is not None:
            self.queue = queue(
                agent_ids=self.agent_ids,
                horizon=self.horizon,
                first_span=_FIRST_SPAN,
                plain=(Eta1Agent, Eta2Agent),
                rule=ExponentialRule,
            )

    def link(self, team: _fastcore.Team) -> None:
        """New searches of the team's agents start from the compiled team's copy of their knowledge
        (`_fastcore.Agenda.link`: what the search would read from the agent, where the agent's counters
        say it still is; the same floats)."""
        if self.queue is not None:
            self.queue.link(team)

    def plan(self, agents: dict, due: list[int], receivers: list[int], t: float) -> None:
        """Plan anew every agent whose information changed at `t`: the `due` ones triggered, the `receivers`
        were sent their triggering information (the compiled queue takes the union and its order in C)."""
        if self.queue is not None:
            self.queue.plan_union(agents, due, receivers)
            return
        for i in sorted(set(due).union(receivers)):
            self.counter += 1
            self.serial[i] = self.counter
            if self.period is None:
                # Searched lazily (`next_time`): only as far as the team's next event needs.
                search = agents[i].trigger_search(self.horizon)
                self.searches[i] = search
                heapq.heappush(self.heap, (search.frontier, 0, i, self.counter))
            else:
                period = self.period
                nxt = (round(t / period) + 1) * period if i in due else self.planned_period[i]
                self.planned_period[i] = nxt
                heapq.heappush(self.heap, (nxt, 1, i, self.counter))

    def next_time(self) -> float:
        if self.queue is None:
            return _next_event_time(self.heap, self.serial, self.searches, self.horizon)
        try:
            return self.queue.next_time()
        except CrossingError as error:
            raise EngineError(f'agent {self.queue.failed}: {error}; {PRECISION_HINT}') from error

    def pop_due(self, t: float) -> list[int]:
        if self.queue is None:
            return _pop_due(self.heap, self.serial, t)
        return self.queue.pop_due(t)
