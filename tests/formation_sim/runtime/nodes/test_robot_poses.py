"""The coordinator's poses of the robots without a node: what is kept before t = 0, the samples
from it on (control points, run times), who is waited for at the end, and the tracks the formation
is sampled from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_sim.runtime.contract import TRAJECTORY_TOPICS
from formation_sim.runtime.errors import CoordinatorError
from formation_sim.runtime.nodes.robot_poses import EARLY_POSES, RobotPoses
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


# -- issue 28: the poses the agents refuse are refused here too --------------------------------


def _gated(**options) -> RobotPoses:
    return RobotPoses(
        [1, 2, 3], model='holonomic', dimension=2, control_point_distance=0.1, silence=0.5, **options
    )


def _take(poses: RobotPoses, agent: int, fields: tuple, *, wall: float) -> tuple[str, str] | None:
    """What the coordinator's pose callback does: refuse, or note as a sample from t = 0."""
    refusal = poses.refusal(agent, fields, wall=wall)
    if refusal is None:
        poses.note(agent, fields, epoch=EPOCH, now=wall - EPOCH)
    return refusal


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize('index', [0, 1, 2, 3, 6])
def test_a_pose_with_a_non_finite_value_is_refused_counted_and_never_sampled(bad, index):
    poses = _gated()
    for k in range(3):
        assert _take(poses, 1, _fields(k * 0.01, x=1.0), wall=EPOCH + k * 0.01) is None
    for k in range(3):
        assert _take(poses, 2, _fields(k * 0.01, x=3.0), wall=EPOCH + k * 0.01) is None
        assert _take(poses, 3, _fields(k * 0.01, x=5.0), wall=EPOCH + k * 0.01) is None
    sec, nanosec, values = _fields(0.05, x=1.0)
    values = list(values)
    values[index] = bad
    for _ in range(5):  # five NaN poses on one robot's odom (issue 28's finding)
        reason, detail = _take(poses, 1, (sec, nanosec, tuple(values)), wall=EPOCH + 0.06)
        assert reason == 'non_finite' and 'must be finite' in detail and 'robot 1' in detail
    assert poses.refused == {'non_finite': 5} and len(poses.samples[1]) == 3
    latest = poses.latest_positions()
    assert np.isfinite(latest).all() and latest[:, 0].tolist() == [1.0, 3.0, 5.0]


def test_a_non_finite_twist_and_a_quaternion_far_from_unit_are_refused():
    poses = _gated()
    sec, nanosec, values = _fields(0.0, x=1.0)
    assert _take(poses, 1, (sec, nanosec, values, (0.0, math.nan, 0, 0, 0, 0)), wall=EPOCH)[0] == 'non_finite'
    zero = (*values[:3], 0.0, 0.0, 0.0, 0.0)
    reason, detail = _take(poses, 1, (sec, nanosec, zero), wall=EPOCH)
    assert reason == 'field' and 'unit quaternion' in detail
    assert poses.samples[1] == [] and poses.refused == {'non_finite': 1, 'field': 1}


def test_a_pose_stamped_ahead_of_the_clock_beyond_the_tolerance_is_refused():
    """Issue 28: one odometry pose stamped 0.4 s ahead gave max_edge_length 5.38 > Δ = 3."""
    poses = _gated(ahead=0.1)
    assert _take(poses, 1, _fields(1.0, x=1.0), wall=EPOCH + 1.0) is None
    reason, detail = _take(poses, 1, _fields(1.4, x=4.0), wall=EPOCH + 1.0)
    assert reason == 'future' and '0.400 s ahead' in detail and 'tolerance 0.1 s' in detail
    # The real next pose, stamped after the one held and before the forged one, is taken.
    assert _take(poses, 1, _fields(1.01, x=1.0), wall=EPOCH + 1.01) is None
    assert [s.time for s in poses.samples[1]] == pytest.approx([1.0, 1.01], abs=1e-7)
    assert _take(poses, 1, _fields(1.09, x=1.0), wall=EPOCH + 1.0) is None  # within the tolerance


def test_a_pose_stamped_before_the_last_accepted_one_is_refused():
    poses = _gated()
    assert _take(poses, 2, _fields(1.0, x=1.0), wall=EPOCH + 1.0) is None
    reason, detail = _take(poses, 2, _fields(0.5, x=1.0), wall=EPOCH + 1.0)
    assert reason == 'time_backwards' and 'before the one held' in detail
    assert len(poses.samples[2]) == 1


def test_a_jump_beyond_the_speed_limit_is_refused_and_a_reachable_pose_is_not():
    poses = _gated(max_speed=0.5, slack=0.05)
    assert _take(poses, 3, _fields(1.0, x=1.0), wall=EPOCH + 1.0) is None
    # 0.1 s later the robot can be 0.5 * 0.1 + 0.05 = 0.1 m further: 0.099 m is taken, 0.2 m not.
    reason, detail = _take(poses, 3, _fields(1.1, x=1.2), wall=EPOCH + 1.1)
    assert reason == 'jump' and '0.200 m' in detail and '0.5 m/s' in detail
    assert _take(poses, 3, _fields(1.1, x=1.099), wall=EPOCH + 1.1) is None
    assert poses.refused == {'jump': 1}
    # Without a speed limit (inf) no jump is refused.
    free = _gated()
    assert _take(free, 3, _fields(1.0, x=1.0), wall=EPOCH + 1.0) is None
    assert _take(free, 3, _fields(1.01, x=100.0), wall=EPOCH + 1.01) is None
