"""Where an agent node senses, at its triggering times only (parameter `sensing`).

- `ServiceSensing` ('service'): its sensing service `/agent_<i>/sense` (rcl_interfaces/SetParameters:
  its request carries the run's tag), served by the simulator from the exact world
  (docs/MESSAGES.md, "SensedState").
- `PoseSensing` ('poses'): the latest poses of its own robot and its neighbours' on their pose
  topics (PoseStamped or Odometry), through `formation_agent.core.pose_sensing.PoseBook`; the
  trigger time is the wall-clock time since the run's epoch, when the poses are read.  Poses
  are taken from keep-last readers only when used (`PoseReaders`): every robot's at a trigger,
  its own robot's on the command timer (`fresh`), and during discovery until each has come.

Both hand the node a getter: calling it gives the SensedState or raises what went wrong.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

import rclpy
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from formation_agent.core.pose_sensing import PoseBook
from formation_msgs_py.cdr import decode_odometry_cdr, decode_pose_stamped_cdr
from formation_msgs_py.codec import (
    check_sensing_answer,
    decode_sensed_state,
    sense_reply_topic,
    sensing_request,
)
from formation_msgs_py.errors import MessageError, TagError
from formation_msgs_py.qos import ROBOT_POSE_QOS
from formation_msgs_py.types import RobotPose, SensedState

SensedGetter = Callable[[], SensedState]


SERVICE_LOOKS = (0.1, 1.0)
"""Seconds between looks for the sensing service during discovery, doubling from the first to the
second while it is not there: rmw_fastrtps answers whether a service is there by walking every
endpoint of the ROS graph it knows (1000 agents: ~20 000), where a match count is one number."""


class ServiceSensing:
    """The simulator's sensing service: one request per trigger, answered asynchronously.  With the
    run's key the request carries the agent's tag and an answer without the simulator's is refused
    (docs/HOSTILE_TRAFFIC.md, "Tags")."""

    def __init__(self, node) -> None:
        self._client = node.create_client(SetParameters, 'sense')
        self._name = node.resolve_service_name('sense')
        self._signer, self._verifier, self._reject = node.signer, node.verifier, node.reject
        self._found = False  # once there, the service stays (a simulator lost is seen by its liveliness)
        self._next_look = 0.0
        self._wait = SERVICE_LOOKS[0]

    def ready(self) -> bool:
        if not self._found and time.monotonic() >= self._next_look:
            self._found = self._client.service_is_ready()
            self._next_look = time.monotonic() + self._wait
            self._wait = min(2.0 * self._wait, SERVICE_LOOKS[1])
        return self._found

    def gaps(self) -> list[str]:
        """What sensing still waits for (empty: ready)."""
        return [] if self.ready() else [f'the sensing service {self._name} (served by the simulator)']

    def start(self, epoch: float) -> None:
        """Wall clock from `epoch` on (the simulator stamps its answers itself)."""

    def request(self, on_sensed: Callable[[SensedGetter], None]) -> None:
        future = self._client.call_async(sensing_request(self._signer, self._name))
        future.add_done_callback(lambda done: on_sensed(lambda: self._answer(done.result())))

    def _answer(self, response) -> SensedState:
        """The state in `response`; TagError (refused, counted, and the agent stops on it) for an
        answer without the simulator's tag: another server of the service answered first, and
        the client has taken it in place of the simulator's."""
        try:
            check_sensing_answer(self._verifier, self._name, response)
        except TagError as error:
            self._reject(sense_reply_topic(self._name), error.reason, str(error))
            raise
        return decode_sensed_state(response)

    def close(self) -> None:
        """Nothing of its own to destroy (its client is the node's)."""


def pose_take_depth(config) -> int:
    """Poses a pose reader keeps (keep last): the latest only, or also the one before it where
    ETA-2's velocity comes from PoseStamped differences (`PoseBook`).  Older poses are never
    looked at; a deeper history would only cost decoding (the command timer takes its own
    robot's poses at 50 Hz while a robot publishes at 100 Hz)."""
    return 2 if config.double and config.pose_type == 'pose' else 1


class PoseReaders:
    """Keep-last readers of the robots' pose topics whose messages are taken only when needed.

    The readers belong to a node of their own that no executor spins (`_formation_agent_poses`, hidden,
    in the agent's namespace; same context, so the same DDS participant): no callback runs and
    nothing is decoded when a pose arrives.  DDS keeps the newest one or two per topic (`pose_take_depth`);
    `take(robot)` takes those serialized and decodes them with `formation_msgs_py.cdr` (no Python
    message objects), then hands them to the `PoseBook` (refusals counted as before).
    A robot publishing at 100 Hz costs its agent nothing between the agent's own triggering
    times and command ticks (before: every pose of itself and of each neighbour was decoded in
    a callback, ~300 Odometry messages a second for two neighbours: 8 % of a core per agent, 4 % now).
    """

    def __init__(self, node, config, book: PoseBook, *, reject: Callable[[str, str, str], None]) -> None:
        self._book = book
        self._reject = reject
        kind, self._decode = (
            (PoseStamped, decode_pose_stamped_cdr)
            if config.pose_type == 'pose'
            else (Odometry, decode_odometry_cdr)
        )
        self.node = rclpy.create_node(
            f'_{node.get_name()}_poses',  # hidden ('_'): `ros2 node list` and `ros2 param list` skip it
            namespace=node.get_namespace(),
            context=node.context,
            use_global_arguments=False,  # the agent's node name and remappings are its own ...
            start_parameter_services=False,
            enable_rosout=False,
            parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, Parameter.Type.BOOL, False)],
        )
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=pose_take_depth(config),
            reliability=ROBOT_POSE_QOS.reliability,
            durability=ROBOT_POSE_QOS.durability,
        )
        # ... so the topics are resolved by the agent's node: remapping applies as to any of its topics.
        self.topics = {
            robot: node.resolve_topic_name(config.robot_pose_topic(robot)) for robot in book.robots
        }
        self._subs = {
            robot: self.node.create_subscription(kind, topic, _never, qos, raw=True)
            for robot, topic in self.topics.items()
        }

    def take(self, robot: int) -> None:
        """Every pose of `robot` waiting in its reader (at most `pose_take_depth`), oldest first,
        into the book."""
        sub = self._subs[robot]
        while True:
            with sub.handle:
                taken = sub.handle.take_message(
                    sub.msg_type, True
                )  # serialized: decoded by formation_msgs_py.cdr
            if taken is None:
                return
            try:
                pose = self._decode(taken[0])
            except MessageError as error:
                self._reject(self.topics[robot], error.reason, str(error))
                continue
            if (refused := self._book.add(robot, pose)) is not None:
                self._reject(self.topics[robot], *refused)

    def unmatched(self) -> list[str]:
        return [sub.topic_name for sub in self._subs.values() if sub.get_publisher_count() < 1]

    def close(self) -> None:
        self.node.destroy_node()


def _never(msg) -> None:
    raise AssertionError('pose readers are taken on demand, never spun')


class PoseSensing:
    """The robots' pose topics: the latest pose of this robot and of each neighbour, read when used."""

    def __init__(self, node, config, *, reject: Callable[[str, str, str], None]) -> None:
        self._config = config
        self.book = PoseBook(
            agent_id=config.agent_id,
            neighbour_ids=config.neighbour_ids,
            dimension=config.dimension,
            offset=config.control_point_offset,
            world_frame=config.world_frame,
            timeout=config.pose_timeout,
            topic=config.robot_pose_topic,
            # the safety layer: every other robot's pose too, those within R handed on as nearby
            other_ids=config.other_robot_ids if config.safety is not None else (),
            sensing_radius=None if config.safety is None else config.safety.sensing_radius,
        )
        self._epoch: float | None = None
        self.readers = PoseReaders(node, config, self.book, reject=reject)

    def _take_all(self) -> None:
        for robot in self.book.robots:
            self.readers.take(robot)

    def ready(self) -> bool:
        """Every pose topic has a writer and a first pose of every robot has arrived."""
        return not self.gaps()

    def gaps(self) -> list[str]:
        """What sensing still waits for (empty: ready)."""
        if unmatched := self.readers.unmatched():
            return [f"a writer of the robots' poses on {', '.join(unmatched)}"]
        self._take_all()
        missing = self.book.missing()
        return (
            [f'a first pose on {", ".join(self.readers.topics[robot] for robot in missing)}']
            if missing
            else []
        )

    def start(self, epoch: float) -> None:
        self._epoch = epoch

    def now(self) -> tuple[float, float]:
        """(t, wall time): the run's time since its epoch and the Unix time it is at."""
        wall = time.time()
        return wall - self._epoch, wall

    def fresh(self, robot: int, *, t: float, now: float) -> RobotPose:
        """The latest pose of `robot`, taken now, if it is fresh (`PoseBook.fresh`): the command
        timer's look at its own robot (the unicycle's heading, the stale-pose stop)."""
        self.readers.take(robot)
        return self.book.fresh(robot, t=t, now=now)

    def request(self, on_sensed: Callable[[SensedGetter], None]) -> None:
        self._take_all()  # the poses waiting now: the newest of each robot
        t, wall = self.now()  # the trigger: the poses as they are now
        on_sensed(functools.partial(self.book.sense, t=t, now=wall, velocities=self._config.double))

    def close(self) -> None:
        self.readers.close()
