"""The run's tag: HMAC-SHA256 over a message's payload, its topic, its writer and its sequence
number, with a secret key each run makes (issue 28 item 2; ROS-free; docs/HOSTILE_TRAFFIC.md, "Tags").

A tagged message carries the text `tag1:<writer>:<sequence>:<64 hex digits>`: a
Float64MultiArray as the label of one more layout dimension of size 0 (its data, and so every
decoder, unchanged), a String as its last line.  The MAC is

    HMAC-SHA256(key, b'formation-tag-1' 0 topic 0 writer 0 sequence (8 bytes, big endian) payload)

with the payload a Float64MultiArray's data as little-endian float64 bytes, or a String's text
before the tag line as UTF-8.  A reader holding the key (`Verifier`) refuses, before the algorithm
sees it, a message without a tag (`untagged`), with a tag that is not the key's (`forged`) — both
counted as foreign — and one whose sequence is not above the last it took from that writer on that
topic (`replayed`: a copy within the run, counted apart: transient local durability re-delivers a
writer's history to a reader that matches it again).  A reader without a key (a run without one,
an agent started by hand) takes every message as before.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import struct
import sys
from array import array
from collections.abc import Sequence
from pathlib import Path

from formation_msgs_py.errors import KeyFileError, TagError
from formation_msgs_py.lockstep import FOREIGN_REASONS, FORGED, REPLAYED, TAG_REASONS, UNTAGGED

KEY_FILE = 'run.key'
"""The key's file in the run folder, beside the parameter files (mode 0600)."""
KEY_BYTES = 32
TAG_PREFIX = 'tag1:'
_DIGEST_HEX = 64
_DOMAIN = b'formation-tag-1\0'


# -- the key ----------------------------------------------------------------------------------


def new_key() -> bytes:
    return secrets.token_bytes(KEY_BYTES)


def write_key(path: str | Path, key: bytes) -> Path:
    """Write `key` as hex into a new file readable only by its owner (0600); never over an existing one."""
    path = Path(path)
    if len(key) != KEY_BYTES:
        raise KeyFileError(f'a run key has {KEY_BYTES} bytes, got {len(key)}')
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise KeyFileError(f'{path}: a key file exists already; a run makes its own key') from None
    with os.fdopen(fd, 'w') as file:
        file.write(key.hex() + '\n')
    return path


def read_key(path: str | Path) -> bytes:
    """The key of a key file; KeyFileError naming the rule if others may read it or it is not a key."""
    path = Path(path)
    try:
        mode = stat.S_IMODE(path.stat().st_mode)
        text = path.read_text().strip()
    except OSError as error:
        raise KeyFileError(f'key_file {path}: cannot be read ({error.strerror})') from None
    if mode & 0o077:
        raise KeyFileError(f'key_file {path}: must be readable by its owner only (mode 0600), got {mode:04o}')
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise KeyFileError(
            f'key_file {path}: must hold {KEY_BYTES} bytes as hex, got {len(text)} characters'
        ) from None
    if len(key) != KEY_BYTES:
        raise KeyFileError(f'key_file {path}: must hold {KEY_BYTES} bytes as hex, got {len(key)} bytes')
    return key


# -- payloads ---------------------------------------------------------------------------------


def array_payload(values: Sequence[float]) -> bytes:
    """A Float64MultiArray's data as the bytes the MAC covers: little-endian float64."""
    data = array('d', values)
    if sys.byteorder != 'little':
        data.byteswap()
    return data.tobytes()


def mac(key: bytes, *, topic: str, writer: str, sequence: int, payload: bytes) -> str:
    head = b'%s%s\0%s\0%s' % (_DOMAIN, topic.encode(), writer.encode(), struct.pack('>Q', sequence))
    return hmac.new(key, head + payload, hashlib.sha256).hexdigest()


def tag_text(key: bytes, *, topic: str, writer: str, sequence: int, payload: bytes) -> str:
    digest = mac(key, topic=topic, writer=writer, sequence=sequence, payload=payload)
    return f'{TAG_PREFIX}{writer}:{sequence}:{digest}'


def parse_tag(text: str) -> tuple[str, int, str]:
    """(writer, sequence, hex digest) of a tag; TagError (forged) if it is not one."""
    body = text[len(TAG_PREFIX) :] if text.startswith(TAG_PREFIX) else None
    parts = body.rsplit(':', 2) if body is not None else []
    if len(parts) != 3 or not parts[1].isdigit() or len(parts[2]) != _DIGEST_HEX:
        raise TagError(
            f'tag {text[:90]!r} is not {TAG_PREFIX}<writer>:<sequence>:<64 hex digits>', reason=FORGED
        )
    return parts[0], int(parts[1]), parts[2]


def split_text(text: str) -> tuple[str, str | None]:
    """A tagged String's text and its tag (None: untagged)."""
    body, newline, last = text.rpartition('\n')
    return (body, last) if newline and last.startswith(TAG_PREFIX) else (text, None)


# -- writers and readers ----------------------------------------------------------------------


class Signer:
    """A node's tags: one sequence per topic, counting up from 1."""

    def __init__(self, key: bytes, *, writer: str) -> None:
        if ':' in writer or '\n' in writer:
            raise ValueError(f'a tag writer name holds no ":" or newline, got {writer!r}')
        self._key = key
        self.writer = writer
        self._sequence: dict[str, int] = {}

    def tag(self, topic: str, payload: bytes) -> str:
        sequence = self._sequence[topic] = self._sequence.get(topic, 0) + 1
        return tag_text(self._key, topic=topic, writer=self.writer, sequence=sequence, payload=payload)

    def tag_array(self, topic: str, values: Sequence[float]) -> str:
        return self.tag(topic, array_payload(values))

    def tag_string(self, topic: str, text: str) -> str:
        """`text` with its tag as its last line."""
        return f'{text}\n{self.tag(topic, text.encode())}'


def agent_writer(agent_id: int) -> str:
    """The writer name in agent `agent_id`'s tags."""
    return f'agent_{agent_id}'


def run_tags(key_file: str, *, writer: str) -> tuple[Signer | None, Verifier]:
    """A node's signer (None without a key) and verifier, from its `key_file` parameter ('': none)."""
    key = read_key(key_file) if key_file else None
    return (Signer(key, writer=writer) if key else None), Verifier(key)


class Verifier:
    """A node's check of the tags it reads.  Without a key it takes every message (`required`
    False); with one, `check` raises TagError for an untagged, forged or replayed message and
    counts it by reason (`refused`)."""

    def __init__(self, key: bytes | None) -> None:
        self._key = key
        self._last: dict[tuple[str, str], int] = {}
        self.refused: dict[str, int] = dict.fromkeys(TAG_REASONS, 0)

    @property
    def required(self) -> bool:
        return self._key is not None

    @property
    def foreign(self) -> int:
        return sum(self.refused[reason] for reason in FOREIGN_REASONS)

    def check(self, topic: str, payload: bytes, tag: str | None, *, writer: str | None = None) -> None:
        """TagError (counted) unless `tag` is the key's for `topic` and `payload`, from `writer`
        when one is named (a sensing request: only agent i may ask for agent i's state)."""
        if self._key is None:
            return
        try:
            self._check(topic, payload, tag, writer)
        except TagError as error:
            self.refused[error.reason] += 1
            raise

    def check_array(self, topic: str, values: Sequence[float], tag: str | None) -> None:
        if self._key is not None:
            self.check(topic, array_payload(values), tag)

    def check_string(self, topic: str, text: str) -> str:
        """The text before its tag, once the tag is checked."""
        body, tag = split_text(text)
        self.check(topic, body.encode(), tag)
        return body

    def _check(self, topic: str, payload: bytes, tag: str | None, only: str | None) -> None:
        if tag is None:
            raise TagError(f"{topic}: a message without the run's tag", reason=UNTAGGED)
        writer, sequence, digest = parse_tag(tag)
        expected = mac(self._key, topic=topic, writer=writer, sequence=sequence, payload=payload)
        if not hmac.compare_digest(expected, digest):
            raise TagError(f"{topic}: a tag from {writer!r} that is not the run key's", reason=FORGED)
        if only is not None and writer != only:
            raise TagError(
                f'{topic}: a tag of the run from {writer!r}, where only {only!r} may write', reason=FORGED
            )
        last = self._last.get((topic, writer), 0)
        if sequence <= last:
            raise TagError(
                f'{topic}: {writer!r} sequence {sequence} again (its last was {last}): a replay',
                reason=REPLAYED,
            )
        self._last[(topic, writer)] = sequence
