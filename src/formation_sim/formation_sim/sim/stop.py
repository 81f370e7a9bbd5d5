"""How an exact run ends: at its horizon, once the formation error is below a fraction of its initial
value (`until_error`), or, when asked, on the engine's rounding floor (`formation_sim.sim.engine.
rounding_floor`) instead of failing there.

`RunStop` is what `formation_sim.sim.engine.simulate` consults at every event time; the record's
`extra['stop']` (and so summary.json's) is `RunStop.extra`: {reason, time, horizon, until_error,
initial_error, error, message}, reason one of STOP_REASONS.

The formation error is max over edges of ||x_i - x_j - d_ij|| (summary.json's `final_formation_error`,
at the run's end). The stop is checked at the engine's event times only, never within an interval
between two events: between events the motion is closed form and the error could be located exactly,
but the audit's guarantees are checked at events, and a stop at the first event at or after the true
crossing is deterministic (the same floats in, the same event out) and costs O(edges) per event. So a
run with `until_error` ends at the first event time t > 0 with error(t) < until_error * error(0),
after the first crossing by at most one inter-event time of the team; the agents due at that event
do not trigger (a run to a horizon that is an event time triggers them there), and neither do those
at a rounding floor stop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formation_sim.sim.errors import EngineError

STOP_REASONS = ('horizon', 'error_reached', 'rounding_floor')


def check_until_error(until_error: float | None) -> None:
    """Refuse a fraction that is not a number in (0, 1) (None: no such stop)."""
    if until_error is None:
        return
    if isinstance(until_error, bool) or not isinstance(until_error, (int, float)):
        raise EngineError(f'until_error must be a number in (0, 1) or None, got {until_error!r}')
    if not (math.isfinite(until_error) and 0.0 < until_error < 1.0):
        raise EngineError(
            f'until_error must be a fraction in (0, 1) of the initial formation error, got {until_error!r}'
        )


def formation_error(world, heads: np.ndarray, tails: np.ndarray, offsets: np.ndarray) -> float:
    """max over edges of ||x_i - x_j - d_ij|| at the world's present time (0.0 without edges)."""
    if len(heads) == 0:
        return 0.0
    x = world.positions
    return float(np.sqrt(np.max(np.sum((x[heads] - x[tails] - offsets) ** 2, axis=1))))


@dataclass(kw_only=True)
class RunStop:
    """The stop rules of one run, and which of them ended it (`reason`, `time`)."""

    horizon: float  # real time [s]
    until_error: float | None = None
    at_floor: bool = False  # the rounding floor ends the run (reason 'rounding_floor') instead of failing it
    heads: np.ndarray | None = None
    tails: np.ndarray | None = None
    offsets: np.ndarray | None = None
    initial_error: float | None = None
    error: float | None = None
    reason: str | None = None
    time: float | None = None
    message: str | None = None

    @classmethod
    def of(cls, scenario, world, *, horizon: float, until_error: float | None, at_floor: bool) -> RunStop:
        check_until_error(until_error)
        stop = cls(horizon=horizon, until_error=None if until_error is None else float(until_error))
        stop.at_floor = bool(at_floor)
        if stop.until_error is not None:
            heads, tails, offsets = scenario.edge_indices()
            stop.heads, stop.tails, stop.offsets = heads, tails, np.asarray(offsets, dtype=float)
            stop.initial_error = stop.error = formation_error(world, heads, tails, stop.offsets)
        return stop

    def error_reached(self, world, t: float, real_t: float) -> bool:
        """At an event time t (the world's time; real_t in real time): is the error below the goal?
        Never at t = 0, never for a team that starts in formation (0 is not below 0)."""
        if self.until_error is None or t == 0.0:
            return False
        self.error = self._error(world)
        if self.error < self.until_error * (self.initial_error or 0.0):
            self.end('error_reached', real_t)
            return True
        return False

    def _error(self, world) -> float:
        if self.heads is None or self.tails is None or self.offsets is None:
            raise ValueError('the formation error is measured only for a run with until_error')
        return formation_error(world, self.heads, self.tails, self.offsets)

    def at_horizon(self, world) -> None:
        """The run reached its horizon (reason 'horizon')."""
        self.end('horizon', self.horizon, world=world)

    def end(self, reason: str, real_t: float, message: str | None = None, *, world=None) -> None:
        """The run ends at real_t for `reason`; with the world, `error` is the formation error there."""
        if reason not in STOP_REASONS:
            raise ValueError(f'a stop reason is one of {", ".join(STOP_REASONS)}, got {reason!r}')
        if world is not None and self.until_error is not None:
            self.error = self._error(world)
        self.reason, self.time, self.message = reason, float(real_t), message

    def extra(self) -> dict:
        """The record's (and summary.json's) `extra['stop']`."""
        return {
            'reason': self.reason,
            'time': self.time,
            'horizon': self.horizon,
            'until_error': self.until_error,
            'initial_error': self.initial_error,
            'error': self.error,
            'message': self.message,
        }
