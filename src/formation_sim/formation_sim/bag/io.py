"""rosbag2 bags (version 9, MCAP storage, CDR messages) without ROS: write, read, decode.

- `BagWriter`: messages arrive already CDR-serialized (from a raw rclpy subscription, or
  `rclpy.serialization.serialize_message`, or rosbags) and are stored byte for byte, in the layout
  rosbag2 Jazzy's MCAP storage plugin writes: one file ``<bag>_0.mcap`` (profile ``ros2``, schemas
  ``ros2msg``), each channel with ``offered_qos_profiles`` (the publishers' QoS, rosbag2's YAML) and
  ``topic_type_hash`` (RIHS01) in its metadata, the bag information both in a ``rosbag2`` metadata
  record and in ``metadata.yaml`` (``ros_distro: jazzy``), so ``ros2 bag play`` offers the recorded
  QoS again (a transient-local topic stays latched for late joiners).
- `read_bag` and `decode`: reading a bag back, with rosbags' typestore of ROS 2 Jazzy.
- `bag_information` and `write_bag_information`: the bag information of a version 9 bag (also
  what `formation_sim.bag.recovery` writes for a recovered bag); `type_hash` the RIHS01 hash of a
  type (REP 2011); `qos_profile_dict` a QoS profile as rosbag2 Jazzy writes it.

Recovering a bag whose recorder died: `formation_sim.bag.recovery`. The recording node:
`formation_sim.runtime.nodes.recorder`.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, BinaryIO, NamedTuple, Self

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from formation_sim.bag.errors import BagError, BagReadError, TopicSpecError, UnknownMessageTypeError
from formation_sim.sim.files import write_atomically

if TYPE_CHECKING:
    from rosbags.interfaces import Qos
    from rosbags.typesys.store import Typestore

BAG_VERSION = 9
ROS_DISTRO = 'jazzy'  # the distribution whose rosbag2 conventions the bags follow
STORAGE = 'mcap'
SERIALIZATION = 'cdr'
METADATA_FILE = 'metadata.yaml'
MCAP_RECORD = 'rosbag2'  # the MCAP metadata record that holds the bag information (rosbag2_storage_mcap)
LIBRARY = 'formation_sim.bag'  # the MCAP header's library


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
    if len(parts) != 3 or parts[1] != 'msg' or not all(parts):
        msg = f"message type {msgtype!r} is not of the form 'package/msg/Type'"
        raise UnknownMessageTypeError(msg)


def type_hash(msgtype: str, *, definition: str | None = None, typestore: Typestore | None = None) -> str:
    """The RIHS01 hash (REP 2011) of `msgtype`, as ROS 2 Jazzy advertises it for a topic.

    From `definition` (a ``ros2msg`` schema as stored in an MCAP file: the type and its
    dependencies) when given, else from `typestore` (ROS 2 Jazzy's by default).
    """
    if definition is not None:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(definition, msgtype))
        return store.hash_rihs01(msgtype)
    return (typestore if typestore is not None else jazzy_typestore()).hash_rihs01(msgtype)


def _duration(time: Any) -> dict[str, int]:
    return {'sec': int(time.sec), 'nsec': int(time.nsec)}


def qos_profile_dict(qos: Qos) -> dict[str, Any]:
    """One offered QoS profile as rosbag2 Jazzy writes it (version 9: policies by name, durations as
    sec/nsec; rosbag2_storage's qos.cpp), keys in its order."""
    return {
        'history': qos.history.name.lower(),
        'depth': int(qos.depth),
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(),
        'deadline': _duration(qos.deadline),
        'lifespan': _duration(qos.lifespan),
        'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': _duration(qos.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions),
    }


def _dump(data: Any) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False, allow_unicode=True)


@dataclass(kw_only=True)
class TopicRecord:
    """A topic of a bag as its metadata describes it."""

    name: str
    msgtype: str
    type_hash: str
    offered_qos_profiles: list[dict[str, Any]] = field(default_factory=list)  # `qos_profile_dict`s
    message_count: int = 0
    serialization_format: str = SERIALIZATION

    def channel_metadata(self) -> dict[str, str]:
        """The MCAP channel's metadata, as rosbag2_storage_mcap writes it."""
        return {'offered_qos_profiles': _dump(self.offered_qos_profiles), 'topic_type_hash': self.type_hash}


def bag_information(
    *,
    relative_path: str,
    topics: Sequence[TopicRecord],
    start_ns: int,
    end_ns: int,
    custom_data: dict[str, str],
) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of a version 9 bag of one MCAP file, keys in rosbag2's order."""
    count = sum(topic.message_count for topic in topics)
    start = start_ns if count else 0
    duration = max(0, end_ns - start_ns) if count else 0
    return {
        'version': BAG_VERSION,
        'storage_identifier': STORAGE,
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': count,
        'topics_with_message_count': [
            {
                'topic_metadata': {
                    'name': topic.name,
                    'type': topic.msgtype,
                    'serialization_format': topic.serialization_format,
                    'offered_qos_profiles': topic.offered_qos_profiles,
                    'type_description_hash': topic.type_hash,
                },
                'message_count': topic.message_count,
            }
            for topic in topics
        ],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [relative_path],
        'files': [
            {
                'path': relative_path,
                'starting_time': {'nanoseconds_since_epoch': start},
                'duration': {'nanoseconds': duration},
                'message_count': count,
            }
        ],
        'custom_data': dict(custom_data),
        'ros_distro': ROS_DISTRO,
    }


def mcap_bag_record(information: dict[str, Any]) -> dict[str, str]:
    """The ``rosbag2`` MCAP metadata record (rosbag2 reads it when metadata.yaml is missing)."""
    return {'serialized_metadata': _dump(information)}


def write_bag_information(bag_dir: Path, information: dict[str, Any]) -> None:
    """Write ``metadata.yaml`` atomically (whole or not at all); OSError names the file."""
    write_atomically(bag_dir / METADATA_FILE, _dump({'rosbag2_bagfile_information': information}))


class BagWriter:
    """Write CDR-serialized messages into a new rosbag2 bag (version 9, MCAP storage).

    Use as a context manager, or call `open` and `close`; `close` writes ``metadata.yaml``.
    A topic's MCAP channel is written with its first message (or at `close`), so its publishers'
    QoS can be given until then (`set_offered_qos`): a recorder learns them once they are found.

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
        if self.path.exists():
            msg = f'cannot create bag {self.path}: it exists already (the recorder never overwrites a bag)'
            raise BagError(msg)
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'  # rosbag2's name for the first file
        self._stream: BinaryIO | None = None
        self._writer: McapWriter | None = None
        self._topics: dict[str, TopicRecord] = {}
        self._channels: dict[str, int] = {}  # topic -> MCAP channel id, once written
        self._schemas: dict[str, int] = {}  # msgtype -> MCAP schema id
        self._custom_data: dict[str, str] = {}
        self._start_ns = 2**63
        self._end_ns = 0
        self._is_open = False

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> message type of every topic added so far."""
        return {name: topic.msgtype for name, topic in self._topics.items()}

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return sum(topic.message_count for topic in self._topics.values())

    def open(self) -> None:
        """Create the bag directory and its MCAP file."""
        try:
            self.path.mkdir(parents=True)
            self._stream = self.mcap_path.open('xb')
        except FileExistsError:
            msg = f'cannot create bag {self.path}: it exists already (the recorder never overwrites a bag)'
            raise BagError(msg) from None
        except OSError as error:
            msg = f'cannot create bag {self.path}: {error}'
            raise BagError(msg) from error
        self._writer = McapWriter(self._stream, compression=CompressionType.NONE)
        self._writer.start(profile='ros2', library=LIBRARY)
        self._is_open = True

    def set_custom_data(self, key: str, value: str) -> None:
        """Store `key: value` under ``custom_data`` in ``metadata.yaml``."""
        if not isinstance(value, str):
            msg = f'custom data {key!r} must be a string, got {value!r}'
            raise BagError(msg)
        self._custom_data[str(key)] = value

    def add_topic(
        self, name: str, msgtype: str, *, offered_qos_profiles: Sequence[Qos] | None = None
    ) -> None:
        """Register topic `name` carrying `msgtype` (``package/msg/Type``); repeats are no-ops.

        `offered_qos_profiles`: its publishers' QoS (one profile per publisher), if known yet.
        """
        self._require_open()
        if not name.startswith('/'):
            msg = f'topic name {name!r} must be absolute (start with "/")'
            raise TopicSpecError(msg)
        check_msgtype(msgtype)
        if (known := self._topics.get(name)) is not None:
            if known.msgtype != msgtype:
                msg = f'topic {name!r} was added with type {known.msgtype!r}, not {msgtype!r}'
                raise TopicSpecError(msg)
            return
        if msgtype not in self._typestore.fielddefs:
            msg = f'message type {msgtype!r} of topic {name!r} is not in the typestore'
            raise UnknownMessageTypeError(msg)
        self._topics[name] = TopicRecord(
            name=name, msgtype=msgtype, type_hash=type_hash(msgtype, typestore=self._typestore)
        )
        if offered_qos_profiles is not None:
            self.set_offered_qos(name, offered_qos_profiles)

    def set_offered_qos(self, name: str, profiles: Sequence[Qos]) -> None:
        """The QoS profiles the publishers of `name` offer; only before its first message (its
        MCAP channel, written then, cannot change)."""
        if name in self._channels:
            msg = f'topic {name!r} already has messages in the bag: its offered QoS can no longer change'
            raise TopicSpecError(msg)
        self._topic(name).offered_qos_profiles = [qos_profile_dict(profile) for profile in profiles]

    def has_channel(self, name: str) -> bool:
        """Whether `name`'s channel (and its offered QoS) is in the file already."""
        return name in self._channels

    def _topic(self, name: str) -> TopicRecord:
        topic = self._topics.get(name)
        if topic is None:
            msg = f'topic {name!r} was not added; added topics: {sorted(self._topics)}'
            raise TopicSpecError(msg)
        return topic

    def _channel(self, topic: TopicRecord) -> int:
        """The MCAP channel of `topic`, written now if it is not yet."""
        if (channel := self._channels.get(topic.name)) is not None:
            return channel
        if (schema := self._schemas.get(topic.msgtype)) is None:
            definition, _ = self._typestore.generate_msgdef(topic.msgtype, ros_version=2)
            schema = self._schemas[topic.msgtype] = self._writer.register_schema(
                name=topic.msgtype, encoding='ros2msg', data=definition.encode()
            )
        channel = self._channels[topic.name] = self._writer.register_channel(
            topic=topic.name,
            message_encoding=topic.serialization_format,
            schema_id=schema,
            metadata=topic.channel_metadata(),
        )
        return channel

    def write(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Append one CDR-serialized message of `topic` received at `timestamp_ns`."""
        self._require_open()
        record = self._topic(topic)
        # rosbag2 timestamps are int64 nanoseconds; a float would silently lose digits.
        if isinstance(timestamp_ns, bool) or not isinstance(timestamp_ns, int):
            msg = f'timestamp of a {topic!r} message must be int nanoseconds, got {timestamp_ns!r}'
            raise BagError(msg)
        if not 0 <= timestamp_ns < 2**63:
            msg = f'timestamp of a {topic!r} message must be in [0, 2**63) ns, got {timestamp_ns}'
            raise BagError(msg)
        channel = self._channel(record)
        # log time = publish time = the recorder's stamp; sequence 0 (unknown), as rosbag2 writes it.
        self._writer.add_message(
            channel_id=channel, log_time=timestamp_ns, data=bytes(data), publish_time=timestamp_ns
        )
        record.message_count += 1
        self._start_ns = min(self._start_ns, timestamp_ns)
        self._end_ns = max(self._end_ns, timestamp_ns)

    def flush(self) -> None:
        """Push every message written so far into the MCAP file (the chunk in progress closed),
        so a SIGKILL after it loses none of them (see `formation_sim.bag.recovery.reindex`)."""
        self._require_open()
        self._writer.flush()

    def information(self) -> dict[str, Any]:
        """The bag information ``metadata.yaml`` holds (as of now)."""
        return bag_information(
            relative_path=self.mcap_path.name,
            topics=list(self._topics.values()),
            start_ns=self._start_ns,
            end_ns=self._end_ns,
            custom_data=self._custom_data,
        )

    def close(self) -> None:
        """Finish the MCAP file (every topic's channel, the summary) and write ``metadata.yaml``."""
        if not self._is_open:
            return
        self._is_open = False
        try:
            for topic in self._topics.values():
                self._channel(topic)  # topics without messages are in the bag too
            information = self.information()
            self._writer.add_metadata(MCAP_RECORD, mcap_bag_record(information))
            self._writer.finish()
        finally:
            self._stream.close()
        write_bag_information(self.path, information)

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
    from rosbags.rosbag2 import Reader  # here: its import (~45 ms of CPU) is not the recorder's to pay

    path = Path(path)
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        mcap = sorted(p.name for p in path.glob('*.mcap'))
        held = f'it holds {", ".join(mcap)}' if mcap else 'nor any .mcap file'
        raise BagReadError(
            f'{path}: no metadata.yaml ({held}); a recorder that was killed leaves its bag so: '
            f'`formation recover {path}` rebuilds it'
        )
    if path.is_dir():
        check_bag_information(path)
    try:
        with Reader(path) as reader:
            for connection, timestamp, rawdata in reader.messages():
                yield BagMessage(connection.topic, connection.msgtype, timestamp, bytes(rawdata))
    except Exception as error:
        if not type(error).__module__.startswith(('rosbags', 'mcap')) and not isinstance(
            error, (OSError, struct.error, KeyError, TypeError, ValueError, IndexError)
        ):
            raise
        raise BagReadError(damaged_bag_message(path, error)) from None


def check_bag_information(path: Path) -> None:
    """BagReadError in words when the bag folder `path`'s metadata.yaml is empty or not a rosbag2
    bag's information (a missing one is the reader's to name)."""
    metadata = Path(path) / METADATA_FILE
    if not metadata.is_file():
        return
    remedy = (
        f'`formation recover {path}` rebuilds it from the MCAP file (the old one kept as '
        'metadata.yaml.damaged)'
    )
    try:
        information = yaml.safe_load(metadata.read_text(encoding='utf-8', errors='replace'))
    except yaml.YAMLError as error:
        raise BagReadError(f'{metadata}: not YAML ({str(error).splitlines()[0]}); {remedy}') from None
    if information is None:
        raise BagReadError(f'{metadata} is empty (its writer was cut short?); {remedy}')
    if not isinstance(information, dict) or not isinstance(
        information.get('rosbag2_bagfile_information'), dict
    ):
        raise BagReadError(f'{metadata} holds no rosbag2_bagfile_information; {remedy}')


def damaged_bag_message(path: Path, error: BaseException) -> str:
    """What is wrong with the bag at `path` that its reader refused with `error`, in words, and
    what to do (issue 28: the readers' own words were 'File end magic is invalid.', 'Chunk
    checksum mismatch.')."""
    text = str(error) or type(error).__name__
    lowered = text.lower()
    recover = (
        f'`formation recover {path}` keeps every intact chunk, says what it dropped and rebuilds the bag'
    )
    if 'checksum' in lowered or 'crc' in lowered:
        return (
            f'{path}: a chunk of its MCAP file is damaged (its checksum does not match what was written: '
            f'bytes changed on disk or in a copy; the reader said {text!r}); {recover}'
        )
    if 'magic' in lowered and 'end magic' not in lowered:
        return (
            f'{path}: its MCAP file is not an MCAP file (its first bytes are not the MCAP magic; the reader '
            f'said {text!r}): a file of something else, or damaged from its start; {recover}'
        )
    if 'magic' in lowered or 'unexpected end' in lowered or isinstance(error, (EOFError, struct.error)):
        return (
            f'{path}: its MCAP file is cut short or its end is damaged (the reader said {text!r}): a copy or '
            f'a disk that stopped midway, or a recorder killed; {recover}'
        )
    return (
        f'{path}: cannot read the bag ({type(error).__name__}: {text}): its files are damaged or not a '
        f'rosbag2 MCAP bag; {recover}'
    )


def decode(rawdata: bytes, msgtype: str, *, typestore: Typestore | None = None) -> Any:
    """Deserialize CDR `rawdata` of `msgtype` into a rosbags message object."""
    store = typestore if typestore is not None else jazzy_typestore()
    if msgtype not in store.fielddefs:
        msg = f'message type {msgtype!r} is not in the typestore'
        raise UnknownMessageTypeError(msg)
    return store.deserialize_cdr(rawdata, msgtype)
