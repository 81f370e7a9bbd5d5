"""formation_msgs_py.cdr: robot poses as CDR bytes, against rclpy's own serialization."""

from __future__ import annotations

import math

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message

from formation_msgs_py.cdr import (
    OdometryWriter,
    decode_odometry_cdr,
    decode_pose_stamped_cdr,
    odometry_fields,
    pack_body_velocity,
    pack_pose_stamped,
    pack_world_velocity,
    pose_stamped_fields,
    twist_fields,
    twist_stamped_fields,
)
from formation_msgs_py.codec import (
    decode_odometry,
    decode_pose_stamped,
    encode_body_velocity,
    encode_world_velocity,
)
from formation_msgs_py.errors import MessageError

FRAMES = [('world', 'agent_1/base_link'), ('', ''), ('map', 'a'), ('odom', 'robot_12/base_footprint_x')]


def _odometry(stamp, frame, child, position, orientation, linear, angular_z, sigma) -> Odometry:
    msg = Odometry()
    seconds = math.floor(stamp)
    msg.header.stamp.sec, msg.header.stamp.nanosec = (
        int(seconds),
        min(999_999_999, round((stamp - seconds) * 1e9)),
    )
    msg.header.frame_id, msg.child_frame_id = frame, child
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = position
    o.x, o.y, o.z, o.w = orientation
    covariance = [0.0] * 36
    for k in range(3):
        covariance[7 * k] = sigma[0] ** 2
    covariance[35] = sigma[1] ** 2
    msg.pose.covariance = covariance
    t = msg.twist.twist
    t.linear.x, t.linear.y, t.linear.z = linear
    t.angular.z = angular_z
    return msg


@pytest.mark.parametrize(('frame', 'child'), FRAMES)
def test_the_odometry_writer_packs_what_rclpy_serializes_and_reads_back(frame, child):
    rng = np.random.default_rng(len(frame) + 7 * len(child))
    writer = OdometryWriter(frame=frame, child_frame=child, sigma=(0.005, 0.01))
    for _ in range(200):
        stamp = float(rng.uniform(0, 2e9))
        position, linear = tuple(rng.normal(size=3)), tuple(rng.normal(size=3))
        q = rng.normal(size=4)
        orientation = tuple(q / np.linalg.norm(q))
        angular = float(rng.normal())
        expected = _odometry(stamp, frame, child, position, orientation, linear, angular, (0.005, 0.01))
        packed = writer.pack(stamp, position, orientation, linear, angular)
        # The same length and layout (rclpy leaves alignment padding unset: compare what it reads).
        assert (
            len(packed) == len(serialize_message(expected))
            and deserialize_message(packed, Odometry) == expected
        )
        pose = PoseStamped(header=expected.header, pose=expected.pose.pose)
        packed = pack_pose_stamped(stamp, frame, position, orientation)
        assert (
            len(packed) == len(serialize_message(pose)) and deserialize_message(packed, PoseStamped) == pose
        )


@pytest.mark.parametrize(('frame', 'child'), FRAMES)
def test_decoding_serialized_poses_equals_decoding_the_messages(frame, child):
    rng = np.random.default_rng(3)
    for _ in range(100):
        q = rng.normal(size=4)
        odometry = _odometry(
            float(rng.uniform(0, 2e9)),
            frame,
            child,
            tuple(rng.normal(size=3)),
            tuple(q / np.linalg.norm(q) * 1.01),
            tuple(rng.normal(size=3)),
            float(rng.normal()),
            (0.0, 0.0),
        )
        data = serialize_message(odometry)
        assert decode_odometry_cdr(data) == decode_odometry(deserialize_message(data, Odometry))
        pose = PoseStamped(header=odometry.header, pose=odometry.pose.pose)
        data = serialize_message(pose)
        assert decode_pose_stamped_cdr(data) == decode_pose_stamped(deserialize_message(data, PoseStamped))


def test_bad_bytes_are_refused_with_the_rule_and_bad_values_as_the_message_decoders_refuse_them():
    good = serialize_message(
        _odometry(12.5, 'world', 'b', (1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.1, 0.0, 0.0), 0.2, (0.0, 0.0))
    )
    for cut in (0, 3, 12, 30, len(good) - 1):
        with pytest.raises(MessageError, match='bytes') as caught:
            decode_odometry_cdr(good[:cut])
        assert caught.value.reason == 'length'
    with pytest.raises(MessageError, match='not a little-endian CDR message'):
        decode_odometry_cdr(b'\x00\x00\x00\x00' + good[4:])  # big endian
    nan = _odometry(
        12.5, 'world', 'b', (math.nan, 2.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.1, 0.0, 0.0), 0.2, (0.0, 0.0)
    )
    with pytest.raises(MessageError, match=r'odometry pose position\[0\] must be finite') as caught:
        decode_odometry_cdr(serialize_message(nan))
    assert caught.value.reason == 'non_finite'
    flat = _odometry(
        12.5, 'world', 'b', (1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 0.1), (0.1, 0.0, 0.0), 0.2, (0.0, 0.0)
    )
    with pytest.raises(MessageError, match='orientation must be a unit quaternion'):
        decode_odometry_cdr(serialize_message(flat))


@pytest.mark.parametrize(('frame', 'child'), FRAMES)
def test_the_fields_of_serialized_poses_are_the_messages_fields_bit_for_bit_and_unchecked(frame, child):
    """What the coordinator samples from raw poses: the fields rclpy (or a bag reader) gives, as sent."""
    rng = np.random.default_rng(5)
    for k in range(100):
        q = rng.normal(size=4)
        position = (math.nan, 1.0, 2.0) if k == 0 else tuple(rng.normal(size=3))  # values unchecked, as sent
        odometry = _odometry(
            float(rng.uniform(0, 2e9)),
            frame,
            child,
            position,
            tuple(q / np.linalg.norm(q) * 1.01),
            tuple(rng.normal(size=3)),
            float(rng.normal()),
            (0.003, 0.0),
        )
        odometry.twist.twist.angular.x, odometry.twist.twist.angular.y = rng.normal(size=2)
        sec, nanosec, pose, twist = odometry_fields(serialize_message(odometry))
        p, o, t = odometry.pose.pose.position, odometry.pose.pose.orientation, odometry.twist.twist
        assert (sec, nanosec) == (odometry.header.stamp.sec, odometry.header.stamp.nanosec)
        expected = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
        assert np.array_equal(pose, expected, equal_nan=True)
        assert twist == (t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z)
        stamped = PoseStamped(header=odometry.header, pose=odometry.pose.pose)
        sec, nanosec, pose = pose_stamped_fields(serialize_message(stamped))
        assert (sec, nanosec) == (odometry.header.stamp.sec, odometry.header.stamp.nanosec)
        assert np.array_equal(pose, expected, equal_nan=True)
    good = serialize_message(odometry)
    for cut in (0, 12, len(good) - 1):
        with pytest.raises(MessageError, match='bytes') as caught:
            odometry_fields(good[:cut])
        assert caught.value.reason == 'length'


@pytest.mark.parametrize('frame', ['world', '', 'map_x'])
def test_twist_fields_are_rclpys_field_for_field_and_cut_bytes_are_refused(frame):
    rng = np.random.default_rng(6)
    for k in range(100):
        values = (math.inf, math.nan, *rng.normal(size=4)) if k == 0 else tuple(rng.normal(size=6))
        twist = Twist()
        twist.linear.x, twist.linear.y, twist.linear.z = values[:3]
        twist.angular.x, twist.angular.y, twist.angular.z = values[3:]
        assert np.array_equal(twist_fields(serialize_message(twist)), values, equal_nan=True)
        stamped = TwistStamped(twist=twist)
        stamped.header.frame_id = frame
        stamped.header.stamp.sec, stamped.header.stamp.nanosec = k, 999_999_999 - k
        got_frame, got = twist_stamped_fields(serialize_message(stamped))
        assert got_frame == frame and np.array_equal(got, values, equal_nan=True)
    for message, fields in ((twist, twist_fields), (stamped, twist_stamped_fields)):
        good = serialize_message(message)
        for cut in (0, 3, len(good) - 1):
            with pytest.raises(MessageError, match='bytes') as caught:
                fields(good[:cut])
            assert caught.value.reason == 'length'


@pytest.mark.parametrize('frame', ['world', '', 'map_x', 'odom_frame_of_robot_12'])
def test_packed_velocity_commands_are_the_encoded_messages_bytes_and_refuse_what_they_refuse(frame):
    """An agent's command as CDR bytes: what rclpy serializes for `encode_body_velocity` /
    `encode_world_velocity` (alignment padding aside, zero here, unset by rclpy), read back field
    for field, with the same errors for bad values."""
    rng = np.random.default_rng(len(frame))
    for k in range(200):
        v, omega = (0.0, -0.0) if k == 0 else rng.normal(size=2)
        assert pack_body_velocity(v, omega) == serialize_message(encode_body_velocity(v, omega))
        velocity = tuple(rng.normal(size=1 + k % 3))
        stamp = float(rng.uniform(0, 2e9)) if k else 1_700_000_000.9999999996  # rounds up a second
        packed = pack_world_velocity(velocity, frame_id=frame, stamp=stamp)
        expected = encode_world_velocity(velocity, frame_id=frame, stamp=stamp)
        assert deserialize_message(packed, TwistStamped) == expected
        assert len(packed) == len(serialize_message(expected))
    for bad in ((math.nan, 0.0), (0.0, math.inf)):
        with pytest.raises(MessageError) as expected_error:
            encode_body_velocity(*bad)
        with pytest.raises(MessageError) as caught:
            pack_body_velocity(*bad)
        assert (
            str(caught.value) == str(expected_error.value)
            and caught.value.reason == expected_error.value.reason
        )
    for velocity, stamp in (
        ((0.0, math.nan), 1.0),
        ((), 1.0),
        ((0.0,) * 4, 1.0),
        ((1.0,), -1.0),
        ((1.0,), math.inf),
    ):
        with pytest.raises(MessageError) as expected_error:
            encode_world_velocity(velocity, frame_id=frame, stamp=stamp)
        with pytest.raises(MessageError) as caught:
            pack_world_velocity(velocity, frame_id=frame, stamp=stamp)
        assert str(caught.value) == str(expected_error.value)
