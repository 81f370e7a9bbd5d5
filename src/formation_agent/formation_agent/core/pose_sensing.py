"""Sensing from robot poses (README, "Running on robots"), ROS-free.

On a robot the agent senses from the latest poses of itself and its neighbours (motion capture
PoseStamped or Odometry), at its triggering times only, as the paper's agents do:

- x_i - x_j from the control points (`kinematics.control_point`: the robot's origin for a
  holonomic robot, the point l ahead of the axle for a unicycle);
- ETA-2 also needs velocities, and its state q_i is the control point's velocity.  From
  Odometry it is the twist, rotated from the body into the world frame (R (v + ω × offset),
  REP 105); from PoseStamped the backward difference of the control point over the last two
  poses, (z_k - z_{k-1}) / (t_k - t_{k-1}) — pose noise σ becomes a velocity noise of about
  √2 σ / (t_k - t_{k-1}), so use Odometry for ETA-2 where there is one.

A pose is used only while it is fresh: at a trigger each pose must be at most `timeout` seconds
old (by its header stamp against the agent's clock) and not stamped more than `timeout` in the
future (clocks out of step).  Otherwise `PoseError` names the robot, its topic, the age and the
limit, and the agent stops safely.  Poses in another frame than the world frame, or older than
the one already held, are refused on arrival and counted (`add`).

The rules a pose must meet to be used are this module's functions, shared by every reader of
poses (issue 28): the agents' `PoseBook` and the coordinator's `formation_sim.runtime.nodes.robot_poses`.
`stamp_refusal` (too old, or stamped ahead of the reader's clock) and `pose_refusal` (finite
values and a unit quaternion as `formation_msgs_py.codec.pose_values` checks them, not stamped
before the last pose accepted from the robot, not stamped ahead beyond a tolerance, and no jump
from the last accepted pose beyond what the robot's speed limit allows between their stamps).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import cast

import numpy as np

from formation_agent.core.errors import PoseError
from formation_agent.core.kinematics import control_point, control_point_velocity
from formation_msgs_py.codec import pose_values, twist_values
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import REJECT_FRAME, REJECT_FUTURE, REJECT_JUMP, REJECT_TIME_BACKWARDS
from formation_msgs_py.types import RobotPose, SensedState


def stamp_refusal(*, age: float, timeout: float, future: float | None = None) -> str | None:
    """Why a pose `age` seconds old (negative: stamped ahead of the reader's clock) must not be
    used, or None: older than `timeout`, or ahead by more than `future` (default `timeout`).
    A NaN age is refused too (no comparison holds for it)."""
    future = timeout if future is None else future
    if age > timeout:
        return 'old'
    if age < -future:
        return 'future'
    if math.isnan(age):
        return 'not a time'
    return None


def pose_refusal(
    robot: int,
    *,
    stamp: float,
    pose: Sequence[float],
    twist: Sequence[float] | None = None,
    now: float,
    ahead: float,
    latest: tuple[float, Sequence[float]] | None = None,
    max_speed: float = math.inf,
    slack: float = 0.0,
) -> tuple[str, str] | None:
    """Why a pose of `robot` (Unix `stamp`, `pose`: position x y z and quaternion x y z w, the
    odometry's `twist`: linear and angular, 3 each) that arrived at Unix time `now` must not be
    used, as (reason, detail), or None.  `latest`: the stamp and position of the last pose of
    `robot` accepted; `ahead`: how far a stamp may be ahead of `now` [s]; `max_speed`: the robot's
    speed limit [m/s] (inf: no jump is refused), `slack` the distance allowed on top [m].

    The rules: finite values and a unit quaternion (`codec.pose_values`, `codec.twist_values`:
    the agents' decoders'); a finite stamp not before `latest`'s (REJECT_TIME_BACKWARDS), nor
    ahead of `now` by more than `ahead` (REJECT_FUTURE, `stamp_refusal`); and a position at most
    `max_speed` (t - t_latest) + `slack` from `latest`'s (REJECT_JUMP)."""
    try:
        position, _ = pose_values(f'pose of robot {robot}', pose[:3], pose[3:7])
        if twist is not None:
            twist_values(twist[:3], twist[3:6])
    except MessageError as error:
        return error.reason, str(error)
    if not math.isfinite(stamp):
        return REJECT_FUTURE, f'pose of robot {robot} stamped {stamp!r}: not a time'
    if stamp_refusal(age=now - stamp, timeout=math.inf, future=ahead) is not None:
        return REJECT_FUTURE, (
            f'pose of robot {robot} stamped {stamp - now:.3f} s ahead of this clock (tolerance {ahead:g} s; '
            'are the clocks synchronised?)'
        )
    if latest is None:
        return None
    held, where = latest
    if stamp < held:
        return (
            REJECT_TIME_BACKWARDS,
            f'pose of robot {robot} stamped {stamp!r}, before the one held ({held!r})',
        )
    moved = math.dist(position[: len(where)], where)
    allowed = max_speed * (stamp - held) + slack
    if moved > allowed:
        return REJECT_JUMP, (
            f'pose of robot {robot} {moved:.3f} m from the one held {stamp - held:.3f} s before it: more '
            f'than its speed limit allows ({max_speed:g} m/s, {slack:g} m slack: {allowed:.3f} m)'
        )
    return None


class PoseBook:
    """The latest pose (and the one before, for differences) of this robot and its neighbours."""

    def __init__(
        self,
        *,
        agent_id: int,
        neighbour_ids: Sequence[int],
        dimension: int,
        offset: Sequence[float],
        world_frame: str,
        timeout: float,
        topic: Callable[[int], str],
        other_ids: Sequence[int] = (),
        sensing_radius: float | None = None,
    ) -> None:
        """`other_ids`, `sensing_radius`: the safety layer (docs/SAFETY.md): the team's other robots,
        whose poses are read too, and the range within which `sense` reports them as `nearby`."""
        if not timeout > 0.0:
            raise ValueError(f'pose timeout must be > 0, got {timeout!r}')
        self.agent_id = agent_id
        self.neighbour_ids = tuple(neighbour_ids)
        self.other_ids = tuple(other_ids)
        self.sensing_radius = sensing_radius
        self.robots = (agent_id, *self.neighbour_ids, *self.other_ids)
        self.dimension = dimension
        self.offset = np.asarray(offset, dtype=float)
        self.world_frame = world_frame
        self.timeout = float(timeout)
        self.topic = topic  # robot id -> the topic its poses come on (for messages)
        self._latest: dict[int, RobotPose] = {}
        self._previous: dict[int, RobotPose] = {}  # the last pose stamped before the latest
        self._refused: dict[int, str] = {}  # robot -> why its last refused pose was refused

    def add(self, robot: int, pose: RobotPose) -> tuple[str, str] | None:
        """Keep `pose` as the latest of `robot`; or say why not: (reason, detail)."""
        if pose.frame != self.world_frame:
            detail = (
                f'pose of robot {robot} in frame {pose.frame!r}, not the world frame {self.world_frame!r}'
            )
            self._refused[robot] = detail
            return REJECT_FRAME, detail
        latest = self._latest.get(robot)
        if latest is not None and pose.stamp < latest.stamp:  # pose_refusal's rule, on a decoded pose
            detail = f'pose of robot {robot} stamped {pose.stamp!r}, before the one held ({latest.stamp!r})'
            return REJECT_TIME_BACKWARDS, detail
        if latest is not None and pose.stamp > latest.stamp:
            self._previous[robot] = latest
        self._latest[robot] = pose
        return None

    def has_all(self) -> bool:
        """A pose of every robot the agent senses has arrived."""
        return all(robot in self._latest for robot in self.robots)

    def missing(self) -> list[int]:
        """The robots the agent senses whose first pose has not arrived."""
        return [robot for robot in self.robots if robot not in self._latest]

    def fresh(self, robot: int, *, t: float, now: float) -> RobotPose:
        """The latest pose of `robot` if it is fresh at wall time `now` (trigger time t), else PoseError."""
        pose = self._latest.get(robot)
        where = f'agent {self.agent_id}: the pose of robot {robot} on {self.topic(robot)}'
        if pose is None:
            refused = f'; its last pose was refused: {self._refused[robot]}' if robot in self._refused else ''
            raise PoseError(f'{where} has not arrived by t={t:.3f}{refused}: the agent stops')
        age = now - pose.stamp
        refusal = stamp_refusal(age=age, timeout=self.timeout)
        if refusal == 'old':
            raise PoseError(
                f'{where} is {age:.3f} s old at t={t:.3f} (pose_timeout {self.timeout:g} s): the agent stops'
            )
        if refusal is not None:
            raise PoseError(
                f'{where} is stamped {-age:.3f} s in the future at t={t:.3f} '
                f'(pose_timeout {self.timeout:g} s; are the clocks synchronised?): the agent stops'
            )
        return pose

    def _point(self, pose: RobotPose) -> np.ndarray:
        point: np.ndarray = control_point(pose.position, pose.orientation, self.offset)[: self.dimension]
        return point

    def _velocity(self, robot: int, pose: RobotPose, t: float) -> np.ndarray:
        if pose.linear is not None:  # Odometry: the body twist, into the world frame
            angular = cast('tuple[float, float, float]', pose.angular)  # Odometry: both parts
            return control_point_velocity(pose.orientation, pose.linear, angular, self.offset)[
                : self.dimension
            ]
        previous = self._previous.get(robot)
        if previous is None:
            raise PoseError(
                f'agent {self.agent_id}: the velocity of robot {robot} needs two poses on '
                f'{self.topic(robot)} (pose differences), one has arrived by t={t:.3f}: the agent stops'
            )
        rate: np.ndarray = (self._point(pose) - self._point(previous)) / (pose.stamp - previous.stamp)
        return rate

    def sense(self, *, t: float, now: float, velocities: bool) -> SensedState:
        """What the agent senses at its trigger t (wall time `now`): x_i - x_j, and for ETA-2 q_i,
        q_i - q_j."""
        poses = {robot: self.fresh(robot, t=t, now=now) for robot in self.robots}
        x = {robot: self._point(pose) for robot, pose in poses.items()}
        i = self.agent_id
        rel_positions = {j: _floats(x[i] - x[j]) for j in self.neighbour_ids}
        if self.sensing_radius is not None:  # the safety layer: the other robots within R
            radius2 = self.sensing_radius * self.sensing_radius
            rel = {j: _floats(x[i] - x[j]) for j in self.other_ids}
            nearby = {j: r for j, r in rel.items() if sum(v * v for v in r) <= radius2}
            return SensedState(agent=i, stamp=t, rel_positions=rel_positions, nearby=nearby)
        if not velocities:
            return SensedState(agent=i, stamp=t, rel_positions=rel_positions)
        q = {robot: self._velocity(robot, pose, t) for robot, pose in poses.items()}
        return SensedState(
            agent=i,
            stamp=t,
            rel_positions=rel_positions,
            rel_velocities={j: _floats(q[i] - q[j]) for j in self.neighbour_ids},
            velocity=_floats(q[i]),
        )


def _floats(vector: np.ndarray) -> tuple[float, ...]:
    return tuple(float(v) for v in vector)
