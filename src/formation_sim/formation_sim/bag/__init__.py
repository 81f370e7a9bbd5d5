"""rosbag2 bags (version 9, MCAP storage, CDR), ROS-free: `io` writes, reads and decodes;
`recovery` rebuilds a bag whose recorder died."""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'io': ('BagMessage', 'BagWriter', 'decode', 'jazzy_typestore', 'read_bag'),
        'recovery': ('Recovery', 'reindex'),
        'errors': ('BagError', 'BagReadError', 'BagRecoveryError', 'UnknownMessageTypeError'),
    },
)
