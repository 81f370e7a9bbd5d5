"""Recording formation runs as rosbag2 bags (version 9, MCAP storage, CDR messages).

Three layers:

- `BagWriter`: a ROS-free writer over rosbags. Messages arrive already CDR-serialized (for example
  from a raw rclpy subscription, or `rclpy.serialization.serialize_message`) and are stored
  byte for byte.
- `RecorderNode` and `main()` (the `formation_recorder` command): an rclpy node that subscribes
  raw to a list of topics (and optionally to every topic under a prefix) and writes each message
  as it arrives, stamped with the latest simulation time seen on the clock topic.
- `read_bag`, `decode` and `reindex`: reading a bag back, and recovering one whose recorder died.

What survives the end of a recorder:

- SIGINT or SIGTERM: `main()` stops its timers and drains: it keeps taking messages until none
  has come for ``drain_quiet`` seconds (messages still in flight from loaded publishers arrive
  late), for at most ``drain_limit`` seconds, or until a second signal. Then it closes the MCAP
  file (summary, footer) and writes ``metadata.yaml``: a complete bag.
- SIGKILL (or a crash of the interpreter): nothing is finalized. The bag directory holds an MCAP
  file without summary and footer, and no ``metadata.yaml``; rosbags and ros2 bag refuse it.
  The file holds every message up to the last `BagWriter.flush` (the node flushes every
  ``flush_period`` seconds); messages after it were still in memory and are lost.
  `reindex(bag_dir)` rebuilds a readable bag from what is in the file.
"""

from __future__ import annotations

import importlib
import math
import signal
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType, TracebackType
from typing import TYPE_CHECKING, Any, NamedTuple, Self

import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapFileWriter
from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from formation_msgs_py.topics import STEP_TOPIC

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Typestore

    from rclpy.executors import Executor
    from rclpy.node import Node
else:
    try:  # The node needs rclpy; BagWriter, read_bag and reindex do not.
        from rclpy.node import Node
    except ImportError:  # pragma: no cover - exercised only without ROS

        class Node:
            def __init__(self, *args: object, **kwargs: object) -> None:
                msg = 'RecorderNode needs rclpy, which is not importable here'
                raise ImportError(msg)

BAG_VERSION = 9
DEFAULT_CLOCK_TOPIC = STEP_TOPIC
# /formation/step carries std_msgs/Float64MultiArray data = [version, step_index, time].
_STEP_TIME_INDEX = 2
_NS_PER_S = 1_000_000_000


class RecorderError(Exception):
    """A bag could not be written, read or recovered."""


class TopicSpecError(RecorderError, ValueError):
    """A topic given to the recorder is malformed or inconsistent."""


class UnknownMessageTypeError(RecorderError, ValueError):
    """A message type is neither in the typestore nor importable."""


class RecorderConfigError(RecorderError, ValueError):
    """A recorder parameter is missing or out of range."""


class BagRecoveryError(RecorderError):
    """`reindex` found nothing it could turn into a readable bag."""


_JAZZY_TYPESTORE: Typestore | None = None


def jazzy_typestore() -> Typestore:
    """Return the shared rosbags typestore of ROS 2 Jazzy's standard messages."""
    global _JAZZY_TYPESTORE  # noqa: PLW0603 - built once, it takes ~0.1 s
    if _JAZZY_TYPESTORE is None:
        _JAZZY_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY_TYPESTORE


def _check_msgtype(msgtype: str) -> None:
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
            raise RecorderError(msg) from err
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
            raise RecorderError(msg) from err
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
        _check_msgtype(msgtype)
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
            raise RecorderError(msg)
        if not 0 <= timestamp_ns < 2**63:
            msg = f'timestamp of a {topic!r} message must be in [0, 2**63) ns, got {timestamp_ns}'
            raise RecorderError(msg)
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
            raise RecorderError(msg)
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
            raise RecorderError(msg)

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
    """Yield every message of the bag at `path` in timestamp order (ties: write order)."""
    with Reader(Path(path)) as reader:
        for connection, timestamp, rawdata in reader.messages():
            yield BagMessage(connection.topic, connection.msgtype, timestamp, bytes(rawdata))


def decode(rawdata: bytes, msgtype: str, *, typestore: Typestore | None = None) -> Any:  # noqa: ANN401
    """Deserialize CDR `rawdata` of `msgtype` into a rosbags message object."""
    store = typestore if typestore is not None else jazzy_typestore()
    if msgtype not in store.fielddefs:
        msg = f'message type {msgtype!r} is not in the typestore'
        raise UnknownMessageTypeError(msg)
    return store.deserialize_cdr(rawdata, msgtype)


# ---------------------------------------------------------------------------------------------
# Recovery


@dataclass(frozen=True, kw_only=True)
class Recovery:
    """What `reindex` found and did."""

    mcap_path: Path
    message_counts: dict[str, int]  # topic -> messages recovered
    rewritten: bool  # False: the MCAP file was complete and is kept as it is
    damaged_copy: Path | None  # the original, truncated file, when rewritten

    @property
    def message_count(self) -> int:
        """Messages recovered in all."""
        return sum(self.message_counts.values())


@dataclass
class _Salvage:
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    messages: list[Message]
    complete: bool  # the footer was reached


def _salvage(mcap_path: Path) -> _Salvage:
    """Read every record up to the end of the file or the first damaged one."""
    salvage = _Salvage(schemas={}, channels={}, messages=[], complete=False)
    with mcap_path.open('rb') as stream:
        try:
            # A chunk is parsed whole before its records are yielded: a chunk cut by the kill
            # raises here and contributes nothing, every earlier chunk is kept.
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Schema):
                    salvage.schemas[record.id] = record
                elif isinstance(record, Channel):
                    salvage.channels[record.id] = record
                elif isinstance(record, Message):
                    salvage.messages.append(record)
                elif isinstance(record, Footer):
                    salvage.complete = True
        except (McapError, ValueError, EOFError, OSError, struct.error):
            salvage.complete = False
    return salvage


def _type_hash(schema: Schema) -> str:
    """RIHS01 hash of the type, computed from the definition stored in the MCAP schema."""
    if schema.encoding != 'ros2msg':
        return ''
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(schema.data.decode(), schema.name))
    return store.hash_rihs01(schema.name)


def _qos_profiles(channel: Channel) -> list[dict[str, Any]]:
    text = channel.metadata.get('offered_qos_profiles', '')
    profiles = yaml.safe_load(text) if text else []
    return profiles if isinstance(profiles, list) else []


def _bag_metadata(
    salvage: _Salvage, relative_path: str, counts: dict[int, int]
) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` of a version 9 bag holding `salvage`."""
    times = [m.log_time for m in salvage.messages]
    start = min(times) if times else 0
    duration = max(times) - start if times else 0
    total = len(salvage.messages)
    topics = []
    for channel_id, channel in sorted(salvage.channels.items()):
        schema = salvage.schemas[channel.schema_id]
        topics.append({
            'topic_metadata': {
                'name': channel.topic,
                'type': schema.name,
                'serialization_format': channel.message_encoding,
                'offered_qos_profiles': _qos_profiles(channel),
                'type_description_hash': _type_hash(schema),
            },
            'message_count': counts.get(channel_id, 0),
        })
    return {
        'version': BAG_VERSION,
        'storage_identifier': 'mcap',
        'relative_file_paths': [relative_path],
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': total,
        'topics_with_message_count': topics,
        'compression_format': '',
        'compression_mode': '',
        'files': [{
            'path': relative_path,
            'starting_time': {'nanoseconds_since_epoch': start},
            'duration': {'nanoseconds': duration},
            'message_count': total,
        }],
        'custom_data': {'recovered_by': 'formation_sim.recorder.reindex'},
        'ros_distro': 'rosbags',
    }


def _rewrite(salvage: _Salvage, target: Path, information: dict[str, Any]) -> None:
    """Write the salvaged records as a complete MCAP file (ros2 profile, uncompressed)."""
    with target.open('xb') as stream:
        writer = McapFileWriter(stream, compression=CompressionType.NONE)
        writer.start(profile='ros2', library='formation_sim.recorder.reindex')
        schema_ids = {
            old: writer.register_schema(name=s.name, encoding=s.encoding, data=s.data)
            for old, s in sorted(salvage.schemas.items())
        }
        channel_ids = {
            old: writer.register_channel(
                topic=c.topic,
                message_encoding=c.message_encoding,
                schema_id=schema_ids[c.schema_id],
                metadata=dict(c.metadata),
            )
            for old, c in sorted(salvage.channels.items())
        }
        for message in salvage.messages:
            writer.add_message(
                channel_id=channel_ids[message.channel_id],
                log_time=message.log_time,
                data=message.data,
                publish_time=message.publish_time,
                sequence=message.sequence,
            )
        # rosbag2 itself reads the bag information from here when metadata.yaml is missing.
        writer.add_metadata('rosbag2', {'serialized_metadata': yaml.safe_dump(information)})
        writer.finish()


def reindex(bag_dir: Path | str) -> Recovery:
    """Rebuild ``metadata.yaml`` (and if needed the MCAP file) of a bag whose recorder died.

    Every message in a complete MCAP chunk is kept; a chunk cut short by the kill is dropped. A
    truncated MCAP file is rewritten complete, and the original kept beside it as
    ``<name>.mcap.damaged``. Any existing ``metadata.yaml`` is replaced.

    Raises:
        BagRecoveryError: `bag_dir` holds no single MCAP file, or no message-bearing record
            survived in it.

    """
    bag_dir = Path(bag_dir)
    candidates = sorted(bag_dir.glob('*.mcap'))
    if len(candidates) != 1:
        msg = f'{bag_dir}: expected exactly one .mcap file, found {[p.name for p in candidates]}'
        raise BagRecoveryError(msg)
    mcap_path = candidates[0]

    salvage = _salvage(mcap_path)
    if missing := {c.schema_id for c in salvage.channels.values()} - set(salvage.schemas):
        msg = f'{mcap_path}: channels refer to schemas {sorted(missing)} that are not in the file'
        raise BagRecoveryError(msg)
    if not salvage.channels:
        size = mcap_path.stat().st_size
        msg = f'{mcap_path}: no complete MCAP chunk in its {size} bytes; nothing to recover'
        raise BagRecoveryError(msg)
    salvage.messages = [m for m in salvage.messages if m.channel_id in salvage.channels]

    counts: dict[int, int] = dict.fromkeys(salvage.channels, 0)
    for message in salvage.messages:
        counts[message.channel_id] += 1
    information = _bag_metadata(salvage, mcap_path.name, counts)

    damaged_copy = None
    if not salvage.complete:
        damaged_copy = mcap_path.with_name(f'{mcap_path.name}.damaged')
        recovered = mcap_path.with_name(f'{mcap_path.name}.recovering')
        recovered.unlink(missing_ok=True)
        _rewrite(salvage, recovered, information)
        mcap_path.replace(damaged_copy)
        recovered.replace(mcap_path)

    metadata_path = bag_dir / 'metadata.yaml'
    staging = bag_dir / 'metadata.yaml.tmp'
    staging.write_text(yaml.safe_dump({'rosbag2_bagfile_information': information}), 'utf8')
    staging.replace(metadata_path)

    return Recovery(
        mcap_path=mcap_path,
        message_counts={salvage.channels[cid].topic: n for cid, n in counts.items()},
        rewritten=not salvage.complete,
        damaged_copy=damaged_copy,
    )


# ---------------------------------------------------------------------------------------------
# ROS node


def parse_topic_spec(spec: str) -> tuple[str, str]:
    """Split ``'/name:package/msg/Type'`` into name and type."""
    name, sep, msgtype = spec.partition(':')
    if not sep or not name or not msgtype:
        msg = f"topic spec {spec!r} is not of the form '/name:package/msg/Type'"
        raise TopicSpecError(msg)
    if not name.startswith('/'):
        msg = f'topic spec {spec!r}: the name must be absolute (start with "/")'
        raise TopicSpecError(msg)
    _check_msgtype(msgtype)
    return name, msgtype


def import_message_class(msgtype: str) -> type:
    """Return the rclpy message class of ``package/msg/Type``."""
    _check_msgtype(msgtype)
    package, _, type_name = msgtype.split('/')
    try:
        module = importlib.import_module(f'{package}.msg')
        return getattr(module, type_name)
    except (ImportError, AttributeError) as err:
        msg = f'message type {msgtype!r} cannot be imported: {err}'
        raise UnknownMessageTypeError(msg) from err


class RecorderNode(Node):
    """Record topics into a bag, stamping messages with the simulation time.

    Parameters (each overridable with ``--ros-args -p name:=value``):

    - ``output`` (string, required): bag directory to create.
    - ``topics`` (string array): ``'/name:package/msg/Type'`` entries recorded from the start.
    - ``prefix`` (string): also record every topic whose name starts with it, found by polling
      the graph every ``discovery_period`` s ('' = off). Messages published before a topic is
      found are not recorded.
    - ``clock_topic`` (string): std_msgs/Float64MultiArray ``[version, step_index, time]``
      topic. Each message is stamped with the latest ``time`` seen there (0 before the first
      step), so bag order follows the simulation. '' stamps with the node's clock instead.
    - ``flush_period`` (double, s): how often written messages are pushed to the file, which
      bounds what a SIGKILL loses.
    - ``drain_quiet`` (double, s): on stopping, `drain` takes messages until none came for this
      long.
    - ``drain_limit`` (double, s): `drain` ends after this long even if messages keep coming.
    """

    def __init__(
        self,
        *,
        output: Path | str = '',
        topics: Sequence[str] = (),
        prefix: str = '',
        clock_topic: str = DEFAULT_CLOCK_TOPIC,
        discovery_period: float = 1.0,
        flush_period: float = 0.5,
        drain_quiet: float = 0.5,
        drain_limit: float = 10.0,
        node_name: str = 'formation_recorder',
    ) -> None:
        """Declare the parameters (the arguments are their defaults) and open the bag."""
        from rclpy.parameter import Parameter
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        super().__init__(node_name)
        output = str(self.declare_parameter('output', str(output)).value)
        specs = self.declare_parameter(
            'topics', list(topics) if topics else Parameter.Type.STRING_ARRAY
        ).value
        self._prefix = str(self.declare_parameter('prefix', prefix).value)
        self._clock_topic = str(self.declare_parameter('clock_topic', clock_topic).value)
        discovery_period = float(
            self.declare_parameter('discovery_period', float(discovery_period)).value
        )
        flush_period = float(self.declare_parameter('flush_period', float(flush_period)).value)
        self._drain_quiet = float(self.declare_parameter('drain_quiet', float(drain_quiet)).value)
        self._drain_limit = float(self.declare_parameter('drain_limit', float(drain_limit)).value)

        if not output:
            msg = "parameter 'output' is required: the bag directory to create"
            raise RecorderConfigError(msg)
        for name, period in (
            ('discovery_period', discovery_period),
            ('flush_period', flush_period),
            ('drain_quiet', self._drain_quiet),
            ('drain_limit', self._drain_limit),
        ):
            if not (math.isfinite(period) and period > 0):
                msg = f'parameter {name!r} must be a positive number of seconds, got {period}'
                raise RecorderConfigError(msg)
        requested = [parse_topic_spec(spec) for spec in (specs or [])]
        names = [name for name, _ in requested]
        if duplicates := sorted({n for n in names if names.count(n) > 1}):
            msg = f"parameter 'topics' names {duplicates} more than once"
            raise TopicSpecError(msg)

        self._qos = QoSProfile(
            history=HistoryPolicy.KEEP_ALL, depth=1000, reliability=ReliabilityPolicy.RELIABLE
        )
        self._sim_time_ns: int | None = None
        self.received_count = 0  # messages taken from all subscriptions, recorded or not
        self._bad_clock_warned = False
        self._subscriptions_by_topic: dict[str, Any] = {}
        self._skipped: set[str] = set()

        self.bag = BagWriter(output)
        self.bag.open()
        self.bag.set_custom_data(
            'formation_timestamps',
            f'simulation time of {self._clock_topic}' if self._clock_topic else 'node clock',
        )
        try:
            for name, msgtype in requested:
                self._record(name, msgtype)
            if self._clock_topic and self._clock_topic not in self._subscriptions_by_topic:
                self._listen(self._clock_topic, 'std_msgs/msg/Float64MultiArray', record=False)
        except BaseException:
            self.bag.close()
            raise

        self._timers = [self.create_timer(flush_period, self.bag.flush)]
        if self._prefix:
            self._timers.append(self.create_timer(discovery_period, self.discover))
            self.discover()
        self.get_logger().info(
            f'recording {sorted(self.bag.topics)} (prefix {self._prefix!r}) into {output}'
        )

    @property
    def message_count(self) -> int:
        """Messages written to the bag so far."""
        return self.bag.message_count

    def discover(self) -> None:
        """Subscribe to every not yet recorded topic under the prefix."""
        for name, types in self.get_topic_names_and_types():
            if not name.startswith(self._prefix) or name in self.bag.topics or name in self._skipped:
                continue
            if len(types) != 1:
                self.get_logger().warning(f'{name} has types {types}; recording it as {types[0]}')
            try:
                self._record(name, types[0])
            except UnknownMessageTypeError as err:
                self._skipped.add(name)
                self.get_logger().warning(f'not recording {name}: {err}')

    def _record(self, name: str, msgtype: str) -> None:
        self.bag.add_topic(name, msgtype)
        if name in self._subscriptions_by_topic:  # the clock topic, so far listened to only
            self.destroy_subscription(self._subscriptions_by_topic.pop(name))
        self._listen(name, msgtype, record=True)

    def _listen(self, name: str, msgtype: str, *, record: bool) -> None:
        message_class = import_message_class(msgtype)
        is_clock = name == self._clock_topic
        if is_clock and msgtype != 'std_msgs/msg/Float64MultiArray':
            msg = f'clock topic {name!r} must carry std_msgs/msg/Float64MultiArray, not {msgtype!r}'
            raise TopicSpecError(msg)

        def on_message(rawdata: bytes) -> None:
            self.received_count += 1
            if is_clock:
                self._on_step(rawdata)
            if record:
                self.bag.write(name, self._timestamp_ns(), rawdata)

        self._subscriptions_by_topic[name] = self.create_subscription(
            message_class, name, on_message, self._qos, raw=True
        )

    def _on_step(self, rawdata: bytes) -> None:
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import Float64MultiArray

        data = deserialize_message(rawdata, Float64MultiArray).data
        if len(data) > _STEP_TIME_INDEX and math.isfinite(data[_STEP_TIME_INDEX]) and (
            data[_STEP_TIME_INDEX] >= 0
        ):
            self._sim_time_ns = round(data[_STEP_TIME_INDEX] * _NS_PER_S)
        elif not self._bad_clock_warned:
            self._bad_clock_warned = True
            self.get_logger().warning(
                f'{self._clock_topic}: data {list(data)} is not [version, step_index, time >= 0];'
                ' keeping the previous time'
            )

    def _timestamp_ns(self) -> int:
        if not self._clock_topic:
            return self.get_clock().now().nanoseconds
        return self._sim_time_ns if self._sim_time_ns is not None else 0

    def stop_timers(self) -> None:
        """Stop discovery and periodic flushing (before draining and closing)."""
        for timer in self._timers:
            self.destroy_timer(timer)
        self._timers.clear()

    def drain(self, executor: Executor, *, interrupted: Callable[[], bool] = lambda: False) -> float:
        """Take the messages still in flight; return the seconds spent.

        Spins until no message came for ``drain_quiet`` s: under load, messages the publishers
        sent before they stopped can arrive well after the queue first looks empty. Ends anyway
        after ``drain_limit`` s (a publisher that never stops), or once `interrupted()` is true;
        even then it takes the messages already queued.
        """
        started = time.monotonic()
        last_arrival = started
        seen = first = self.received_count
        ending = ''
        while not ending:
            now = time.monotonic()
            quiet_left = self._drain_quiet - (now - last_arrival)
            limit_left = self._drain_limit - (now - started)
            if quiet_left <= 0:
                ending = 'quiet'
            elif limit_left <= 0:
                ending = 'limit'
            elif interrupted():
                ending = 'interrupted'
            else:
                # At most 0.1 s per wait, so that a second signal ends the drain promptly.
                executor.spin_once(timeout_sec=min(quiet_left, limit_left, 0.1))
                if self.received_count != seen:
                    seen = self.received_count
                    last_arrival = time.monotonic()
        if ending == 'interrupted':  # still take what is queued already (bounded by the limit)
            while time.monotonic() - started < self._drain_limit:
                before = self.received_count
                executor.spin_once(timeout_sec=0.0)
                if self.received_count == before:
                    break
        drained = time.monotonic() - started
        taken = self.received_count - first
        logger = self.get_logger()
        if ending == 'quiet':
            logger.info(
                f'drained {taken} messages in {drained:.2f} s (then none for {self._drain_quiet:g} s)'
            )
        elif ending == 'limit':
            logger.warning(
                f'drain limit reached: drained {taken} messages in {drained:.2f} s and messages were'
                f' still arriving (drain_limit {self._drain_limit:g} s)'
            )
        else:
            logger.warning(
                f'drain cut short by a second stop signal after {drained:.2f} s ({taken} messages)'
            )
        return drained

    def close(self) -> None:
        """Finalize the bag (MCAP summary and ``metadata.yaml``)."""
        self.stop_timers()
        self.bag.close()


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder until SIGINT or SIGTERM, then finalize the bag."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from formation_agent.node import make_executor

    stop = threading.Event()
    requests = 0  # the first stop signal starts the drain, a second one ends it

    def request_stop(signum: int, frame: FrameType | None) -> None:
        nonlocal requests
        requests += 1
        stop.set()

    # Own handlers instead of rclpy's: rclpy's would shut the context down before the messages
    # still queued in the subscriptions are taken.
    rclpy.init(args=list(args) if args is not None else None,
               signal_handler_options=SignalHandlerOptions.NO)
    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    node: RecorderNode | None = None
    try:
        node = RecorderNode()
        # The EventsExecutor takes a message several times faster than the SingleThreadedExecutor,
        # which fell behind a 3-agent lock-step run on a loaded machine.
        executor = make_executor('events')
        executor.add_node(node)
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
        node.stop_timers()
        node.drain(executor, interrupted=lambda: requests > 1)
        node.get_logger().info(f'stopping: {node.message_count} messages in {node.bag.path}')
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
