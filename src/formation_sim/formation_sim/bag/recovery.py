"""Recovering a bag whose recorder died (SIGKILL, a crash): `reindex`.

A recorder killed hard leaves an MCAP file without summary and footer, and no ``metadata.yaml``;
rosbags and ros2 bag refuse it. The file holds every message up to the recorder's last flush.
`reindex(bag_dir)` rebuilds a readable bag from what is in the file.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as McapFileWriter
from rosbags.rosbag2 import Reader

from formation_sim.bag.errors import BagRecoveryError
from formation_sim.bag.io import (
    MCAP_RECORD,
    TopicRecord,
    bag_information,
    mcap_bag_record,
    type_hash,
    write_bag_information,
)


@dataclass(frozen=True, kw_only=True)
class Recovery:
    """What `reindex` found and did."""

    mcap_path: Path
    message_counts: dict[str, int]  # topic -> messages recovered
    rewritten: bool  # False: the MCAP file was complete and is kept as it is
    damaged_copy: Path | None  # the original, truncated file, when rewritten
    healthy: bool = False  # the bag was readable as it was: nothing was changed
    dropped: tuple[str, ...] = ()  # what was left out (damaged chunks, a cut-short end), in words

    @property
    def message_count(self) -> int:
        """Messages recovered in all."""
        return sum(self.message_counts.values())


_MAGIC = b'\x89MCAP0\r\n'
_RECORD_HEAD = struct.Struct('<BQ')  # opcode, content length
_CHUNK_TIMES = struct.Struct('<QQ')  # a chunk's first and last message's log time


@dataclass
class _Salvage:
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    messages: list[Message]
    complete: bool  # the footer was reached
    dropped: list[str] = field(default_factory=list)  # what was left out, in words


def _salvage(mcap_path: Path) -> _Salvage:
    """Every intact record of the file's data, record by record: a chunk whose checksum does not
    match (flipped bytes) or that does not parse is dropped and named, the records after it are
    still read; a file cut short ends at its last whole record."""
    salvage = _Salvage(schemas={}, channels={}, messages=[], complete=False)
    with mcap_path.open('rb') as stream:
        data = stream.read()
    if not data.startswith(_MAGIC):
        salvage.dropped.append(f'the file does not begin with the MCAP magic bytes ({len(data)} bytes)')
        return salvage
    offset = len(_MAGIC)
    while offset < len(data):
        if offset + _RECORD_HEAD.size > len(data):
            break  # cut short inside a record's head
        opcode, length = _RECORD_HEAD.unpack_from(data, offset)
        end = offset + _RECORD_HEAD.size + length
        if end > len(data):
            what = (
                f'a chunk ({_times(data, offset)})'
                if opcode == Opcode.CHUNK
                else f'a record (opcode {opcode:#04x})'
            )
            salvage.dropped.append(
                f'bytes {offset}-{len(data)}: {what} of {length} bytes that the file does not hold '
                '(cut short, or its length damaged): the rest of the file'
            )
            break
        if opcode == Opcode.FOOTER:
            salvage.complete = True
            break
        if opcode in (Opcode.CHUNK, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
            _take(salvage, data, offset, end, opcode)
        offset = end
    return salvage


def _times(data: bytes, offset: int) -> str:
    """A chunk's log times as it states them (they may be damaged too)."""
    at = offset + _RECORD_HEAD.size
    if at + _CHUNK_TIMES.size > len(data):
        return 'its times unknown'
    start, end = _CHUNK_TIMES.unpack_from(data, at)
    return f'messages logged {start / 1e9:.3f}-{end / 1e9:.3f} s'


def _take(salvage: _Salvage, data: bytes, offset: int, end: int, opcode: int) -> None:
    """Keep the schemas, channels and messages of one record (a chunk's checked against its
    checksum), or name it in `salvage.dropped`."""
    content = data[offset + _RECORD_HEAD.size : end]
    stream = ReadDataStream(io.BytesIO(content))
    try:
        if opcode == Opcode.CHUNK:
            records = breakup_chunk(Chunk.read(stream), validate_crc=True)
        elif opcode == Opcode.MESSAGE:
            records = [Message.read(stream, len(content))]
        else:
            records = [(Schema if opcode == Opcode.SCHEMA else Channel).read(stream)]
        if stream.count != len(content):
            raise ValueError(f'{stream.count} of its {len(content)} bytes make the record')
    except (McapError, ValueError, EOFError, struct.error, KeyError, IndexError, UnicodeDecodeError) as error:
        what = 'a chunk' if opcode == Opcode.CHUNK else f'a record (opcode {opcode:#04x})'
        why = (
            'its checksum does not match' if isinstance(error, CRCValidationError) else f'unreadable: {error}'
        )
        times = f', {_times(data, offset)}' if opcode == Opcode.CHUNK else ''
        salvage.dropped.append(f'bytes {offset}-{end}: {what} dropped, {why}{times}')
        return
    for record in records:
        if isinstance(record, Schema):
            salvage.schemas[record.id] = record
        elif isinstance(record, Channel):
            salvage.channels[record.id] = record
        elif isinstance(record, Message):
            salvage.messages.append(record)


def _topic_record(channel: Channel, schema: Schema, count: int) -> TopicRecord:
    """A salvaged channel as the bag's metadata describes it: its recorded QoS and type hash kept
    (the hash computed from the stored definition when the channel has none)."""
    text = channel.metadata.get('offered_qos_profiles', '')
    profiles = yaml.safe_load(text) if text else []
    digest = channel.metadata.get('topic_type_hash', '')
    if not digest and schema.encoding == 'ros2msg':
        digest = type_hash(schema.name, definition=schema.data.decode())
    return TopicRecord(
        name=channel.topic,
        msgtype=schema.name,
        type_hash=digest,
        offered_qos_profiles=profiles if isinstance(profiles, list) else [],
        message_count=count,
        serialization_format=channel.message_encoding,
    )


def _bag_metadata(salvage: _Salvage, relative_path: str, counts: dict[int, int]) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` of a version 9 bag holding `salvage`."""
    times = [m.log_time for m in salvage.messages]
    return bag_information(
        relative_path=relative_path,
        topics=[
            _topic_record(channel, salvage.schemas[channel.schema_id], counts.get(channel_id, 0))
            for channel_id, channel in sorted(salvage.channels.items())
        ],
        start_ns=min(times, default=0),
        end_ns=max(times, default=0),
        custom_data={'recovered_by': 'formation_sim.bag.recovery.reindex'},
    )


def _rewrite(salvage: _Salvage, target: Path, information: dict[str, Any]) -> None:
    """Write the salvaged records as a complete MCAP file (ros2 profile, uncompressed)."""
    with target.open('xb') as stream:
        writer = McapFileWriter(stream, compression=CompressionType.NONE)
        writer.start(profile='ros2', library='formation_sim.bag.recovery.reindex')
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
        writer.add_metadata(MCAP_RECORD, mcap_bag_record(information))
        writer.finish()


def _readable_counts(bag_dir: Path) -> dict[str, int] | None:
    """Messages per topic of a bag that opens as it is (metadata.yaml and a complete MCAP file)."""
    if not (bag_dir / 'metadata.yaml').is_file():
        return None
    try:
        with Reader(bag_dir) as reader:
            counts: dict[str, int] = {}
            for connection in reader.connections:
                counts[connection.topic] = counts.get(connection.topic, 0) + connection.msgcount
            return counts
    except Exception:  # noqa: BLE001 - rosbags raises several unrelated types for a damaged bag
        return None


def _write_metadata(bag_dir: Path, information: dict, *, mcap_path: Path, damaged_copy: Path | None) -> None:
    """Write the recovered bag's metadata.yaml (an unreadable one kept as metadata.yaml.damaged)."""
    metadata = bag_dir / 'metadata.yaml'
    if metadata.is_file() and _readable_counts(bag_dir) is None:
        # An unreadable metadata.yaml is the user's file: kept beside the new one.
        metadata.replace(metadata.with_name('metadata.yaml.damaged'))
    try:
        write_bag_information(bag_dir, information)
    except OSError as error:
        done = (
            f'{mcap_path.name} was rebuilt complete ({damaged_copy.name} kept), but ' if damaged_copy else ''
        )
        msg = (
            f'{bag_dir}: {done}cannot write metadata.yaml: {error.strerror}; free space, then recover it '
            'again'
        )
        raise BagRecoveryError(msg) from error


def reindex(bag_dir: Path | str) -> Recovery:
    """Rebuild ``metadata.yaml`` (and if needed the MCAP file) of a bag whose recorder died.

    A bag that opens as it is (metadata.yaml and a complete MCAP file whose every chunk matches
    its checksum) is left alone (`Recovery.healthy`). Otherwise every message in an intact MCAP
    chunk is kept; a chunk cut short by the kill, or whose checksum does not match (flipped
    bytes), is dropped and named (`Recovery.dropped`), and the chunks after it are still read. A
    truncated or damaged MCAP file is rewritten complete, and the original kept beside it as
    ``<name>.mcap.damaged``; ``metadata.yaml`` is written anew (atomically; an unreadable one is
    kept as ``metadata.yaml.damaged``).
    Nothing is changed if the rewrite cannot be written (a full disk), and no temporary stays.

    Raises:
        BagRecoveryError: `bag_dir` holds no single MCAP file, no message-bearing record
            survived in it, or the recovered files cannot be written (the message says what
            was done and what to do).

    """
    bag_dir = Path(bag_dir)
    candidates = sorted(bag_dir.glob('*.mcap'))
    if len(candidates) != 1:
        msg = f'{bag_dir}: expected exactly one .mcap file, found {[p.name for p in candidates]}'
        raise BagRecoveryError(msg)
    mcap_path = candidates[0]
    salvage = _salvage(mcap_path)
    intact = salvage.complete and not salvage.dropped  # every chunk's checksum checked
    if intact and (healthy := _readable_counts(bag_dir)) is not None:
        return Recovery(
            mcap_path=mcap_path, message_counts=healthy, rewritten=False, damaged_copy=None, healthy=True
        )
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
    if not intact:
        damaged_copy = mcap_path.with_name(f'{mcap_path.name}.damaged')
        recovered = mcap_path.with_name(f'{mcap_path.name}.recovering')
        recovered.unlink(missing_ok=True)
        try:
            _rewrite(salvage, recovered, information)
        except OSError as error:
            recovered.unlink(missing_ok=True)
            size = sum(len(m.data) for m in salvage.messages)
            msg = (
                f'{bag_dir}: cannot write the recovered copy {recovered.name}: {error.strerror} (it '
                f'needs about {size / 1e6:.1f} MB beside the cut-short {mcap_path.name}, which holds '
                f'{len(salvage.messages)} messages in complete chunks); the bag is unchanged: free '
                'space, then recover it again'
            )
            raise BagRecoveryError(msg) from error
        mcap_path.replace(damaged_copy)
        recovered.replace(mcap_path)

    _write_metadata(bag_dir, information, mcap_path=mcap_path, damaged_copy=damaged_copy)
    return Recovery(
        mcap_path=mcap_path,
        message_counts={salvage.channels[cid].topic: n for cid, n in counts.items()},
        rewritten=not intact,
        damaged_copy=damaged_copy,
        dropped=tuple(salvage.dropped),
    )
