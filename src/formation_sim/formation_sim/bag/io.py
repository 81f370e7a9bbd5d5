"""rosbag2 bags (version 9, MCAP storage, CDR messages) without ROS: write, read, decode.

- `BagWriter`: messages arrive already CDR-serialized (from a raw rclpy subscription, or
  `rclpy.serialization.serialize_message`, or rosbags) and are stored byte for byte.
- `read_bag` and `decode`: reading a bag back, with rosbags' typestore of ROS 2 Jazzy.

Recovering a bag whose recorder died: `formation_sim.bag.recovery`. The recording node:
`formation_sim.runtime.recorder`.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, NamedTuple, Self

from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

BAG_VERSION = 9


class BagError(Exception):
    """A bag could not be written, read or recovered."""


class BagReadError(BagError):
    """A bag that cannot be read: no metadata.yaml (its recorder died), or a damaged or foreign file."""


class UnknownMessageTypeError(BagError, ValueError):
    """A message type is neither in the typestore nor importable."""


class TopicSpecError(BagError, ValueError):
    """A topic name or specification is malformed or inconsistent."""


_JAZZY_TYPESTORE: Typestore | None = None


def jazzy_typestore() -> Typestore:
    """Return the shared rosbags typestore of ROS 2 Jazzy's standard messages."""
    global _JAZZY_TYPESTORE  # noqa: PLW0603 - built once, it takes ~0.1 s
    if _JAZZY_TYPESTORE is None:
        _JAZZY_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY_TYPESTORE



def check_msgtype(msgtype: str) -> None:
    """Raise UnknownMessageTypeError unless `msgtype` reads 'package/msg/Type'."""
    parts = msgtype.split('/')
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):  # noqa: PLR2004
        msg = f"message type {msgtype!r} is not of the form 'package/msg/Type'"
        raise UnknownMessageTypeError(msg)


class BagWriter:
    """Write CDR-serialized messages into a new rosbag2 bag (version 9, MCAP storage).

    Use as a context manager, or call `open` and `close`; `close` writes ``metadata.yaml``.

    >>> with BagWriter('runs/x/bag') as bag:
    ...     bag.add_topic('/formation/step', 'std_msgs/msg/Float64MultiArray')
    ...     bag.write('/formation/step', 0, cdr_bytes)
    """

    def __init__(self, path: Path | str, *, typestore: Typestore | None = None) -> None:
        """Prepare a writer for the bag directory `path`, which must not exist yet.

        Args:
            path: Bag directory to create.
            typestore: Message definitions to store; ROS 2 Jazzy's standard messages if None.

        """
        self.path = Path(path)
        self._typestore = typestore if typestore is not None else jazzy_typestore()
        try:
            self._writer = Writer(
                self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP
            )
        except WriterError as err:
            msg = f'cannot create bag {self.path}: {err} (the recorder never overwrites a bag)'
            raise BagError(msg) from err
        self._connections: dict[str, Connection] = {}
        self._counts: dict[str, int] = {}
        self._is_open = False

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> message type of every topic added so far."""
        return {name: conn.msgtype for name, conn in self._connections.items()}

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(self._counts.values())

    def open(self) -> None:
        """Create the bag directory and its MCAP file."""
        try:
            self._writer.open()
        except WriterError as err:
            msg = f'cannot create bag {self.path}: {err} (the recorder never overwrites a bag)'
            raise BagError(msg) from err
        self._is_open = True

    def set_custom_data(self, key: str, value: str) -> None:
        """Store `key: value` under ``custom_data`` in ``metadata.yaml``."""
        self._writer.set_custom_data(key, value)

    def add_topic(self, name: str, msgtype: str) -> None:
        """Register topic `name` carrying `msgtype` (``package/msg/Type``); repeats are no-ops."""
        self._require_open()
        if not name.startswith('/'):
            msg = f'topic name {name!r} must be absolute (start with "/")'
            raise TopicSpecError(msg)
        check_msgtype(msgtype)
        if (known := self._connections.get(name)) is not None:
            if known.msgtype != msgtype:
                msg = f'topic {name!r} was added with type {known.msgtype!r}, not {msgtype!r}'
                raise TopicSpecError(msg)
            return
        if msgtype not in self._typestore.fielddefs:
            msg = f'message type {msgtype!r} of topic {name!r} is not in the typestore'
            raise UnknownMessageTypeError(msg)
        self._connections[name] = self._writer.add_connection(
            name, msgtype, typestore=self._typestore, serialization_format='cdr'
        )
        self._counts[name] = 0

    def write(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Append one CDR-serialized message of `topic` received at `timestamp_ns`."""
        self._require_open()
        connection = self._connections.get(topic)
        if connection is None:
            msg = f'topic {topic!r} was not added; added topics: {sorted(self._connections)}'
            raise TopicSpecError(msg)
        # rosbag2 timestamps are int64 nanoseconds; a float would silently lose digits.
        if isinstance(timestamp_ns, bool) or not isinstance(timestamp_ns, int):
            msg = f'timestamp of a {topic!r} message must be int nanoseconds, got {timestamp_ns!r}'
            raise BagError(msg)
        if not 0 <= timestamp_ns < 2**63:
            msg = f'timestamp of a {topic!r} message must be in [0, 2**63) ns, got {timestamp_ns}'
            raise BagError(msg)
        self._writer.write(connection, timestamp_ns, bytes(data))
        self._counts[topic] += 1

    def flush(self) -> None:
        """Push every message written so far into the MCAP file.

        rosbags keeps up to 1 MiB of messages in a pending chunk in memory; this closes that
        chunk and flushes the file, so a SIGKILL after it loses none of them (see `reindex`).
        """
        self._require_open()
        storage = self._writer.storage
        # Internals of rosbags' McapWriter (pinned in requirements.txt); checked, not assumed.
        chunk = getattr(storage, 'chunk', None)
        if chunk is None or not (hasattr(storage, 'close_chunk') and hasattr(storage, 'bio')):
            msg = 'this rosbags version has no McapWriter.close_chunk/bio: cannot flush'
            raise BagError(msg)
        if chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()

    def close(self) -> None:
        """Finish the MCAP file and write ``metadata.yaml``."""
        if self._is_open:
            self._is_open = False
            self._writer.close()

    def _require_open(self) -> None:
        if not self._is_open:
            msg = f'bag {self.path} is not open'
            raise BagError(msg)

    def __enter__(self) -> Self:
        """Open the bag."""
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc_val: BaseException | None,
        exc_tb: TracebackType | None,
    ) -> None:
        """Close the bag, also after an error: what was written stays readable."""
        self.close()


class BagMessage(NamedTuple):
    """One message of a bag, as stored."""

    topic: str
    msgtype: str
    timestamp_ns: int
    rawdata: bytes


def read_bag(path: Path | str) -> Iterator[BagMessage]:
    """Yield every message of the bag at `path` in timestamp order (ties: write order).

    Raises BagReadError for a folder without metadata.yaml (what a recorder killed by SIGKILL
    leaves: `formation_sim.bag.recovery.reindex`, `formation recover`, rebuilds it) and for files
    rosbags cannot read.
    """
    path = Path(path)
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        mcap = sorted(p.name for p in path.glob('*.mcap'))
        held = f'it holds {", ".join(mcap)}' if mcap else 'nor any .mcap file'
        raise BagReadError(
            f'{path}: no metadata.yaml ({held}); a recorder that was killed leaves its bag so: '
            f'`formation recover {path}` rebuilds it'
        )
    try:
        with Reader(path) as reader:
            for connection, timestamp, rawdata in reader.messages():
                yield BagMessage(connection.topic, connection.msgtype, timestamp, bytes(rawdata))
    except Exception as error:
        if not type(error).__module__.startswith(('rosbags', 'mcap')) and not isinstance(error, (OSError, struct.error)):
            raise
        raise BagReadError(f'{path}: cannot read the bag: {error}') from None


def decode(rawdata: bytes, msgtype: str, *, typestore: Typestore | None = None) -> Any:  # noqa: ANN401
    """Deserialize CDR `rawdata` of `msgtype` into a rosbags message object."""
    store = typestore if typestore is not None else jazzy_typestore()
    if msgtype not in store.fielddefs:
        msg = f'message type {msgtype!r} is not in the typestore'
        raise UnknownMessageTypeError(msg)
    return store.deserialize_cdr(rawdata, msgtype)
