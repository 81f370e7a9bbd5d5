"""Robot poses as serialized CDR bytes, without rclpy's Python messages (issue 19).

A robot publishes its odometry at 100 Hz and an agent reads its own at 50 Hz: building and
converting `nav_msgs/Odometry` Python objects (a header, four nested structures, two arrays of 36
doubles) was most of what both spent per message.  Publishers take serialized bytes as they are
(`Publisher.publish(bytes)`), raw subscriptions hand them over, and this module writes and reads
the two pose types with `struct`:

- `OdometryWriter`: one robot's `nav_msgs/Odometry` (frames and covariances fixed, packed once),
  `pack_pose_stamped`: a `geometry_msgs/PoseStamped`;
- `pack_body_velocity`, `pack_world_velocity`: an agent's velocity command to its robot (50 Hz),
  `codec.encode_body_velocity` / `encode_world_velocity` as bytes, with their checks;
- `decode_odometry_cdr`, `decode_pose_stamped_cdr`: bytes -> `RobotPose`, with the checks of
  `codec.decode_odometry` / `codec.decode_pose_stamped` (finite values, a unit quaternion);
  bytes that are not such a message raise `MessageError` (reason `length`).
- `odometry_fields`, `pose_stamped_fields`, `twist_fields`, `twist_stamped_fields`: the fields
  as sent, unchecked (the coordinator's poses, a simulated robot's velocity commands).

The layout is ROS 2's: a 4-byte encapsulation header (CDR little endian: 00 01 00 00), then the
fields in order, each aligned to its size from the end of that header; a string is a uint32
length counting its terminating NUL, its bytes and the NUL.  `tests/formation_msgs_py/test_cdr.py`
holds both directions to rclpy's own serialization (every field; rclpy leaves the alignment
padding unset, this module writes zeros).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

from formation_msgs_py.codec import nanoseconds, pose_values, twist_values, vector3_values
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import REJECT_LENGTH
from formation_msgs_py.types import RobotPose

ENCAPSULATION = b'\x00\x01\x00\x00'  # CDR, little endian
_HEADER = 4
_STAMP = struct.Struct('<iI')
_LENGTH = struct.Struct('<I')
_POSE = struct.Struct('<7d')  # position x y z, orientation x y z w
_TWIST = struct.Struct('<6d')  # linear x y z, angular x y z
_COVARIANCE = struct.Struct('<36d')


def _string(text: str, offset: int) -> tuple[bytes, int]:
    """A CDR string at `offset` (from the end of the encapsulation header), aligned to 4."""
    pad = -offset % 4
    data = text.encode() + b'\x00'
    out = b'\x00' * pad + _LENGTH.pack(len(data)) + data
    return out, offset + len(out)


def _read_string(data: bytes, offset: int, what: str) -> tuple[str, int]:
    offset += -(offset - _HEADER) % 4
    if offset + _LENGTH.size > len(data):  # no room for the string's length
        raise MessageError(
            f'{what}: a string at byte {offset} does not fit a message of {len(data)} bytes',
            reason=REJECT_LENGTH,
        )
    (length,) = _LENGTH.unpack_from(data, offset)
    end = offset + 4 + length
    if length < 1 or end > len(data) or data[end - 1] != 0:
        raise MessageError(
            f'{what}: a string of {length} bytes does not fit a message of {len(data)} bytes',
            reason=REJECT_LENGTH,
        )
    return data[offset + 4 : end - 1].decode(errors='replace'), end


def _align8(offset: int) -> int:
    return offset + (-(offset - _HEADER) % 8)


class OdometryWriter:
    """A robot's `nav_msgs/Odometry` as CDR bytes: its frames and covariance packed once, the
    stamp, pose and twist at every call."""

    def __init__(self, *, frame: str, child_frame: str, sigma: tuple[float, float]) -> None:
        strings, end = _string(frame, _STAMP.size)
        child, end = _string(child_frame, end)
        self._strings = strings + child + b'\x00' * (-end % 8)
        covariance = [0.0] * 36
        for k in range(3):
            covariance[7 * k] = sigma[0] ** 2
        covariance[35] = sigma[1] ** 2
        self._pose_covariance = _COVARIANCE.pack(*covariance)
        self._twist_covariance = _COVARIANCE.pack(*[0.0] * 36)

    def pack(
        self,
        stamp: float,
        position: Sequence[float],
        orientation: Sequence[float],
        linear: Sequence[float],
        angular_z: float,
    ) -> bytes:
        """Unix time `stamp`, the pose (position x y z, quaternion x y z w), the body twist (linear
        x y z, angular z)."""
        seconds = math.floor(stamp)
        nanoseconds = min(999_999_999, round((stamp - seconds) * 1e9))
        return b''.join(
            (
                ENCAPSULATION,
                _STAMP.pack(int(seconds), nanoseconds),
                self._strings,
                _POSE.pack(*position, *orientation),
                self._pose_covariance,
                _TWIST.pack(*linear, 0.0, 0.0, angular_z),
                self._twist_covariance,
            )
        )


def pack_pose_stamped(
    stamp: float, frame: str, position: Sequence[float], orientation: Sequence[float]
) -> bytes:
    """A `geometry_msgs/PoseStamped` as CDR bytes (Unix time `stamp`)."""
    seconds = math.floor(stamp)
    nanoseconds = min(999_999_999, round((stamp - seconds) * 1e9))
    strings, end = _string(frame, _STAMP.size)
    return b''.join(
        (
            ENCAPSULATION,
            _STAMP.pack(int(seconds), nanoseconds),
            strings,
            b'\x00' * (-end % 8),
            _POSE.pack(*position, *orientation),
        )
    )


def pack_body_velocity(linear: float, angular: float) -> bytes:
    """`codec.encode_body_velocity` as CDR bytes: a `geometry_msgs/Twist` in the body frame
    (linear.x = v, angular.z = ω), both checked finite."""
    (v, omega), _ = vector3_values('body velocity', (linear, angular))
    return ENCAPSULATION + _TWIST.pack(v, 0.0, 0.0, 0.0, 0.0, omega)


def pack_world_velocity(velocity: Sequence[float], *, frame_id: str, stamp: float) -> bytes:
    """`codec.encode_world_velocity` as CDR bytes: a `geometry_msgs/TwistStamped` whose linear
    is `velocity` (1 to 3 components, checked finite) in the frame `frame_id`, stamped at Unix
    time `stamp` (rounded to the nanosecond as `codec.ros_time`)."""
    seconds, nano = divmod(nanoseconds(stamp), 1_000_000_000)  # checked first, as the message's
    _, linear = vector3_values('world velocity', velocity)
    strings, end = _string(frame_id, _STAMP.size)
    return b''.join(
        (
            ENCAPSULATION,
            _STAMP.pack(seconds, nano),
            strings,
            b'\x00' * (-end % 8),
            _TWIST.pack(*linear, 0.0, 0.0, 0.0),
        )
    )


def _header(data: bytes, what: str) -> tuple[float, str, int]:
    sec, nanosec, frame, end = _stamp_and_frame(data, what)
    return sec + nanosec * 1e-9, frame, end


def _stamp_and_frame(data: bytes, what: str) -> tuple[int, int, str, int]:
    if len(data) < _HEADER + _STAMP.size + 4 or data[:2] != ENCAPSULATION[:2]:
        raise MessageError(
            f'{what}: {len(data)} bytes are not a little-endian CDR message', reason=REJECT_LENGTH
        )
    sec, nanosec = _STAMP.unpack_from(data, _HEADER)
    frame, end = _read_string(data, _HEADER + _STAMP.size, what)
    return sec, nanosec, frame, end


def _need(data: bytes, end: int, what: str) -> None:
    if end > len(data):
        raise MessageError(f'{what}: {len(data)} bytes, its layout needs {end}', reason=REJECT_LENGTH)


def decode_odometry_cdr(data: bytes) -> RobotPose:
    """Serialized nav_msgs/Odometry -> RobotPose with the body-frame twist (REP 105)."""
    stamp, frame, end = _header(data, 'odometry')
    _, end = _read_string(data, end, 'odometry child_frame_id')
    pose_at = _align8(end)
    twist_at = pose_at + _POSE.size + _COVARIANCE.size
    _need(data, twist_at + _TWIST.size + _COVARIANCE.size, 'odometry')
    values = _POSE.unpack_from(data, pose_at)
    position, orientation = pose_values('odometry pose', values[:3], values[3:])
    twist = _TWIST.unpack_from(data, twist_at)
    linear, angular = twist_values(twist[:3], twist[3:])
    return RobotPose(
        stamp=stamp, frame=frame, position=position, orientation=orientation, linear=linear, angular=angular
    )


def decode_pose_stamped_cdr(data: bytes) -> RobotPose:
    """Serialized geometry_msgs/PoseStamped -> RobotPose (no twist)."""
    stamp, frame, end = _header(data, 'pose')
    pose_at = _align8(end)
    _need(data, pose_at + _POSE.size, 'pose')
    values = _POSE.unpack_from(data, pose_at)
    position, orientation = pose_values('pose', values[:3], values[3:])
    return RobotPose(stamp=stamp, frame=frame, position=position, orientation=orientation)


def odometry_fields(data: bytes) -> tuple[int, int, tuple[float, ...], tuple[float, ...]]:
    """Serialized nav_msgs/Odometry -> (stamp sec, stamp nanosec, pose: position x y z and
    orientation x y z w, twist: linear x y z and angular x y z), the values as sent, unchecked:
    what a reader of the bag gets from the same message, field for field."""
    sec, nanosec, _, end = _stamp_and_frame(data, 'odometry')
    _, end = _read_string(data, end, 'odometry child_frame_id')
    pose_at = _align8(end)
    twist_at = pose_at + _POSE.size + _COVARIANCE.size
    _need(data, twist_at + _TWIST.size + _COVARIANCE.size, 'odometry')
    return sec, nanosec, _POSE.unpack_from(data, pose_at), _TWIST.unpack_from(data, twist_at)


def pose_stamped_fields(data: bytes) -> tuple[int, int, tuple[float, ...]]:
    """Serialized geometry_msgs/PoseStamped -> (stamp sec, stamp nanosec, pose: position x y z
    and orientation x y z w), the values as sent, unchecked."""
    sec, nanosec, _, end = _stamp_and_frame(data, 'pose')
    pose_at = _align8(end)
    _need(data, pose_at + _POSE.size, 'pose')
    return sec, nanosec, _POSE.unpack_from(data, pose_at)


def twist_fields(data: bytes) -> tuple[float, ...]:
    """Serialized geometry_msgs/Twist -> (linear x y z, angular x y z), as sent, unchecked: a
    unicycle's velocity command, taken by a simulated robot without rclpy's Python message."""
    if len(data) < _HEADER or data[:2] != ENCAPSULATION[:2]:
        raise MessageError(
            f'twist: {len(data)} bytes are not a little-endian CDR message', reason=REJECT_LENGTH
        )
    _need(data, _HEADER + _TWIST.size, 'twist')
    return _TWIST.unpack_from(data, _HEADER)


def twist_stamped_fields(data: bytes) -> tuple[str, tuple[float, ...]]:
    """Serialized geometry_msgs/TwistStamped -> (frame_id, (linear x y z, angular x y z)), as
    sent, unchecked: a holonomic robot's velocity command."""
    _, _, frame, end = _stamp_and_frame(data, 'twist')
    twist_at = _align8(end)
    _need(data, twist_at + _TWIST.size, 'twist')
    return frame, _TWIST.unpack_from(data, twist_at)
