"""The errors of rosbag2 reading, writing and recovery. Each is a `FormationError`."""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class BagError(FormationError):
    """A bag could not be written, read or recovered."""


class BagReadError(BagError):
    """A bag that cannot be read: no metadata.yaml (its recorder died), or a damaged or foreign file."""


class UnknownMessageTypeError(BagError, ValueError):
    """A message type is neither in the typestore nor importable."""


class TopicSpecError(BagError, ValueError):
    """A topic name or specification is malformed or inconsistent."""


class BagRecoveryError(BagError):
    """`reindex` found nothing it could turn into a readable bag."""
