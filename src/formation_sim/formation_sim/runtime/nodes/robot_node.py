"""A simulated robot: what the robot backends of `formation run` (one per robot kind of
`formation_agent.core.kinds`: `holonomic`, `unicycle`) put under each agent, as a swarm stack's
simulation backend stands in for its hardware.

Each robot is its own node (`/agent_<i>/simulated_robot`, its own process by default) and talks to
its agent only as a real robot would (README, "Running on robots"; names in
`formation_msgs_py.topics`):

- it takes velocity commands on `/agent_<i>/robot/cmd_vel`, of its kind's message type:
  `geometry_msgs/TwistStamped` in the world frame (`header.frame_id` = `world_frame`) for a
  holonomic robot, `geometry_msgs/Twist` (v = linear.x, ω = angular.z) in its body frame for a
  unicycle (differential drive);
- it publishes its pose at `rate` Hz (100 by default): `geometry_msgs/PoseStamped` on
  `/agent_<i>/robot/pose` and `nav_msgs/Odometry` on `/agent_<i>/robot/odom` (pose in the world
  frame, twist in the body frame, REP 105), with seeded Gaussian noise (`pose_noise`, `yaw_noise`)
  and `pose_latency` s late (stamped with the time of the measurement);
- for tools only, the noise-free state on `/agent_<i>/robot/true_odom` (the run's summary and
  `formation analyze` measure the formation on it; an agent never reads it).

Between ticks the robot moves exactly under the command it holds (`formation_sim.sim.robots`, by
its kind's model: a straight line, or the closed-form arc of a unicycle); a command takes effect at
the first tick at least `command_latency` s after it arrived, clipped to `max_linear_speed` and
`max_angular_speed` as a real base clips it.  A robot whose commands stop coming (its agent died,
the network broke) stops `command_timeout` s after the last one took effect, as a real base's
watchdog stops it: at that instant, not at the next tick, so a robot whose process was frozen
(SIGSTOP) moved under its last command for `command_timeout` at most, however long the freeze (its
first tick after it went 2 s under the held command before: 0.60 m at 0.3 m/s).  Command ages are
measured on the monotonic clock, which runs on through a freeze.

Time is the wall clock (`time.time()`, the clock of the Step 0 epoch the agents time their
triggers from), so poses line up with the run on one machine and on machines whose clocks agree.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import traceback
from collections import deque
from collections.abc import Sequence
from typing import NoReturn

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from formation_agent.core.kinds.shape import Geometry, declared
from formation_agent.ros.commands import command_message
from formation_agent.ros.errors import ParameterError
from formation_agent.ros.kind_parameters import SpecTable, limit_spec, shape_specs
from formation_agent.ros.parameters import (
    BOOL,
    DOUBLE,
    DOUBLE_ARRAY,
    INTEGER,
    STRING,
    ParameterSpec,
    declare_parameters,
    parameter_help,
)
from formation_agent.ros.process import StopSignals, exit_process, make_executor, release_ros, shutdown_guard
from formation_msgs_py.cdr import OdometryWriter, pack_pose_stamped, twist_fields, twist_stamped_fields
from formation_msgs_py.errors import MessageError
from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.qos import ROBOT_COMMAND_READER_QOS
from formation_msgs_py.topics import (
    ROBOT_NODE,
    WORLD_FRAME,
    agent_namespace,
    robot_command_topic,
    robot_odom_topic,
    robot_pose_topic,
    robot_true_odom_topic,
)
from formation_msgs_py.types import MAX_AGENT_ID
from formation_sim.sim.errors import RobotError
from formation_sim.sim.robots import ROBOT_MODELS, Command, Limits, PoseNoise, make_robot, quaternion_from_yaw

NODE_NAME = ROBOT_NODE

# A robot's topics keep ROS's default profile (reliable, volatile, keep last 10), what mobile bases
# and motion-capture bridges use: a command stream supersedes itself, a late joiner wants no old
# poses.  Reliable, so the recorder (a reliable reader) matches and records them.
ROBOT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


_HEAD = (
    ParameterSpec(
        name='robot_id',
        type=INTEGER,
        description='id i of the agent this robot carries',
        low=0,
        high=MAX_AGENT_ID,
    ),
    ParameterSpec(
        name='model', type=STRING, default='unicycle', description='kinematics', choices=ROBOT_MODELS
    ),
    ParameterSpec(
        name='position',
        type=DOUBLE_ARRAY,
        description="initial position in the scenario's sense [m] (a unicycle: its control point)",
    ),
    ParameterSpec(name='yaw', type=DOUBLE, default=0.0, description='initial heading θ [rad]'),
)
_TAIL = (
    ParameterSpec(
        name='rate',
        type=DOUBLE,
        default=100.0,
        low=0.0,
        low_open=True,
        description='ticks (pose publications) per second [Hz]',
    ),
    limit_spec('max_linear_speed', 'speed limit [m/s]'),
    limit_spec('max_angular_speed', 'turn-rate limit [rad/s]'),
    limit_spec('max_steering_angle', 'car: steering limit φ_max [rad]'),
    ParameterSpec(
        name='pose_noise',
        type=DOUBLE,
        default=0.0,
        low=0.0,
        description='σ of the Gaussian noise on each position axis [m]',
    ),
    ParameterSpec(
        name='yaw_noise',
        type=DOUBLE,
        default=0.0,
        low=0.0,
        description='σ of the Gaussian noise on the heading [rad]',
    ),
    ParameterSpec(
        name='pose_latency',
        type=DOUBLE,
        default=0.0,
        low=0.0,
        description='delay between a measurement and its publication [s] (stamped with the measurement time)',
    ),
    ParameterSpec(
        name='command_latency',
        type=DOUBLE,
        default=0.0,
        low=0.0,
        description='delay before a command takes effect [s]',
    ),
    ParameterSpec(
        name='command_timeout',
        type=DOUBLE,
        default=0.5,
        low=0.0,
        low_open=True,
        description='stop when no command has come for this long [s]',
    ),
    ParameterSpec(
        name='seed',
        type=INTEGER,
        default=0,
        low=0,
        description='seed of the pose noise (one stream per robot)',
    ),
    ParameterSpec(
        name='world_frame',
        type=STRING,
        default=WORLD_FRAME,
        description='frame of poses and holonomic commands',
    ),
    ParameterSpec(
        name='publish_truth',
        type=BOOL,
        default=True,
        description='also publish the noise-free state on robot/true_odom',
    ),
)


def _robot_parameters() -> tuple[ParameterSpec, ...]:
    """Built at each use: a kind registered later brings its shape parameters."""
    return (*_HEAD, *shape_specs('robot'), *_TAIL)


SPECS = SpecTable(_robot_parameters)
"""A simulated robot's parameters (`formation_robot --help`; docs/PARAMETERS.md)."""


class SimulatedRobotNode(Node):
    """One kinematic robot (of a registered kind) at a fixed rate, talking only poses and commands.

    `own_timer` False: the robot ticks when `tick()` is called (`RobotTicker`: one timer for the
    robots of a process at each rate).
    """

    def __init__(
        self,
        *,
        namespace: str | None = None,
        parameter_overrides: list[Parameter] | None = None,
        context=None,
        own_timer: bool = True,
    ) -> None:
        super().__init__(
            NODE_NAME, namespace=namespace, parameter_overrides=parameter_overrides or [], context=context
        )
        p = declare_parameters(self, SPECS)
        self.robot_id = int(p['robot_id'])
        name = self.get_fully_qualified_name()
        try:
            self.robot = make_robot(
                p['model'],
                scenario_position=p['position'],
                yaw=float(p['yaw']),
                geometry=Geometry(**{shape.name: float(p[shape.name]) for shape in declared(node='robot')}),
                limits=Limits(
                    linear=float(p['max_linear_speed']),
                    angular=float(p['max_angular_speed']),
                    steering=float(p['max_steering_angle']),
                ),
            )
            self.noise = PoseNoise(
                position_sigma=float(p['pose_noise']),
                yaw_sigma=float(p['yaw_noise']),
                seed=int(p['seed']),
                robot_id=self.robot_id,
            )
        except RobotError as error:
            raise RobotError(f'{name}: {error}') from None
        self.world_frame = str(p['world_frame'])
        self.body_frame = f'{agent_namespace(self.robot_id).lstrip("/")}/base_link'
        self.pose_latency = float(p['pose_latency'])
        self.command_latency = float(p['command_latency'])
        self.command_timeout = float(p['command_timeout'])
        self.world_frame_command = (
            self.robot.world_frame_command
        )  # TwistStamped in the world frame, else Twist (v, ω)

        self._pose_pub = self.create_publisher(PoseStamped, robot_pose_topic(self.robot_id), ROBOT_QOS)
        self._odom_pub = self.create_publisher(Odometry, robot_odom_topic(self.robot_id), ROBOT_QOS)
        self._truth_pub = (
            self.create_publisher(Odometry, robot_true_odom_topic(self.robot_id), ROBOT_QOS)
            if p['publish_truth']
            else None
        )
        # Raw: its fields read from its bytes (formation_msgs_py.cdr), no rclpy message (issue 19).
        self._command_sub = self.create_subscription(
            command_message(self.robot.kind),
            robot_command_topic(self.robot_id),
            self._on_command,
            ROBOT_COMMAND_READER_QOS,  # the newest command only: none from before a freeze after it
            raw=True,
        )
        self._commands: deque[tuple[float, Command]] = deque()  # (monotonic arrival, command) to apply
        self._measurements: deque[tuple[float, np.ndarray, float, np.ndarray, float]] = (
            deque()
        )  # pose_latency queue
        self._last_command_at: float | None = None  # arrival of the command the robot holds (monotonic)
        self.commands_received = 0
        self.commands_refused = 0
        self.timeouts = 0  # times the robot stopped because commands stopped coming
        # Published as CDR bytes (formation_msgs_py.cdr): building two Odometry messages a tick was
        # most of a robot's CPU (issue 19).
        self._truth = OdometryWriter(frame=self.world_frame, child_frame=self.body_frame, sigma=(0.0, 0.0))
        self._measured = OdometryWriter(
            frame=self.world_frame,
            child_frame=self.body_frame,
            sigma=(self.noise.position_sigma, self.noise.yaw_sigma),
        )
        self.rate = float(p['rate'])
        self._last_tick = time.time()
        self._last_tick_clock = time.monotonic()  # the same instant on the monotonic clock
        self._timer = self.create_timer(1.0 / self.rate, self.tick) if own_timer else None

    # -- commands -------------------------------------------------------------------------------

    def _on_command(self, data: bytes) -> None:
        now = time.monotonic()
        try:
            if self.world_frame_command:
                frame, twist = twist_stamped_fields(data)
            else:
                frame, twist = None, twist_fields(data)
        except MessageError as error:
            self._refuse(f'refused a command that is not a {self.robot.kind.command_type}: {error}')
            return
        if frame is not None and frame != self.world_frame:
            self._refuse(
                f'refused a command in frame {frame!r}: this {self.robot.model} robot takes world-frame '
                f'velocities in {self.world_frame!r}'
            )
            return
        linear = twist[: self.robot.dimension] if self.world_frame_command else twist[:1]
        command = Command(linear=linear, angular=twist[5])
        values = (*command.linear, command.angular)
        if not all(math.isfinite(v) for v in values):
            self._refuse(f'refused a command with a non-finite value: {values}')
            return
        self.commands_received += 1
        self._commands.append((now, command))

    def _refuse(self, why: str) -> None:
        self.commands_refused += 1
        if self.commands_refused <= 3 or self.commands_refused % 100 == 0:
            self.get_logger().warning(f'{why} ({self.commands_refused} refused so far)')

    def _take_command(self, clock: float) -> None:
        """The newest command that arrived at least `command_latency` before `clock` (monotonic)."""
        due = None
        while self._commands and self._commands[0][0] + self.command_latency <= clock:
            due = self._commands.popleft()
        if due is not None:
            self._last_command_at = due[0]
            self.robot.set_command(due[1])

    def _timeout_after(self) -> float | None:
        """Seconds after the last tick at which the base's watchdog stops the non-zero command it
        holds (`command_timeout` after it took effect; <= 0: already due), or None."""
        held = self.robot.command
        if held is None or held.is_zero or self._last_command_at is None:
            return None
        return self._last_command_at + self.command_latency + self.command_timeout - self._last_tick_clock

    def _move(self, elapsed: float) -> None:
        """Move exactly for `elapsed` s since the last tick under the command held, stopped at the
        instant its timeout passes (a tick late, or a freeze late, the robot moved no further)."""
        stop_after = self._timeout_after()
        if stop_after is None or stop_after >= elapsed:
            self.robot.advance(elapsed)
            return
        before = min(elapsed, max(0.0, stop_after))
        self.robot.advance(before)
        self.timeouts += 1
        self.get_logger().warning(
            f'no command for {self.command_timeout} s: stopping (timeout {self.timeouts}; '
            f'{elapsed - before:.3f} s before this tick)'
        )
        held = self.robot.command
        self.robot.set_command(Command(linear=(0.0,) * len(held.linear), angular=0.0))
        self.robot.advance(elapsed - before)

    # -- ticks ----------------------------------------------------------------------------------

    def tick(self) -> None:
        """Move to now under the command held (exactly), publish, take the command due."""
        now, clock = time.time(), time.monotonic()
        # Exact, under the command held since the last tick (until its timeout, if that passed).
        self._move(max(0.0, now - self._last_tick))
        self._last_tick, self._last_tick_clock = now, clock
        position, yaw = self.robot.position.copy(), self.robot.yaw
        linear, angular = self.robot.body_twist()
        if self._truth_pub is not None:
            self._truth_pub.publish(
                self._truth.pack(now, _xyz(position), quaternion_from_yaw(yaw), linear, angular)
            )
        measured, measured_yaw = self.noise.measure(position, yaw)
        self._measurements.append((now, measured, measured_yaw, linear, angular))
        while self._measurements and self._measurements[0][0] + self.pose_latency <= now:
            stamp, where, heading, body_linear, body_angular = self._measurements.popleft()
            where, orientation = _xyz(where), quaternion_from_yaw(heading)
            self._odom_pub.publish(self._measured.pack(stamp, where, orientation, body_linear, body_angular))
            if self._pose_pub.get_subscription_count():  # most readers take the odometry
                self._pose_pub.publish(pack_pose_stamped(stamp, self.world_frame, where, orientation))
        self._take_command(clock)  # held from now to the next tick


class RobotTicker:
    """The robots of a process ticked by one timer per rate: a timer of its own per robot woke the
    executor 400 times a second for 4 robots at 100 Hz (issue 19, BENCHMARKS.md "CPU of a robot
    run").  Each robot still reads the clock itself (`SimulatedRobotNode.tick`)."""

    def __init__(self, robots: Sequence[SimulatedRobotNode]) -> None:
        by_rate: dict[float, list[SimulatedRobotNode]] = {}
        for robot in robots:
            by_rate.setdefault(robot.rate, []).append(robot)
        self._timers = [
            group[0].create_timer(1.0 / rate, lambda group=tuple(group): _tick_all(group))
            for rate, group in by_rate.items()
        ]


def _tick_all(robots: Sequence[SimulatedRobotNode]) -> None:
    for robot in robots:
        robot.tick()


def _xyz(position: np.ndarray) -> tuple[float, float, float]:
    """A position of 1 to 3 axes as (x, y, z), the axes it lacks 0."""
    values = [float(v) for v in position] + [0.0, 0.0]
    return values[0], values[1], values[2]


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='formation_robot',
        description='Simulated kinematic robots (of a registered kind: parameter model) for formation runs: '
        'each takes velocity commands on /agent_<i>/robot/cmd_vel and publishes its pose and odometry.',
        epilog=parameter_help(SPECS)
        + '\n\nParameters per robot, keyed by node name /agent_<i>/simulated_robot '
        '(formation run --backend unicycle writes robots.params.yaml).',
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        '--robots',
        help='comma-separated robot ids to run in this process, each in namespace /agent_<i> '
        '(default: one node whose namespace and parameters come from the ROS arguments)',
    )
    return parser.parse_args(list(argv))


def main(args: Sequence[str] | None = None) -> int:
    argv = list(args if args is not None else sys.argv)
    options = _parse(rclpy.utilities.remove_ros_args(argv)[1:])  # --help before ROS starts
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[SimulatedRobotNode] = []
    executor = None
    status = 0
    with StopSignals() as stop:
        try:
            if options.robots:
                for robot_id in (int(text) for text in options.robots.split(',') if text.strip()):
                    nodes.append(
                        SimulatedRobotNode(
                            namespace=agent_namespace(robot_id),
                            parameter_overrides=[Parameter('robot_id', Parameter.Type.INTEGER, robot_id)],
                            own_timer=False,
                        )
                    )
                ticker = RobotTicker(nodes)  # noqa: F841 - its timers belong to the nodes
            else:
                nodes.append(SimulatedRobotNode())
            executor = make_executor('events')
            for node in nodes:
                executor.add_node(node)
            never = Future()  # a robot runs until it is stopped, as a real one does
            while True:
                # Every event of 0.1 s dispatched in C++, then a look at the stop signals: a
                # spin_once per event cost 40 µs of CPU each, this 24 (600 events/s for 4 robots).
                executor.spin_until_future_complete(never, timeout_sec=0.1)
                stop.check()
        except (KeyboardInterrupt, ExternalShutdownException):
            status = 0
        except (ParameterError, RobotError) as error:  # bad input: every problem named, nothing started
            print(f'formation_robot: {error}', file=sys.stderr, flush=True)
            status = ExitCode.BAD_INPUT
        except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
            if stop.received.is_set() or not rclpy.ok():
                return 0
            print(f'formation_robot: {error}', file=sys.stderr, flush=True)
            traceback.print_exc(file=sys.stderr)
            status = 1
        finally:
            for node in nodes:
                node.get_logger().info(
                    f'commands received {node.commands_received}, refused {node.commands_refused}, '
                    f'clipped by the limits {node.robot.saturated}, stops on timeout {node.timeouts}'
                )
            with shutdown_guard('formation_robot', lambda: status, announce=bool(nodes)):
                release_ros(executor, nodes)
                executor = None  # its C++ teardown, under the guard
    return status


def entry_point() -> NoReturn:
    """The `formation_robot` console script: `main()`, then `exit_process` (a plain entry point's
    `sys.exit(main())` would run the interpreter's finalization and C++ static destructors after
    rclpy's shutdown)."""
    exit_process(main())


if __name__ == '__main__':
    entry_point()
