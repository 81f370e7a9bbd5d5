"""The in-process engine against the paper's guarantees, checked on the true trajectory.

The checker here recomputes e_i(t) (resp. E_i(t)) from its definition in Theorem 1 (resp. 2)
out of the true world states, with its own formulas, independently of the agents' predictions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.errors import AgentError
from formation_sim.model import theory
from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError

REL = 1e-9


def _omega(r, c):
    # ω_ij (paper, Section 3), written out again on purpose: the checker shares no code with agents.
    return (2 * c - r) / (c - r) ** 2


def _propagate(x, q, u, k3, tau):
    if q is None:
        return x + tau * u, None
    decay = np.exp(-k3 * tau)
    q_t = decay * q + (1 - decay) * u / k3
    x_t = x + (1 - decay) * q / k3 + (k3 * tau - (1 - decay)) * u / k3**2
    return x_t, q_t


class Trace:
    """Snapshots of the true world at every event, before the due agents trigger."""

    def __init__(self, scenario):
        self.scenario = scenario
        self.snaps = []

    def __call__(self, t, world, due):
        self.snaps.append((t, world.positions, world.velocities, world.controls, list(due)))


class EdgeSums:
    """sum_j ω_ij y_ij and sum_j ω_ij q_ij for every agent i at a state (x, q), over edge arrays."""

    def __init__(self, scenario):
        index = {a: k for k, a in enumerate(scenario.agent_ids)}
        self.n = scenario.n
        self.heads = np.array([index[e.i] for e in scenario.edges])
        self.tails = np.array([index[e.j] for e in scenario.edges])
        self.d = np.array([e.d for e in scenario.edges])
        self.c = scenario.delta - np.linalg.norm(self.d, axis=1)

    def __call__(self, x, q):
        y = x[self.heads] - x[self.tails] - self.d
        w = _omega(np.linalg.norm(y, axis=1), self.c)[:, None]
        return self._accumulate(w * y), None if q is None else self._accumulate(
            w * (q[self.heads] - q[self.tails])
        )

    def _accumulate(self, per_edge):
        # Edge (i, j) contributes +ω y_ij to agent i and +ω y_ji = -ω y_ij to agent j.
        total = np.zeros((self.n, per_edge.shape[1]))
        np.add.at(total, self.heads, per_edge)
        np.add.at(total, self.tails, -per_edge)
        return total


def check_triggering(scenario, trace, horizon, *, dense=40):
    """Every trigger sits on the threshold; between triggers the error stays below it.

    e_i(t) of Theorem 1 is sum_j ω_ij y_ij at t minus the same at agent i's last trigger; E_i of
    Theorem 2 is k1 e_i + k2 e_qi with e_qi built the same way from q_i - q_j.
    """
    g = scenario.gains
    single = scenario.dynamics == 'single'
    alpha, beta = (g.alpha, g.beta) if single else (g.alpha_d, g.beta_d)
    k3 = None if single else g.k3
    sums = EdgeSums(scenario)
    row = {a: k for k, a in enumerate(scenario.agent_ids)}

    def combined(x, q):
        s_y, s_q = sums(x, q)
        return s_y if single else g.k1 * s_y + g.k2 * s_q

    snaps = trace.snaps
    anchor = np.zeros((scenario.n, scenario.dimension))  # combined sums at each agent's last trigger
    worst_inside = 0.0
    on_threshold = []
    for k, (t, x, q, _, due) in enumerate(snaps):
        now = combined(x, q)
        if k:
            for i in due:
                e = np.linalg.norm(now[row[i]] - anchor[row[i]])
                on_threshold.append(abs(e / (alpha * math.exp(-beta * t)) - 1.0))
        for i in due:
            anchor[row[i]] = now[row[i]]
        if k + 1 == len(snaps):
            break
        t_end, controls = snaps[k + 1][0], snaps[k + 1][3]
        for s in np.linspace(t, t_end, dense + 2)[1:-1]:
            e = np.linalg.norm(combined(*_propagate(x, q, controls, k3, s - t)) - anchor, axis=1)
            worst_inside = max(worst_inside, float(e.max()) / (alpha * math.exp(-beta * s)))
    return np.array(on_threshold), worst_inside


def _edge_lengths(scenario, positions):
    index = {a: k for k, a in enumerate(scenario.agent_ids)}
    return np.array(
        [np.linalg.norm(positions[:, index[e.i]] - positions[:, index[e.j]], axis=-1) for e in scenario.edges]
    )


def _traced_paper_run(name: str):
    """(scenario, trace, record) of a built-in example up to t = 10, every event traced."""
    scenario = load_scenario(name)
    trace = Trace(scenario)
    record = simulate(scenario, horizon=10.0, sample_dt=0.01, on_event=trace)
    return scenario, trace, record


@pytest.fixture(scope='module')
def paper_single_run():
    return _traced_paper_run('paper_single')


@pytest.fixture(scope='module')
def paper_double_run():
    return _traced_paper_run('paper_double')


@pytest.mark.parametrize('run', ['paper_single_run', 'paper_double_run'])
def test_paper_triggers_sit_on_threshold_and_error_stays_below(run, request):
    scenario, trace, record = request.getfixturevalue(run)
    on_threshold, worst_inside = check_triggering(scenario, trace, record.horizon)
    assert len(on_threshold) == record.total_events - scenario.n  # all but t_1 = 0
    assert on_threshold.max() < REL
    assert worst_inside <= 1.0 + REL


@pytest.mark.parametrize('run', ['paper_single_run', 'paper_double_run'])
def test_paper_connectivity_is_preserved(run, request):
    scenario, _, record = request.getfixturevalue(run)
    assert _edge_lengths(scenario, record.sample_positions).max() < scenario.delta


def test_paper_single_inter_event_times_respect_xi(paper_single_run):
    scenario, _, record = paper_single_run
    xi = theory.theorem_constants(scenario).xi
    for agent, times in record.trigger_times.items():
        assert np.diff(times).min() >= xi[agent]


def test_paper_single_starts_with_sub_microsecond_bursts(paper_single_run):
    # Edge 2-3 starts with slack 0.054 of Δ-||d_23||, so its weight is large and the first
    # inter-event times of agents 2 and 3 are of the order of 5e-7 s.
    _, _, record = paper_single_run
    first_gaps = [record.trigger_times[a][1] for a in (2, 3)]
    assert all(1e-7 < gap < 1e-6 for gap in first_gaps)


def test_paper_single_formation_error_decays_at_rate_beta(paper_single_run):
    scenario, _, record = paper_single_run
    constants = theory.theorem_constants(scenario)
    beta = scenario.gains.beta
    tau = theory.formation_feasibility(scenario).tau
    v = np.array([theory.lyapunov(scenario, x, tau=tau) for x in record.sample_positions])
    # (betaV): V(t) < k_V e^{-2βt}, hence ||y_i - y_j|| < 2 sqrt(k_V) e^{-βt} (lengthysV).
    assert np.all(v <= constants.k_V * np.exp(-2 * beta * record.sample_times))
    errors = np.array([theory.formation_error(scenario, x) for x in record.sample_positions])
    assert np.all(errors <= 2 * math.sqrt(constants.k_V) * np.exp(-beta * record.sample_times))


def test_periodic_baseline_samples_on_the_grid():
    scenario = load_scenario('paper_single')
    record = simulate(scenario, horizon=1e-3, period=2.5e-4, sample_dt=None)
    for times in record.trigger_times.values():
        assert np.allclose(times, [0.0, 2.5e-4, 5e-4, 7.5e-4, 1e-3], rtol=0, atol=1e-15)


def test_periodic_sampling_too_slow_for_the_paper_example_loses_the_edge():
    # Edge 2-3 starts 0.054 from its range limit with |u| in the hundreds: sampling every
    # 0.25 s lets it leave its range, which event triggering never does.
    with pytest.raises(EngineError, match='out of its range'):
        simulate(load_scenario('paper_single'), horizon=1.0, period=0.25, sample_dt=None)


@pytest.mark.parametrize('tolerance', [1e-10, 1e-13])
def test_internal_tolerance_does_not_move_triggering_times(tolerance, paper_single_run):
    scenario, _, reference = paper_single_run
    record = simulate(scenario, horizon=10.0, sample_dt=None, tolerance=tolerance)
    for agent, times in reference.trigger_times.items():
        assert len(record.trigger_times[agent]) == len(times)
        assert np.max(np.abs(np.subtract(record.trigger_times[agent], times))) < 1e-9


def test_bad_horizon_is_refused():
    with pytest.raises(EngineError, match='horizon'):
        simulate(load_scenario('paper_single'), horizon=-1.0)


def _random_cases():
    cases = []
    for seed in range(50):
        rng = np.random.default_rng(1000 + seed)
        cases.append(
            dict(
                seed=seed,
                n=int(rng.integers(3, 9)),
                dimension=int(rng.integers(1, 4)),
                dynamics='single' if seed % 3 else 'double',
                slack=float(rng.uniform(0.05, 0.9)),
            )
        )
    return cases


@pytest.mark.parametrize(
    'case', _random_cases(), ids=lambda c: f'seed{c["seed"]}-{c["dynamics"]}-n{c["n"]}-p{c["dimension"]}'
)
def test_random_scenarios_keep_every_guarantee(case):
    scenario = random_scenario(
        n=case['n'],
        seed=case['seed'],
        dynamics=case['dynamics'],
        dimension=case['dimension'],
        slack=case['slack'],
    )
    horizon = 2.0
    trace = Trace(scenario)
    record = simulate(scenario, horizon=horizon, sample_dt=0.02, on_event=trace)
    on_threshold, worst_inside = check_triggering(scenario, trace, horizon, dense=10)
    if len(on_threshold):
        assert on_threshold.max() < REL
    assert worst_inside <= 1.0 + REL
    assert _edge_lengths(scenario, record.sample_positions).max() < scenario.delta
    constants = theory.theorem_constants(scenario)
    if constants.xi is not None:
        for agent, times in record.trigger_times.items():
            if len(times) > 1:
                assert np.diff(times).min() >= constants.xi[agent]
    if scenario.dynamics == 'single':
        tau = theory.formation_feasibility(scenario).tau
        v = np.array([theory.lyapunov(scenario, x, tau=tau) for x in record.sample_positions])
        assert np.all(v <= constants.k_V * np.exp(-2 * scenario.gains.beta * record.sample_times))


def _eager_reference(scenario, horizon):
    """The plain event loop: every agent whose knowledge changed searches to the end at once."""
    from formation_sim.sim.engine import build_agent
    from formation_sim.sim.world import World

    world = World.from_scenario(scenario)
    agents = {i: build_agent(scenario, i) for i in scenario.agent_ids}
    times = {i: [] for i in scenario.agent_ids}
    planned = {}
    t, due = 0.0, list(scenario.agent_ids)
    while True:
        infos = []
        for i in due:
            out = agents[i].trigger(t, world.sense(i, agents[i].neighbour_ids))
            world.set_control(i, out.control)
            times[i].append(t)
            infos.extend(out.infos)
        for info in infos:
            agents[info.receiver].receive(info)
        for i in set(due) | {info.receiver for info in infos}:
            planned[i] = agents[i].next_trigger_time(horizon)
        t_next = min(planned.values())
        if t_next > horizon:
            return times
        world.advance(t_next)
        t, due = t_next, sorted(i for i, s in planned.items() if s == t_next)


@pytest.mark.parametrize(('dynamics', 'n', 'seed'), [('single', 40, 7), ('double', 12, 8)])
def test_lazy_searches_give_the_eager_event_chain_float_for_float(dynamics, n, seed):
    # The engine advances searches only as far as the next event needs and drops those overtaken
    # by new information; the triggering times must be exactly those of the plain loop.
    scenario = random_scenario(n=n, seed=seed, dynamics=dynamics)
    horizon = 1.0
    record = simulate(scenario, horizon=horizon, sample_dt=None)
    reference = _eager_reference(scenario, horizon)
    assert record.trigger_times == reference
    assert record.total_events > 3 * n


def test_without_event_samples_only_the_grid_and_the_ends_are_kept():
    scenario = load_scenario('paper_single')
    full = simulate(scenario, horizon=1.0, sample_dt=0.25)
    lean = simulate(scenario, horizon=1.0, sample_dt=0.25, sample_events=False)
    assert lean.trigger_times == full.trigger_times
    assert lean.sample_times.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    grid = np.isin(full.sample_times, lean.sample_times)
    assert grid.sum() == 5 and len(full.sample_times) > 5 + 10
    assert np.array_equal(full.sample_positions[grid], lean.sample_positions)


def test_news_that_puts_an_agent_on_its_threshold_makes_it_trigger_at_that_instant():
    # Late in paper_single the threshold is a few thousand ulps of the positions: an agent given a
    # neighbour's exact relative state at the neighbour's trigger can already be on its own
    # threshold (it would have crossed within rounding). It then triggers at that very instant,
    # in a further round, exactly as the plain event loop (every agent re-planned, the minimum
    # taken, the world advanced by zero) does.
    scenario = load_scenario('paper_single')
    horizon = 30.0
    trace = Trace(scenario)
    record = simulate(scenario, horizon=horizon, sample_dt=0.01, on_event=trace)
    assert record.trigger_times == _eager_reference(scenario, horizon)
    rounds = [(snap[0], snap[4]) for snap in trace.snaps]
    repeated = [(t, first, second) for (t, first), (t2, second) in zip(rounds, rounds[1:]) if t == t2]
    assert repeated, 'no instant with a second round: the test no longer covers it'
    for _, first, second in repeated:
        assert not set(first) & set(second), 'an agent triggered twice at one instant'
    # Every trigger on its threshold, to 1e-9 of it or, where the threshold is down to a few
    # thousand ulps, to the rounding of the positions (recomputed from the true states).
    on_threshold, _ = check_triggering(scenario, trace, horizon, dense=2)
    times = np.array([t for t, due in rounds[1:] for _ in due])
    threshold = scenario.gains.alpha * np.exp(-scenario.gains.beta * times)
    rounding = 16 * np.spacing(np.abs(record.sample_positions).max())
    assert np.all(on_threshold * threshold <= 1e-9 * threshold + rounding)


def test_the_run_stops_once_rounding_decides_the_events():
    # The rule, recomputed from the true states: at the stop the threshold is below 8 rounding
    # steps of the triggering error, g_ij(0) ulp(largest |x|, |d_ij|) on the edge of least capacity
    # (it compared with 8 ulps of the largest |x| until that moved with the length unit:
    # tests/formation_sim/sim/test_engine_rounding_floor.py); at the event before it is not.
    scenario = load_scenario('paper_single')
    events = []
    with pytest.raises(
        EngineError, match='from here on rounding, not the dynamics, decides the events'
    ) as stop:
        simulate(
            scenario,
            horizon=200.0,
            sample_dt=None,
            on_event=lambda t, world, due: events.append((t, world.positions, world)),
        )
    t = float(str(stop.value).split('at t=')[1].split()[0])
    before_t, before_x, world = events[-1]  # the last event, and the engine's world, left at the stop
    assert world.time == t > before_t
    capacity = float(theory.edge_capacities(scenario).min())
    offset = max(abs(float(v)) for edge in scenario.edges for v in edge.d)

    def floor(x):
        return 8 * 2.0 / capacity * float(np.spacing(max(np.abs(x).max(), offset)))

    alpha, beta = scenario.gains.alpha, scenario.gains.beta
    assert alpha * math.exp(-beta * before_t) >= floor(before_x)
    assert alpha * math.exp(-beta * t) < floor(world.positions)


def test_initial_slack_just_above_the_precision_floor_triggers_on_the_threshold(tight_edge):
    # Relative slack 1e-3 on edge (2, 3) (formation validate's floor is 9.1e-4): the first
    # inter-event times are ~3e-15 s. Checked on the true states, a trigger may sit off the
    # threshold by what one ulp of the positions (8.9e-16) moves e_i: g_23 ulp / α = 1.5e-7.
    from formation_sim.model.validate import require_valid

    scenario = tight_edge('paper_single', 1e-3)
    assert require_valid(scenario).ok
    horizon = 1e-12
    trace = Trace(scenario)
    record = simulate(scenario, horizon=horizon, sample_dt=None, on_event=trace)
    assert record.total_events > 300
    on_threshold, worst_inside = check_triggering(scenario, trace, horizon, dense=4)
    assert on_threshold.max() < 1e-6
    assert worst_inside <= 1.0 + 1e-6


def test_a_search_rounding_stalls_is_an_engine_error_naming_the_agent(tight_edge):
    # Slack 1e-12 of the capacity (refused by formation validate, rule precision): the rounded
    # prediction of agent 2 stands still below its threshold and the search gives up. The engine
    # says so instead of letting the search's CrossingError through.
    with pytest.raises(
        EngineError, match=r'agent 2: no convergence after 200000 certified steps .*\[precision\]'
    ):
        simulate(tight_edge('paper_single', 1e-12), horizon=1e-20, sample_dt=None)


def _agent_bits(agent) -> dict:
    """Everything an agent holds after its construction, floats by their bytes (its neighbourhood's and its
    rule's fields included)."""
    out = {}
    for name, value in vars(agent).items():
        if name == '_hood':
            value = dict(sorted(vars(value).items()))  # its attributes whatever order they were set in
        elif name == '_threshold':
            value = (type(value), repr(value))
        out[name] = value
    return {name: _bytes(value) for name, value in out.items()}


def _bytes(value):
    if isinstance(value, np.ndarray):
        return ('array', value.dtype.str, value.shape, value.flags.writeable, value.tobytes())
    if isinstance(value, float):
        return ('float', np.float64(value).tobytes())
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [_bytes(v) for v in value])
    if isinstance(value, dict):
        return ('dict', [(k, _bytes(v)) for k, v in value.items()])
    if isinstance(value, set):
        return ('set', sorted(value))
    return (type(value).__name__, value)


@pytest.mark.parametrize(
    'scenario',
    [
        load_scenario('paper_single'),
        load_scenario('paper_double'),
        random_scenario(n=40, seed=3, dynamics='single', dimension=3),
        random_scenario(n=30, seed=4, dynamics='double', dimension=1),
    ],
    ids=['paper_single', 'paper_double', 'random ETA-1 3-D', 'random ETA-2 1-D'],
)
def test_the_team_built_at_once_is_the_agents_built_one_by_one(scenario):
    # build_agents (simulate's): the neighbourhoods of the whole team in one numpy call; every attribute of
    # every agent (d_ij, capacities, their tuples, the rule, the zeros) the same bytes as build_agent's.
    from formation_sim.sim.engine import build_agent, build_agents

    team = build_agents(scenario)
    assert list(team) == list(scenario.agent_ids)
    for i, agent in team.items():
        alone = build_agent(scenario, i)
        assert type(agent) is type(alone)
        assert _agent_bits(agent) == _agent_bits(alone)


def test_a_team_whose_neighbourhood_an_agent_refuses_raises_that_agents_error(monkeypatch):
    # One agent's d_ij not below Δ: the team is built one by one, and the agent raises its own error.
    from formation_sim.sim import engine

    scenario = load_scenario('paper_single')
    table = {i: scenario.neighbours(i) for i in scenario.agent_ids}
    last = scenario.agent_ids[-1]
    j = next(iter(table[last]))
    table[last][j] = np.array([scenario.delta, 0.0])
    monkeypatch.setattr(type(scenario), 'neighbours', lambda self, i: table[i])
    with pytest.raises(AgentError, match=rf'^edge \({last},{j}\): .* is not below Δ = .* \(Assumption 1\)$'):
        engine.build_agents(scenario)
