"""The robots' poses as the coordinator of a robot run reads them (`coordinator`), without ROS.

Each pose arrives as its fields (`formation_msgs_py.cdr`: stamp, pose and, from odometry, twist);
before t = 0 the last `EARLY_POSES` of each robot are kept (the first sample needs the last of
them), from t = 0 on each becomes a `RobotSample` (run time, control point, its velocity) and its
arrival is noted in the `PoseWatch` (a robot whose poses stop is lost).  At the end the samples
are cut as `formation analyze` cuts the bag (`sim.robots.poses_for_end`) into `PoseTrack`s.

A pose is kept only if the agents' rules accept it (`formation_agent.core.pose_sensing.pose_refusal`,
issue 28): finite with a unit quaternion, not stamped before the robot's last accepted pose, nor
ahead of this clock beyond `ahead` seconds, nor further from the last accepted one than the
robot's speed limit allows.  A refused pose is counted by its reason (`refused`), never sampled,
never used for a connectivity verdict and never a sign of the robot's life.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable

import numpy as np

from formation_agent.core.pose_sensing import pose_refusal
from formation_sim.runtime.errors import CoordinatorError
from formation_sim.runtime.nodes.run_book import PoseWatch
from formation_sim.sim.robots import PoseTrack, RobotSample, poses_for_end, sample_from_fields

EARLY_POSES = 50  # poses kept per robot from before t = 0 (the first sample needs the last of them)


def pose_rules(values: dict) -> dict:
    """The coordinator's pose rules as /formation/robots tells them (`formation analyze` applies
    them to the bag): its parameters pose_ahead_tolerance, max_linear_speed (None: none) and
    pose_jump_slack."""
    speed = values['max_linear_speed']
    return {
        'pose_ahead_tolerance': values['pose_ahead_tolerance'],
        'max_linear_speed': speed if math.isfinite(speed) else None,
        'pose_jump_slack': values['pose_jump_slack'],
    }


class RobotPoses:
    """Every robot's poses of a run: kept from before t = 0, sampled from it on, watched."""

    def __init__(
        self,
        agent_ids: Iterable[int],
        *,
        model: str,
        dimension: int,
        control_point_distance: float,
        silence: float,
        ahead: float = 0.1,
        max_speed: float = math.inf,
        slack: float = 0.05,
    ) -> None:
        self.model = model
        self.dimension = dimension
        self.control_point_distance = control_point_distance
        self.silence = silence
        self.samples: dict[int, list[RobotSample]] = {i: [] for i in agent_ids}
        self.early: dict[int, deque] = {i: deque(maxlen=EARLY_POSES) for i in self.samples}
        self.watch = PoseWatch(self.samples, silence=silence)
        self.ahead, self.max_speed, self.slack = ahead, max_speed, slack
        self._accepted: dict[int, tuple[float, tuple[float, ...]]] = {}  # robot -> (stamp, position)
        self.refused: dict[str, int] = {}  # reason -> poses refused

    def sample(self, fields: tuple, *, epoch: float) -> RobotSample:
        """A pose's fields (stamp, pose, and the twist of odometry) as a sample, run time from `epoch`."""
        return sample_from_fields(
            *fields,
            model=self.model,
            dimension=self.dimension,
            control_point_distance=self.control_point_distance,
            epoch=epoch,
        )

    @classmethod
    def of_coordinator(cls, scenario, values: dict) -> RobotPoses:
        """The poses of `scenario`'s robots as a coordinator with parameter `values` reads them."""
        return cls(
            scenario.agent_ids,
            model=values['robot'],
            dimension=scenario.dimension,
            control_point_distance=values['control_point_distance'],
            silence=values['pose_silence'],
            ahead=values['pose_ahead_tolerance'],
            max_speed=values['max_linear_speed'],
            slack=values['pose_jump_slack'],
        )

    def refusal(self, agent: int, fields: tuple, *, wall: float) -> tuple[str, str] | None:
        """Why a pose of robot `agent` (its fields) that arrived at Unix time `wall` is refused
        (reason, detail; counted in `refused`), or None: then it is the robot's latest accepted."""
        sec, nanosec, pose = fields[0], fields[1], fields[2]
        stamp = sec + nanosec * 1e-9
        refusal = pose_refusal(
            agent,
            stamp=stamp,
            pose=pose,
            twist=fields[3] if len(fields) > 3 else None,
            now=wall,
            ahead=self.ahead,
            latest=self._accepted.get(agent),
            max_speed=self.max_speed,
            slack=self.slack,
        )
        if refusal is None:
            self._accepted[agent] = (stamp, tuple(pose[:3]))
        else:
            self.refused[refusal[0]] = self.refused.get(refusal[0], 0) + 1
        return refusal

    def note(self, agent: int, fields: tuple, *, epoch: float | None, now: float) -> None:
        """A pose of robot `agent` (accepted by `refusal`) arrived at monotonic time `now`; `epoch`
        None: before t = 0."""
        if epoch is None:  # before t = 0: the last few, for the first sample
            self.early[agent].append(fields)
            return
        sample = self.sample(fields, epoch=epoch)
        self.samples[agent].append(sample)
        self.watch.note(agent, now=now, t=sample.time)

    def unheard(self) -> list[int]:
        """The robots with no pose yet from before t = 0."""
        return [i for i, early in self.early.items() if not early]

    def start_positions(self, *, epoch: float) -> list[np.ndarray]:
        """Each robot's latest position before t = 0 (every robot was heard), in id order."""
        return [self.sample(early[-1], epoch=epoch).position for early in self.early.values()]

    def begin(self, *, epoch: float, now: float) -> None:
        """t = 0: the poses kept from before it are the first samples; each robot was heard now."""
        for agent, early in self.early.items():
            self.samples[agent] = [self.sample(fields, epoch=epoch) for fields in early]
        for agent in self.samples:
            self.watch.note(agent, now=now, t=0.0)

    def latest_positions(self) -> np.ndarray | None:
        """Each robot's latest sampled position (rows in id order), or None while one has none."""
        latest = [samples[-1] if samples else None for samples in self.samples.values()]
        if any(sample is None for sample in latest):
            return None
        return np.array([sample.position for sample in latest])

    def expected(self, *, lost: Iterable[int], now: float) -> list[int]:
        """The robots whose poses may still come: not `lost` and not silent for half the silence."""
        gone = set(lost) | set(self.watch.silent(now, fraction=0.5))
        return [i for i in self.samples if i not in gone]

    def behind(self, robots: Iterable[int], end: float) -> bool:
        """Whether one of `robots` has no pose stamped at `end` or after yet."""
        return any(not self.samples[i] or self.samples[i][-1].time < end for i in robots)

    def tracks(self, end: float, *, source: str) -> dict[int, PoseTrack]:
        """Each robot's poses to sample the formation from, a run ending at `end`: as `formation
        analyze` reads the bag, not long past the end, not a robot silent at it."""
        silent = [i for i, samples in self.samples.items() if not samples]
        if silent:
            raise CoordinatorError(
                f'robots {silent} published no pose on their {source} topic: '
                'the formation cannot be summarised'
            )
        return {
            i: PoseTrack.from_samples(poses_for_end(samples, end, silence=self.silence))
            for i, samples in self.samples.items()
        }
