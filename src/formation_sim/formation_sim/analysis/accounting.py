"""What a run published against what its bag holds: a run that lost messages never reports done.

Every node of a run counts what it publishes per topic from step 0 on, when its recorder is
matched for sure (summary.json `extra.published`: the simulator's own, plus each agent's from its
final report).  After the run the bag must hold at least as many on every topic.  Fewer: the
recorder missed messages (it froze, fell behind a keep-last writer's history, or died), and the
run failed.  More: publishers outside the run wrote on its topics (a fault injector, a replay
on the same domain): the bag holds messages that are not the run's, which is said, not hidden.

The discovery announcements agents publish on `/formation/status` before step 0 are not counted
by them (the recorder may not be matched yet), so they are left out of the bag's count too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from formation_msgs_py.codec import decode_status
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import DISCOVERY_STEP
from formation_msgs_py.topics import STATUS_TOPIC
from formation_sim.bag.io import decode

_SHOWN = 6  # topics named in a message


@dataclass(frozen=True, kw_only=True)
class RecordingCheck:
    """Messages per topic: published by the run, recorded in its bag; where they differ."""

    published: dict[str, int]
    recorded: dict[str, int]
    missing: dict[str, int]  # topic -> messages published but not in the bag
    foreign: dict[str, int]  # topic -> messages in the bag beyond what the run published

    @property
    def complete(self) -> bool:
        return not self.missing

    def to_dict(self) -> dict:
        """extra.recording of summary.json."""
        return {
            'complete': self.complete,
            'missing': self.missing,
            'foreign': self.foreign,
            'published': sum(self.published.values()),
            'recorded': sum(self.recorded.get(topic, 0) for topic in self.published),
        }

    def describe_missing(self) -> str:
        """'the bag misses 120 of 3420 messages the run published: /formation/status 435 of 555, …'."""
        total = sum(self.published.values())
        shown = [
            f'{topic} {self.recorded.get(topic, 0)} of {self.published[topic]}'
            for topic in sorted(self.missing, key=lambda topic: -self.missing[topic])[:_SHOWN]
        ]
        more = f' and {len(self.missing) - _SHOWN} more topics' if len(self.missing) > _SHOWN else ''
        return (
            f'the bag misses {sum(self.missing.values())} of {total} messages the run published '
            f'(recorded of published: {", ".join(shown)}{more})'
        )

    def describe_foreign(self) -> str:
        """'the bag also holds 30 messages from publishers outside the run: /agent_2/trigger_info/to_1 30'."""
        shown = [
            f'{topic} {n}' for topic, n in sorted(self.foreign.items(), key=lambda item: -item[1])[:_SHOWN]
        ]
        more = f' and {len(self.foreign) - _SHOWN} more topics' if len(self.foreign) > _SHOWN else ''
        return (
            f'the bag also holds {sum(self.foreign.values())} messages from publishers outside the run '
            f'({", ".join(shown)}{more})'
        )


def recorded_counts(bag: str | Path) -> dict[str, int]:
    """Messages per topic in a readable bag, without the agents' discovery announcements."""
    from rosbags.rosbag2 import Reader

    counts: dict[str, int] = {}
    with Reader(Path(bag)) as reader:
        for connection in reader.connections:
            counts[connection.topic] = counts.get(connection.topic, 0) + connection.msgcount
        status = [c for c in reader.connections if c.topic == STATUS_TOPIC]
        for connection, _, rawdata in reader.messages(connections=status) if status else ():  # [] reads all
            try:
                announced = decode_status(decode(rawdata, connection.msgtype)).step_index == DISCOVERY_STEP
            except (MessageError, Exception):  # noqa: BLE001, S112 - junk CDR fails in several ways
                continue  # not a Status of the run: left in the count (and found foreign)
            counts[STATUS_TOPIC] -= announced
    return counts


def check_recording(published: dict[str, int], bag: str | Path) -> RecordingCheck:
    """Compare what the run published with what the readable bag at `bag` holds."""
    recorded = recorded_counts(bag)
    missing = {
        topic: n - recorded.get(topic, 0) for topic, n in published.items() if recorded.get(topic, 0) < n
    }
    foreign = {
        topic: recorded[topic] - published.get(topic, 0)
        for topic in recorded
        if recorded[topic] > published.get(topic, 0)
    }
    return RecordingCheck(
        published=dict(published),
        recorded=recorded,
        missing=dict(sorted(missing.items())),
        foreign=dict(sorted(foreign.items())),
    )
