"""The recorder node: formation runs recorded as rosbag2 bags (version 9, MCAP storage, CDR).

`RecorderNode` and `main()` (the `formation_recorder` command) subscribe raw to a list of topics
(and optionally to every topic under a prefix) and write each message as it arrives through the
ROS-free `formation_sim.bag.io.BagWriter`. Reading bags back: `formation_sim.bag.io`; recovering
one: `formation_sim.bag.recovery`.

Time stamps (`RunClock`): bag time is the run's time.  In lock-step a message is stamped with the
simulation time of the latest Step received on the clock topic (a message that overtook its Step
on the way, on a loaded machine, gets an earlier Step's time: the events executor gives no DDS
source times to order them by); on the wall clock (a Step flagged realtime:
`formation run --real-time` and every robot run) with the time it was received, counted from the
Step's epoch (t = 0 of the run) on a monotonic clock, so that bag time equals sim time on a
synchronised clock.  Messages received before the first Step wait up to `EARLY_WINDOW` s for it:
those received after its epoch (they overtook Step 0) get their time, older ones are stamped 0.
Either way the stamps of a topic never decrease.

QoS: each topic's MCAP channel is written with its first message, carrying the QoS every
publisher of the topic offered then (`formation_sim.runtime.nodes.bag_qos.offered_qos`, from the ROS
graph, as rosbag2 records it), so `ros2 bag play` and `formation replay` offer the same again.

What survives the end of a recorder:

- SIGINT or SIGTERM: `main()` stops its timers and drains: it keeps taking messages until none
  has come for ``drain_quiet`` seconds (messages still in flight from loaded publishers arrive
  late), for at most ``drain_limit`` seconds, or until a second signal. Then it closes the MCAP
  file (summary, footer) and writes ``metadata.yaml``: a complete bag.
- SIGKILL (or a crash of the interpreter): nothing is finalized. The bag directory holds an MCAP
  file without summary and footer, and no ``metadata.yaml``; rosbags and ros2 bag refuse it.
  The file holds every message up to the last `BagWriter.flush` (the node flushes every
  ``flush_period`` seconds); messages after it were still in memory and are lost (before the
  first Step, also those of the last `EARLY_WINDOW` s, which wait for it).
  `reindex(bag_dir)` rebuilds a readable bag from what is in the file.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import signal
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from types import FrameType
from typing import TYPE_CHECKING, Any, NoReturn

from rclpy.node import Node
from rclpy.parameter import Parameter

from formation_agent.ros.errors import ParameterError
from formation_agent.ros.parameters import (
    DOUBLE,
    STRING,
    STRING_ARRAY,
    ParameterSpec,
    parameter_help,
    read_parameters,
)
from formation_msgs_py.codec import check_array
from formation_msgs_py.errors import TagError
from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.lockstep import STEP_FLAG_REALTIME
from formation_msgs_py.tags import run_tags
from formation_msgs_py.topics import RECORDER_NODE, RECORDER_TOPIC, STEP_TOPIC
from formation_sim.bag.errors import BagError, TopicSpecError, UnknownMessageTypeError
from formation_sim.bag.io import BagWriter, check_msgtype, jazzy_typestore
from formation_sim.runtime.errors import RecorderError
from formation_sim.runtime.nodes.bag_qos import offered_qos

if TYPE_CHECKING:
    from rclpy.executors import Executor

DEFAULT_CLOCK_TOPIC = STEP_TOPIC
NODE_NAME = RECORDER_NODE
# /formation/step carries std_msgs/Float64MultiArray data = [version, step_index, time, flags, epoch, ...]
# (formation_msgs_py.codec.encode_step); flags and epoch are optional for other clock topics.
_STEP_INDEX = 1
_STEP_TIME_INDEX = 2
_STEP_FLAGS_INDEX = 3
_STEP_EPOCH_INDEX = 4
_NS_PER_S = 1_000_000_000
# Messages that come before the first Step wait this long [s] before they are written: on the wall
# clock a message of the run can overtake Step 0 (an agent triggers the moment it gets Step 0, the
# recorder may take its message first), and only Step 0's epoch gives its time.  Older ones were
# surely sent before the run began and are stamped 0.
EARLY_WINDOW = 2.0

_positive_seconds = {'low': 0.0, 'low_open': True, 'high': math.inf, 'high_open': True}
RECORDER_PARAMETERS = (
    ParameterSpec(
        name='output',
        type=STRING,
        description='the bag directory to create (it must not exist: a bag is never overwritten)',
    ),
    ParameterSpec(
        name='topics',
        type=STRING_ARRAY,
        default=[],
        description="topics recorded from the start, each '/name:package/msg/Type'",
    ),
    ParameterSpec(
        name='prefix',
        type=STRING,
        default='',
        description='also record every topic whose name starts with this, found by polling the graph '
        "('': none)",
    ),
    ParameterSpec(
        name='clock_topic',
        type=STRING,
        default=DEFAULT_CLOCK_TOPIC,
        description="the run's Step topic (std_msgs/Float64MultiArray [version, step, time, flags, epoch, "
        '...]): bag time is its sim time in lock-step, the receive time since its epoch on the wall clock '
        "('': the node's clock)",
    ),
    ParameterSpec(
        name='key_file',
        type=STRING,
        default='',
        description="the run's key (docs/HOSTILE_TRAFFIC.md, Tags): a Step without a valid tag is "
        "recorded but moves no bag time ('': every Step does)",
    ),
    ParameterSpec(
        name='discovery_period',
        type=DOUBLE,
        default=1.0,
        description='how often the graph is polled for topics under prefix [s]',
        **_positive_seconds,
    ),
    ParameterSpec(
        name='flush_period',
        type=DOUBLE,
        default=0.5,
        description='how often written messages are pushed to the file (what a SIGKILL can lose) [s]',
        **_positive_seconds,
    ),
    ParameterSpec(
        name='heartbeat_topic',
        type=STRING,
        default=RECORDER_TOPIC,
        description='where it says how much it recorded, after every flush and step (a run watches its '
        "liveliness; '': none)",
    ),
    ParameterSpec(
        name='watched_topics',
        type=STRING_ARRAY,
        default=[],
        description="recorded topics the heartbeat lists as 'silent' until their first message came (a robot "
        "run's time "
        "keeper starts only once the recorder has the robots' poses from before t = 0)",
    ),
    ParameterSpec(
        name='endless_topics',
        type=STRING_ARRAY,
        default=[],
        description="recorded topics whose writers outlive the run (external robots' poses): on stopping, "
        'their '
        'messages are recorded but do not hold the drain up',
    ),
    ParameterSpec(
        name='drain_quiet',
        type=DOUBLE,
        default=0.5,
        description='on stopping, take messages until none came for this long [s]',
        **_positive_seconds,
    ),
    ParameterSpec(
        name='drain_limit',
        type=DOUBLE,
        default=10.0,
        description='on stopping, stop taking messages after this long anyway [s]',
        **_positive_seconds,
    ),
)


def parse_topic_spec(spec: str) -> tuple[str, str]:
    """Split ``'/name:package/msg/Type'`` into name and type."""
    name, sep, msgtype = spec.partition(':')
    if not sep or not name or not msgtype:
        msg = f"topic spec {spec!r} is not of the form '/name:package/msg/Type'"
        raise TopicSpecError(msg)
    if not name.startswith('/'):
        msg = f'topic spec {spec!r}: the name must be absolute (start with "/")'
        raise TopicSpecError(msg)
    check_msgtype(msgtype)
    return name, msgtype


def import_message_class(msgtype: str) -> type:
    """Return the rclpy message class of ``package/msg/Type``."""
    check_msgtype(msgtype)
    package, _, type_name = msgtype.split('/')
    try:
        module = importlib.import_module(f'{package}.msg')
        return getattr(module, type_name)
    except (ImportError, AttributeError) as err:
        msg = f'message type {msgtype!r} cannot be imported: {err}'
        raise UnknownMessageTypeError(msg) from err


MAX_BAG_TIME = 2**63 / _NS_PER_S / 2
"""A bag stamps int64 nanoseconds: a Step's time or epoch must be below half of 2**63 ns (~146
years), so that wall time minus epoch plus run time fits too."""


def bag_time(seconds: float) -> bool:
    """Whether `seconds` is a time a bag can stamp: finite, in [0, MAX_BAG_TIME)."""
    return isinstance(seconds, (int, float)) and math.isfinite(seconds) and 0.0 <= seconds < MAX_BAG_TIME


class RunClock:
    """Bag time of the messages of a run, from the Steps on its clock topic (module docstring).

    `on_step(data)` takes each Step's data; `stamp_ns()` is the time stamp of a message received now.
    """

    def __init__(
        self,
        *,
        monotonic_ns: Callable[[], int] = time.monotonic_ns,
        wall_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self._monotonic_ns = monotonic_ns
        self._wall_ns = wall_ns
        self._sim_ns = 0  # lock-step: the latest Step's time
        # Wall clock: (monotonic time, run time) when the first realtime Step came.
        self._anchor: tuple[int, int] | None = None
        self.step_index = -1  # the latest Step's index (-1: none yet)
        self.started = False  # a Step has come (before it, the wall-clock epoch is unknown)

    @property
    def realtime(self) -> bool:
        return self._anchor is not None

    def on_step(self, data: Sequence[float]) -> bool:
        """Take a Step's data; False (and nothing changed) unless it holds [version, step, time, ...]
        with a time a bag can stamp (`bag_time`: in [0, MAX_BAG_TIME) s, issue 28: t = 1e300 and
        t = 1e11 killed the recorder) and, on the wall clock, such an epoch."""
        if len(data) <= _STEP_TIME_INDEX or not bag_time(data[_STEP_TIME_INDEX]):
            return False
        flags = data[_STEP_FLAGS_INDEX] if len(data) > _STEP_FLAGS_INDEX else 0.0
        epoch = data[_STEP_EPOCH_INDEX] if len(data) > _STEP_EPOCH_INDEX else 0.0
        realtime = math.isfinite(flags) and flags.is_integer() and int(flags) & STEP_FLAG_REALTIME
        if realtime and not bag_time(epoch):
            return False
        if realtime:
            if self._anchor is None:  # the epoch is the run's t = 0 on every machine's wall clock
                self._anchor = (self._monotonic_ns(), self._wall_ns() - round(epoch * _NS_PER_S))
        else:
            self._sim_ns = round(data[_STEP_TIME_INDEX] * _NS_PER_S)
        if float(data[_STEP_INDEX]).is_integer():
            self.step_index = int(data[_STEP_INDEX])
        self.started = True
        return True

    def received_ns(self) -> int:
        """When a message is received now, on the clock `stamp_ns` takes."""
        return self._monotonic_ns()

    def stamp_ns(self, received_ns: int | None = None) -> int:
        """The bag time of a message received at `received_ns` (`received_ns()`; default now): sim
        time of the latest Step (lock-step), time since the epoch (wall clock; never decreasing,
        0 before the epoch), 0 before the first Step."""
        if self._anchor is None:
            return self._sim_ns
        since, run_time = self._anchor
        return max(0, run_time + (self._monotonic_ns() if received_ns is None else received_ns) - since)


def _untagged_step(node, msg) -> bool:
    """Whether a Step lacks the run's valid tag: it moves no bag time (it is recorded all the same,
    as every foreign message; docs/HOSTILE_TRAFFIC.md, Tags)."""
    try:
        check_array(node._verifier, node._clock_topic, msg)
    except TagError as error:
        if node._verifier.refused[error.reason] <= 3:
            node.get_logger().warning(f'a Step that moves no bag time: {error}')
        return True
    return False


def _requested_topics(values: dict) -> tuple[list[tuple[str, str]], list[str]]:
    """The recorder's `topics` parameter as (name, type) pairs, and the problems of `topics`,
    `watched_topics` and `output` (each type importable here and in the Jazzy typestore)."""
    requested: list[tuple[str, str]] = []
    problems: list[str] = []
    for spec in values.get('topics') or []:
        try:
            name, msgtype = parse_topic_spec(spec)
            import_message_class(msgtype)  # recordable: importable here and known to the bag
            if msgtype not in jazzy_typestore().fielddefs:
                raise UnknownMessageTypeError(
                    f'message type {msgtype!r} is not in the typestore of ROS 2 Jazzy'
                )
            requested.append((name, msgtype))
        except BagError as error:
            problems.append(f"parameter 'topics': {error}")
    names = [name for name, _ in requested]
    if duplicates := sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"parameter 'topics' names {duplicates} more than once")
    if unrecorded := sorted(set(values.get('watched_topics') or []) - set(names)):
        problems.append(f"parameter 'watched_topics' names topics that are not in 'topics': {unrecorded}")
    if values.get('output') == '':
        problems.append("parameter 'output' (string) must name the bag directory to create, got ''")
    return requested, problems


class RunBag:
    """What goes into the bag, stamped with the run's time (`RunClock`), ROS-free: the node hands
    it each message's CDR bytes (`take`).  With a clock topic, what comes before the first Step
    waits (up to EARLY_WINDOW s) and is written once a Step says when the run began.  A bag that
    cannot be written (a full disk) stops the recording (`failure`); a message whose stamp no bag
    holds is counted (`unwritable`), not recorded.  `offered(name)`: the QoS the publishers of a
    topic offer, recorded before its first message; `now_ns()`: the stamp without a clock topic.
    """

    def __init__(
        self,
        output: str,
        *,
        clock_topic: str,
        warn: Callable[[str], None],
        offered: Callable[[str], list],
        now_ns: Callable[[], int],
    ) -> None:
        self.clock = RunClock()
        self._clock_topic = clock_topic
        self._warn, self._offered, self._now_ns = warn, offered, now_ns
        self._early: deque[tuple[int, str, bytes]] = (
            deque()
        )  # (received, topic, rawdata) before the first Step
        self.unwritable = 0  # messages the bag could not stamp (not recorded; a warning names the first)
        self.flushed_count = 0  # messages in the file for sure (as of the last flush)
        self.failure: RecorderError | None = None  # the bag could not be written
        self.bag = BagWriter(output)
        self.bag.open()
        self.bag.set_custom_data(
            'formation_timestamps',
            f'run time: sim time of {clock_topic} (lock-step), receive time since its epoch (wall clock)'
            if clock_topic
            else 'node clock',
        )

    def take(self, name: str, rawdata: bytes) -> None:
        """A message of `name` received now: written, or held until the first Step."""
        if self.failure is not None:
            return
        if self._clock_topic and not self.clock.started:
            self._early.append((self.clock.received_ns(), name, bytes(rawdata)))
            self.write_early(before=self.clock.received_ns() - round(EARLY_WINDOW * _NS_PER_S))
        else:
            self.write_early()  # the first Step has come: what waited goes first
            self._write(name, self.clock.stamp_ns() if self._clock_topic else self._now_ns(), rawdata)

    def flush(self) -> bool:
        """Write what waited too long for the first Step and flush the file; False once it cannot."""
        self.write_early(before=self.clock.received_ns() - round(EARLY_WINDOW * _NS_PER_S))
        if self.failure is not None:
            return False
        try:
            self.bag.flush()
        except OSError as error:
            self._fail(error)
            return False
        self.flushed_count = self.bag.message_count
        return True

    def _fail(self, error: OSError) -> None:
        """The bag cannot be written (a full disk): stop recording; `main` leaves with the error."""
        self.failure = RecorderError(
            f'cannot write the bag {self.bag.path}: {error}; recording stopped, {self.flushed_count} '
            'messages are in the file (formation recover BAG rebuilds it, once there is space)'
        )

    def _write(self, name: str, stamp_ns: int, rawdata: bytes) -> None:
        if self.failure is not None:
            return
        try:
            if not self.bag.has_channel(name):
                self._offer(name)
            self.bag.write(name, stamp_ns, rawdata)
        except OSError as error:
            self._fail(error)
        except BagError as error:  # a stamp no bag holds (RunClock refuses the Steps that would)
            self.unwritable += 1
            if self.unwritable <= 3:
                self._warn(f'{name}: a message not recorded: {error}')

    def write_early(self, *, before: int | None = None) -> None:
        """Write the messages that came before the first Step (those received before `before`
        only), stamped as the clock now can (0 until a Step says when the run began)."""
        while self._early and (before is None or self._early[0][0] < before):
            received, name, rawdata = self._early.popleft()
            self._write(name, self.clock.stamp_ns(received) if self.clock.started else 0, rawdata)

    def _offer(self, name: str) -> None:
        """Record the QoS the publishers of `name` offer (before its first message is written)."""
        profiles = self._offered(name)
        if not profiles:
            self._warn(f'{name}: no publisher in the ROS graph yet: its offered QoS is not recorded')
        self.bag.set_offered_qos(name, profiles)

    def close(self) -> None:
        """Finalize the bag (MCAP summary and ``metadata.yaml``), unless it could not be written.

        Raises:
            RecorderError: finalizing failed (a full disk); the MCAP file is then cut short and
                has no ``metadata.yaml`` (`formation_sim.bag.recovery.reindex` rebuilds it).

        """
        self.write_early()
        if self.failure is not None:
            return  # writing more would fail again: the file stays as the last flush left it
        for name in self.bag.topics:
            if not self.bag.has_channel(name):  # no message came: its publishers as they are now
                with contextlib.suppress(Exception):  # the node's context may be gone already
                    self.bag.set_offered_qos(name, self._offered(name))
        try:
            self.bag.close()
        except OSError as error:
            self._fail(error)
            raise self.failure from None


class RecorderNode(Node):
    """Record topics into a bag, stamped with the run's time (`RunClock`).

    Parameters: `RECORDER_PARAMETERS` (`formation_recorder --help` prints them, docs/PARAMETERS.md
    lists them).  ``heartbeat_topic``: ``{"version": 1, "recorder": NODE, "recorded": N, "step":
    K}`` (std_msgs/String, the protocol's QoS): N messages written so far, the latest step K
    recorded (-1: none); with ``watched_topics`` also ``"silent": [...]``, those of them that
    brought no message yet. The simulator keeps its steps at most
    `formation_sim.runtime.nodes.sim_node.RECORDER_LAG` ahead of K, and its writer's DDS liveliness
    tells a run the recorder still works.
    """

    def __init__(
        self, *, parameter_overrides: list[Parameter] | None = None, context=None, node_name: str = NODE_NAME
    ) -> None:
        """Declare and check the parameters (one ParameterError names every problem), open the bag."""
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        super().__init__(node_name, parameter_overrides=parameter_overrides or [], context=context)
        values, problems = read_parameters(self, RECORDER_PARAMETERS)
        requested, topic_problems = _requested_topics(values)
        problems += topic_problems
        if problems:
            name = self.get_fully_qualified_name()
            self.destroy_node()  # nothing of it outlives the refusal
            raise ParameterError(name, problems)
        output = values['output']
        self._prefix = values['prefix']
        self._clock_topic = values['clock_topic']
        self._verifier = run_tags(values['key_file'], writer=RECORDER_NODE)[1]
        heartbeat_topic = self._heartbeat_topic = values['heartbeat_topic']
        self._drain_quiet = values['drain_quiet']
        self._endless = frozenset(values['endless_topics'])
        self.run_count = 0  # messages received on topics that end with the run (not endless ones)
        self._watching = bool(values['watched_topics'])
        self._silent = set(values['watched_topics'])  # watched topics with no message yet
        self._drain_limit = values['drain_limit']

        self._qos = QoSProfile(
            history=HistoryPolicy.KEEP_ALL, depth=1000, reliability=ReliabilityPolicy.RELIABLE
        )
        self.received_count = 0  # messages taken from all subscriptions, recorded or not
        self._bad_clock_warned = False
        self._subscriptions_by_topic: dict[str, Any] = {}
        self._skipped: set[str] = set()

        self.run_bag = RunBag(
            output,
            clock_topic=self._clock_topic,
            warn=self.get_logger().warning,
            offered=lambda name: offered_qos(self, name),
            now_ns=lambda: self.get_clock().now().nanoseconds,
        )
        self.bag, self.clock = self.run_bag.bag, self.run_bag.clock
        try:
            for name, msgtype in requested:
                self._record(name, msgtype)
            if self._clock_topic and self._clock_topic not in self._subscriptions_by_topic:
                self._listen(self._clock_topic, 'std_msgs/msg/Float64MultiArray', record=False)
        except BaseException:
            self.bag.close()
            raise

        self._heartbeat = None
        if heartbeat_topic:
            from std_msgs.msg import String

            from formation_msgs_py.qos import PROTOCOL_QOS  # its liveliness lease is the run's

            self._heartbeat = self.create_publisher(String, heartbeat_topic, PROTOCOL_QOS)
            self._heartbeat_type = String
        self._timers = [self.create_timer(values['flush_period'], self._flush)]
        if self._prefix:
            self._timers.append(self.create_timer(values['discovery_period'], self.discover))
            self.discover()
        self.get_logger().info(f'recording {sorted(self.bag.topics)} (prefix {self._prefix!r}) into {output}')

    @property
    def message_count(self) -> int:
        """Messages written to the bag so far."""
        return self.bag.message_count

    @property
    def failure(self) -> RecorderError | None:
        """The bag could not be written (None: it could)."""
        return self.run_bag.failure

    def _flush(self) -> None:
        if self.run_bag.flush():
            self._beat()

    def _beat(self) -> None:
        if self._heartbeat is not None:
            beat = {
                'version': 1,
                'recorder': self.get_fully_qualified_name(),
                'recorded': self.bag.message_count,
                'step': self.clock.step_index,
            }
            if self._watching:
                beat['silent'] = sorted(self._silent)
            self._heartbeat.publish(self._heartbeat_type(data=json.dumps(beat, separators=(',', ':'))))

    def discover(self) -> None:
        """Subscribe to every not yet recorded topic under the prefix."""
        for name, types in self.get_topic_names_and_types():
            if not name.startswith(self._prefix) or name in self.bag.topics or name in self._skipped:
                continue
            if name == self._heartbeat_topic:  # its own sign of life, not a topic of the run
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
            if name not in self._endless:
                self.run_count += 1
            self._silent.discard(name)
            if is_clock:
                self._on_step(rawdata)
            if record:
                self.run_bag.take(name, rawdata)
            if is_clock and self.failure is None:
                self._beat()  # a run paces its steps on this (the simulator's flow control)

        self._subscriptions_by_topic[name] = self.create_subscription(
            message_class, name, on_message, self._qos, raw=True
        )

    def _on_step(self, rawdata: bytes) -> None:
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import Float64MultiArray

        if _untagged_step(self, msg := deserialize_message(rawdata, Float64MultiArray)):
            return
        if not self.clock.on_step(data := msg.data) and not self._bad_clock_warned:
            self._bad_clock_warned = True
            self.get_logger().warning(
                f'{self._clock_topic}: data {list(data)} is not [version, step_index, time, ...] with a time '
                f'(and a wall-clock epoch) in [0, {MAX_BAG_TIME:.4g}) s, what a bag can stamp;'
                ' keeping the previous time'
            )

    def stop_timers(self) -> None:
        """Stop discovery and periodic flushing (before draining and closing)."""
        for timer in self._timers:
            self.destroy_timer(timer)
        self._timers.clear()

    def drain(self, executor: Executor, *, interrupted: Callable[[], bool] = lambda: False) -> float:
        """Take the messages still in flight; return the seconds spent.

        Spins until no message came for ``drain_quiet`` s (on a topic that is not one of
        ``endless_topics``, whose writers go on): under load, messages the publishers
        sent before they stopped can arrive well after the queue first looks empty. Ends anyway
        after ``drain_limit`` s (a publisher that never stops), or once `interrupted()` is true;
        even then it takes the messages already queued.
        """
        started = time.monotonic()
        last_arrival = started
        first = self.received_count
        seen = self.run_count
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
                if self.run_count != seen:
                    seen = self.run_count
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
        """Stop the timers and finalize the bag (`RunBag.close`; RecorderError on a full disk)."""
        self.stop_timers()
        self.run_bag.close()


def _parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(
        prog='formation_recorder',
        description='Record topics of a formation run into a rosbag2 bag (version 9, MCAP, CDR; '
        'readable by ros2 bag and rosbags) until SIGINT or SIGTERM, then drain and finalize it.',
        epilog=parameter_help(RECORDER_PARAMETERS)
        + '\n\nExample: formation_recorder --ros-args -p output:=runs/x/bag '
        '-p "topics:=[\'/formation/step:std_msgs/msg/Float64MultiArray\']" -p prefix:=/formation/\n'
        'Exit status: 0 the bag is complete; 1 it could not be written (a full disk); 2 bad parameters '
        '(every problem named, nothing created).',
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder until SIGINT or SIGTERM, then finalize the bag."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    from rclpy.task import Future

    from formation_agent.ros.process import (
        SignalFlag,
        make_executor,
        release_ros,
        shutdown_guard,
        stacks_on_signal,
    )

    argv = list(args if args is not None else sys.argv)
    _parser().parse_args(rclpy.utilities.remove_ros_args(argv)[1:])  # --help before ROS starts (exit 0)
    stop = SignalFlag()  # set by a signal handler: no lock (threading.Event's could deadlock)
    requests = 0  # the first stop signal starts the drain, a second one ends it

    def request_stop(signum: int, frame: FrameType | None) -> None:
        nonlocal requests
        requests += 1
        stop.set()

    # Own handlers instead of rclpy's: rclpy's would shut the context down before the messages
    # still queued in the subscriptions are taken.
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    stacks_on_signal()
    node: RecorderNode | None = None
    executor = None
    try:
        node = RecorderNode()
        # The EventsExecutor takes a message several times faster than the SingleThreadedExecutor,
        # which fell behind a 3-agent lock-step run on a loaded machine.
        executor = make_executor('events')
        executor.add_node(node)
        never = Future()  # every event of 0.1 s dispatched in C++, then a look at the stop flag:
        while not stop.is_set() and node.failure is None:  # a spin_once per message cost more
            executor.spin_until_future_complete(never, timeout_sec=0.1)
        node.stop_timers()
        if node.failure is None:
            node.drain(executor, interrupted=lambda: requests > 1)
            node.get_logger().info(f'stopping: {node.message_count} messages in {node.bag.path}')
            node.close()
    except (ParameterError, BagError) as error:
        if node is None:  # bad parameters, or a bag that exists already: nothing was recorded
            print(f'formation_recorder: {error}', file=sys.stderr, flush=True)
            return ExitCode.BAD_INPUT
        if node.failure is None:
            raise
    finally:
        if node is not None:
            with contextlib.suppress(RecorderError):
                node.close()
        with shutdown_guard(
            'formation_recorder',
            lambda: ExitCode.BAD_INPUT if node is None else 1 if node.failure is not None else 0,
            announce=node is not None,
        ):
            release_ros(executor, [] if node is None else [node])
            executor = None  # its C++ teardown, under the guard and the stop handlers
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if node is not None and node.failure is not None:
        with contextlib.suppress(OSError):  # the log may be on the full disk too
            print(f'formation_recorder: {node.failure}', file=sys.stderr, flush=True)
        return 1
    return 0


def entry_point() -> NoReturn:
    """The `formation_recorder` console script: `main()`, then `exit_process` (a plain entry point's
    `sys.exit(main())` would run the interpreter's finalization and C++ static destructors after
    rclpy's shutdown)."""
    from formation_agent.ros.process import exit_process

    exit_process(main())


if __name__ == '__main__':
    entry_point()
