"""Collision avoidance composed with connectivity preservation for ETA-1 (issue 27), ROS-free.

The layer filters an agent's ETA-1 command at its own triggers through decentralized barrier
certificates (Wang, Ames, Egerstedt, T-RO 2017, "Safety barrier certificates for collisions-free
multirobot systems"): agent i keeps its own half of each pair's barrier, using only the relative
position of the other robot (no v_j), and the edges' barriers likewise. docs/SAFETY.md argues the
design and proves what holds; the equations below carry its labels (S1)-(S6).

Barriers, with r_ij = x_i - x_j, y_ij = x_i - x_j - d_ij and c_ij = Δ - ||d_ij|| (the capacity):

    h_ij  = ||r_ij||² - D²                 (S1)  collision: robots at least D apart
    h^e_ij = c_ij² - ||y_ij||²             (S2)  connectivity: the edge in the paper's range

Agent i keeps its halves

    a_ij = 2 r_ij·v_i + (γ/2) h_ij >= 0     (S3)  every robot j it knows of
    b_ij = -2 y_ij·v_i + (γ/2) h^e_ij >= 0  (S4)  every neighbour j

and as a_ij + a_ji = ḣ_ij + γ h_ij (b likewise), both halves kept give ḣ >= -γ h, so
h(t) >= h(0) e^{-γt} > 0: robots never closer than D, edges never at capacity.

At a trigger the filter picks the command closest to the nominal one under the tightened halves
2 r·v + (γ/4) h >= 0 and -2 y·v + (γ/4) h^e >= 0 (S5) and ||v|| <= v̄, so every half starts at
>= (γ/4) h > 0 (v = 0 is always feasible). Between triggers the command is held; the agent
triggers again when a half could reach 0 (S6): for a neighbour exactly (its command is known
from its triggering information), for another robot seen within the sensing radius R at the
trigger under the worst case of its motion (||v_j|| <= v̄), and at least every (R - ρ*) / (2 v̄)
for robots not seen (a robot farther than ρ* cannot make a half negative). Every half is a
quadratic in time between events, so its first zero is closed form: the engine stays exact.

Everything is plain floats in a fixed order, so the engine and an agent node get the same bits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from formation_agent.core.errors import SafetyError

if TYPE_CHECKING:
    from formation_agent.core.crossing import CrossingSearch

DEFAULT_GAMMA = 2.0  # [1/s]
DEFAULT_MAX_SPEED = 0.5  # [m/s]
DEFAULT_SENSING_RADIUS = 2.0  # [m]
DEFAULT_TURN = 1.5  # λ: the tie-break turns the nominal command by atan(λ) = 56.3° to the right (SAFETY.md)

SAFETY_KEYS = ('min_separation', 'sensing_radius', 'gamma', 'max_speed', 'turn')
"""The scenario's `safety` keys (min_separation required)."""

# Relative slack under which a constraint of the filter counts as met (rounding of the vertices).
_FEASIBLE = 1e-12
# Relative slack under which a pair constraint counts as active at the filtered command.
_ACTIVE = 1e-9

RECOVERY_SPEED = 0.25
"""(S9): a pair closer than D (set down inside the margin) is asked apart, each robot moving away from the
other at >= this share of v̄ along x_i - x_j at its triggers (and >= half of it between them)."""
RECOVERY_EXIT = 1.1
"""(S9): a pair leaves recovery at a trigger that finds its robots at least RECOVERY_EXIT · D apart (a
margin, so that the usual barrier starts from h >= 0.21 D², not from 0)."""
RECOVERY_HALVINGS = 10
"""(S9): a robot boxed in by recovering pairs halves their demand up to this many times, then holds still."""


def _number(name: str, value: Any, *, positive: bool = True) -> float:  # any value given: checked
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SafetyError(f'{name}: must be a number, got {value!r}')
    number = float(value)
    if not math.isfinite(number) or (positive and not number > 0.0) or number < 0.0:
        raise SafetyError(f'{name}: must be a finite number {"> 0" if positive else ">= 0"}, got {value!r}')
    return number


@dataclass(frozen=True, kw_only=True)
class SafetyConfig:
    """The layer's parameters: D (min_separation, between the points the agents control), R, γ, v̄, λ."""

    min_separation: float
    sensing_radius: float = DEFAULT_SENSING_RADIUS
    gamma: float = DEFAULT_GAMMA
    max_speed: float = DEFAULT_MAX_SPEED
    turn: float = DEFAULT_TURN

    def __post_init__(self) -> None:
        for name in SAFETY_KEYS:
            value = _number(f'safety.{name}', getattr(self, name), positive=name != 'turn')
            object.__setattr__(self, name, value)
        reach = self.guard_radius
        if not self.sensing_radius > reach:
            raise SafetyError(
                f'safety.sensing_radius: must exceed the guard radius ρ* = (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ '
                f'= {reach:.6g} m (beyond it no robot can make a half-barrier negative, (S3)), got '
                f'{self.sensing_radius!r}; raise sensing_radius or gamma, or lower max_speed'
            )

    @property
    def guard_radius(self) -> float:
        """ρ*: for ||r_ij|| >= ρ*, a_ij >= -2 ||r|| v̄ + (γ/2)(||r||² - D²) >= 0 (S3) whatever v_i."""
        v, g, d = self.max_speed, self.gamma, self.min_separation
        return (2.0 * v + math.sqrt(4.0 * v * v + g * g * d * d)) / g

    @property
    def heartbeat(self) -> float:
        """(R - ρ*) / (2 v̄): the least time a robot unseen at a trigger needs to come within ρ*."""
        return (self.sensing_radius - self.guard_radius) / (2.0 * self.max_speed)

    def as_dict(self) -> dict[str, float]:
        return {name: getattr(self, name) for name in SAFETY_KEYS}

    @classmethod
    def from_mapping(cls, raw: Mapping[str, Any]) -> SafetyConfig:
        if not isinstance(raw, Mapping):
            raise SafetyError(f'safety: expected a mapping, got {raw!r}')
        unknown = [key for key in raw if key not in SAFETY_KEYS]
        if unknown:
            raise SafetyError(f'safety: unknown key {unknown[0]!r} (allowed: {", ".join(SAFETY_KEYS)})')
        if 'min_separation' not in raw:
            raise SafetyError(
                'safety: missing key min_separation (the least distance between two robots [m])'
            )
        return cls(**dict(raw))


# -- the filter (S5) -----------------------------------------------------------------------------


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    product: float = a[0] * b[0] + a[1] * b[1]
    return product


def _meets(
    v: tuple[float, float], lines: Sequence[tuple[tuple[float, float], float]], max_speed: float
) -> bool:
    """Whether v meets every a·v >= b of `lines` and ||v|| <= v̄, within the relative slack _FEASIBLE."""
    if v[0] * v[0] + v[1] * v[1] > max_speed * max_speed * (1.0 + _FEASIBLE):
        return False
    return all(_dot(a, v) >= b - _FEASIBLE * (abs(b) + math.hypot(*a) * max_speed) for a, b in lines)


def meets(v: Sequence[float], constraints: Sequence[tuple[float, float, float]], max_speed: float) -> bool:
    """Whether v meets every constraint (a_x, a_y, b_k) of `filter_command` and the speed bound: the
    filter's own test (a filter with no feasible point answers v = 0, which then fails it)."""
    lines = [((a0, a1), b) for a0, a1, b in constraints if a0 != 0.0 or a1 != 0.0]
    return _meets((float(v[0]), float(v[1])), lines, max_speed)


def filter_command(
    nominal: Sequence[float], constraints: Sequence[tuple[float, float, float]], max_speed: float
) -> tuple[float, float]:
    """argmin ||v - u||² s.t. a_k·v >= b_k for each (a_x, a_y, b_k), ||v|| <= v̄ (2-D).

    Exact by enumerating active sets: the optimum of a strictly convex objective over a convex set
    is the unconstrained point, a projection onto one boundary (a line or the circle) or a vertex
    of two (two lines, a line and the circle). The feasible candidate nearest u wins, the first in
    this fixed order on ties; v = 0, feasible whenever every b_k <= 0, is the fallback should
    rounding reject every candidate.
    """
    u = (float(nominal[0]), float(nominal[1]))
    cap2 = max_speed * max_speed
    lines = [((a0, a1), b) for a0, a1, b in constraints if a0 != 0.0 or a1 != 0.0]

    def feasible(v: tuple[float, float]) -> bool:
        return _meets(v, lines, max_speed)

    candidates = [u]
    norm_u = math.hypot(*u)
    if norm_u > 0.0:
        candidates.append((u[0] * max_speed / norm_u, u[1] * max_speed / norm_u))
    for a, b in lines:
        aa = _dot(a, a)
        shift = (b - _dot(a, u)) / aa
        candidates.append((u[0] + shift * a[0], u[1] + shift * a[1]))
        base = (b * a[0] / aa, b * a[1] / aa)  # the line's point nearest 0
        rest = cap2 - _dot(base, base)
        if rest >= 0.0:
            step = math.sqrt(rest / aa)  # along the line's direction (-a_y, a_x)/||a||
            candidates.append((base[0] - step * a[1], base[1] + step * a[0]))
            candidates.append((base[0] + step * a[1], base[1] - step * a[0]))
    for k, (a, b) in enumerate(lines):
        for c, e in lines[k + 1 :]:
            det = a[0] * c[1] - a[1] * c[0]
            if det != 0.0:
                candidates.append(((b * c[1] - a[1] * e) / det, (a[0] * e - b * c[0]) / det))
    best, best_cost = (0.0, 0.0), math.inf
    for v in candidates:
        cost = (v[0] - u[0]) ** 2 + (v[1] - u[1]) ** 2
        if cost < best_cost and feasible(v):
            best, best_cost = v, cost
    return best


# -- the halves' first zeros (S6) ----------------------------------------------------------------


def first_zero(c0: float, c1: float, c2: float, after: float) -> float:
    """The least τ >= `after` with c0 + c1 τ + c2 τ² <= 0 (inf if none), for a quadratic positive
    somewhere after `after` or not: at `after` itself when it is <= 0 there."""
    if c0 + after * (c1 + after * c2) <= 0.0:
        return after
    if c2 == 0.0:
        if c1 >= 0.0:
            return math.inf
        return max(-c0 / c1, after)
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc < 0.0:
        return math.inf if c2 > 0.0 else after
    q = -0.5 * (c1 + math.copysign(math.sqrt(disc), c1))  # the stable pair of roots q/c2, c0/q
    roots = sorted((q / c2, c0 / q)) if q != 0.0 else [0.0]
    later = [r for r in roots if r > after]
    if not later:
        return math.inf if c2 > 0.0 else after
    return later[0]


def worst_case_half(
    r0: tuple[float, float], v: tuple[float, float], config: SafetyConfig
) -> tuple[float, float, float]:
    """(c0, c1, c2): a quadratic lower bound in τ of a_ij (S3) for a robot j seen at r0 = x_i - x_j
    while i holds v and j moves at any speed <= v̄ (docs/SAFETY.md, (S7)):

    a(τ) >= a(0) + τ [2||v||² - 2 v̄ ||v|| + γ r0·v - γ v̄ ||r0||] + τ² (γ/2) [||v||² - 2 v̄ ||v||].
    """
    g, vm, d = config.gamma, config.max_speed, config.min_separation
    vv = _dot(v, v)
    speed = math.sqrt(vv)
    r_norm = math.hypot(*r0)
    rv = _dot(r0, v)
    c0 = 2.0 * rv + 0.5 * g * (_dot(r0, r0) - d * d)
    c1 = 2.0 * vv - 2.0 * vm * speed + g * rv - g * vm * r_norm
    c2 = 0.5 * g * (vv - 2.0 * vm * speed)
    return c0, c1, c2


def courteous_zero(r0: tuple[float, float], v: tuple[float, float], config: SafetyConfig) -> float:
    """A time W before which a_ij (S3) cannot reach 0 for a robot j seen at r0 while i holds v, using
    that j keeps its own half, r_ij·v_j <= (γ/4) h_ij, at all times (S7'). On [0, W]

        ȧ_ij = 2||v||² - 2 v_j·v + γ r·v - γ r·v_j
             >= m(W) = 2||v||² - 2v̄||v|| + γ (r0·v - v̄||v|| W) - (γ²/4) [(||r0|| + (||v|| + v̄) W)² - D²]

    so a_ij >= 0 on [0, W] whenever a_ij(0) + m(W) W >= 0. The largest such W up to the heartbeat,
    by 40 bisections from 0 (plain floats, fixed steps: the same bits everywhere). Where (S7) needs
    ~h/(4 v̄ ||r||) for two robots standing next to each other, this needs ~2/γ."""
    g, vm, d = config.gamma, config.max_speed, config.min_separation
    speed = math.hypot(*v)
    r_norm = math.hypot(*r0)
    rv = _dot(r0, v)
    a0 = 2.0 * rv + 0.5 * g * (_dot(r0, r0) - d * d)
    base = 2.0 * speed * speed - 2.0 * vm * speed + g * rv

    def holds(window: float) -> bool:
        reach = r_norm + (speed + vm) * window
        slope = base - g * vm * speed * window - 0.25 * g * g * (reach * reach - d * d)
        return a0 + slope * window >= 0.0

    low, high = 0.0, config.heartbeat
    if a0 <= 0.0 or holds(high):
        return high if a0 > 0.0 else 0.0
    for _ in range(40):
        mid = 0.5 * (low + high)
        if holds(mid):
            low = mid
        else:
            high = mid
    return low


def recovering_half(
    r0: tuple[float, float], v: tuple[float, float], sigma: float, max_speed: float
) -> tuple[float, float, float]:
    """(c0, c1, c2): a linear lower bound in τ of a recovering pair's half 2 r_ij·v_i - σ (S9) for a
    robot j seen at r0 while i holds v and j moves at any speed <= v̄: (S7) with γ = 0,

        2 r(τ)·v - σ >= 2 r0·v - σ + τ [2||v||² - 2 v̄ ||v||]."""
    vv = _dot(v, v)
    return 2.0 * _dot(r0, v) - sigma, 2.0 * vv - 2.0 * max_speed * math.sqrt(vv), 0.0


def exact_half(
    r: tuple[float, float],
    w: tuple[float, float],
    v: tuple[float, float],
    *,
    gamma: float,
    level: float,
    sign: float,
) -> tuple[float, float, float]:
    """(c0, c1, c2) of a half along z(τ) = r + τ w exactly: sign = +1 is a_ij (S3) with z = r_ij and
    level = D²; sign = -1 is b_ij (S4) with z = y_ij and level = c_ij²."""
    c0 = sign * (2.0 * _dot(r, v) + 0.5 * gamma * (_dot(r, r) - level))
    c1 = sign * (2.0 * _dot(w, v) + gamma * _dot(r, w))
    c2 = sign * 0.5 * gamma * _dot(w, w)
    return c0, c1, c2


# -- the layer of one agent ----------------------------------------------------------------------


class SafetyLayer:
    """One agent's filter (S5) at its triggers and its safety time (S6) between them."""

    def __init__(self, config: SafetyConfig, *, agent_id: int) -> None:
        self.config = config
        self.agent_id = agent_id
        self._seen: list[
            tuple[int, tuple[float, float]]
        ] = []  # (j, x_i - x_j) of the robots seen at the trigger
        self._recovering: dict[tuple[str, int], float] = {}  # pairs in recovery (S9) -> σ
        self._trigger_time = 0.0
        self.interventions = 0  # triggers where the applied command differs from the nominal one
        self.last_intervention: float | None = None  # the time of the latest such trigger

    def check_nearby(
        self, nearby: Mapping[int, Sequence[float]] | None, *, neighbours: Sequence[int]
    ) -> None:
        """SafetyError unless `nearby` is what a range sensor within R gives: other robots only (not
        this agent, not a neighbour), planar, finite, each within the sensing radius (the engine's
        `World.nearby` rule, ||r||² <= R²). None is refused: the layer blind to the robots that are
        not neighbours would keep no distance from them."""
        me = self.agent_id
        if nearby is None:
            raise SafetyError(
                f'agent {me}: the safety layer needs the other robots within the sensing radius '
                '(nearby) at every trigger; the sensing gave none (docs/SAFETY.md)'
            )
        radius2 = self.config.sensing_radius * self.config.sensing_radius
        for j, r in nearby.items():
            if j == me or j in neighbours:
                raise SafetyError(
                    f'agent {me}: nearby robot {j} is the agent itself or one of its neighbours'
                )
            if len(r) != 2 or not all(math.isfinite(v) for v in r):
                raise SafetyError(
                    f'agent {me}: nearby robot {j} must be at a finite planar x_i - x_j, got {r!r}'
                )
            if not sum(v * v for v in r) <= radius2:
                raise SafetyError(
                    f'agent {me}: nearby robot {j} at {math.hypot(*r)!r} m is beyond the sensing radius '
                    f'{self.config.sensing_radius!r} m'
                )

    def filter(
        self,
        *,
        t: float,
        nominal: Sequence[float],
        rel: Sequence[Sequence[float]],
        y: Sequence[Sequence[float]],
        capacity: Sequence[float],
        nearby: Mapping[int, Sequence[float]] | None,
    ) -> tuple[float, float]:
        """The applied command at a trigger: the nominal one through (S5), with the tie-break.

        `rel`, `y`, `capacity`: each neighbour's r_ij, y_ij and c_ij; `nearby`: x_i - x_j of the
        other robots within the sensing radius. A pair closer than D (a start inside the margin)
        is recovering (S9): its constraint asks the robots apart instead."""
        cfg = self.config
        pairs = [(float(r[0]), float(r[1])) for r in rel]
        seen_items = [(j, (float(r[0]), float(r[1]))) for j, r in sorted((nearby or {}).items())]
        seen = [r for _, r in seen_items]
        keys = [('edge', k) for k in range(len(pairs))] + [('seen', j) for j, _ in seen_items]
        points = (*pairs, *seen)
        recovering = self._recovering_pairs(keys, points)
        g4 = 0.25 * cfg.gamma
        edge_rows = []
        for row, c in zip(y, capacity):  # -2 y·v >= -(γ/4) h^e_ij
            z = (float(row[0]), float(row[1]))
            edge_rows.append((-2.0 * z[0], -2.0 * z[1], -g4 * (c * c - _dot(z, z))))
        u = (float(nominal[0]), float(nominal[1]))
        v, constraints, scale = self._solve(u, points, recovering, edge_rows)
        # Tie-break: a pair constraint active at v may hold the robots where the nominal commands
        # cancel (head on, or a ring closing on its centre). Each robot then turns its nominal
        # command to its right, u' = u + λ ||u|| right(u), and filters again: the robots pass each
        # other on the right, a roundabout. Deterministic: fixed order, fixed share λ.
        blocked = any(
            a0 * v[0] + a1 * v[1] - b <= _ACTIVE * (abs(b) + math.hypot(a0, a1) * cfg.max_speed)
            for a0, a1, b in constraints[: len(points)]
        )
        if blocked and cfg.turn > 0.0:
            lam = cfg.turn
            v, constraints, scale = self._solve(
                (u[0] + lam * u[1], u[1] - lam * u[0]), points, recovering, edge_rows
            )
        share = RECOVERY_SPEED * cfg.max_speed * scale
        self._recovering = {keys[k]: math.hypot(*points[k]) * share for k in recovering}
        self._seen = seen_items
        self._trigger_time = t
        self._command = v
        if v != u:
            self.interventions += 1
            self.last_intervention = t
        return v

    def _recovering_pairs(
        self, keys: Sequence[tuple[str, int]], points: Sequence[tuple[float, float]]
    ) -> set[int]:
        """The pairs (indices into `points`) in recovery at this trigger (S9): closer than D, or in
        recovery at the previous trigger and not yet RECOVERY_EXIT D apart."""
        dd = self.config.min_separation * self.config.min_separation
        exit2 = dd * RECOVERY_EXIT * RECOVERY_EXIT
        return {
            k
            for k, (key, r) in enumerate(zip(keys, points))
            if _dot(r, r) <= dd or (key in self._recovering and _dot(r, r) < exit2)
        }

    def _solve(
        self,
        u: tuple[float, float],
        points: Sequence[tuple[float, float]],
        recovering: set[int],
        edge_rows: list[tuple[float, float, float]],
    ) -> tuple[tuple[float, float], list[tuple[float, float, float]], float]:
        """(v, the constraints it meets, the recovery demand's scale): (S5) with every pair's
        constraint, a recovering pair's asking r̂_ij·v >= scale · RECOVERY_SPEED · v̄ (S9). Boxed in
        (no v meets them all) the demand is halved, RECOVERY_HALVINGS times at most; then the robot
        holds still (scale 0: v = 0 meets every constraint then)."""
        cfg = self.config
        g4, dd = 0.25 * cfg.gamma, cfg.min_separation * cfg.min_separation
        scale = 1.0
        for _ in range(RECOVERY_HALVINGS + 1):
            share = RECOVERY_SPEED * cfg.max_speed * scale
            constraints = []
            for k, r in enumerate(points):  # 2 r·v >= -(γ/4) h_ij, or 2 r·v >= 2 ||r|| share (S9)
                bound = 2.0 * math.hypot(*r) * share if k in recovering else -g4 * (_dot(r, r) - dd)
                constraints.append((2.0 * r[0], 2.0 * r[1], bound))
            constraints.extend(edge_rows)
            v = filter_command(u, constraints, cfg.max_speed)
            if not recovering or meets(v, constraints, cfg.max_speed):
                return v, constraints, scale
            scale *= 0.5
        constraints = [
            (2.0 * r[0], 2.0 * r[1], 0.0 if k in recovering else -g4 * (_dot(r, r) - dd))
            for k, r in enumerate(points)
        ]
        return (0.0, 0.0), [*constraints, *edge_rows], 0.0

    def safety_time(
        self,
        *,
        now: float,
        edges: Sequence[tuple[float, Sequence[float], Sequence[float], Sequence[float], float]],
    ) -> float:
        """The first time any half (S3), (S4) or a recovering pair's (S9) could reach 0 (S6), or the
        heartbeat; `edges`: per neighbour (anchor time s, y_ij(s), d_ij, its command u_j, its
        capacity c_ij), with the agent's command held."""
        cfg = self.config
        v = self._command
        t0 = self._trigger_time
        best = t0 + cfg.heartbeat
        for j, r in self._seen:  # (S7) and (S7'), each a valid bound: the later one; (S9) recovering
            sigma = self._recovering.get(('seen', j))
            if sigma is None:
                zero = max(
                    first_zero(*worst_case_half(r, v, cfg), max(now - t0, 0.0)), courteous_zero(r, v, cfg)
                )
            elif sigma > 0.0:
                zero = first_zero(*recovering_half(r, v, sigma, cfg.max_speed), max(now - t0, 0.0))
            else:  # holding still: its own part of dh/dt is 0 until it triggers again
                continue
            best = min(best, t0 + zero)
        dd = cfg.min_separation * cfg.min_separation
        for k, (s, y, d, u_j, c) in enumerate(edges):
            w = (v[0] - u_j[0], v[1] - u_j[1])
            z = (y[0], y[1])
            r = (z[0] + d[0], z[1] + d[1])
            after = max(now - s, 0.0)
            sigma = self._recovering.get(('edge', k))
            if sigma is None:
                collide = first_zero(*exact_half(r, w, v, gamma=cfg.gamma, level=dd, sign=1.0), after)
            elif sigma > 0.0:  # 2 r(τ)·v - σ, r(τ) = r + τ w exactly (S9)
                c0, c1, _ = exact_half(r, w, v, gamma=0.0, level=0.0, sign=1.0)
                collide = first_zero(c0 - sigma, c1, 0.0, after)
            else:
                collide = math.inf
            stretch = first_zero(*exact_half(z, w, v, gamma=cfg.gamma, level=c * c, sign=-1.0), after)
            best = min(best, s + collide, s + stretch)
        return best

    @property
    def recovering(self) -> dict[tuple[str, int], float]:
        """The pairs in recovery at the latest trigger (S9): ('edge', k) for the k-th neighbour,
        ('seen', j) for robot j, each with its σ (0: holding still, boxed in)."""
        return dict(self._recovering)

    _command: tuple[float, float] = (0.0, 0.0)


class CappedSearch:
    """The agent's certified ETA-1 search (`crossing.CrossingSearch`) with the safety time as a cap:
    its answer is min(first crossing, cap), found with the very steps of the search alone, so it
    does not depend on how far a caller advanced it. Same interface (frontier, advance, run)."""

    def __init__(self, inner: CrossingSearch, cap: float) -> None:
        self.inner = inner
        self.cap = cap
        self.limit = inner.limit
        self.result: float | None = None
        self._settle()

    @property
    def frontier(self) -> float:
        return min(self.inner.frontier, self.cap)

    @property
    def done(self) -> bool:
        return self.result is not None

    def _settle(self) -> None:
        inner, cap = self.inner, self.cap if self.cap <= self.limit else math.inf
        if inner.result is not None:
            self.result = min(inner.result, cap)
        elif inner.frontier >= self.cap:  # no crossing before the frontier: the cap comes first
            self.result = cap

    def advance(self, until: float) -> float | None:
        if self.result is None:
            self.inner.advance(min(until, self.cap))
            self._settle()
        return self.result

    def run(self) -> float:
        return cast(float, self.advance(math.inf))  # settled once the search reached inf
