"""Sensing from robot poses: control points, ETA-2 velocities, and stale poses refused with the numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.errors import PoseError
from formation_agent.core.pose_sensing import PoseBook
from formation_msgs_py.types import RobotPose

NOW = 1_700_000_000.0  # wall time of the trigger


def _book(*, offset=(0.0, 0.0, 0.0), dimension=2, timeout=0.5):
    return PoseBook(
        agent_id=1,
        neighbour_ids=(2, 3),
        dimension=dimension,
        offset=offset,
        world_frame='world',
        timeout=timeout,
        topic=lambda robot: f'/agent_{robot}/robot/pose',
    )


def _pose(x, y, theta=0.0, *, age=0.01, frame='world', linear=None, angular=None):
    return RobotPose(
        stamp=NOW - age,
        frame=frame,
        position=(x, y, 0.0),
        orientation=(0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2)),
        linear=linear,
        angular=angular,
    )


def test_relative_positions_are_those_of_the_control_points():
    book = _book(offset=(0.1, 0.0, 0.0))  # unicycles, l = 0.1 m
    for robot, pose in (
        (1, _pose(0.0, 0.0, 0.0)),
        (2, _pose(1.0, 0.0, math.pi / 2)),
        (3, _pose(0.0, -1.0, math.pi)),
    ):
        assert book.add(robot, pose) is None
    sensed = book.sense(t=4.25, now=NOW, velocities=False)
    assert (sensed.agent, sensed.stamp, sensed.velocity, sensed.rel_velocities) == (1, 4.25, None, None)
    # control points: 1 at (0.1, 0), 2 at (1, 0.1), 3 at (-0.1, -1)
    assert sensed.rel_positions[2] == pytest.approx((-0.9, -0.1), abs=1e-15)
    assert sensed.rel_positions[3] == pytest.approx((0.2, 1.0), abs=1e-15)


def test_eta2_velocities_from_the_odometry_twist_rotated_into_the_world():
    book = _book(offset=(0.1, 0.0, 0.0))
    book.add(1, _pose(0.0, 0.0, math.pi / 2, linear=(0.2, 0.0, 0.0), angular=(0.0, 0.0, 1.0)))
    book.add(2, _pose(1.0, 0.0, 0.0, linear=(0.1, 0.0, 0.0), angular=(0.0, 0.0, 0.0)))
    book.add(3, _pose(0.0, 1.0, math.pi, linear=(0.0, 0.0, 0.0), angular=(0.0, 0.0, -2.0)))
    sensed = book.sense(t=1.0, now=NOW, velocities=True)
    # Control points: 1 heads +y at 0.2 m/s and turns left at 1 rad/s, its point 0.1 m ahead moves
    # ω l = 0.1 m/s towards -x; 2 drives +x; 3 heads -x and turns right: its point moves +y at 0.2.
    q1, q2, q3 = np.array([-0.1, 0.2]), np.array([0.1, 0.0]), np.array([0.0, 0.2])
    assert sensed.velocity == pytest.approx(tuple(q1), abs=1e-15)
    assert sensed.rel_velocities[2] == pytest.approx(tuple(q1 - q2), abs=1e-15)
    assert sensed.rel_velocities[3] == pytest.approx(tuple(q1 - q3), abs=1e-15)


def test_eta2_velocities_from_pose_differences_of_the_control_points():
    book = _book()
    for robot, y in ((1, 0.0), (2, 2.0), (3, 3.0)):
        book.add(robot, _pose(0.0, y, age=0.03))
    book.add(1, _pose(0.002, 0.0, age=0.01))  # 0.1 m/s along x over 20 ms
    book.add(2, _pose(0.0, 2.0 - 0.004, age=0.01))  # -0.2 m/s along y
    with pytest.raises(PoseError, match=r'velocity of robot 3 needs two poses on /agent_3/robot/pose'):
        book.sense(t=1.0, now=NOW, velocities=True)
    book.add(3, _pose(0.0, 3.0, age=0.02))
    sensed = book.sense(t=1.0, now=NOW, velocities=True)
    assert sensed.velocity == pytest.approx((0.1, 0.0), rel=1e-6)
    assert sensed.rel_velocities[2] == pytest.approx((0.1, 0.2), rel=1e-6)
    assert sensed.rel_velocities[3] == pytest.approx((0.1, 0.0), rel=1e-6)


def test_a_stale_pose_is_refused_naming_robot_topic_age_and_limit():
    book = _book()
    book.add(1, _pose(0.0, 0.0))
    book.add(2, _pose(1.0, 0.0, age=0.734))
    book.add(3, _pose(0.0, 1.0))
    with pytest.raises(PoseError) as error:
        book.sense(t=4.2, now=NOW, velocities=False)
    assert str(error.value) == (
        'agent 1: the pose of robot 2 on /agent_2/robot/pose is 0.734 s old at t=4.200 (pose_timeout 0.5 s): '
        'the agent stops'
    )
    book.add(2, _pose(1.0, 0.0, age=0.5))  # exactly at the limit: still fresh
    assert book.sense(t=4.2, now=NOW, velocities=False).rel_positions[2] == (-1.0, 0.0)


def test_missing_and_future_poses_are_refused():
    book = _book()
    book.add(1, _pose(0.0, 0.0))
    assert book.add(3, _pose(0.0, 1.0, frame='map')) == (
        'frame',
        "pose of robot 3 in frame 'map', not the world frame 'world'",
    )
    book.add(2, _pose(1.0, 0.0, age=-0.75))  # stamped ahead of this machine's clock
    assert not book.has_all()
    with pytest.raises(
        PoseError,
        match=r'robot 2 on /agent_2/robot/pose is stamped 0.750 s in the future at t=0.000 '
        r'\(pose_timeout 0.5 s; are the clocks synchronised\?\)',
    ):
        book.sense(t=0.0, now=NOW, velocities=False)
    book = _book()
    book.add(1, _pose(0.0, 0.0))
    book.add(2, _pose(1.0, 0.0))
    book.add(3, _pose(0.0, 1.0, frame='map'))
    with pytest.raises(PoseError) as error:
        book.sense(t=0.0, now=NOW, velocities=False)
    assert str(error.value) == (
        'agent 1: the pose of robot 3 on /agent_3/robot/pose has not arrived by t=0.000; '
        'its last pose was refused: '
        "pose of robot 3 in frame 'map', not the world frame 'world': the agent stops"
    )


def test_a_pose_older_than_the_one_held_is_refused():
    book = _book()
    book.add(1, _pose(0.0, 0.0, age=0.01))
    assert book.add(1, _pose(5.0, 0.0, age=0.02)) == (
        'time_backwards',
        f'pose of robot 1 stamped {NOW - 0.02!r}, before the one held ({NOW - 0.01!r})',
    )
    assert book.fresh(1, t=0.0, now=NOW).position == (0.0, 0.0, 0.0)


def test_the_shared_stamp_rule_refuses_old_future_and_nan_ages():
    """`stamp_refusal` is the rule of the agents' `fresh` and of the coordinator's poses (issue 28)."""
    from formation_agent.core.pose_sensing import stamp_refusal

    assert stamp_refusal(age=0.51, timeout=0.5) == 'old' and stamp_refusal(age=0.5, timeout=0.5) is None
    assert stamp_refusal(age=-0.51, timeout=0.5) == 'future' and stamp_refusal(age=-0.5, timeout=0.5) is None
    assert stamp_refusal(age=-0.4, timeout=math.inf, future=0.1) == 'future'
    assert stamp_refusal(age=math.nan, timeout=0.5) == 'not a time'


def test_the_safety_layer_sees_the_other_robots_within_its_radius_from_their_poses():
    # docs/SAFETY.md on robots: the others' control points within R are handed on as nearby; every
    # robot's pose must be fresh (a robot not seen may be close), the neighbours stay as they were.
    book = PoseBook(
        agent_id=1,
        neighbour_ids=(2,),
        dimension=2,
        offset=(0.1, 0.0, 0.0),
        world_frame='world',
        timeout=0.5,
        topic=lambda robot: f'/agent_{robot}/robot/pose',
        other_ids=(3, 4, 5),
        sensing_radius=2.0,
    )
    assert book.robots == (1, 2, 3, 4, 5)
    for robot, pose in (
        (1, _pose(0.0, 0.0)),
        (2, _pose(1.0, 0.0)),
        (3, _pose(1.9, 0.0)),
        (4, _pose(2.1, 0.0)),
    ):
        assert book.add(robot, pose) is None
    with pytest.raises(PoseError, match='the pose of robot 5 on /agent_5/robot/pose has not arrived'):
        book.sense(t=1.0, now=NOW, velocities=False)
    book.add(5, _pose(0.0, -2.2, -math.pi / 2))  # its control point at (0, -2.3): 2.302 m from (0.1, 0)
    sensed = book.sense(t=1.0, now=NOW, velocities=False)
    assert sensed.rel_positions == {2: (-1.0, 0.0)}
    # control points: 1 at (0.1, 0), 3 at (2.0, 0): 1.9 m; 4 at (2.2, 0): 2.1 m; 5 at (0, -2.3)
    assert list(sensed.nearby) == [3] and sensed.nearby[3] == pytest.approx((-1.9, 0.0), abs=1e-15)
    plain = _book()
    for robot, pose in ((1, _pose(0.0, 0.0)), (2, _pose(1.0, 0.0)), (3, _pose(1.9, 0.0))):
        plain.add(robot, pose)
    assert plain.sense(t=1.0, now=NOW, velocities=False).nearby is None  # the layer off: as before
