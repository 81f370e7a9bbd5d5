"""The coordinator's poses of the robots without a node: what is kept before t = 0, the samples
from it on (control points, run times), who is waited for at the end, and the tracks the formation
is sampled from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.runtime.robot_poses import EARLY_POSES, TRAJECTORY_TOPICS, RobotPoses
from formation_sim.runtime.run_book import CoordinatorError
from formation_sim.sim.robots import POSES_AFTER_END

EPOCH = 1_700_000_000.0


def _fields(t: float, x: float, y: float = 0.0, yaw: float = 0.0) -> tuple:
    """A PoseStamped's fields at run time `t`, robot at (x, y) heading `yaw`."""
    stamp = EPOCH + t
    sec = math.floor(stamp)
    return sec, round((stamp - sec) * 1e9), (x, y, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def _poses(model: str = 'holonomic', *, silence: float = 0.5) -> RobotPoses:
    return RobotPoses([1, 2, 3], model=model, dimension=2, control_point_distance=0.1, silence=silence)


def test_before_t0_only_the_latest_poses_are_kept_and_become_the_first_samples():
    poses = _poses()
    assert poses.unheard() == [1, 2, 3]
    for k in range(EARLY_POSES + 10):
        poses.note(1, _fields(-1.0 + k / 128, x=float(k)), epoch=None, now=0.0)
    poses.note(2, _fields(-0.5, x=2.0), epoch=None, now=0.0)
    assert poses.unheard() == [3] and poses.samples[1] == []  # nothing sampled before t = 0
    poses.note(3, _fields(-0.25, x=3.0, y=1.0), epoch=None, now=0.0)
    assert [p.tolist() for p in poses.start_positions(epoch=EPOCH)] == [
        [EARLY_POSES + 9.0, 0.0],
        [2.0, 0.0],
        [3.0, 1.0],
    ]
    poses.begin(epoch=EPOCH, now=7.0)
    assert [s.time for s in poses.samples[1]] == pytest.approx(
        [-1.0 + k / 128 for k in range(10, EARLY_POSES + 10)], abs=1e-12
    )
    assert [s.time for s in poses.samples[3]] == pytest.approx([-0.25], abs=1e-12)
    assert poses.watch.heard == {1: 7.0, 2: 7.0, 3: 7.0} and poses.watch.stamps == {1: 0.0, 2: 0.0, 3: 0.0}


def test_from_t0_each_pose_is_a_sample_of_the_control_point_at_run_time():
    poses = _poses('unicycle')
    poses.note(2, _fields(0.375, x=1.0, y=2.0, yaw=0.5), epoch=EPOCH, now=3.0)
    (sample,) = poses.samples[2]
    assert (
        sample.time == pytest.approx(0.375, abs=1e-12)
        and poses.watch.heard[2] == 3.0
        and poses.watch.stamps[2] == sample.time
    )
    # A unicycle's scenario position is its control point, l = 0.1 ahead of the axle.
    assert np.allclose(sample.position, [1.0 + 0.1 * math.cos(0.5), 2.0 + 0.1 * math.sin(0.5)], atol=1e-15)
    assert sample.velocity is None  # a pose carries no twist


def test_the_latest_positions_exist_once_every_robot_has_a_sample():
    poses = _poses()
    poses.note(1, _fields(0.0, x=1.0), epoch=EPOCH, now=0.0)
    poses.note(3, _fields(0.0, x=3.0), epoch=EPOCH, now=0.0)
    assert poses.latest_positions() is None
    poses.note(2, _fields(0.0, x=2.0), epoch=EPOCH, now=0.0)
    poses.note(1, _fields(0.125, x=1.5), epoch=EPOCH, now=0.0)
    assert poses.latest_positions().tolist() == [[1.5, 0.0], [2.0, 0.0], [3.0, 0.0]]


def test_at_the_end_only_robots_still_publishing_are_waited_for():
    poses = _poses(silence=0.5)
    for agent, heard in ((1, 10.0), (2, 9.8), (3, 9.7)):  # robot 3 silent 0.3 s > half the silence
        poses.note(agent, _fields(0.5, x=float(agent)), epoch=EPOCH, now=heard)
    assert poses.expected(lost=[], now=10.0) == [1, 2]
    assert poses.expected(lost=[2], now=10.0) == [1]
    assert poses.behind([1, 2], 0.75) and not poses.behind([1, 2], 0.5)
    poses.note(2, _fields(0.75, x=2.0), epoch=EPOCH, now=10.1)
    assert poses.behind([1, 2], 0.75) and not poses.behind([2], 0.75)


def test_the_tracks_are_cut_as_analyze_cuts_the_bag_and_a_robot_without_poses_is_named():
    poses = _poses(silence=0.5)
    with pytest.raises(
        CoordinatorError, match=r'^robots \[1, 2, 3\] published no pose on their odom topic: '
    ):
        poses.tracks(1.0, source='odom')
    for t in (0.0, 0.5, 0.875, 1.25, 0.9 + POSES_AFTER_END + 0.125):  # robot 1: the last one too late
        poses.note(1, _fields(t, x=t), epoch=EPOCH, now=0.0)
    for t in (0.0, 0.25, 1.0):  # robot 2 frozen from 0.25 to past the end: nothing after the end
        poses.note(2, _fields(t, x=t), epoch=EPOCH, now=0.0)
    for t in (0.0, 0.75, 1.125):  # robot 3: a gap within the silence, its pose after the end kept
        poses.note(3, _fields(t, x=t), epoch=EPOCH, now=0.0)
    tracks = poses.tracks(0.9, source='odom')
    assert tracks[1].times == pytest.approx([0.0, 0.5, 0.875, 1.25], abs=1e-12)
    assert tracks[2].times == pytest.approx([0.0, 0.25], abs=1e-12)
    assert tracks[3].times == pytest.approx([0.0, 0.75, 1.125], abs=1e-12)


def test_every_trajectory_source_names_its_robot_topic():
    assert {source: topic(4) for source, topic in TRAJECTORY_TOPICS.items()} == {
        'true_odom': '/agent_4/robot/true_odom',
        'odom': '/agent_4/robot/odom',
        'pose': '/agent_4/robot/pose',
    }
