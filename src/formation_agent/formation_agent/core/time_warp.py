"""A time warp s(t), ds/dt = κ(t): the paper's run replayed at a speed that follows the run
(docs/SPEED_SCALE.md, "A time warp"; issue 27).

κ is piecewise constant: κ_m on the real-time pieces [t_m, t_{m+1}), so s(t) is continuous and
piecewise linear, and the run at real time t is the paper's run at s(t): x(t) = x_p(s(t)), ETA-1's
command κ(t) u_p,i. A warp is given in the paper's time: its pieces start at s_0 = 0 < s_1 < ...
with the rates κ_0, κ_1, ...; the real starts follow, t_{m+1} = t_m + (s_{m+1} - s_m)/κ_m, and the
last piece lasts for ever. The agents' cores run in s (the paper's gains, κ = 1), so the events
of the warped run are the κ = 1 run's, bit for bit; only their labels in real time, t = real(s),
and the commands, κ(t) u_p, change.

`real` and `paper` are each other's inverse up to rounding, each monotone in floats (a value
rounded past its piece's end is held at that end): map each time once, the way it is used (events
are found in s and labelled with `real(s)`; a clock's real time is read with `paper(t)`).

No ROS: the agent layer's core, so that an agent node can apply it at its edges (`WarpedAgent`:
an agent's core in s seen in real time; a robot's command κ(t) u_p: `RobotCommander`'s warp).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from formation_agent.core.errors import WarpError
from formation_agent.core.speed_scale import SPEED_SCALE_LIMITS

if TYPE_CHECKING:
    import numpy as np

    from formation_agent.core.eta import Eta1Agent, TriggerOutput
    from formation_msgs_py.types import SensedState, TriggerInfo

MAX_PIECES = 100_000
"""A warp holds at most this many pieces (rule time_warp): it travels as one parameter to every
agent, two floats a piece."""

WARP_CAP = 1.0
"""The default cap κ_max on a chosen warp's rate: never faster than the paper's own time. By
Theorem 1 (iii) an agent's inter-event times in s are >= ξ_i, so in real time they are >= ξ_i/κ_max:
the events per real second of every agent stay within the κ = 1 run's bound, 1/ξ_i."""


@dataclass(frozen=True, kw_only=True)
class TimeWarp:
    """κ_m from s_m on (`paper_starts`, `rates`); `real_starts` t_m are derived."""

    paper_starts: tuple[float, ...]
    rates: tuple[float, ...]
    real_starts: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        starts = tuple(_number('paper_starts', s) for s in self.paper_starts)
        rates = tuple(_number('rates', k) for k in self.rates)
        if not starts or len(starts) != len(rates):
            raise WarpError(
                f'time_warp: needs as many rates as piece starts (at least one), got {len(starts)} starts '
                f'and {len(rates)} rates'
            )
        if len(starts) > MAX_PIECES:
            raise WarpError(f'time_warp: at most {MAX_PIECES} pieces, got {len(starts)}')
        if starts[0] != 0.0:
            raise WarpError(f'time_warp: the first piece starts at s = 0, got {starts[0]!r}')
        for before, after in zip(starts, starts[1:]):
            if not after > before:
                raise WarpError(f'time_warp: piece starts must increase, got {before!r} then {after!r}')
        low, high = SPEED_SCALE_LIMITS
        for kappa in rates:
            if not low <= kappa <= high:
                raise WarpError(
                    f'time_warp: every rate must lie in [{low:g}, {high:g}] (the rule speed_scale), got '
                    f'{kappa!r}'
                )
        real = [0.0]
        for m in range(len(starts) - 1):
            real.append(real[m] + (starts[m + 1] - starts[m]) / rates[m])
        object.__setattr__(self, 'paper_starts', starts)
        object.__setattr__(self, 'rates', rates)
        object.__setattr__(self, 'real_starts', tuple(real))

    @classmethod
    def constant(cls, kappa: float) -> TimeWarp:
        """The constant speed scale κ as a warp of one piece."""
        return cls(paper_starts=(0.0,), rates=(kappa,))

    @property
    def pieces(self) -> int:
        return len(self.rates)

    @property
    def max_rate(self) -> float:
        return max(self.rates)

    @property
    def min_rate(self) -> float:
        return min(self.rates)

    def paper(self, t: float) -> float:
        """s(t) for a real time t >= 0: s_m + κ_m (t - t_m) on piece m, held within the piece."""
        m = max(bisect.bisect_right(self.real_starts, t) - 1, 0)
        s = self.paper_starts[m] + self.rates[m] * (t - self.real_starts[m])
        return min(s, self.paper_starts[m + 1]) if m + 1 < len(self.rates) else s

    def real(self, s: float) -> float:
        """t(s) for a paper time s >= 0: t_m + (s - s_m)/κ_m on piece m, held within the piece."""
        m = max(bisect.bisect_right(self.paper_starts, s) - 1, 0)
        t = self.real_starts[m] + (s - self.paper_starts[m]) / self.rates[m]
        return min(t, self.real_starts[m + 1]) if m + 1 < len(self.rates) else t

    def rate(self, t: float) -> float:
        """κ(t) at a real time t (right-continuous: at a piece's start, the new rate)."""
        return self.rates[max(bisect.bisect_right(self.real_starts, t) - 1, 0)]

    def paper_rate(self, s: float) -> float:
        """κ at the paper's time s (right-continuous)."""
        return self.rates[max(bisect.bisect_right(self.paper_starts, s) - 1, 0)]

    def to_parameter(self) -> list[float]:
        """The agents' parameter time_warp: [s_0, κ_0, s_1, κ_1, ...]."""
        return [value for pair in zip(self.paper_starts, self.rates) for value in pair]

    @classmethod
    def from_parameter(cls, values: Iterable[float]) -> TimeWarp:
        """The warp of `to_parameter`'s list; WarpError naming the rule and the value."""
        values = list(values)
        if not values or len(values) % 2:
            raise WarpError(
                f'time_warp: must be the pairs [s_0, κ_0, s_1, κ_1, ...] (an even, non-zero count), got '
                f'{len(values)} numbers'
            )
        return cls(paper_starts=tuple(values[0::2]), rates=tuple(values[1::2]))

    def to_dict(self) -> dict[str, list[float]]:
        return {
            'paper_starts': list(self.paper_starts),
            'real_starts': list(self.real_starts),
            'rates': list(self.rates),
        }


def _number(what: str, value: Any) -> float:  # any value given: checked here
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise WarpError(f'time_warp: {what} must be finite numbers, got {value!r}') from None
    if not math.isfinite(number):
        raise WarpError(f'time_warp: {what} must be finite numbers, got {number!r}')
    return number


class WarpedAgent:
    """An ETA-1 agent core running in the paper's time s (κ = 1 gains), seen in real time through a
    warp: what an agent node on the wall clock drives (`trigger`, `receive`, `next_trigger_time`,
    `ready`, as `formation_agent.core.eta`'s agents).

    A real time is mapped to s once, where it enters (a trigger's time, a neighbour's stamp), and a
    triggering time found in s leaves as t(s); the times this agent planned or triggered at map back
    to their own s exactly (no round trip through the floats). Its `control` and the controls it
    sends are the paper's u_p: a robot is sent κ(t) u_p (`RobotCommander`), neighbours predict in s.
    """

    def __init__(self, core: Eta1Agent, warp: TimeWarp) -> None:
        self.core = core
        self.warp = warp
        self._known: dict[float, float] = {}  # real -> paper of the planned and the last trigger
        self._last = (-math.inf, -math.inf)  # (real, paper) of the last trigger

    @property
    def ready(self) -> bool:
        ready: bool = self.core.ready
        return ready

    @property
    def control(self) -> np.ndarray:
        return self.core.control

    def paper(self, t: float) -> float:
        known = self._known.get(t)
        return self.warp.paper(t) if known is None else known

    @property
    def safety_interventions(self) -> int:
        """The core's count of triggers at which the safety layer changed the command."""
        return self.core.safety_interventions

    @property
    def safety_last_intervention(self) -> float | None:
        """The latest such trigger in real time (the core's, t(s)), or None."""
        last = self.core.safety_last_intervention
        return None if last is None else self.warp.real(last)

    def trigger(self, t: float, sensed: SensedState, **nearby: Any) -> TriggerOutput:
        """The core's trigger at s(t); `nearby` (the safety layer's other robots within R, positions
        relative to this one at that instant) passes on unchanged: every robot follows the same
        warp, so the team at real time t is the paper's team at s(t) and the layer's barriers hold
        in s as they do at κ = 1 (docs/SAFETY.md, "Robots set down anywhere")."""
        s = self.paper(t)
        out = self.core.trigger(s, sensed, **nearby)
        self._known = {t: s}
        self._last = (t, s)
        infos = tuple(dataclasses.replace(info, stamp=t) for info in out.infos)
        return dataclasses.replace(out, time=t, infos=infos)

    def receive(self, info: TriggerInfo) -> None:
        """A neighbour's information, its real stamp mapped to s; a stamp at or after this agent's
        last trigger maps to no earlier s than that trigger's (order in real time is kept in s)."""
        s = self.paper(info.stamp)
        if info.stamp >= self._last[0]:
            s = max(s, self._last[1])
        self.core.receive(dataclasses.replace(info, stamp=s))

    def next_trigger_time(self, limit: float = math.inf) -> float:
        s = self.core.next_trigger_time(self.warp.paper(limit) if math.isfinite(limit) else math.inf)
        if not math.isfinite(s):
            return s
        t = self.warp.real(s)
        self._known[t] = s
        return t
