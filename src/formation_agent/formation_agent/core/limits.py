"""A robot's limits and the count of every command clipped to them (ROS-free).

The theorems assume no limits, so every clip is counted per kind
(`formation_msgs_py.lockstep.SATURATION_KINDS`) with the largest value asked for, and reported
(README, "Running on robots").  Which limits a robot has, and how its command is held to them,
is its kind's (`formation_agent.core.kinds`); the two ways of scaling below are shared by kinds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from formation_msgs_py.lockstep import SATURATION_ANGULAR_SPEED, SATURATION_LINEAR_SPEED, Saturation


@dataclass(frozen=True, kw_only=True)
class Limits:
    """A robot's limits; inf: none."""

    linear_speed: float = math.inf  # m/s
    angular_speed: float = math.inf  # rad/s (differential drive, car)
    linear_acceleration: float = math.inf  # m/s² (ETA-2's velocity reference)
    steering_angle: float = math.inf  # rad: φ_max of a car's steered wheels (kinds.car)

    def __post_init__(self) -> None:
        for name in ('linear_speed', 'angular_speed', 'linear_acceleration', 'steering_angle'):
            value = getattr(self, name)
            if not value > 0.0:  # also refuses NaN
                raise ValueError(f'limit {name} must be > 0 (inf: none), got {value!r}')


class SaturationLog:
    """Clipped commands per kind: how many, the largest value asked for, the limit."""

    def __init__(self) -> None:
        self._records: dict[str, Saturation] = {}

    def note(self, kind: str, requested: float, allowed: float) -> None:
        previous = self._records.get(kind)
        count = 1 if previous is None else previous.count + 1
        largest = requested if previous is None else max(previous.largest_requested, requested)
        self._records[kind] = Saturation(
            count=count, largest_requested=float(largest), allowed=float(allowed)
        )

    @property
    def records(self) -> dict[str, Saturation]:
        return dict(self._records)


def limit_world_velocity(u: Sequence[float] | np.ndarray, limits: Limits, log: SaturationLog) -> np.ndarray:
    """u scaled down to the speed limit (direction kept); a clip is noted in `log`."""
    velocity = np.asarray(u, dtype=float)
    speed = float(np.linalg.norm(velocity))
    if speed > limits.linear_speed:
        log.note(SATURATION_LINEAR_SPEED, speed, limits.linear_speed)
        scaled: np.ndarray = velocity * (limits.linear_speed / speed)
        return scaled
    return velocity


def limit_body_velocity(v: float, omega: float, limits: Limits, log: SaturationLog) -> tuple[float, float]:
    """(v, ω) scaled down by one factor to both limits (README: the control point keeps its course)."""
    scale = 1.0
    if abs(v) > limits.linear_speed:
        log.note(SATURATION_LINEAR_SPEED, abs(v), limits.linear_speed)
        scale = limits.linear_speed / abs(v)
    if abs(omega) > limits.angular_speed:
        log.note(SATURATION_ANGULAR_SPEED, abs(omega), limits.angular_speed)
        scale = min(scale, limits.angular_speed / abs(omega))
    return v * scale, omega * scale
