"""Replay a bag on ROS: every message republished byte for byte with its original timing.

A publisher per topic is created with the rclpy class of the stored type (imported by name, as
the recorder does) and the stored CDR bytes are published raw (`Publisher.publish(bytes)`), so
nothing is deserialized or re-encoded (readers get the same bytes, which the DDS transport pads
with zeros to a multiple of 4). Message k is published at wall time
start + (stamp_k - stamp_0) / rate; rate 0 publishes as fast as possible.

QoS: reliable and transient local, like the formation protocol, so the formation's own nodes
and tools match the replay. History keep-all by default: a keep-last writer drops the oldest
sample once `depth` newer ones are queued, even if a slow reader has not acknowledged it yet, and
a fast replay would then lose messages; keep-all never drops (the writer holds every message it
published, for late joiners too: memory grows with the bag). `depth` selects keep-last instead.
Pacing on acknowledgements (`wait_for_all_acked`) was tried and rejected: across processes each
wait lasts until the writer's next periodic heartbeat, which made a 2 s bag take 37 s.

`/clock`: a bag that recorded `/clock` replays it like any topic; otherwise the player publishes
`rosgraph_msgs/Clock` on `/clock` with each new bag timestamp (disable with `clock=False`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from formation_sim.bag.io import BagError, UnknownMessageTypeError, read_bag
from formation_sim.runtime.recorder import import_message_class

CLOCK_TOPIC = '/clock'


class ReplayError(ValueError):
    """Bad replay arguments, an unreadable bag, or subscribers that never came."""


@dataclass(kw_only=True)
class ReplayResult:
    published: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    skipped_topics: dict[str, str] = field(default_factory=dict)  # topic -> why
    clock_messages: int = 0  # synthetic /clock messages
    wall_time: float = 0.0
    interrupted: bool = False


def replay_qos(depth: int | None = None):
    """Reliable, transient local; keep-all, or keep-last `depth`."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if depth is None else HistoryPolicy.KEEP_LAST,
        depth=1 if depth is None else depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def _bag_topics(bag: Path) -> dict[str, str]:
    from rosbags.rosbag2 import Reader

    try:
        with Reader(bag) as reader:
            return {connection.topic: connection.msgtype for connection in reader.connections}
    except Exception as error:  # noqa: BLE001 - rosbags raises several unrelated types
        raise ReplayError(f'{bag}: cannot read the bag: {error}') from None


class BagPlayer:
    """Publishes a bag's messages from `node` (an rclpy node the caller spins or not: publishing needs no spin)."""

    def __init__(
        self,
        node,
        bag: str | Path,
        *,
        rate: float = 1.0,
        topics: Iterable[str] | None = None,
        clock: bool = True,
        depth: int | None = None,
        ack_timeout: float = 10.0,
    ) -> None:
        if not (math.isfinite(rate) and rate >= 0.0):
            raise ReplayError(f'rate must be a finite number >= 0 (0: as fast as possible), got {rate!r}')
        if depth is not None and depth < 1:
            raise ReplayError(f'depth must be >= 1 (or None: keep all), got {depth}')
        self.node = node
        self.bag = Path(bag)
        self.rate = rate
        self.depth = depth
        self.ack_timeout = ack_timeout
        self._stop = threading.Event()
        stored = _bag_topics(self.bag)
        wanted = set(stored) if topics is None else set(topics)
        unknown = wanted - set(stored)
        if unknown:
            raise ReplayError(f'topics {sorted(unknown)} are not in {self.bag} (it has {sorted(stored)})')
        self.result = ReplayResult()
        qos = replay_qos(depth)
        self.publishers = {}
        for topic in sorted(wanted):
            try:
                msg_class = import_message_class(stored[topic])
            except UnknownMessageTypeError as error:
                self.result.skipped_topics[topic] = str(error)
                continue
            self.publishers[topic] = node.create_publisher(msg_class, topic, qos)
            self.result.per_topic[topic] = 0
        self._clock = None
        if clock and CLOCK_TOPIC not in stored:
            from rosgraph_msgs.msg import Clock

            self._clock = node.create_publisher(Clock, CLOCK_TOPIC, qos)

    def stop(self) -> None:
        """Ask `play` to return after the message in progress (thread-safe)."""
        self._stop.set()

    def wait_for_subscribers(self, count: int, *, timeout: float) -> None:
        """Block until every publisher has at least `count` matched subscriptions."""
        deadline = time.monotonic() + timeout
        while True:
            lacking = [topic for topic, publisher in self.publishers.items() if publisher.get_subscription_count() < count]
            if not lacking:
                return
            if self._stop.is_set():
                return
            if time.monotonic() > deadline:
                raise ReplayError(f'no {count} subscriber(s) within {timeout} s on {lacking[:10]}{" …" if len(lacking) > 10 else ""}')
            time.sleep(0.05)

    def _publish_clock(self, stamp_ns: int) -> None:
        from builtin_interfaces.msg import Time
        from rosgraph_msgs.msg import Clock

        self._clock.publish(Clock(clock=Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)))
        self.result.clock_messages += 1

    def play(self, *, progress: Callable[[int, int | None], None] | None = None, total: int | None = None) -> ReplayResult:
        """Publish every message of the chosen topics; returns counts (also on `stop`)."""
        from rclpy.duration import Duration

        started = time.monotonic()
        first_stamp = None
        last_stamp = None
        try:
            for message in read_bag(self.bag):
                if self._stop.is_set():
                    self.result.interrupted = True
                    break
                publisher = self.publishers.get(message.topic)
                if publisher is None:
                    continue
                if first_stamp is None:
                    first_stamp = message.timestamp_ns
                if self.rate > 0.0:
                    due = started + (message.timestamp_ns - first_stamp) / 1e9 / self.rate
                    while (wait := due - time.monotonic()) > 0.0 and not self._stop.is_set():
                        time.sleep(min(wait, 0.1))
                    if self._stop.is_set():
                        self.result.interrupted = True
                        break
                if self._clock is not None and message.timestamp_ns != last_stamp:
                    self._publish_clock(message.timestamp_ns)
                last_stamp = message.timestamp_ns
                publisher.publish(message.rawdata)  # raw CDR, byte for byte
                self.result.per_topic[message.topic] += 1
                self.result.published += 1
                if progress is not None and self.result.published % 500 == 0:
                    progress(self.result.published, total)
        except BagError as error:
            raise ReplayError(f'{self.bag}: {error}') from None
        # Reliable readers get the tail too before the node goes away.
        for publisher in [*self.publishers.values(), *([self._clock] if self._clock is not None else [])]:
            publisher.wait_for_all_acked(Duration(seconds=self.ack_timeout))
        if progress is not None:
            progress(self.result.published, total)
        self.result.wall_time = time.monotonic() - started
        return self.result


def main_replay(
    bag: str | Path,
    *,
    rate: float = 1.0,
    domain_id: int | None = None,
    topics: Iterable[str] | None = None,
    clock: bool = True,
    depth: int | None = None,
    delay: float = 0.0,
    wait_for_subscribers: int = 0,
    wait_timeout: float = 30.0,
    progress: Callable[[int, int | None], None] | None = None,
) -> ReplayResult:
    """Start rclpy (in `domain_id` if given), replay `bag`, shut down; Ctrl-C stops cleanly."""
    import rclpy
    from rclpy.node import Node

    bag = Path(bag)
    if not bag.exists():
        raise ReplayError(f'{bag}: no such bag')
    if bag.is_file():
        bag = bag.parent
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = None
    try:
        node = Node('formation_replay', context=context, start_parameter_services=False)
        player = BagPlayer(node, bag, rate=rate, topics=topics, clock=clock, depth=depth)
        try:
            if wait_for_subscribers > 0:
                player.wait_for_subscribers(wait_for_subscribers, timeout=wait_timeout)
            if delay > 0.0:
                time.sleep(delay)
            total = sum(count for topic, count in _counts(bag).items() if topic in player.publishers)
            return player.play(progress=progress, total=total)
        except KeyboardInterrupt:
            player.result.interrupted = True
            return player.result
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def _counts(bag: Path) -> dict[str, int]:
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        return {connection.topic: connection.msgcount for connection in reader.connections}
