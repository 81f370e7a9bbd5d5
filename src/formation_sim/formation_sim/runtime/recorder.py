"""The recorder node: formation runs recorded as rosbag2 bags (version 9, MCAP storage, CDR).

`RecorderNode` and `main()` (the `formation_recorder` command) subscribe raw to a list of topics
(and optionally to every topic under a prefix) and write each message as it arrives through the
ROS-free `formation_sim.bag.io.BagWriter`, stamped with the latest simulation time seen on the
clock topic. Reading bags back: `formation_sim.bag.io`; recovering one: `formation_sim.bag.recovery`.

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

import contextlib
import importlib
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from formation_msgs_py.topics import RECORDER_TOPIC, STEP_TOPIC
from formation_sim.bag.io import BagError, BagWriter, TopicSpecError, UnknownMessageTypeError, check_msgtype

from rclpy.node import Node

if TYPE_CHECKING:
    from rclpy.executors import Executor

DEFAULT_CLOCK_TOPIC = STEP_TOPIC
# /formation/step carries std_msgs/Float64MultiArray data = [version, step_index, time].
_STEP_INDEX = 1
_STEP_TIME_INDEX = 2
_NS_PER_S = 1_000_000_000


class RecorderError(BagError):
    """The recorder could not be set up or could not write its bag."""



class RecorderConfigError(RecorderError, ValueError):
    """A recorder parameter is missing or out of range."""





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
    - ``heartbeat_topic`` (string): after every flush and every step recorded,
      ``{"version": 1, "recorder": NODE, "recorded": N, "step": K}`` (std_msgs/String, the
      protocol's QoS): N messages written so far, the latest step K recorded (-1: none). The
      simulator keeps its steps at most `formation_sim.runtime.sim_node.RECORDER_LAG` ahead of K,
      and its writer's DDS liveliness tells a run the recorder still works ('' = off).
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
        heartbeat_topic: str = RECORDER_TOPIC,
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
        heartbeat_topic = str(self.declare_parameter('heartbeat_topic', heartbeat_topic).value)
        self._heartbeat_topic = heartbeat_topic
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
        self._step_index = -1  # the latest step recorded (-1: none yet)
        self.received_count = 0  # messages taken from all subscriptions, recorded or not
        self.flushed_count = 0  # messages in the file for sure (as of the last flush)
        self.failure: RecorderError | None = None  # the bag could not be written
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

        self._heartbeat = None
        if heartbeat_topic:
            from std_msgs.msg import String

            from formation_msgs_py.qos import PROTOCOL_QOS  # its liveliness lease is the run's

            self._heartbeat = self.create_publisher(String, heartbeat_topic, PROTOCOL_QOS)
            self._heartbeat_type = String
        self._timers = [self.create_timer(flush_period, self._flush)]
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

    def _fail(self, error: OSError) -> None:
        """The bag cannot be written (a full disk): stop recording; `main` leaves with the error."""
        self.failure = RecorderError(
            f'cannot write the bag {self.bag.path}: {error}; recording stopped, {self.flushed_count} '
            'messages are in the file (formation recover BAG rebuilds it, once there is space)'
        )

    def _flush(self) -> None:
        if self.failure is not None:
            return
        try:
            self.bag.flush()
        except OSError as error:
            self._fail(error)
            return
        self.flushed_count = self.bag.message_count
        self._beat()

    def _beat(self) -> None:
        if self._heartbeat is not None:
            beat = {'version': 1, 'recorder': self.get_fully_qualified_name(), 'recorded': self.bag.message_count, 'step': self._step_index}
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
            if is_clock:
                self._on_step(rawdata)
            if record and self.failure is None:
                try:
                    self.bag.write(name, self._timestamp_ns(), rawdata)
                except OSError as error:
                    self._fail(error)
            if is_clock and self.failure is None:
                self._beat()  # a run paces its steps on this (the simulator's flow control)

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
            if float(data[_STEP_INDEX]).is_integer():
                self._step_index = int(data[_STEP_INDEX])
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
        """Finalize the bag (MCAP summary and ``metadata.yaml``), unless it could not be written.

        Raises:
            RecorderError: finalizing failed (a full disk); the MCAP file is then cut short and
                has no ``metadata.yaml`` (`formation_sim.bag.recovery.reindex` rebuilds it).

        """
        self.stop_timers()
        if self.failure is not None:
            return  # writing more would fail again: the file stays as the last flush left it
        try:
            self.bag.close()
        except OSError as error:
            self._fail(error)
            raise self.failure from None


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder until SIGINT or SIGTERM, then finalize the bag."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from formation_agent.ros.process import make_executor

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
        while not stop.is_set() and node.failure is None:
            executor.spin_once(timeout_sec=0.1)
        node.stop_timers()
        if node.failure is None:
            node.drain(executor, interrupted=lambda: requests > 1)
            node.get_logger().info(f'stopping: {node.message_count} messages in {node.bag.path}')
            node.close()
    except RecorderError:
        if node is None or node.failure is None:
            raise  # not the bag failing to be written (e.g. a bad parameter)
    finally:
        if node is not None:
            with contextlib.suppress(RecorderError):
                node.close()
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if node is not None and node.failure is not None:
        with contextlib.suppress(OSError):  # the log may be on the full disk too
            print(f'formation_recorder: {node.failure}', file=sys.stderr, flush=True)
        return 1
    return 0


if __name__ == '__main__':
    from formation_agent.ros.process import exit_process

    exit_process(main())
