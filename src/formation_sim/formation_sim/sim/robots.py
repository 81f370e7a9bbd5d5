"""Simulated robots, ROS-free: how the simulated robot backends move, and what a robot's pose means.

A robot is of a kind of `formation_agent.core.kinds` (the registry), which holds its model: how a
base of that kind clips what it is sent and how it moves exactly under a command held constant
between two instants (a base's control loop holds its last command over a tick), never with a
fixed integration step — a straight line for a holonomic robot, the closed-form arc for a
unicycle.  `Robot` keeps the pose, the command held and the count of clipped commands.

A robot's scenario position is its kind's *control point* (a unicycle's: p = (x, y) + l (cos θ,
sin θ), the point l ahead of the axle that the near-identity diffeomorphism lets the agent steer
like a single integrator; README, "Running on robots"; `formation_agent.core.kinematics`, which
reads poses here as the agents read them); `control_point` places it for a planar pose and
`axle_position` goes back.  `trajectory_samples` turns recorded pose streams into the samples of
a `RunRecord`, the one way both the coordinator (summary.json) and `formation analyze` (the bag)
read them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache, partial

import numpy as np

from formation_agent.core import kinematics
from formation_agent.core.errors import KindError
from formation_agent.core.kinds import KIND_NAMES, Geometry, RobotKind, robot_kind
from formation_agent.core.limits import Limits as KindLimits
from formation_sim.sim.errors import RobotError

ROBOT_MODELS = KIND_NAMES  # the registered robot kinds, read at each use


@dataclass(frozen=True, kw_only=True)
class Limits:
    """What the base can do; commands beyond are clipped (and counted) as a real base does, by its
    kind's `clip` (holonomic: the velocity scaled down to `linear` keeping its direction, |ω|
    clipped; unicycle: |v| clipped to `linear`, |ω| to `angular`, each on its own, as a TurtleBot3
    does; car: also |ω| to |v| tan(`steering`) / L)."""

    linear: float = math.inf  # [m/s]
    angular: float = math.inf  # [rad/s]
    steering: float = math.inf  # [rad] φ_max (car)

    def __post_init__(self) -> None:
        for name in ('linear', 'angular'):
            value = getattr(self, name)
            if not value > 0.0:  # also NaN
                raise RobotError(f'the {name} speed limit must be > 0 (inf: none), got {value!r}')
        if not self.steering > 0.0:
            raise RobotError(f'the steering limit must be > 0 (inf: none), got {self.steering!r}')

    def kind_limits(self) -> KindLimits:
        """These limits as the kinds take them."""
        return KindLimits(linear_speed=self.linear, angular_speed=self.angular, steering_angle=self.steering)


@dataclass(frozen=True, kw_only=True)
class Command:
    """A velocity command as the base applies it: `linear` in the world frame (holonomic, p values)
    or (v,) in the body frame (unicycle); `angular` = ω [rad/s]."""

    linear: tuple[float, ...]
    angular: float = 0.0

    @property
    def is_zero(self) -> bool:
        return self.angular == 0.0 and not any(self.linear)


@dataclass(kw_only=True)
class Robot:
    """A robot of kind `model`: its pose (position, yaw), limits, the command held and how many
    commands the limits clipped; moved exactly by its kind's model."""

    model: str
    position: np.ndarray
    yaw: float = 0.0
    limits: Limits = field(default_factory=Limits)
    geometry: Geometry = field(default_factory=Geometry)
    command: Command | None = None  # None: standing still
    saturated: int = 0  # commands clipped by the limits

    def __post_init__(self) -> None:
        try:
            self.kind: RobotKind = robot_kind(self.model)
        except KindError as error:
            raise RobotError(str(error)) from None
        self.position = np.array(self.position, dtype=float)
        if self.position.ndim != 1 or self.position.size not in self.kind.dimensions:
            raise RobotError(
                f'a {self.model} robot moves in {" or ".join(map(str, self.kind.dimensions))} dimensions: '
                f'its position has that many values, got {self.position.tolist()}'
            )

    @property
    def dimension(self) -> int:
        return int(self.position.size)

    @property
    def world_frame_command(self) -> bool:
        return self.kind.world_frame_command

    def advance(self, duration: float) -> None:
        """Move for `duration` seconds under the current command (exact)."""
        if duration < 0.0:
            raise RobotError(f'time only goes forwards, got a step of {duration!r} s')
        if self.command is not None and duration > 0.0:
            position, yaw = self.kind.move(
                self.position, self.yaw, self.command.linear, self.command.angular, duration
            )
            self.position, self.yaw = position, wrap_angle(yaw)

    def set_command(self, command: Command) -> Command:
        """Apply `command` from now on, clipped to the limits as its kind's base does; returns what is
        applied."""
        size = self.dimension if self.kind.world_frame_command else 1
        if len(command.linear) != size:
            what = (
                f'{size} world-frame velocity values'
                if self.kind.world_frame_command
                else 'one forward speed v'
            )
            raise RobotError(
                f'a {self.model} robot in {self.dimension} dimensions takes {what}, got '
                f'{list(command.linear)}'
            )
        linear, angular, clipped = self.kind.clip(
            tuple(float(v) for v in command.linear),
            float(command.angular),
            geometry=self.geometry,
            limits=self.limits.kind_limits(),
        )
        self.saturated += clipped
        self.command = Command(linear=linear, angular=angular)
        return self.command

    def body_twist(self) -> tuple[np.ndarray, float]:
        """The velocity in the body frame (3,) and ω (REP 105: Odometry's twist is in child_frame_id)."""
        if self.command is None:
            return np.zeros(3), 0.0
        return self.kind.body_twist(self.command.linear, self.command.angular, self.yaw)

    def scenario_position(self) -> np.ndarray:
        """The control point: what the scenario places."""
        return self.position + self.kind.world_offset(self.yaw, self.geometry, self.dimension)


HolonomicRobot = partial(Robot, model='holonomic')
UnicycleRobot = partial(Robot, model='unicycle')


def make_robot(model: str, *, scenario_position, yaw: float, geometry: Geometry, limits: Limits) -> Robot:
    """A robot of kind `model` and shape `geometry` whose scenario position (its control point) is
    `scenario_position`."""
    try:
        kind = robot_kind(model)
    except KindError as error:
        raise RobotError(str(error)) from None
    point = np.asarray(scenario_position, dtype=float)
    problems = kind.problems(dimension=point.size, geometry=geometry, limits=limits.kind_limits())
    if problems:
        raise RobotError('; '.join(problems))
    return Robot(
        model=model, position=kind.origin(point, yaw, geometry), yaw=yaw, limits=limits, geometry=geometry
    )


def wrap_angle(angle: float) -> float:
    """The same angle in [-π, π)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def control_point(position, yaw: float, distance: float) -> np.ndarray:
    """The point `distance` ahead of the axle at `position` heading `yaw` (near-identity diffeomorphism)."""
    return np.asarray(position, dtype=float) + distance * np.array([math.cos(yaw), math.sin(yaw)])


def axle_position(point, yaw: float, distance: float) -> np.ndarray:
    """The axle whose control point, heading `yaw`, is `point` (the inverse of `control_point`)."""
    return np.asarray(point, dtype=float) - distance * np.array([math.cos(yaw), math.sin(yaw)])


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by `yaw` about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


class PoseNoise:
    """Seeded Gaussian measurement noise: σ [m] on each position axis, σ_yaw [rad] on the heading.

    One stream per (seed, robot), so a run's noise depends only on the seed and how many poses
    each robot published.
    """

    def __init__(self, *, position_sigma: float, yaw_sigma: float, seed: int, robot_id: int) -> None:
        for name, value in (('position_sigma', position_sigma), ('yaw_sigma', yaw_sigma)):
            if not (math.isfinite(value) and value >= 0.0):
                raise RobotError(f'{name} must be a finite number >= 0, got {value!r}')
        self.position_sigma = position_sigma
        self.yaw_sigma = yaw_sigma
        self._random = np.random.default_rng([int(seed), int(robot_id)])

    def measure(self, position: np.ndarray, yaw: float) -> tuple[np.ndarray, float]:
        if self.position_sigma > 0.0:
            position = position + self._random.normal(0.0, self.position_sigma, size=position.shape)
        if self.yaw_sigma > 0.0:
            yaw = wrap_angle(yaw + float(self._random.normal(0.0, self.yaw_sigma)))
        return position, yaw


@dataclass(frozen=True, kw_only=True)
class RobotSample:
    """One pose of a robot as a run sees it: run time (stamp − Step 0 epoch), the scenario
    position (a unicycle's control point) and, from odometry, that point's world velocity."""

    time: float
    position: np.ndarray
    velocity: np.ndarray | None = None


def run_time(stamp, epoch: float) -> float:
    """A header stamp (builtin_interfaces/Time) as run time: seconds since the epoch."""
    return _run_time(stamp.sec, stamp.nanosec, epoch)


def _run_time(sec: int, nanosec: int, epoch: float) -> float:
    """(sec − epoch) first: two numbers near 1.7e9 subtract exactly, and the nanoseconds keep
    their precision (sec + nanosec·1e-9 alone rounds to ~0.2 µs)."""
    return (sec - epoch) + nanosec * 1e-9


@lru_cache(maxsize=64)
def _control_offset(model: str, control_point_distance: float) -> tuple[float, float, float]:
    """Where the scenario's point sits in the body frame, by the robot's kind (a unicycle's: l ahead on x).
    Cached: a run's robots share one, and a coordinator samples 400 poses a second (issue 19)."""
    return robot_kind(model).control_offset(Geometry(control_point_distance=control_point_distance))


def _pose(pose) -> tuple[float, float, float, float, float, float, float]:
    p, q = pose.position, pose.orientation
    return (p.x, p.y, p.z, q.x, q.y, q.z, q.w)


def _twist(twist) -> tuple[float, float, float, float, float, float]:
    return (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z)


def sample_from_fields(
    sec: int,
    nanosec: int,
    pose: Sequence[float],
    twist: Sequence[float] | None = None,
    *,
    model: str,
    dimension: int,
    control_point_distance: float,
    epoch: float,
) -> RobotSample:
    """A pose as a `RobotSample`, from its fields: the header stamp (sec, nanosec), the pose
    (position x y z, orientation x y z w) and, from odometry, the body-frame twist (linear x y z,
    angular x y z; REP 105), giving the control point's world velocity R (v + ω × offset).

    The one computation behind `pose_sample`, `odometry_sample` (rclpy or rosbags messages:
    `formation analyze`) and the coordinator's raw poses (`formation_msgs_py.cdr`): the same
    floats from the same message, whichever way it was read."""
    offset = _control_offset(model, control_point_distance)
    position, orientation = pose[:3], pose[3:]
    time = _run_time(sec, nanosec, epoch)
    point = kinematics.control_point(position, orientation, offset)[:dimension]
    if twist is None:
        return RobotSample(time=time, position=point)
    velocity = kinematics.control_point_velocity(orientation, twist[:3], twist[3:], offset)[:dimension]
    return RobotSample(time=time, position=point, velocity=velocity)


def pose_sample(
    msg, *, model: str, dimension: int, control_point_distance: float, epoch: float
) -> RobotSample:
    """A `geometry_msgs/PoseStamped` (an rclpy or rosbags message) as a `RobotSample`: the control
    point as the agents compute it (`formation_agent.core.kinematics`)."""
    stamp = msg.header.stamp
    return sample_from_fields(
        stamp.sec,
        stamp.nanosec,
        _pose(msg.pose),
        model=model,
        dimension=dimension,
        control_point_distance=control_point_distance,
        epoch=epoch,
    )


def odometry_sample(
    msg, *, model: str, dimension: int, control_point_distance: float, epoch: float
) -> RobotSample:
    """A `nav_msgs/Odometry` (pose in the world frame, twist in the body frame, REP 105) as a
    `RobotSample` with the control point's world velocity R (v + ω × offset)."""
    stamp = msg.header.stamp
    return sample_from_fields(
        stamp.sec,
        stamp.nanosec,
        _pose(msg.pose.pose),
        _twist(msg.twist.twist),
        model=model,
        dimension=dimension,
        control_point_distance=control_point_distance,
        epoch=epoch,
    )


POSES_AFTER_END = 1.0
"""[s] A robot run's formation is sampled from poses stamped up to this long past its end: the
coordinator waits at most this long for them, and `formation analyze` ignores later ones."""


def poses_for_end(samples: list, end: float, *, silence: float | None = None) -> list:
    """The poses a robot run's formation is sampled from, `end` its end: those stamped at most
    POSES_AFTER_END past it and, when the robot's poses had stopped more than `silence` before
    the first one after it (a robot frozen or cut off at the end, resumed later), none after it.
    The coordinator (summary.json) and `formation analyze` (the bag) both cut so, whenever each
    got the later poses."""
    kept = [p for p in samples if p.time <= end + POSES_AFTER_END] or samples[:1]
    before = [p.time for p in kept if p.time <= end]
    after = [p.time for p in kept if p.time > end]
    if silence is not None and before and after and min(after) - max(before) > silence:
        kept = [p for p in kept if p.time <= end]
    return kept


@dataclass(frozen=True, kw_only=True)
class PoseTrack:
    """One robot's recorded poses: run times, increasing, with the scenario position at each and,
    when the source carries it, the velocity of that point in the world frame."""

    times: np.ndarray  # (K,)
    positions: np.ndarray  # (K, p)
    velocities: np.ndarray | None = None  # (K, p)

    @classmethod
    def from_samples(cls, samples: list[RobotSample]) -> PoseTrack:
        """In time order; of poses stamped alike, the first received."""
        if not samples:
            raise RobotError('a robot published no pose: its trajectory cannot be sampled')
        ordered = sorted(range(len(samples)), key=lambda k: samples[k].time)  # stable
        kept = [k for n, k in enumerate(ordered) if n == 0 or samples[k].time != samples[ordered[n - 1]].time]
        velocities = None
        if all(samples[k].velocity is not None for k in kept):
            velocities = np.array([samples[k].velocity for k in kept])
        return cls(
            times=np.array([samples[k].time for k in kept]),
            positions=np.array([samples[k].position for k in kept]),
            velocities=velocities,
        )


def trajectory_samples(
    tracks: dict[int, PoseTrack], agent_ids, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """Every agent's position and velocity at `times`, linearly interpolated in its track.

    Before a track's first pose and after its last the nearest pose is held.  Tracks without
    velocities (PoseStamped) get them from the positions' differences over `times` (central,
    np.gradient); None with a single sample.  The coordinator (summary.json) and
    `formation analyze` (the bag) both sample a robot run this way, so the two agree whenever they
    saw the same poses.
    """
    times = np.asarray(times, dtype=float)
    positions = np.stack(
        [_interpolate(tracks[i].times, tracks[i].positions, times) for i in agent_ids], axis=1
    )
    if any(tracks[i].velocities is None for i in agent_ids):
        return positions, (np.gradient(positions, times, axis=0) if len(times) > 1 else None)
    velocities = np.stack(
        [_interpolate(tracks[i].times, tracks[i].velocities, times) for i in agent_ids], axis=1
    )
    return positions, velocities


def _interpolate(stamps: np.ndarray, values: np.ndarray, times: np.ndarray) -> np.ndarray:
    if len(stamps) == 0:
        raise RobotError('a robot published no pose: its trajectory cannot be sampled')
    return np.stack([np.interp(times, stamps, values[:, axis]) for axis in range(values.shape[1])], axis=1)


def sample_times(horizon: float, period: float, events=()) -> np.ndarray:
    """The sample grid of a robot run: 0, period, 2 period, … up to the horizon, the horizon
    itself and every event time in [0, horizon] (so that every trigger has its sample)."""
    if not (math.isfinite(period) and period > 0.0):
        raise RobotError(f'the sample period must be > 0, got {period!r}')
    grid = np.arange(0, math.floor(horizon / period) + 1) * period
    extra = [t for t in events if 0.0 <= t <= horizon]
    return np.unique(np.concatenate([grid[grid <= horizon], [horizon], np.asarray(extra, dtype=float)]))
