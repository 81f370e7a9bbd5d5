"""The time warp that keeps ETA-1's commands within a robot's limits (ROS-free, pure arithmetic on
the numbers of one exact run or of the proofs' bound; docs/SPEED_SCALE.md, "A time warp").

Under a warp the command at real time t is κ(t) u_p(s(t)) (`formation_agent.core.time_warp`), so
on a piece [s_m, s_{m+1}) of the paper's time the rate

    κ_m = min(κ_max, L / (m U_m)),   U_m >= max_i ||u_p,i(s)|| for s in [s_m, s_{m+1}),

keeps every command within the speed limit L = min(V, W l) (a unicycle steered at l turns at
||u||/l at most; `RobotLimits.speed_limit`), m the margin. Two sources of U_m:

- **observed**: the largest command of the exact run at κ = 1 in force on the piece (ETA-1's
  commands are constant between events, so this is exact for that run), margin OBSERVED_MARGIN.
- **guaranteed**: the proofs' bound, which decays: u_p,i = e_i(s) - Σ_j ω_ij(s) y_ij(s) at any s
  before i's next event (the definition of e_i), so with (wij), (lengthysV) and (triggersingle)
  ||u_p,i(s)|| <= min(Σ_j f_ij(k_ij) min(k_ij, 2 sqrt(k_V)), (α + 2 sqrt(k_V) Σ_j f_ij(k_ij)) e^{-βs}),
  the two numbers `command_bound` reports as speed and (dotyi); margin 1. It decreases in s, so its
  value at s_m bounds the piece.

Each piece lasts `window` seconds of real time (its paper length κ_m × window), so the warp
follows the run as closely early on, when κ is small, as late. κ_max caps the events per real
second that ETA-1's own bound allows (`formation_agent.core.time_warp.WARP_CAP`); the observed
warp also caps every piece at the events the exact run has on it: at most `event_rate` per agent
per real second (WARP_EVENT_RATE), which the safety layer's triggers, not bounded by ETA-1's ξ_i,
can otherwise exceed (docs/SPEED_SCALE.md, "The events' cap").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formation_agent.core.time_warp import WARP_CAP, TimeWarp
from formation_sim.model.errors import LimitsError
from formation_sim.model.speed_choice import OBSERVED_MARGIN, RobotLimits, Settling, check_limits_apply

WARP_WINDOW = 0.5
"""The real duration of one piece of a chosen warp [s]."""

WARP_EVENT_RATE = 40.0
"""The most events per agent per real second an observed warp lets the team have on any piece
[1/s].  With the safety layer a robot run of random_square(201) had 869 events in one second of
the paper's time (the layer's triggers of robots in each other's way, milliseconds apart), ~350 per
real second for 4 agents under the warp, and the loaded machine's robots' poses went stale
(issue 27).  A run at κ = 1 without the layer stays far below (robots_lab: ~1 per agent per
second)."""

__all__ = [
    'OBSERVED_MARGIN',
    'WARP_CAP',
    'WARP_EVENT_RATE',
    'WARP_WINDOW',
    'WarpChoice',
    'guaranteed_warp',
    'observed_warp',
    'warp_limit',
]


def warp_limit(limits: RobotLimits, dynamics: str, *, cap: float, window: float) -> float:
    """The speed limit L a warp keeps the commands within; LimitsError where no warp applies."""
    check_limits_apply(limits, dynamics)
    if dynamics != 'single':
        raise LimitsError(
            'time_warp: ETA-1 only: under a piecewise-constant warp ETA-2 velocities would jump with κ at '
            'every piece, which a double integrator cannot (docs/SPEED_SCALE.md, "A time warp"); use a '
            'constant --speed-scale'
        )
    if math.isfinite(limits.max_acceleration):
        raise LimitsError('time_warp: an acceleration limit applies to ETA-2 only')
    for name, value in (('cap', cap), ('window', window)):
        if not (math.isfinite(value) and value > 0.0):
            raise LimitsError(f'time_warp: {name} must be a finite number > 0, got {value!r}')
    limit, _ = limits.speed_limit()
    if not math.isfinite(limit):
        raise LimitsError('time_warp: needs a speed or turn-rate limit (--max-speed, --max-angular-speed)')
    return limit


def _pieces(
    largest_on,
    *,
    limit: float,
    margin: float,
    cap: float,
    window: float,
    horizons: tuple[float, float],
    longest=None,
):
    """(starts, rates) from `largest_on(a, b)`, a bound on the commands over [a, b) of the paper's
    time, until the paper time or the real time of `horizons` is reached; `longest(s)` (if given):
    the longest paper time from s that a piece may cover (the events' cap)."""
    paper_horizon, real_horizon = horizons
    starts: list[float] = []
    rates: list[float] = []
    s = t = 0.0
    while True:
        rate_cap = cap if longest is None else min(cap, longest(s) / window)
        kappa = _rate(largest_on(s, s), limit=limit, margin=margin, cap=rate_cap)
        # The largest over the piece can only lower κ, and a lower κ shortens the piece, over
        # which the largest is no larger (nor are its events more): one correction is enough.
        kappa = _rate(largest_on(s, s + kappa * window), limit=limit, margin=margin, cap=rate_cap)
        if not rates or kappa != rates[-1]:
            starts.append(s)
            rates.append(kappa)
        s, t = s + kappa * window, t + window
        if s >= paper_horizon or t >= real_horizon:
            return starts, rates


def _rate(largest: float, *, limit: float, margin: float, cap: float) -> float:
    return cap if largest <= 0.0 else min(cap, limit / (margin * largest))


def observed_warp(
    *,
    times,
    largest,
    limits: RobotLimits,
    horizons: tuple[float, float],
    margin: float = OBSERVED_MARGIN,
    cap: float = WARP_CAP,
    window: float = WARP_WINDOW,
    events=None,
    agents: int = 1,
    event_rate: float = WARP_EVENT_RATE,
) -> TimeWarp:
    """The warp from an exact κ = 1 run: `largest[k]` is the largest ||u_i|| in force from the
    paper time `times[k]` (increasing, times[0] = 0) to the next.  `horizons`: (the paper time the
    exact run covers, the real horizon of the warped run); beyond the last piece its rate holds, so
    the exact run must cover the paper time the warped run reaches (κ_max times its horizon).
    `events`: every trigger time of the run's `agents` agents (one per event); then no piece holds
    more than `event_rate` × `agents` × `window` of them."""
    limit = warp_limit(limits, 'single', cap=cap, window=window)
    if not (math.isfinite(margin) and margin >= 1.0):
        raise LimitsError(f'margin: must be a finite number >= 1, got {margin!r}')
    times = np.asarray(times, dtype=float)
    largest = np.asarray(largest, dtype=float)
    if times.size == 0 or times.size != largest.size or times[0] != 0.0 or np.any(np.diff(times) <= 0.0):
        raise LimitsError(
            'time_warp: the exact run must give one largest command per increasing event time from t = 0'
        )

    def largest_on(a: float, b: float) -> float:
        first = int(np.searchsorted(times, a, side='right')) - 1
        last = max(int(np.searchsorted(times, b, side='left')), first + 1)
        return float(largest[first:last].max())

    starts, rates = _pieces(
        largest_on,
        limit=limit,
        margin=margin,
        cap=cap,
        window=window,
        horizons=horizons,
        longest=None if events is None else _events_cap(events, per_piece=event_rate * agents * window),
    )
    return TimeWarp(paper_starts=tuple(starts), rates=tuple(rates))


def _events_cap(events, *, per_piece: float):
    """`longest(s)`: the longest paper time [s, s + ℓ) holding at most `per_piece` of `events`
    (inf when fewer remain); ℓ > 0 however dense they are (they are counted, not spaced)."""
    if not (math.isfinite(per_piece) and per_piece >= 1.0):
        raise LimitsError(
            f"time_warp: the events' cap must allow at least one event a piece, got {per_piece!r}"
        )
    events = np.sort(np.asarray(events, dtype=float))
    count = int(per_piece)

    def longest(s: float) -> float:
        # events[first:] are at or after s; [s, events[first + count]) holds count of them at most.
        first = int(np.searchsorted(events, s, side='left'))
        if first + count >= events.size:
            return math.inf
        end = float(events[first + count])
        if end <= s:  # more than `count` at s itself (one instant's triggers): to the next instant
            after = int(np.searchsorted(events, s, side='right'))
            return float(events[after]) - s if after < events.size else math.inf
        return end - s

    return longest


def guaranteed_warp(
    *,
    speed: float,
    dotyi: float,
    beta: float,
    limits: RobotLimits,
    horizons: tuple[float, float],
    cap: float = WARP_CAP,
    window: float = WARP_WINDOW,
) -> TimeWarp:
    """The warp from the proofs' bound min(speed, dotyi e^{-βs}) on every agent's command (the
    largest over the agents of `command_bound`'s speed and of its (dotyi), at κ = 1), up to
    `horizons` (paper, real)."""
    limit = warp_limit(limits, 'single', cap=cap, window=window)

    def largest_on(a: float, b: float) -> float:
        return min(speed, dotyi * math.exp(-beta * a))  # decreasing in s: its value at a

    starts, rates = _pieces(largest_on, limit=limit, margin=1.0, cap=cap, window=window, horizons=horizons)
    return TimeWarp(paper_starts=tuple(starts), rates=tuple(rates))


@dataclass(frozen=True, kw_only=True)
class WarpChoice:
    """The observed and (where the proofs apply) the guaranteed warp for some limits, with the time
    each needs to settle; `warp` is what `--speed-scale warp` runs (the observed one)."""

    limits: RobotLimits
    observed: TimeWarp
    guaranteed: TimeWarp | None
    guaranteed_missing: str | None  # why there is none (outside the proofs' hypotheses)
    settling: Settling  # of the exact run at κ = 1
    margin: float
    cap: float
    window: float
    event_rate: float  # the observed warp's events' cap, per agent per real second
    turn: float | None = None  # the safety layer's tie-break turn λ chosen when the default's robots jam
    jams: tuple[tuple[float, int, float], ...] = ()  # (λ, events, paper time) of each turn that jammed

    @property
    def warp(self) -> TimeWarp:
        return self.observed

    def settle_time(self, warp: TimeWarp) -> float:
        """The real time the κ = 1 run's settling time maps to under `warp` (inf: not reached)."""
        return warp.real(self.settling.time) if math.isfinite(self.settling.time) else math.inf

    def to_dict(self) -> dict:
        def one(warp: TimeWarp | None) -> dict | None:
            if warp is None:
                return None
            settle = self.settle_time(warp)
            return {**warp.to_dict(), 'settle_time': settle if math.isfinite(settle) else None}

        return {
            'kind': 'time_warp',
            'source': 'observed',
            'margin': self.margin,
            'cap': self.cap,
            'window': self.window,
            'event_rate': self.event_rate,
            'limits': self.limits.to_dict(),
            'observed': one(self.observed),
            'guaranteed': one(self.guaranteed),
            'guaranteed_missing': self.guaranteed_missing,
            'settle_fraction': self.settling.fraction,
            'tie_break_turn': None
            if self.turn is None
            else {
                'turn': self.turn,
                'jams': [{'turn': turn, 'events': events, 'time': t} for turn, events, t in self.jams],
            },
        }

    def turn_line(self) -> str | None:
        """The safety layer's tie-break turn chosen and why (None: the scenario's own)."""
        if self.turn is None:
            return None
        jams = ', '.join(f'λ = {turn:g} ({events} events by t = {t:.4g} s)' for turn, events, t in self.jams)
        return (
            f"the safety layer's tie-break turn λ = {self.turn:g} for every agent: the robots jam at {jams} "
            '(docs/SAFETY.md, "Ties")'
        )

    def lines(self, *, constant: float | None = None) -> list[str]:
        """What validate prints; `constant`: today's constant κ, to compare the time to settle."""
        fraction = f'{100 * self.settling.fraction:g} %'
        lines = [
            f'time warp κ(t) for these limits (pieces of {self.window:g} s, κ <= {self.cap:g}, observed: '
            f'<= {self.event_rate:g} events per agent per second; docs/SPEED_SCALE.md, "A time warp"):'
        ]
        for source, warp in (('guaranteed', self.guaranteed), ('observed', self.observed)):
            if warp is None:
                lines.append(f'  guaranteed: none: {self.guaranteed_missing}')
                continue
            settle = self.settle_time(warp)
            when = f'after {settle:.4g} s' if math.isfinite(settle) else 'not within the exact run'
            lines.append(
                f'  {source}: {warp.pieces} pieces, κ from {warp.rates[0]:.4g} to {warp.max_rate:.4g}; '
                f'{fraction} of the formation error {when}'
            )
        if constant is not None and math.isfinite(self.settling.time):
            lines.append(
                f'  the constant observed κ = {constant:.4g}: {fraction} after '
                f'{self.settling.at(constant):.4g} s'
            )
        if (turn := self.turn_line()) is not None:
            lines.append(f'  {turn}')
        lines.append('  --speed-scale warp (and auto on robots, ETA-1) runs the observed warp')
        return lines
