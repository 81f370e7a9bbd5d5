"""The safety layer's pieces (formation_agent.core.safety), each against an independent check:
the filter against a dense search of the feasible set, the first zeros against sign scans, the
worst-case bound against sampled motions of the other robot, the no-Zeno bound (S8) on random
configurations, the capped search against its parts, and the configuration's errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.errors import AgentError, SafetyError
from formation_agent.core.eta import Eta1Agent, make_agent
from formation_agent.core.safety import (
    RECOVERY_EXIT,
    RECOVERY_SPEED,
    CappedSearch,
    SafetyConfig,
    SafetyLayer,
    courteous_zero,
    exact_half,
    filter_command,
    first_zero,
    recovering_half,
    worst_case_half,
)
from formation_msgs_py.types import SensedState

CONFIG = SafetyConfig(min_separation=0.25)


def _dense_disk(max_speed: float, count: int = 400) -> np.ndarray:
    """A polar grid of the disk ||v|| <= v̄ (boundary included)."""
    radius = np.linspace(0.0, max_speed, count // 8)
    angle = np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    r, a = np.meshgrid(radius, angle)
    return np.stack([(r * np.cos(a)).ravel(), (r * np.sin(a)).ravel()], axis=1)


@pytest.mark.parametrize('seed', range(12))
def test_the_filter_is_feasible_and_no_feasible_point_is_nearer_the_nominal(seed):
    rng = np.random.default_rng(seed)
    max_speed = 0.5
    u = rng.normal(size=2) * 0.6
    constraints = [(*rng.normal(size=2), -abs(rng.normal()) * 0.1) for _ in range(int(rng.integers(1, 5)))]
    v = filter_command(u, constraints, max_speed)
    assert math.hypot(*v) <= max_speed * (1 + 1e-9)
    for a0, a1, b in constraints:
        assert a0 * v[0] + a1 * v[1] >= b - 1e-9
    grid = _dense_disk(max_speed)
    ok = np.all([grid @ np.array([a0, a1]) >= b for a0, a1, b in constraints], axis=0)
    nearest = np.min(((grid[ok] - u) ** 2).sum(axis=1))
    assert (v[0] - u[0]) ** 2 + (v[1] - u[1]) ** 2 <= nearest + 1e-9


def test_the_filter_leaves_a_feasible_nominal_alone_and_clips_the_speed():
    assert filter_command((0.1, -0.2), [(1.0, 0.0, -1.0)], 0.5) == (0.1, -0.2)
    assert filter_command((3.0, 4.0), [], 0.5) == pytest.approx((0.3, 0.4), abs=1e-15)
    # head on: the other robot at +x, 2 r·v >= -(γ/4) h with r = (-1, 0): v_x <= (γ/8) h
    v = filter_command((0.4, 0.0), [(-2.0, 0.0, -0.1)], 0.5)
    assert v == pytest.approx((0.05, 0.0))


@pytest.mark.parametrize('seed', range(20))
def test_first_zero_is_the_first_sign_change_after_the_start(seed):
    rng = np.random.default_rng(seed)
    c0, c1, c2 = rng.normal(size=3)
    after = float(abs(rng.normal()))
    tau = first_zero(c0, c1, c2, after)
    value = np.polynomial.Polynomial([c0, c1, c2])
    if value(after) <= 0.0:
        assert tau == after
        return
    end = tau if math.isfinite(tau) else after + 100.0
    scan = np.linspace(after, end, 20001)[:-1]
    assert np.all(value(scan) > -1e-12)  # no earlier zero
    if math.isfinite(tau):
        assert abs(value(tau)) <= 1e-9 * (1 + abs(c0) + abs(c1) * tau + abs(c2) * tau * tau)
    else:
        assert c2 >= 0.0 and np.all(value(np.linspace(after, after + 1e3, 1001)) > 0.0)


@pytest.mark.parametrize('seed', range(10))
def test_the_worst_case_half_bounds_every_motion_of_the_other_robot(seed):
    """(S7): whatever j does at speeds <= v̄, a_ij(τ) stays above the quadratic."""
    rng = np.random.default_rng(seed)
    cfg = CONFIG
    r0 = rng.normal(size=2) * 0.6
    v = rng.normal(size=2)
    v = v / np.linalg.norm(v) * cfg.max_speed * rng.random()
    c0, c1, c2 = worst_case_half(tuple(r0), tuple(v), cfg)
    taus = np.linspace(0.0, 2.0, 401)
    bound = c0 + c1 * taus + c2 * taus**2
    for _ in range(30):  # piecewise-constant velocities of j, each of norm <= v̄
        steps = rng.normal(size=(400, 2))
        steps *= (cfg.max_speed * rng.random((400, 1))) / np.linalg.norm(steps, axis=1, keepdims=True)
        w = np.vstack([[0.0, 0.0], np.cumsum(steps * (taus[1] - taus[0]), axis=0)])
        r = r0 + taus[:, None] * v - w
        half = 2.0 * r @ v + 0.5 * cfg.gamma * ((r * r).sum(axis=1) - cfg.min_separation**2)
        assert np.all(half >= bound - 1e-12)


@pytest.mark.parametrize('seed', range(10))
def test_the_courteous_bound_holds_while_the_other_robot_keeps_its_half(seed):
    """(S7'): j moves at any speed <= v̄ but keeps r_ij·v_j <= (γ/4) h_ij (its own half); then
    a_ij stays >= 0 up to courteous_zero (400 Euler steps, 3 random motions of j per seed)."""
    rng = np.random.default_rng(seed)
    cfg = CONFIG
    d = cfg.min_separation
    r0 = rng.normal(size=2)
    r0 *= (d + rng.uniform(1e-4, 0.3)) / np.linalg.norm(r0)  # close: where (S7') matters
    v = rng.normal(size=2)
    v *= cfg.max_speed * rng.random() ** 3 / np.linalg.norm(v)
    if 2 * r0 @ v + 0.25 * cfg.gamma * (r0 @ r0 - d * d) < 0:  # a command the filter could give
        v = np.zeros(2)
    limit = courteous_zero(tuple(r0), tuple(v), cfg)
    steps = 400
    dt = min(limit, 0.2) / steps  # Euler steps, each v_j projected onto j's half
    g, vm, vx, vy = cfg.gamma, cfg.max_speed, float(v[0]), float(v[1])
    for _ in range(3):
        rx, ry = float(r0[0]), float(r0[1])
        for angle, size in zip(rng.uniform(0, 2 * math.pi, steps), rng.random(steps)):
            jx, jy = vm * size * math.cos(angle), vm * size * math.sin(angle)
            excess = rx * jx + ry * jy - 0.25 * g * (rx * rx + ry * ry - d * d)
            if excess > 0:
                norm2 = rx * rx + ry * ry
                jx, jy = jx - excess * rx / norm2, jy - excess * ry / norm2
                scale = min(1.0, vm / math.hypot(jx, jy))
                jx, jy = jx * scale, jy * scale
            rx, ry = rx + dt * (vx - jx), ry + dt * (vy - jy)
            assert 2 * (rx * vx + ry * vy) + 0.5 * g * (rx * rx + ry * ry - d * d) >= -1e-9
    assert limit > 0.0


def test_the_exact_half_is_the_barrier_along_the_line():
    r, w, v = (0.3, -0.4), (0.2, 0.1), (0.05, -0.3)
    taus = np.linspace(0.0, 3.0, 31)
    for sign, level in ((1.0, 0.0625), (-1.0, 9.0)):
        c0, c1, c2 = exact_half(r, w, v, gamma=2.0, level=level, sign=sign)
        z = np.array(r) + taus[:, None] * np.array(w)
        direct = sign * (2.0 * z @ np.array(v) + 1.0 * ((z * z).sum(axis=1) - level))
        np.testing.assert_allclose(c0 + c1 * taus + c2 * taus**2, direct, rtol=1e-12, atol=1e-14)


def test_beyond_the_guard_radius_no_command_makes_a_half_negative():
    cfg = CONFIG
    angles = np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
    worst = np.stack([np.cos(angles), np.sin(angles)], axis=1) * cfg.max_speed
    for distance, negative in ((cfg.guard_radius * (1 + 1e-9), False), (cfg.guard_radius * 0.99, True)):
        r = np.array([distance, 0.0])
        half = 2.0 * worst @ r + 0.5 * cfg.gamma * (distance**2 - cfg.min_separation**2)
        assert bool(np.any(half < 0.0)) is negative


@pytest.mark.parametrize('seed', range(30))
def test_after_a_filter_no_half_reaches_zero_before_the_no_zeno_bound(seed):
    """(S8): every half starts at >= (γ/4) h and moves at most B + 2Aτ, so the safety time is at
    least 2 c / (B + sqrt(B² + 4 A c)), c = (γ/4) min(h, h^e), B = 4v̄² + 2γv̄ρ, A = 2γv̄²."""
    rng = np.random.default_rng(seed)
    cfg = CONFIG
    layer = SafetyLayer(cfg, agent_id=1)
    t = float(rng.random() * 5)
    nominal = rng.normal(size=2)
    rel = [tuple(rng.normal(size=2) * 0.8) for _ in range(2)]
    offsets = [tuple(rng.normal(size=2) * 0.5) for _ in range(2)]
    rel = [r if math.hypot(*r) > 0.3 else (0.3, 0.3) for r in rel]
    y = [(r[0] - d[0], r[1] - d[1]) for r, d in zip(rel, offsets)]
    capacity = [4.0 - math.hypot(*d) for d in offsets]
    nearby = {7: (0.4, -0.2), 8: (-0.5, 1.2)}
    v = layer.filter(t=t, nominal=nominal, rel=rel, y=y, capacity=capacity, nearby=nearby)
    u_j = [tuple(rng.normal(size=2)) for _ in range(2)]
    u_j = [tuple(np.array(u) / max(1.0, np.linalg.norm(u) / cfg.max_speed)) for u in u_j]
    edges = [(t, y[k], offsets[k], u_j[k], capacity[k]) for k in range(2)]
    when = layer.safety_time(now=t, edges=edges)
    h = [math.hypot(*r) ** 2 - cfg.min_separation**2 for r in (*rel, *nearby.values())]
    h_e = [c * c - math.hypot(*z) ** 2 for z, c in zip(y, capacity)]
    c = 0.25 * cfg.gamma * min(h + h_e)
    rho = max(cfg.sensing_radius, 4.0, *(math.hypot(*r) for r in rel))
    big_b = 4 * cfg.max_speed**2 + 2 * cfg.gamma * cfg.max_speed * rho
    big_a = 2 * cfg.gamma * cfg.max_speed**2
    bound = 2 * c / (big_b + math.sqrt(big_b**2 + 4 * big_a * c))
    assert math.hypot(*v) <= cfg.max_speed * (1 + 1e-9)
    assert when - t >= min(bound, cfg.heartbeat) * (1 - 1e-9)
    assert when - t <= cfg.heartbeat


class _Search:
    """A stand-in for crossing.CrossingSearch: certified steps of 0.1 up to its answer."""

    def __init__(self, answer: float, limit: float = math.inf) -> None:
        self.answer, self.limit, self.frontier, self.result = answer, limit, 0.0, None

    def advance(self, until: float):
        while self.result is None and self.frontier <= until:
            if self.frontier >= self.answer:
                self.result = self.answer
            else:
                self.frontier = min(self.frontier + 0.1, self.answer)
        return self.result


@pytest.mark.parametrize(('answer', 'cap'), [(1.0, 0.55), (0.55, 1.0), (1.0, 1.0), (math.inf, 0.3)])
@pytest.mark.parametrize('pieces', [(), (0.2,), (0.2, 0.5, 0.7)])
def test_the_capped_search_answers_min_of_both_however_it_is_advanced(answer, cap, pieces):
    search = CappedSearch(_Search(answer), cap)
    for until in pieces:
        result = search.advance(until)
        assert result is None or result == min(answer, cap)
        assert search.frontier <= min(answer, cap)
    assert search.run() == min(answer, cap)


def test_a_cap_beyond_the_limit_means_no_time_within_it():
    assert CappedSearch(_Search(math.inf, limit=2.0), 5.0).run() == math.inf


@pytest.mark.parametrize(
    ('keys', 'rule'),
    [
        ({'min_separation': -0.1}, 'safety.min_separation: must be a finite number > 0, got -0.1'),
        ({'min_separation': 0.25, 'gamma': float('nan')}, 'safety.gamma: must be a finite number > 0'),
        ({'min_separation': 0.25, 'turn': -1}, 'safety.turn: must be a finite number >= 0, got -1'),
        ({'min_separation': 0.25, 'max_speed': 'fast'}, "safety.max_speed: must be a number, got 'fast'"),
        (
            {'min_separation': 0.25, 'sensing_radius': 1.0},
            'safety.sensing_radius: must exceed the guard radius',
        ),
        ({'min_separation': 0.25, 'radius': 1.0}, "safety: unknown key 'radius'"),
        ({'gamma': 1.0}, 'safety: missing key min_separation'),
    ],
)
def test_a_bad_configuration_names_its_rule_and_value(keys, rule):
    with pytest.raises(SafetyError) as caught:
        SafetyConfig.from_mapping(keys)
    assert rule in str(caught.value)


def test_the_guard_radius_error_says_the_least_radius():
    # (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ with v̄ = 0.5, γ = 2, D = 0.25: (1 + sqrt(1.25)) / 2 = 1.059017
    with pytest.raises(SafetyError, match=r'ρ\* = .* = 1\.05902 m .* got 1\.0;'):
        SafetyConfig(min_separation=0.25, sensing_radius=1.0)


def _pair(safety):
    agents = {
        1: Eta1Agent(agent_id=1, neighbours={2: (1.0, 0.0)}, delta=4.0, alpha=1.0, beta=0.3, safety=safety),
        2: Eta1Agent(agent_id=2, neighbours={1: (-1.0, 0.0)}, delta=4.0, alpha=1.0, beta=0.3, safety=safety),
    }
    sensed = {
        1: SensedState(
            agent=1, stamp=0.0, rel_positions={2: (-1.0, 0.0)}, rel_velocities=None, velocity=None
        ),
        2: SensedState(agent=2, stamp=0.0, rel_positions={1: (1.0, 0.0)}, rel_velocities=None, velocity=None),
    }
    return agents, sensed


def test_with_the_layer_the_applied_command_is_broadcast_and_the_error_keeps_the_nominal_one():
    plain, sensed = _pair(None)
    safe, _ = _pair(CONFIG)
    nominal = plain[1].trigger(0.0, sensed[1])
    applied = safe[1].trigger(0.0, sensed[1], nearby={})
    assert math.hypot(*applied.control) <= CONFIG.max_speed * (1 + 1e-12) < math.hypot(*nominal.control)
    assert applied.infos[0].control == tuple(applied.control)
    np.testing.assert_array_equal(safe[1]._offset, plain[1]._offset)  # e_i = Σ ω y + u_i (nominal)
    assert safe[1].safety_interventions == 1 and plain[1].safety_interventions == 0
    assert safe[1].safety == CONFIG and plain[1].safety is None


def test_the_layer_is_refused_where_it_does_not_apply():
    with pytest.raises(AgentError, match="agent 3: the safety layer runs with eta1 only, got 'eta2'"):
        make_agent(
            algorithm='eta2',
            agent_id=3,
            neighbours={1: (1.0, 0.0)},
            delta=4.0,
            gains={'alpha_d': 1.0, 'beta_d': 0.5, 'k1': 1.0, 'k2': 1.0, 'k3': 0.5},
            safety=CONFIG,
        )
    with pytest.raises(AgentError, match='agent 1: the safety layer is planar, got dimension 3'):
        Eta1Agent(agent_id=1, neighbours={2: (1.0, 0.0, 0.0)}, delta=4.0, alpha=1.0, beta=0.3, safety=CONFIG)


@pytest.mark.parametrize(
    ('nearby', 'complaint'),
    [
        (None, 'agent 1: the safety layer needs the other robots within the sensing radius (nearby)'),
        ({1: (0.5, 0.0)}, 'agent 1: nearby robot 1 is the agent itself or one of its neighbours'),
        ({2: (0.5, 0.0)}, 'agent 1: nearby robot 2 is the agent itself or one of its neighbours'),
        ({3: (0.5, 0.0, 0.0)}, 'agent 1: nearby robot 3 must be at a finite planar x_i - x_j'),
        ({3: (math.nan, 0.0)}, 'agent 1: nearby robot 3 must be at a finite planar x_i - x_j'),
        ({3: (2.5, 0.0)}, 'agent 1: nearby robot 3 at 2.5 m is beyond the sensing radius 2.0 m'),
    ],
)
def test_a_trigger_refuses_nearby_robots_a_range_sensor_cannot_give(nearby, complaint):
    # What a distributed agent is handed by its sensing (docs/SAFETY.md): refused before anything
    # changes, so the agent stays as it was.
    safe, sensed = _pair(CONFIG)
    with pytest.raises(SafetyError) as error:
        safe[1].trigger(0.0, sensed[1], nearby=nearby)
    assert complaint in str(error.value)
    assert safe[1].last_trigger is None and safe[1].safety_interventions == 0
    edge = {3: (2.0, 0.0)}  # exactly at R: seen, as `World.nearby` sees it (||r||² <= R²)
    assert safe[1].trigger(0.0, sensed[1], nearby=edge).time == 0.0


def _filter_alone(layer: SafetyLayer, nominal, nearby, t: float = 0.0):
    return layer.filter(t=t, nominal=nominal, rel=[], y=[], capacity=[], nearby=nearby)


@pytest.mark.parametrize('seed', range(20))
def test_a_pair_inside_the_margin_is_moved_apart_and_its_half_holds_until_the_next_trigger(seed):
    """(S9): whatever the nominal command, a robot set down closer than D to another moves away from
    it at >= RECOVERY_SPEED v̄ along r̂, and the safety time keeps 2 r·v - σ >= 0 under every motion
    of the other robot up to v̄ (sampled), with a next trigger strictly later."""
    rng = np.random.default_rng(seed)
    r = rng.normal(size=2)
    r = tuple(r / np.linalg.norm(r) * rng.uniform(0.02, 0.99) * CONFIG.min_separation)
    nominal = tuple(rng.normal(size=2) * 0.4)
    layer = SafetyLayer(CONFIG, agent_id=1)
    v = _filter_alone(layer, nominal, {2: r})
    assert np.dot(r, v) / np.linalg.norm(r) >= RECOVERY_SPEED * CONFIG.max_speed * (1 - 1e-12)
    assert math.hypot(*v) <= CONFIG.max_speed * (1 + 1e-12)
    sigma = layer.recovering[('seen', 2)]
    assert sigma == pytest.approx(np.linalg.norm(r) * RECOVERY_SPEED * CONFIG.max_speed)
    until = layer.safety_time(now=0.0, edges=[])
    assert until > 0.0
    for _ in range(20):  # the other robot's motions: piecewise constant velocities up to v̄
        steps = rng.normal(size=(50, 2))
        steps *= CONFIG.max_speed * rng.uniform(0, 1, size=(50, 1)) / np.linalg.norm(steps, axis=1)[:, None]
        tau = np.linspace(0.0, until, 51)[1:]
        moved = np.cumsum(steps * (until / 50), axis=0)
        rel = np.asarray(r) + tau[:, None] * np.asarray(v) - moved
        assert np.all(2 * rel @ np.asarray(v) - sigma >= -1e-12)
    c0, _, c2 = recovering_half(r, v, sigma, CONFIG.max_speed)  # starts at >= σ: twice the demand
    assert c0 >= sigma * (1 - 1e-9) and c2 == 0.0


def test_a_robot_boxed_in_by_two_recovering_pairs_holds_still_without_a_trigger_loop():
    """The middle of three robots 0.1 m apart on a line cannot move away from both: the demand is
    halved until none is asked, and it holds still (v = 0) with its next trigger at the heartbeat."""
    layer = SafetyLayer(CONFIG, agent_id=2)
    v = _filter_alone(layer, (0.3, 0.1), {1: (0.1, 0.0), 3: (-0.1, 0.0)})
    assert v == (0.0, 0.0)
    assert layer.recovering == {('seen', 1): 0.0, ('seen', 3): 0.0}
    assert layer.safety_time(now=0.0, edges=[]) == CONFIG.heartbeat


def test_recovery_ends_only_at_the_exit_margin():
    """Hysteresis: a pair in recovery stays in it until a trigger finds it RECOVERY_EXIT · D apart; a
    pair never inside the margin at 1.05 D is an ordinary pair."""
    d = CONFIG.min_separation
    layer = SafetyLayer(CONFIG, agent_id=1)
    _filter_alone(layer, (0.0, 0.0), {2: (0.5 * d, 0.0)})
    _filter_alone(layer, (0.0, 0.0), {2: (1.05 * d, 0.0)}, t=0.1)
    assert ('seen', 2) in layer.recovering
    _filter_alone(layer, (0.0, 0.0), {2: (RECOVERY_EXIT * d, 0.0)}, t=0.2)
    assert layer.recovering == {}
    fresh = SafetyLayer(CONFIG, agent_id=1)
    assert _filter_alone(fresh, (0.0, 0.0), {2: (1.05 * d, 0.0)}) == (0.0, 0.0)
    assert fresh.recovering == {}
