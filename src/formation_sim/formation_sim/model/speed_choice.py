"""The speed scale κ that keeps a team's commands within a robot's limits, and the threshold floor
c0 that a pose noise asks for (ROS-free, pure arithmetic on the numbers of one exact run).

The run at speed scale κ is the paper's run in the time s = κt (docs/SPEED_SCALE.md): the same
paths, every triggering time divided by κ; ETA-1's velocity command is κ u_i, ETA-2's velocity κ q_i
and its acceleration κ² (u^d_i − k3 q_i) in the paper's terms.  So the largest commands at κ = 1
fix every κ at once:

- speed:      κ s <= V                (s: the largest ||u_i|| (ETA-1) or ||q_i|| (ETA-2) at κ = 1)
- turn rate:  κ s / l <= W            (a unicycle steered at its control point l ahead of the axle
                                       turns at ω = (−sin θ u_x + cos θ u_y)/l <= ||u||/l)
- ETA-2:      κ² a <= A               (a: the largest ||u^d_i − k3 q_i|| at κ = 1)

Two values of κ come from two sources of s and a:

- **guaranteed**: the proofs' bound on the commands (`formation_sim.model.command_bound`); every
  run within the theorems' hypotheses stays within the limits.  Often far below what a run asks
  for (a hand-placed square: 68.8 m/s bound against 9.95 m/s asked), hence a slow run.
- **observed**: the exact in-process run's largest commands, each kept OBSERVED_MARGIN times below
  its limit.  Not a proof: it holds for this run, and the margin stands for what the exact run does
  not have (below).

The turn rate uses the bound ||u||/l for both, not the unicycle's heading simulated exactly: the
bound is reached by a robot whose heading is perpendicular to its first command, which a team set
down by hand may have (a scenario's `heading` is used by the simulated robots only; a real robot's
is whatever it is), while an exact heading would tune κ to one set of headings.

The time to settle, `Settling`: the first time after which the formation error (the summary's
`final_formation_error`: the largest ||x_i − x_j − d_ij|| over the edges) stays at or below
SETTLE_FRACTION (5 %) of its value at t = 0, from the exact run at κ = 1; at κ it is that time / κ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formation_agent.core.tension import omega
from formation_sim.model.errors import LimitsError

OBSERVED_MARGIN = 1.25
"""The observed κ keeps the exact run's largest command this many times below each limit (its
acceleration κ² a as well).  What the exact run does not hold: a noisy pose adds ω_ij times its
error to a command at every trigger (σ = 5 mm, ω_ij ≈ 1, two neighbours: ≈ 0.016 m/s at κ = 1, a
few mm/s once scaled); a trigger that comes late (latency, load: tens of ms) holds a command
whose e_i has grown past its threshold; a robot's velocity loop overshoots.  25 % covers these
for robots_lab with σ = 5 mm and 20 ms latency (README, "Running on robots": no saturated command)."""

SETTLE_FRACTION = 0.05
"""The formation error the settling time waits for, as a fraction of its value at t = 0."""

NOISE_QUANTILE = 3.0
"""c0 = NOISE_QUANTILE times the per-axis standard deviation that a pose noise σ puts into e_i
(E_i): a jump of ||e_i|| beyond it, the norm of p Gaussian components, has probability
e^{-q²/2} = 1.1 % in the plane (q = 3) per trigger (`noise_floor`)."""


@dataclass(frozen=True, kw_only=True)
class RobotLimits:
    """A robot's limits (inf: none) and, for unicycles, its control point distance l."""

    max_speed: float = math.inf  # V [m/s]
    max_angular_speed: float = math.inf  # W [rad/s]
    control_point_distance: float = 0.1  # l [m]
    max_acceleration: float = math.inf  # A [m/s²], ETA-2

    def __post_init__(self) -> None:
        for name in ('max_speed', 'max_angular_speed', 'control_point_distance', 'max_acceleration'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0.0 and not math.isnan(value)):
                raise LimitsError(f'{name}: must be a number > 0 (inf: none), got {value!r}')
        if math.isinf(self.control_point_distance):
            raise LimitsError(f'control_point_distance: must be finite, got {self.control_point_distance!r}')

    @property
    def any(self) -> bool:
        return any(math.isfinite(v) for v in (self.max_speed, self.max_angular_speed, self.max_acceleration))

    def speed_limit(self) -> tuple[float, str]:
        """The tighter of V and W·l, as a speed of the control point, and which it is."""
        turn = self.max_angular_speed * self.control_point_distance
        if turn < self.max_speed:
            return (
                turn,
                f'turn rate {self.max_angular_speed:g} rad/s (l = {self.control_point_distance:g} m: '
                f'||u|| <= W l = {turn:.4g} m/s)',
            )
        return self.max_speed, f'speed {self.max_speed:g} m/s'

    def largest_scale(
        self, *, speed: float, acceleration: float | None, margin: float = 1.0
    ) -> tuple[float, str]:
        """The largest κ with κ m s <= min(V, W l) and κ² m a <= A (m = margin); inf if nothing binds.

        Returns (κ, the limit that binds)."""
        best, binding = math.inf, 'no limit binds (the team asks for no motion)'
        limit, what = self.speed_limit()
        if speed > 0.0 and math.isfinite(limit):
            best, binding = limit / (margin * speed), what
        if acceleration is not None and acceleration > 0.0 and math.isfinite(self.max_acceleration):
            kappa = math.sqrt(self.max_acceleration / (margin * acceleration))
            if kappa < best:
                best, binding = kappa, f'acceleration {self.max_acceleration:g} m/s²'
        return best, binding

    def to_dict(self) -> dict:
        return {
            name: (getattr(self, name) if math.isfinite(getattr(self, name)) else None)
            for name in ('max_speed', 'max_angular_speed', 'control_point_distance', 'max_acceleration')
        }


def check_limits_apply(limits: RobotLimits, dynamics: str) -> None:
    """LimitsError when no κ can meet `limits` for this dynamics: none given, or an acceleration
    limit on ETA-1, whose velocity commands (uxsingle) jump at every event."""
    if not limits.any:
        raise LimitsError(
            'a speed scale from the limits needs at least one of --max-speed, --max-angular-speed, '
            '--max-acceleration'
        )
    if dynamics == 'single' and math.isfinite(limits.max_acceleration):
        raise LimitsError(
            f'max_acceleration {limits.max_acceleration:g} m/s²: ETA-1 commands velocities (uxsingle) '
            'that jump at every event, which no speed scale bounds in acceleration; the limit applies '
            'to ETA-2 (double integrators)'
        )


@dataclass(frozen=True, kw_only=True)
class Settling:
    """When the exact run at κ = 1 reached SETTLE_FRACTION of its initial formation error for good."""

    initial_error: float  # the formation error at t = 0 (largest ||x_i - x_j - d_ij||)
    time: float  # at κ = 1 [s]; inf: not within the run
    run_horizon: float  # how far the exact run at κ = 1 went [s]
    fraction: float = SETTLE_FRACTION
    resolution: str = 'exact'  # 'exact' (ETA-1: linear between events) or the sample spacing it is known to

    def at(self, kappa: float) -> float:
        return self.time / kappa


@dataclass(frozen=True, kw_only=True)
class ScaleValue:
    """One speed scale: its value, where it comes from, which limit binds, the time to settle then."""

    source: str  # 'guaranteed' | 'observed'
    value: float  # inf: no limit binds
    binding: str
    speed: float  # the κ = 1 speed it scales (m/s)
    acceleration: float | None  # the κ = 1 acceleration it scales (ETA-2)
    margin: float
    settle_time: float  # Settling.time / value [s]

    def to_dict(self) -> dict:
        finite = math.isfinite
        return {
            'source': self.source,
            'value': self.value if finite(self.value) else None,
            'binding': self.binding,
            'speed_at_1': self.speed,
            'acceleration_at_1': self.acceleration,
            'margin': self.margin,
            'settle_time': self.settle_time if finite(self.settle_time) else None,
        }


@dataclass(frozen=True, kw_only=True)
class SpeedScaleChoice:
    """The guaranteed and the observed κ for some limits; `value` is what `--speed-scale auto` runs."""

    limits: RobotLimits
    guaranteed: ScaleValue | None
    guaranteed_missing: str | None  # why there is no guaranteed κ (outside the proofs' hypotheses)
    observed: ScaleValue
    settling: Settling
    horizon: float  # the run's horizon [s], to say whether it covers the time to settle

    @property
    def value(self) -> float:
        """The observed κ; 1 when no limit binds (a team already in formation asks for nothing)."""
        return self.observed.value if math.isfinite(self.observed.value) else 1.0

    @property
    def source(self) -> str:
        return 'observed' if math.isfinite(self.observed.value) else 'observed: no limit binds, κ = 1'

    def to_dict(self) -> dict:
        return {
            'value': self.value,
            'source': self.source,
            'limits': self.limits.to_dict(),
            'guaranteed': None if self.guaranteed is None else self.guaranteed.to_dict(),
            'guaranteed_missing': self.guaranteed_missing,
            'observed': self.observed.to_dict(),
            'settling': {
                'definition': f'first time after which the formation error (largest ||x_i - x_j - '
                f'd_ij|| over the edges) stays <= {self.settling.fraction:g} of its value at t = 0',
                'initial_error': self.settling.initial_error,
                'time_at_1': self.settling.time if math.isfinite(self.settling.time) else None,
                'exact_run_horizon': self.settling.run_horizon,
                'resolution': self.settling.resolution,
            },
        }

    def lines(self) -> list[str]:
        settling = self.settling
        fraction = f'{100 * settling.fraction:g} %'
        lines = [
            f'speed scale κ for these limits (κ = 1 asks for up to {self.observed.speed:.4g} m/s'
            + ('' if self.observed.acceleration is None else f', {self.observed.acceleration:.4g} m/s²')
            + f' in the exact run; the formation error {settling.initial_error:.4g} m at t = 0 '
            f'reaches {fraction} '
            + (
                f'at t = {settling.time:.4g} s'
                if math.isfinite(settling.time)
                else f'not within the exact run, t <= {settling.run_horizon:g} s'
            )
            + (f', to {settling.resolution}' if settling.resolution != 'exact' else '')
            + '):'
        ]
        for value in (self.guaranteed, self.observed):
            if value is None:
                lines.append(f'  guaranteed: none: {self.guaranteed_missing}')
                continue
            how = (
                "from the proofs' bound on the commands"
                if value.source == 'guaranteed'
                else f"from the exact run's largest commands, each kept {value.margin:g}× below its limit "
                '(not a guarantee)'
            )
            if not math.isfinite(value.value):
                lines.append(f'  {value.source}: any κ ({value.binding}; {how})')
                continue
            lines.append(
                f'  {value.source}: κ = {value.value:.4g}, bound by the {value.binding}; {how}; '
                f'{self._settle_words(value)}'
            )
        chosen = self.value
        lines.append(f'  --speed-scale auto runs κ = {chosen:.4g} ({self.source})')
        return lines

    def _settle_words(self, value: ScaleValue) -> str:
        fraction = f'{100 * self.settling.fraction:g} %'
        if not math.isfinite(value.settle_time):
            return f'{fraction} not reached within the exact run'
        words = f'{fraction} of the formation error after {value.settle_time:.4g} s'
        if value.settle_time > self.horizon:
            words += (
                f' — beyond the horizon {self.horizon:g} s: the run ends before it forms (a longer '
                '--horizon, or other gains)'
            )
        return words


def scale_choice(
    *,
    limits: RobotLimits,
    dynamics: str,
    theory: tuple[float, float | None] | str,
    observed: tuple[float, float | None],
    settling: Settling,
    horizon: float,
    margin: float = OBSERVED_MARGIN,
) -> SpeedScaleChoice:
    """Both values of κ from the κ = 1 commands: `theory` = (speed, acceleration) of the proofs'
    bound, or why there is none; `observed` = those of the exact run.  LimitsError if the limits do
    not apply (`check_limits_apply`)."""
    check_limits_apply(limits, dynamics)
    if not (margin >= 1.0 and math.isfinite(margin)):
        raise LimitsError(f'margin: must be a finite number >= 1, got {margin!r}')

    def value(source: str, speed: float, acceleration: float | None, m: float) -> ScaleValue:
        kappa, binding = limits.largest_scale(speed=speed, acceleration=acceleration, margin=m)
        return ScaleValue(
            source=source,
            value=kappa,
            binding=binding,
            speed=speed,
            acceleration=acceleration,
            margin=m,
            settle_time=settling.at(kappa)
            if math.isfinite(kappa)
            else (0.0 if settling.time == 0.0 else math.nan),
        )

    guaranteed = None if isinstance(theory, str) else value('guaranteed', *theory, 1.0)
    return SpeedScaleChoice(
        limits=limits,
        guaranteed=guaranteed,
        guaranteed_missing=theory if isinstance(theory, str) else None,
        observed=value('observed', *observed, margin),
        settling=settling,
        horizon=horizon,
    )


def settling_time(times: np.ndarray, errors: np.ndarray, *, threshold: float, segment_crossing=None) -> float:
    """The first time after which `errors` (the formation error at `times`) stays <= threshold.

    `segment_crossing(k)`, if given, returns the exact time in [times[k], times[k+1]] at which the
    error comes down to the threshold for good (ETA-1: every edge error is the norm of an affine
    function between events, hence convex); without it, the first sample after the last above.
    inf if the last sample is above."""
    above = np.flatnonzero(errors > threshold)
    if above.size == 0:
        return float(times[0])
    k = int(above[-1])
    if k == times.size - 1:
        return math.inf
    return float(segment_crossing(k)) if segment_crossing is not None else float(times[k + 1])


def linear_crossing(start: np.ndarray, end: np.ndarray, *, t0: float, t1: float, threshold: float) -> float:
    """The last time in [t0, t1] at which max_e ||a_e + (t − t0) b_e|| (edge errors moving linearly
    from `start` to `end`, shape (m, p)) comes down to `threshold`, given it is above at t0 and at
    or below at t1.  Each edge's norm is convex in t, so each is <= threshold on an interval ending
    at t1: the answer is the latest of those intervals' left ends (the smaller root of a quadratic)."""
    duration = t1 - t0
    rate = (end - start) / duration
    a = (rate * rate).sum(axis=1)
    b = 2.0 * (start * rate).sum(axis=1)
    c = (start * start).sum(axis=1) - threshold * threshold
    latest = t0
    for ae, be, ce in zip(a.tolist(), b.tolist(), c.tolist()):
        if ce <= 0.0:  # this edge is within the threshold from t0 on
            continue
        disc = max(be * be - 4.0 * ae * ce, 0.0)
        # ce > 0 and the edge is within at t1: ae > 0 and the smaller root lies in (0, duration]
        root = (2.0 * ce) / (-be + math.sqrt(disc)) if -be + math.sqrt(disc) > 0.0 else duration
        latest = max(latest, t0 + min(root, duration))
    return latest


def noise_floor(
    *,
    weights: dict[int, list[float]],
    pose_noise: float,
    dynamics: str,
    k1: float = 1.0,
    k2: float = 0.0,
    pose_period: float | None = None,
    speed_scale: float = 1.0,
    quantile: float = NOISE_QUANTILE,
) -> tuple[float, dict[int, float], str]:
    """The threshold floor c0 for a pose noise σ (per axis, every robot's pose on its own).

    ETA-1 (Theorem 1): e_i(t) = Σ_j ω_ij(t) y_ij(t) − Σ_j ω_ij(t_k) y_ij(t_k).  At its trigger t_k
    agent i senses every y_ij = x_i − x_j − d_ij from its own pose (noise a, shared by all its
    edges) and each neighbour's (b_j); a neighbour's trigger replaces i's model of y_ij with the
    neighbour's own sense (c_j, e_j: fresh noise).  Just after, with ω_ij at the formation
    (y_ij = 0), 2/(Δ − ||d_ij||):
        e_i = Σ_j ω_ij (c_j − e_j + b_j) − a Σ_j ω_ij,
        s_i = σ sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²)  per axis,   c0 = q max_i s_i   (q = NOISE_QUANTILE)
    (two neighbours with ω = 1: √10 σ).
    ETA-2 (Theorem 2): E_i = k1 e_i + k2 e_qi.  A velocity from the backward difference of two
    poses Δt apart holds √2 σ/Δt per axis where a position holds σ, and in the paper's time
    (E_i's units) the velocities are 1/κ of the robots':
        s_i = σ sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²) (k1 + k2 √2 / (κ Δt)),
    added, not in quadrature, since the position and the velocity noise come from the same poses.

    `weights`: per agent the ω_ij of its edges at the formation.  Returns (c0, s_i per agent, formula)."""
    if not (pose_noise >= 0.0 and math.isfinite(pose_noise)):
        raise LimitsError(f'pose_noise: must be a finite number >= 0, got {pose_noise!r}')
    if dynamics == 'double' and not (
        pose_period is not None and pose_period > 0.0 and math.isfinite(pose_period)
    ):
        raise LimitsError(
            'pose_period: ETA-2 senses velocities from two poses Δt apart: Δt must be a number > 0, '
            f'got {pose_period!r}'
        )
    per_agent = {}
    for agent, omegas in weights.items():
        position = pose_noise * math.sqrt(3.0 * sum(w * w for w in omegas) + sum(omegas) ** 2)
        if dynamics == 'double':
            position *= k1 + k2 * math.sqrt(2.0) / (speed_scale * pose_period)
        per_agent[agent] = position
    floor = quantile * max(per_agent.values())
    if dynamics == 'single':
        formula = (
            f'c0 = q σ max_i sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²), ω_ij = 2/(Δ − ||d_ij||), q = {quantile:g}, '
            f'σ = {pose_noise:g} m'
        )
    else:
        formula = (
            'c0 = q σ max_i sqrt(3 Σ_j ω_ij² + (Σ_j ω_ij)²) (k1 + k2 √2/(κ Δt)), ω_ij = 2/(Δ − '
            f'||d_ij||), q = {quantile:g}, σ = {pose_noise:g} m, Δt = {pose_period:g} s, κ = '
            f'{speed_scale:g}'
        )
    return floor, per_agent, formula


def scenario_noise_floor(
    scenario,
    *,
    pose_noise: float,
    pose_period: float | None = None,
    speed_scale: float = 1.0,
    quantile: float = NOISE_QUANTILE,
) -> tuple[float, dict[int, float], str]:
    """`noise_floor` for `scenario`: ω_ij at the formation, 2/(Δ − ||d_ij||) ((wij) at y_ij = 0)."""
    weights = {agent: omega_at_formation(scenario, agent) for agent in scenario.agent_ids}
    gains = scenario.gains
    double = scenario.dynamics == 'double'
    return noise_floor(
        weights=weights,
        pose_noise=pose_noise,
        dynamics=scenario.dynamics,
        k1=gains.k1 if double else 1.0,
        k2=gains.k2 if double else 0.0,
        pose_period=pose_period,
        speed_scale=speed_scale,
        quantile=quantile,
    )


def omega_at_formation(scenario, agent: int) -> list[float]:
    """ω_ij of `agent`'s edges at the formation (y_ij = 0): f_ij(0) = 2/(Δ − ||d_ij||) (fij)."""
    return [
        float(omega(0.0, scenario.delta - float(np.linalg.norm(d))))
        for d in scenario.neighbours(agent).values()
    ]
