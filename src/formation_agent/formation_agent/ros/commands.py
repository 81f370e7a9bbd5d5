"""Where an agent node's commands go (parameter `robot`), and the zero command when it stops.

- `PlantOutput` ('none'): the agent's command as is to the simulator's plant — u_i on `cmd_vel`
  (geometry_msgs/Twist, eq. uxsingle) or u^d_i on `cmd_accel` (geometry_msgs/Accel); the plant
  closes -k3 q_i(t) of (uxdouble) itself.  Published at triggers only.
- `RobotOutput` (a robot kind of `formation_agent.core.kinds`: 'holonomic', 'unicycle', 'car'): a
  robot's velocity command from `formation_agent.core.commander.RobotCommander` by its kind's
  adapter, of its kind's message type (`command_message`) — a world-frame TwistStamped
  (holonomic) or a body-frame Twist (v, ω) (differential drive, from the robot's heading) —
  within the robot's limits, recomputed and republished at `command_rate` (a unicycle's (v, ω) depends on its
  heading, ETA-2's velocity reference on time).

`stop()` sends the zero command (once, nothing after it; to a robot as many times as a default
command reader keeps, so that a robot frozen meanwhile holds only zeros when it resumes:
`formation_msgs_py.qos.ROBOT_COMMAND_QOS`).  The node calls it on every way out: the final Step, a
lost peer, SIGINT/SIGTERM, a stale pose, any exception.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable

from geometry_msgs.msg import Accel, Twist

from formation_agent.core.commander import RobotCommander
from formation_agent.core.errors import PoseError
from formation_agent.core.kinds import RobotKind
from formation_agent.core.kinematics import yaw
from formation_agent.core.speed_scale import damping
from formation_agent.ros.errors import StaleStateError
from formation_msgs_py.cdr import pack_body_velocity, pack_world_velocity
from formation_msgs_py.codec import encode_acceleration_command, encode_velocity_command
from formation_msgs_py.qos import PROTOCOL_QOS, ROBOT_COMMAND_QOS
from formation_msgs_py.types import SensedState


def command_message(kind: RobotKind) -> type:
    """The ROS message class of a kind's command, from its type name ('geometry_msgs/msg/Twist')."""
    package, _, name = kind.command_type.rpartition('/')
    return getattr(importlib.import_module(package.replace('/', '.')), name)


def publish_zero(publisher, kind: RobotKind, *, dimension: int, world_frame: str) -> None:
    """A robot's zero command of its kind (a world-frame TwistStamped stamped now, or a body-frame
    Twist), `ROBOT_COMMAND_QOS.depth` times in a row: a frozen robot's reader of the default depth
    holds only zeros when it resumes, not the commands sent before."""
    zero = kind.zero_command(dimension)
    if kind.world_frame_command:
        message = pack_world_velocity(zero, frame_id=world_frame, stamp=time.time())
    else:
        message = pack_body_velocity(*zero)
    for _ in range(ROBOT_COMMAND_QOS.depth):
        publisher.publish(message)


class PlantOutput:
    """robot: none — u_i / u^d_i to the simulator's plant (or any plant that takes them)."""

    robot_commands = 0  # no robot: nothing sent to one, nothing clipped

    @property
    def saturation(self) -> dict:
        return {}

    def __init__(self, node, config) -> None:
        double = config.double
        self._encode = encode_acceleration_command if double else encode_velocity_command
        self._zeros = (0.0,) * config.dimension
        self.publisher = node.create_publisher(
            Accel if double else Twist, 'cmd_accel' if double else 'cmd_vel', PROTOCOL_QOS
        )
        self._wall_clock = False
        self._stopped = False
        self.sent = 0  # commands published (its report's count of what a recorder must hold)

    def start(self, epoch: float) -> None:
        self._wall_clock = True

    def publish(self, t: float, control, sensed: SensedState) -> None:
        if not self._stopped:
            self.publisher.publish(self._encode(control))
            self.sent += 1

    def stop(self) -> None:
        """A zero command on the wall clock.  In lock-step none: the simulated world stops with the
        run, and a command outside a triggering time would be a protocol violation."""
        if self._wall_clock and not self._stopped:
            self.publisher.publish(self._encode(self._zeros))
            self.sent += 1
        self._stopped = True


class RobotOutput:
    """robot: a robot kind — velocity commands to the robot, republished at `command_rate`.

    `poses.fresh(robot, t=, now=)` gives its own robot's latest pose or raises PoseError
    (`formation_agent.ros.sensing.PoseSensing`: taken from its reader at each command).
    """

    def __init__(
        self,
        node,
        config,
        poses,
        *,
        on_failure: Callable[[Exception], None],
        guard: Callable[[float, float], None] | None = None,
    ) -> None:
        """`guard(now, t)` before each periodic command: raises StaleStateError after a freeze
        (`formation_agent.ros.staleness`); `on_failure(error)` once the robot is stopped."""
        self._node = node
        self._config = config
        self._poses = poses
        self._on_failure = on_failure
        self._guard = guard
        self.commander = RobotCommander(
            drive=config.robot,
            dimension=config.dimension,
            limits=config.limits,
            geometry=config.geometry,
            k3=damping(config.gains['k3'], config.gains['speed_scale']) if config.double else None,  # κ k3
            time_warp=config.time_warp,  # the agent's controls are then u_p: sent as κ(t) u_p
        )
        self._world_frame = self.commander.kind.world_frame_command  # TwistStamped; else Twist (v, ω)
        self.publisher = node.create_publisher(
            command_message(self.commander.kind), config.robot_command_topic, ROBOT_COMMAND_QOS
        )
        self._epoch = 0.0
        self._last_t = 0.0  # the latest time a command was computed for (the clock may step back)
        self._timer = None
        self._stopped = False

    @property
    def robot_commands(self) -> int:
        return self.commander.commands

    @property
    def saturation(self) -> dict:
        return self.commander.saturation.records

    def start(self, epoch: float) -> None:
        self._epoch = epoch

    def publish(self, t: float, control, sensed: SensedState) -> None:
        """The agent's new command at its trigger t: send at once, then keep sending at the command rate."""
        if self._stopped:
            return
        self._last_t = max(self._last_t, t)
        self.commander.set_control(t, control, sensed.velocity)
        self._send()
        if self._timer is None:
            self._timer = self._node.create_timer(1.0 / self._config.command_rate, self._tick)

    def _tick(self) -> None:
        if self._stopped:
            return
        try:
            wall = time.time()
            if self._guard is not None:
                self._guard(wall, wall - self._epoch)
            self._send(wall)
        except (
            PoseError,
            StaleStateError,
        ) as error:  # its own pose, or all it knows, went stale: stop now, then leave
            self.stop()
            self._on_failure(error)

    def _send(self, wall: float | None = None) -> None:
        wall = time.time() if wall is None else wall
        t = self._last_t = max(wall - self._epoch, self._last_t)
        pose = self._poses.fresh(self._config.agent_id, t=t, now=wall)  # an unobserved robot stops
        # As CDR bytes (`formation_msgs_py.cdr`): no Python message to build and convert (issue 19).
        if self._world_frame:
            velocity = self.commander.command(t)
            self.publisher.publish(
                pack_world_velocity(velocity, frame_id=self._config.world_frame, stamp=wall)
            )
        else:
            self.publisher.publish(pack_body_velocity(*self.commander.command(t, yaw(pose.orientation))))

    def stop(self) -> None:
        """The zero command (`publish_zero`); nothing is sent after it."""
        if self._stopped:
            return
        self._stopped = True
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None
        publish_zero(
            self.publisher,
            self.commander.kind,
            dimension=self._config.dimension,
            world_frame=self._config.world_frame,
        )
