"""ETA-1 / ETA-2 agents alone: inputs, predictions, next triggering times, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.errors import AgentError
from formation_agent.core.eta import Eta1Agent, Eta2Agent, make_agent, make_agents
from formation_agent.core.neighbourhood import Neighbourhood
from formation_msgs_py.types import SensedState, TriggerInfo

D12 = np.array([0.0, -2.0])
D13 = np.array([-2.0, 0.0])


def _eta1(**overrides):
    kwargs = dict(agent_id=1, neighbours={2: D12, 3: D13}, delta=4.0, alpha=10.0, beta=1.0)
    kwargs.update(overrides)
    return Eta1Agent(**kwargs)


def _omega(r, c):
    return (2 * c - r) / (c - r) ** 2


def _sensed(agent, rel, t=0.0, **extra):
    return SensedState(agent=agent, stamp=t, rel_positions=rel, **extra)


def _info(sender, receiver, t, control, rel, rel_velocity=None):
    return TriggerInfo(
        sender=sender,
        receiver=receiver,
        stamp=t,
        control=tuple(control),
        rel_position=tuple(rel),
        rel_velocity=rel_velocity,
    )


def test_eta1_input_is_the_weighted_sum_of_edge_errors():
    agent = _eta1()
    rel = {2: (-1.5, -3.0), 3: (-2.5, -1.5)}  # x_1 - x_j of the paper's example
    out = agent.trigger(0.0, _sensed(1, rel))
    expected = np.zeros(2)
    for j, d in ((2, D12), (3, D13)):
        y = np.array(rel[j]) - d
        expected -= _omega(np.linalg.norm(y), 4.0 - np.linalg.norm(d)) * y  # (uxsingle)
    assert np.allclose(out.control, expected, rtol=1e-15)
    assert [info.receiver for info in out.infos] == [2, 3]
    assert all(info.rel_position == rel[info.receiver] for info in out.infos)


def test_eta1_next_time_is_where_predicted_error_meets_threshold():
    agent = _eta1()
    agent.trigger(0.0, _sensed(1, {2: (-1.5, -3.0), 3: (-2.5, -1.5)}))
    agent.receive(_info(2, 1, 0.0, (0.3, -0.2), (1.5, 3.0)))
    agent.receive(_info(3, 1, 0.0, (-0.1, 0.4), (2.5, 1.5)))
    t = agent.next_trigger_time(10.0)
    assert 0.0 < t < 10.0
    # Independently: positions move linearly (statexixj), e_1 from its definition in Theorem 1.
    u1 = agent.control

    def error(s):
        total = np.zeros(2)
        for _j, d, u_j, rel in ((2, D12, (0.3, -0.2), (-1.5, -3.0)), (3, D13, (-0.1, 0.4), (-2.5, -1.5))):
            y0 = np.array(rel) - d
            y = y0 + s * (u1 - np.array(u_j))
            c = 4.0 - np.linalg.norm(d)
            total += _omega(np.linalg.norm(y), c) * y - _omega(np.linalg.norm(y0), c) * y0
        return np.linalg.norm(total)

    assert error(t) == pytest.approx(10.0 * math.exp(-t), rel=1e-12)
    grid = np.linspace(0.0, t, 20001)[:-1]
    assert all(error(s) < 10.0 * math.exp(-s) for s in grid)


def test_neighbour_information_in_any_order_gives_the_same_plan():
    plans = []
    for order in ((2, 3), (3, 2)):
        agent = _eta1()
        agent.trigger(0.0, _sensed(1, {2: (-1.5, -3.0), 3: (-2.5, -1.5)}))
        infos = {2: _info(2, 1, 0.0, (0.3, -0.2), (1.5, 3.0)), 3: _info(3, 1, 0.0, (-0.1, 0.4), (2.5, 1.5))}
        for j in order:
            agent.receive(infos[j])
            if agent.ready:
                agent.next_trigger_time(10.0)
        plans.append(agent.next_trigger_time(10.0))
    assert plans[0] == plans[1]


def _two_agents_near_range_limit(slack):
    agent = Eta1Agent(agent_id=1, neighbours={2: (0.0,)}, delta=1.0, alpha=1.0, beta=0.5)
    rel = (1.0 - slack,)
    out = agent.trigger(0.0, _sensed(1, {2: rel}))
    agent.receive(_info(2, 1, 0.0, (-out.control[0],), (-rel[0],)))
    return agent, out


def test_large_weight_near_range_limit_still_triggers_on_the_threshold():
    # Edge error 1e-2 short of its range Δ - ||d|| = 1: ω ~ 2e4 and dω/dr ~ 2e6.
    agent, out = _two_agents_near_range_limit(1e-2)
    assert out.control[0] < -9e3
    t = agent.next_trigger_time(1.0)
    assert 0.0 < t < 1e-6
    assert np.linalg.norm(agent.error(t)) == pytest.approx(agent.threshold(t), rel=1e-9)


def test_weight_beyond_double_resolution_triggers_at_first_visible_change():
    # 1e-6 short of the range: e_i moves by g_ij(r) ulp(r) ~ 200 x the threshold per ulp of r,
    # so the crossing is only resolvable as the first instant the rounded edge state changes.
    agent, _ = _two_agents_near_range_limit(1e-6)
    t = agent.next_trigger_time(1.0)
    assert 0.0 < t < 1e-25
    assert np.linalg.norm(agent.error(t)) >= agent.threshold(t)


def test_eta2_prediction_matches_closed_form_of_double_integrators():
    agent = Eta2Agent(
        agent_id=1, neighbours={2: D12}, delta=4.0, alpha_d=10.0, beta_d=0.1, k1=1.1547, k2=1.4502, k3=0.6
    )
    rel_x, rel_q = (-1.5, -3.0), (2.0, 4.0)
    out = agent.trigger(0.0, _sensed(1, {2: rel_x}, rel_velocities={2: rel_q}, velocity=(1.0, 2.0)))
    ud2 = np.array([0.5, -0.25])
    agent.receive(_info(2, 1, 0.0, ud2, (1.5, 3.0), rel_velocity=(-2.0, -4.0)))
    # Integrate the relative dynamics x' = q, q' = Δu - k3 q with scipy as an independent check.
    from scipy.integrate import solve_ivp

    du = out.control - ud2

    def rhs(_, z):
        return np.concatenate([z[2:], du - 0.6 * z[2:]])

    sol = solve_ivp(rhs, (0.0, 3.0), np.array(rel_x + rel_q), rtol=1e-12, atol=1e-12, dense_output=True)
    y, q, _ = agent._state(3.0)
    assert np.allclose(y[0] + D12, sol.y[:2, -1], rtol=1e-9, atol=1e-10)
    assert np.allclose(q[0], sol.y[2:, -1], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize(
    ('info', 'message'),
    [
        (_info(4, 1, 0.0, (0.0, 0.0), (1.0, 1.0)), 'not a neighbour'),
        (_info(2, 3, 0.0, (0.0, 0.0), (1.0, 1.0)), 'addressed to agent 3'),
        (_info(2, 1, math.nan, (0.0, 0.0), (1.0, 1.0)), 'non-finite time'),
        (_info(2, 1, 0.5, (math.nan, 0.0), (1.0, 1.0)), 'not finite'),
        (_info(2, 1, 0.5, (0.0, 0.0, 0.0), (1.0, 1.0)), 'shape'),
    ],
)
def test_bad_information_is_rejected_and_changes_nothing(info, message):
    agent = _eta1()
    agent.trigger(0.5, _sensed(1, {2: (-1.5, -3.0), 3: (-2.5, -1.5)}, t=0.5))
    before = (agent._anchor_time.copy(), agent._anchor_y.copy(), agent._neighbour_control.copy())
    with pytest.raises(AgentError, match=message):
        agent.receive(info)
    after = (agent._anchor_time, agent._anchor_y, agent._neighbour_control)
    assert all(np.array_equal(a, b) for a, b in zip(before, after))


def test_information_from_the_past_is_rejected():
    agent = _eta1()
    agent.trigger(0.5, _sensed(1, {2: (-1.5, -3.0), 3: (-2.5, -1.5)}, t=0.5))
    with pytest.raises(AgentError, match='goes back in time'):
        agent.receive(_info(2, 1, 0.25, (0.0, 0.0), (1.5, 3.0)))


def test_sensing_out_of_range_names_the_edge():
    agent = _eta1()
    with pytest.raises(AgentError, match='edge to agent 3 is out of its range'):
        agent.trigger(0.0, _sensed(1, {2: (-1.5, -3.0), 3: (-4.5, 0.0)}))


def test_sensing_must_cover_exactly_the_neighbours():
    agent = _eta1()
    with pytest.raises(AgentError, match=r'exactly its neighbours \[2, 3\]'):
        agent.trigger(0.0, _sensed(1, {2: (-1.5, -3.0)}))


@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        (dict(alpha=0.0), 'alpha must be'),
        (dict(beta=-1.0), 'beta must be'),
        (dict(delta=math.inf), 'delta'),
        (dict(neighbours={}), 'no neighbours'),
        (dict(neighbours={1: D12}), 'self-loop'),
        (dict(neighbours={2: (0.0, 5.0)}), 'Assumption 1'),
    ],
)
def test_bad_parameters_are_named(overrides, message):
    with pytest.raises(AgentError, match=message):
        _eta1(**overrides)


def test_a_neighbourhood_built_already_must_be_the_agents_own():
    hoods = Neighbourhood.team(neighbours={1: {2: D12, 3: D13}, 2: {1: D12}}, delta=4.0)
    assert hoods is not None
    agent = _eta1(neighbours=hoods[1])
    assert agent.neighbour_ids == (2, 3) and agent._hood is hoods[1]
    with pytest.raises(
        AgentError, match=r"^agent 1: the neighbourhood given is agent 2's with Δ = 4.0, not Δ = 4.0$"
    ):
        _eta1(neighbours=hoods[2])
    with pytest.raises(
        AgentError, match=r"^agent 1: the neighbourhood given is agent 1's with Δ = 4.0, not Δ = 5.0$"
    ):
        _eta1(neighbours=hoods[1], delta=5.0)


def test_make_agents_makes_each_agent_as_make_agent_does_and_raises_its_error():
    table = {1: {2: D12, 3: D13}, 2: {1: D12}, 3: {1: D13}}
    gains = {'alpha_d': 1.0, 'beta_d': 0.1, 'k1': 1.0, 'k2': 2.0, 'k3': 0.5, 'speed_scale': 2.0}
    agents = make_agents(
        algorithm='eta2', neighbours=table, delta=4.0, gains=gains, trigger_rule='exponential'
    )
    assert list(agents) == [1, 2, 3]
    for i, agent in agents.items():
        alone = make_agent(algorithm='eta2', agent_id=i, neighbours=table[i], delta=4.0, gains=gains)
        assert type(agent) is Eta2Agent and agent.neighbour_ids == alone.neighbour_ids
        assert (agent.k1, agent.k2, agent.k3, agent.speed_scale) == (alone.k1, alone.k2, alone.k3, 2.0)
        assert agent.trigger_rule == alone.trigger_rule and agent.capacity.tolist() == alone.capacity.tolist()
    with pytest.raises(AgentError, match=r"^agent 2: eta1 needs the gains \['beta'\]$"):
        make_agents(algorithm='eta1', neighbours={2: table[2], 1: table[1]}, delta=4.0, gains={'alpha': 1.0})
    assert make_agents(algorithm='eta1', neighbours={}, delta=4.0, gains={}) == {}


def test_eta2_information_without_relative_velocity_is_rejected():
    agent = Eta2Agent(
        agent_id=1, neighbours={2: D12}, delta=4.0, alpha_d=1.0, beta_d=0.1, k1=1.0, k2=1.0, k3=0.5
    )
    with pytest.raises(AgentError, match='lacks rel_velocity'):
        agent.receive(_info(2, 1, 0.0, (0.0, 0.0), (1.5, 3.0)))


def test_planning_before_hearing_every_neighbour_is_an_error():
    agent = _eta1()
    assert agent.next_trigger_time() == 0.0  # t_1 = 0
    agent.trigger(0.0, _sensed(1, {2: (-1.5, -3.0), 3: (-2.5, -1.5)}))
    agent.receive(_info(2, 1, 0.0, (0.0, 0.0), (1.5, 3.0)))
    with pytest.raises(AgentError, match=r'not heard from neighbours \[3\]'):
        agent.next_trigger_time()


# -- the plain-float evaluation (p <= 3) against formulas written out here ----------------------
#
# The agent state is built through the public API (one trigger, then one message per neighbour at
# its own time); these helpers keep the same knowledge and evaluate e_i (ETA-1) or E_i (ETA-2) and
# their rates from the paper's definitions, with 50-digit closed-form factors for ETA-2.


def _exact_factors(k3, tau):
    from decimal import Decimal, getcontext

    getcontext().prec = 50
    z = Decimal(k3) * Decimal(tau)
    decay = 1 - (-z).exp()
    return float(decay), float(z - decay)  # 1 - e^{-z}, z - 1 + e^{-z}


def _reference(kind, t, knowledge):
    """(e, de/dt) at t from the anchors: eqs. statexixj / statexixjd, stateqiqj, dotei, doteidouble."""
    u_i = knowledge['control']
    e, rate = u_i.copy(), np.zeros_like(u_i)
    for t0, y0, q0, u_j, c in knowledge['edges']:
        if kind == 'eta1':
            v = u_i - u_j
            y, dy = y0 + (t - t0) * v, v
            mix, dmix = y, dy
        else:
            k1, k2, k3 = knowledge['gains']
            du = u_i - u_j
            a, b = _exact_factors(k3, t - t0)
            y = y0 + a / k3 * q0 + b / k3**2 * du
            q = (1 - a) * q0 + a / k3 * du
            dy = q
            mix, dmix = k1 * y + k2 * q, k1 * q + k2 * (du - k3 * q)
        r = np.linalg.norm(y)
        w, w_prime = (2 * c - r) / (c - r) ** 2, (3 * c - r) / (c - r) ** 3
        e += w * mix
        rate += w_prime * (y @ dy / r) * mix + w * dmix
    return e, rate


def _agent_with_knowledge(kind, seed, p, alpha=0.5):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 6))
    d = rng.uniform(-1.0, 1.0, (m, p))
    ids = list(range(2, 2 + m))
    delta = 4.0
    caps = delta - np.linalg.norm(d, axis=1)
    common = dict(agent_id=1, neighbours={j: d[k] for k, j in enumerate(ids)}, delta=delta)
    if kind == 'eta1':
        agent = Eta1Agent(**common, alpha=alpha, beta=0.7)
        gains = None
    else:
        gains = (1.2, 1.5, 0.8)
        agent = Eta2Agent(**common, alpha_d=alpha, beta_d=0.3, k1=gains[0], k2=gains[1], k3=gains[2])

    def small(count):  # edge errors up to 0.15 of the capacity
        direction = rng.standard_normal((count, p))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        return direction * (0.15 * caps * rng.uniform(0.2, 1.0, count))[:, None]

    y = small(m)
    rel = {j: tuple(y[k] + d[k]) for k, j in enumerate(ids)}
    extra = {}
    if kind == 'eta2':
        qs = rng.uniform(-0.3, 0.3, (m, p))
        extra = dict(
            rel_velocities={j: tuple(qs[k]) for k, j in enumerate(ids)},
            velocity=tuple(rng.uniform(-0.3, 0.3, p)),
        )
    out = agent.trigger(0.0, _sensed(1, rel, **extra))
    edges = []
    y_msg = small(m)
    for k, j in enumerate(ids):
        stamp = float(rng.choice([0.0, rng.uniform(0.0, 0.2)]))
        u_j = rng.uniform(-0.5, 0.5, p)
        q_j = rng.uniform(-0.3, 0.3, p)
        rel_j = -(y_msg[k] + d[k])  # x_j - x_i as the message carries it
        agent.receive(_info(j, 1, stamp, u_j, rel_j, rel_velocity=None if kind == 'eta1' else tuple(-q_j)))
        edges.append((stamp, y_msg[k], q_j, u_j, caps[k]))
    knowledge = dict(control=np.array(out.control), edges=edges, gains=gains)
    return agent, knowledge


CASES = [(kind, seed, p) for kind in ('eta1', 'eta2') for p in (1, 2, 3) for seed in range(4)]


@pytest.mark.parametrize(('kind', 'seed', 'p'), CASES)
def test_fast_prediction_matches_the_paper_formulas(kind, seed, p):
    agent, knowledge = _agent_with_knowledge(kind, seed, p)
    for t in (0.2, 0.31, 0.5, 0.9):
        e, rate = agent.error_and_rate(t)
        e_ref, rate_ref = _reference(kind, t, knowledge)
        scale = 1.0 + float(np.abs(e_ref).max()) + float(np.abs(rate_ref).max())
        assert np.abs(e - e_ref).max() <= 1e-13 * scale
        assert np.abs(rate - rate_ref).max() <= 1e-13 * scale
        size_sq, size_rate = agent.error_terms(t)
        assert size_sq == pytest.approx(float(e @ e), rel=1e-15)
        assert size_rate == pytest.approx(float(e @ rate), rel=1e-13, abs=1e-15 * scale**2)
        assert agent.error_norm(t) == pytest.approx(float(np.linalg.norm(e)), rel=1e-15)


@pytest.mark.parametrize(('kind', 'seed', 'p'), CASES)
def test_fast_bounds_hold_over_their_span(kind, seed, p):
    # E >= ||e||, E1 >= ||de/dt|| on [a, a+H], and E2 >= ||d²e/dt²|| (by centred differences).
    agent, knowledge = _agent_with_knowledge(kind, seed, p)
    for a, span in ((0.2, 0.05), (0.3, 0.4), (0.5, 1.0)):
        size = float(np.linalg.norm(agent.error(a)))
        h_span, bound_e, bound_rate, bound_curv = agent.bounds(a, span, size)
        assert 0.0 < h_span <= span
        grid = np.linspace(a, a + h_span, 101)
        values = [_reference(kind, s, knowledge) for s in grid]
        assert max(np.linalg.norm(e) for e, _ in values) <= bound_e * (1 + 1e-12)
        assert max(np.linalg.norm(r) for _, r in values) <= bound_rate * (1 + 1e-12)
        if math.isfinite(bound_curv):
            h = h_span / 400
            for s in grid[1:-1:10]:
                second = (_reference(kind, s + h, knowledge)[1] - _reference(kind, s - h, knowledge)[1]) / (
                    2 * h
                )
                assert np.linalg.norm(second) <= bound_curv * (1 + 1e-6) + 1e-9


@pytest.mark.parametrize(('kind', 'seed', 'p'), CASES)
def test_fast_and_numpy_paths_find_the_same_crossing(kind, seed, p):
    agent, knowledge = _agent_with_knowledge(kind, seed, p)
    # A threshold 1.5 times the error where the search starts, so that it has a way to go.
    size = float(np.linalg.norm(_reference(kind, agent.last_event, knowledge)[0]))
    alpha = 1.5 * size * math.exp((0.7 if kind == 'eta1' else 0.3) * agent.last_event)
    agent, knowledge = _agent_with_knowledge(kind, seed, p, alpha=alpha)
    fast = agent.next_trigger_time(50.0)
    agent._fast = False  # the numpy evaluation, which agents of dimension p > 3 use
    agent._search = None
    vector = agent.next_trigger_time(50.0)
    assert math.isfinite(fast)
    assert fast == pytest.approx(vector, rel=1e-12)
    # On the threshold by the formulas above, and below it before (dense check).
    e_ref, _ = _reference(kind, fast, knowledge)
    assert np.linalg.norm(e_ref) / agent.threshold(fast) == pytest.approx(1.0, rel=1e-9)
    start = agent.last_event
    for s in np.linspace(start, fast, 401)[:-1]:
        assert np.linalg.norm(_reference(kind, s, knowledge)[0]) < agent.threshold(s) * (1 + 1e-12)


def test_four_dimensional_agents_use_numpy_and_trigger_on_the_threshold():
    d = {2: (1.0, 0.0, 0.0, 0.5), 3: (0.0, -1.0, 0.5, 0.0)}
    agent = Eta1Agent(agent_id=1, neighbours=d, delta=4.0, alpha=0.5, beta=1.0)
    rel = {2: (1.3, 0.1, -0.2, 0.6), 3: (-0.1, -1.2, 0.4, 0.3)}
    out = agent.trigger(0.0, _sensed(1, rel))
    agent.receive(_info(2, 1, 0.0, (0.2, 0.0, 0.1, 0.0), tuple(-np.array(rel[2]))))
    agent.receive(_info(3, 1, 0.0, (0.0, -0.3, 0.0, 0.1), tuple(-np.array(rel[3]))))
    assert not agent._fast
    t = agent.next_trigger_time(20.0)
    knowledge = dict(
        control=np.array(out.control),
        edges=[
            (0.0, np.array(rel[2]) - d[2], None, np.array((0.2, 0.0, 0.1, 0.0)), 4.0 - np.linalg.norm(d[2])),
            (0.0, np.array(rel[3]) - d[3], None, np.array((0.0, -0.3, 0.0, 0.1)), 4.0 - np.linalg.norm(d[3])),
        ],
        gains=None,
    )
    assert np.linalg.norm(_reference('eta1', t, knowledge)[0]) / agent.threshold(t) == pytest.approx(
        1.0, rel=1e-9
    )


def test_first_span_follows_the_last_inter_event_time():
    # The search's first trial span is the agent's own last inter-event time (at least 1e-3):
    # knowledge only, so a robot and the simulator step alike.
    agent, _ = _agent_with_knowledge('eta1', 0, 2)
    assert agent.trigger_search(10.0)._span == 1e-3
    rel = {j: tuple(agent.offsets[k]) for k, j in enumerate(agent.neighbour_ids)}  # in formation
    agent.trigger(0.25, _sensed(1, rel, t=0.25))
    assert agent.trigger_search(10.0)._span == 0.25


def test_each_algorithm_supplies_every_hook_the_shared_base_calls():
    """eta._AgentHooks declares what _EventTriggeredAgent calls and never defines: both ETAs define
    each of them, and the base class none (it would hide a missing one)."""
    import inspect

    from formation_agent.core import eta

    hooks = {name for name, member in vars(eta._AgentHooks).items() if inspect.isfunction(member)} | set(
        eta._AgentHooks.__annotations__
    )
    assert hooks == {
        '_update',
        '_row',
        '_fast_probe',
        '_threshold',
        # the vector path's error and bounds, the plain-float path's bounds (declared for mypy)
        '_vector_error_and_rate',
        '_vector_bounds',
        '_fast_bounds',
    }
    assert not hooks & set(vars(eta._EventTriggeredAgent))
    base = inspect.getsource(eta._EventTriggeredAgent)
    assert all(f'self.{hook}(' in base for hook in hooks)  # each declared hook is called by the base
    for agent in (eta.Eta1Agent, eta.Eta2Agent):
        methods = {name for name in hooks if name in vars(agent)}
        assert methods == hooks - {'_threshold'}, agent
        assert 'self._threshold = ' in inspect.getsource(
            agent.__init__
        ) or 'self._threshold =' in inspect.getsource(agent)
