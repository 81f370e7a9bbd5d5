"""Replay a bag on ROS: every message republished byte for byte with its original timing.

A publisher per topic is created with the rclpy class of the stored type (imported by name, as
the recorder does) and the stored CDR bytes are published raw (`Publisher.publish(bytes)`), so
nothing is deserialized or re-encoded (readers get the same bytes, which the DDS transport pads
with zeros to a multiple of 4). Message k is published at wall time
start + (stamp_k - stamp_0) / rate; rate 0 publishes as fast as possible.

QoS: what the topic's publishers offered when it was recorded (the bag's `offered_qos_profiles`,
`formation_sim.runtime.nodes.bag_qos.replay_offer`, as ros2 bag play does): a transient-local topic such
as `/formation/scenario` is latched again for late joiners, a volatile one is not.  A topic recorded
without them, or with publishers that offered different policies: reliable and transient local,
like the formation protocol, so the formation's own nodes and tools match the replay.  History
keep-all by default: a keep-last writer drops the oldest
sample once `depth` newer ones are queued, even if a slow reader has not acknowledged it yet, and
a fast replay would then lose messages; keep-all never drops (the writer holds every message it
published, for late joiners too: memory grows with the bag). `depth` selects keep-last instead.
Pacing on acknowledgements (`wait_for_all_acked`) was tried and rejected: across processes each
wait lasts until the writer's next periodic heartbeat, which made a 2 s bag take 37 s.

`/clock`: a bag that recorded `/clock` replays it like any topic; otherwise the player publishes
`rosgraph_msgs/Clock` on `/clock` with each new bag timestamp (disable with `clock=False`).

Never into a live run: a replay on the domain of a formation run would feed that run's agents
old messages and mix them into its bag.  `main_replay` holds the domain's lock, as a run does
(`formation_sim.runtime.launch.orchestrate.reserve_domain`: refused if a run on this machine holds it, and no
run can start there meanwhile), and refuses a domain whose ROS graph shows a run's nodes or a
writer of the Step topic (a run on another machine).
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from formation_msgs_py.topics import AGENT_NODE, RECORDER_NODE, SIMULATOR_NODE
from formation_sim.bag.errors import BagError, UnknownMessageTypeError
from formation_sim.bag.io import read_bag
from formation_sim.runtime.errors import ReplayError
from formation_sim.runtime.nodes.bag_qos import replay_offer
from formation_sim.runtime.nodes.recorder import import_message_class

if TYPE_CHECKING:
    from rclpy.qos import QoSProfile

CLOCK_TOPIC = '/clock'
RUN_NODES = (SIMULATOR_NODE, AGENT_NODE, RECORDER_NODE)  # the nodes of a formation run
GRAPH_WAIT = 1.5  # seconds to discover a run already on the domain before publishing anything


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


def _bag_topics(bag: Path) -> dict[str, tuple[str, list]]:
    """Topic -> (message type, the QoS profiles its publishers offered when recorded)."""
    from rosbags.rosbag2 import Reader

    from formation_sim.bag.errors import BagReadError
    from formation_sim.bag.io import check_bag_information, damaged_bag_message

    try:
        check_bag_information(bag)
        with Reader(bag) as reader:
            return {
                connection.topic: (
                    connection.msgtype,
                    list(getattr(connection.ext, 'offered_qos_profiles', [])),
                )
                for connection in reader.connections
            }
    except BagReadError as error:
        raise ReplayError(str(error)) from None
    except Exception as error:  # noqa: BLE001 - rosbags raises several unrelated types
        raise ReplayError(damaged_bag_message(bag, error)) from None


class BagPlayer:
    """Publishes a bag's messages from `node` (an rclpy node the caller spins or not: publishing
    needs no spin)."""

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
        self.offered: dict[str, QoSProfile] = {}  # topic -> the QoS its publisher offers
        for topic in sorted(wanted):
            msgtype, recorded = stored[topic]
            try:
                msg_class = import_message_class(msgtype)
            except UnknownMessageTypeError as error:
                self.result.skipped_topics[topic] = str(error)
                continue
            self.offered[topic] = replay_offer(recorded, depth=depth) or qos
            self.publishers[topic] = node.create_publisher(msg_class, topic, self.offered[topic])
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
            lacking = [
                topic
                for topic, publisher in self.publishers.items()
                if publisher.get_subscription_count() < count
            ]
            if not lacking:
                return
            if self._stop.is_set():
                return
            if time.monotonic() > deadline:
                raise ReplayError(
                    f'no {count} subscriber(s) within {timeout} s on '
                    f'{lacking[:10]}{" …" if len(lacking) > 10 else ""}'
                )
            time.sleep(0.05)

    def _publish_clock(self, stamp_ns: int) -> None:
        from builtin_interfaces.msg import Time
        from rosgraph_msgs.msg import Clock

        self._clock.publish(
            Clock(clock=Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000))
        )
        self.result.clock_messages += 1

    def play(
        self, *, progress: Callable[[int, int | None], None] | None = None, total: int | None = None
    ) -> ReplayResult:
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
    """Start rclpy (in `domain_id`, else ROS_DOMAIN_ID's), replay `bag`, shut down; Ctrl-C stops cleanly.

    Refused (ReplayError) on a domain where a formation run is live (see the module docstring).
    """
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.orchestrate import reserve_domain

    bag = Path(bag)
    if not bag.exists():
        raise ReplayError(f'{bag}: no such bag')
    if bag.is_file():
        bag = bag.parent
    try:
        domain = domain_id if domain_id is not None else int(os.environ.get('ROS_DOMAIN_ID') or 0)
    except ValueError:
        raise ReplayError(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]!r} is not a domain id') from None
    hint = (
        'replaying there would feed that run old messages and mix them into its bag; '
        'choose another --domain-id'
    )
    with contextlib.ExitStack() as held:
        try:
            held.enter_context(reserve_domain(domain))
        except RunError as error:
            raise ReplayError(f'{error}: {hint}') from None
        return _replay_on(
            bag,
            domain,
            hint,
            rate=rate,
            topics=topics,
            clock=clock,
            depth=depth,
            delay=delay,
            wait_for_subscribers=wait_for_subscribers,
            wait_timeout=wait_timeout,
            progress=progress,
        )


def live_run_nodes(node, *, wait: float) -> list[str]:
    """The nodes of a formation run (or the writers of its Step topic) `node` sees within `wait` s."""
    from formation_msgs_py.topics import STEP_TOPIC

    deadline = time.monotonic() + wait
    while True:
        found = sorted(
            f'{namespace.rstrip("/")}/{name}'
            for name, namespace in node.get_node_names_and_namespaces()
            if name in RUN_NODES
        )
        writers = node.get_publishers_info_by_topic(STEP_TOPIC)
        found += [
            f'{info.node_namespace.rstrip("/")}/{info.node_name} (writes {STEP_TOPIC})' for info in writers
        ]
        named = all(
            info.node_name != '_NODE_NAME_UNKNOWN_' for info in writers
        )  # a writer is seen before its node
        if (found and named) or time.monotonic() > deadline:
            return sorted(set(found))
        time.sleep(0.05)


def _replay_on(
    bag: Path,
    domain: int,
    hint: str,
    *,
    rate,
    topics,
    clock,
    depth,
    delay,
    wait_for_subscribers,
    wait_timeout,
    progress,
) -> ReplayResult:
    import rclpy
    from rclpy.node import Node

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = None
    try:
        node = Node('formation_replay', context=context, start_parameter_services=False)
        if running := live_run_nodes(node, wait=GRAPH_WAIT):
            shown = ', '.join(running[:5]) + (f' and {len(running) - 5} more' if len(running) > 5 else '')
            raise ReplayError(f'ROS domain {domain} has a formation run live ({shown}): {hint}')
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
