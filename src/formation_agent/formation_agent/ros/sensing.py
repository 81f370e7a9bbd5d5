"""Where an agent node senses, at its triggering times only (parameter `sensing`).

- `ServiceSensing` ('service'): its sensing service `/agent_<i>/sense` (std_srvs/Trigger), served
  by the simulator from the exact world (docs/MESSAGES.md, "SensedState").
- `PoseSensing` ('poses'): the latest poses of its own robot and its neighbours' on their pose
  topics (PoseStamped or Odometry), through `formation_agent.core.pose_sensing.PoseBook`; the
  trigger time is the wall-clock time since the run's epoch, when the poses are read.

Both hand the node a getter: calling it gives the SensedState or raises what went wrong.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from std_srvs.srv import Trigger

from formation_agent.core.pose_sensing import PoseBook
from formation_msgs_py.codec import MessageError, decode_odometry, decode_pose_stamped, decode_sensed_state
from formation_msgs_py.qos import ROBOT_POSE_QOS
from formation_msgs_py.types import SensedState

SensedGetter = Callable[[], SensedState]


SERVICE_LOOKS = (0.1, 1.0)
"""Seconds between looks for the sensing service during discovery, doubling from the first to the
second while it is not there: rmw_fastrtps answers whether a service is there by walking every
endpoint of the ROS graph it knows (1000 agents: ~20 000), where a match count is one number."""


class ServiceSensing:
    """The simulator's sensing service: one request per trigger, answered asynchronously."""

    def __init__(self, node) -> None:
        self._client = node.create_client(Trigger, 'sense')
        self._name = node.resolve_service_name('sense')
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
        future = self._client.call_async(Trigger.Request())
        future.add_done_callback(lambda done: on_sensed(lambda: decode_sensed_state(done.result())))


class PoseSensing:
    """The robots' pose topics: the latest pose of this robot and of each neighbour."""

    def __init__(self, node, config, *, reject: Callable[[str, str, str], None]) -> None:
        self._config = config
        self._reject = reject
        self.book = PoseBook(
            agent_id=config.agent_id,
            neighbour_ids=config.neighbour_ids,
            dimension=config.dimension,
            offset=config.control_point_offset,
            world_frame=config.world_frame,
            timeout=config.pose_timeout,
            topic=config.robot_pose_topic,
        )
        self._epoch: float | None = None
        kind, self._decode = (PoseStamped, decode_pose_stamped) if config.pose_type == 'pose' else (Odometry, decode_odometry)
        self._subs = [
            node.create_subscription(
                kind, config.robot_pose_topic(robot), lambda msg, robot=robot: self._on_pose(msg, robot), ROBOT_POSE_QOS
            )
            for robot in self.book.robots
        ]

    def _on_pose(self, msg, robot: int) -> None:
        topic = self._config.robot_pose_topic(robot)
        try:
            pose = self._decode(msg)
        except MessageError as error:
            self._reject(topic, error.reason, str(error))
            return
        if (refused := self.book.add(robot, pose)) is not None:
            self._reject(topic, *refused)

    def ready(self) -> bool:
        """Every pose topic has a writer and a first pose of every robot has arrived."""
        return all(sub.get_publisher_count() >= 1 for sub in self._subs) and self.book.has_all()

    def gaps(self) -> list[str]:
        """What sensing still waits for (empty: ready)."""
        unmatched = [sub.topic_name for sub in self._subs if sub.get_publisher_count() < 1]
        if unmatched:
            return [f'a writer of the robots\' poses on {", ".join(unmatched)}']
        missing = self.book.missing()
        return [f'a first pose on {", ".join(self._config.robot_pose_topic(robot) for robot in missing)}'] if missing else []

    def start(self, epoch: float) -> None:
        self._epoch = epoch

    def now(self) -> tuple[float, float]:
        """(t, wall time): the run's time since its epoch and the Unix time it is at."""
        wall = time.time()
        return wall - self._epoch, wall

    def request(self, on_sensed: Callable[[SensedGetter], None]) -> None:
        t, wall = self.now()  # the trigger: the poses as they are now
        on_sensed(functools.partial(self.book.sense, t=t, now=wall, velocities=self._config.double))
