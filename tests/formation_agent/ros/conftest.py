"""A bench for one real agent process on robots: its robots' poses, its coordinator, its neighbour.

The agent is agent 1 of a two-agent team (edge 1-2, d_12 = (-1, 0), Δ = 4), sensing from poses
and commanding a robot; the bench, one rclpy node in the test process, plays everything around
it: the pose topics of robots 1 and 2 (100 Hz), the coordinator (Step 0 on the wall clock, the
final Step; it reads Status and reports), agent 2's triggering-information endpoints, and the
robot's command reader, which records every command with its arrival time.

Each test gets a ROS domain of its own from a small pool (`robot_domain`), held by a lock file
where `formation run` keeps its own, so tests in parallel (and other people's runs) never meet.
"""

from __future__ import annotations

import fcntl
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

TEAM = {
    'agent_id': 1,
    'algorithm': 'eta1',
    'dimension': 2,
    'neighbour_ids': [2],
    'neighbour_offsets': [-1.0, 0.0],
    'delta': 4.0,
    'horizon': 100.0,
    'alpha': 10.0,
    'beta': 1.0,
    'sensing': 'poses',
    'robot': 'holonomic',
}
DOMAIN_POOL = range(81, 90)  # below formation run's own range (100-232); no other test uses them
DOMAIN_LOCKS = Path('/tmp/formation_domains')  # where formation run locks the domains it uses


def agent_environment(domain_id: int, log_dir: Path) -> dict[str, str]:
    return {
        **os.environ,
        'ROS_DOMAIN_ID': str(domain_id),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(log_dir),
        'PYTHONUNBUFFERED': '1',
    }


class AgentProcess:
    """`formation_agent` for agent 1 in its own process; stdout/stderr kept in files."""

    def __init__(
        self,
        tmp_path: Path,
        domain_id: int,
        *,
        python_prelude: str | None = None,
        params_files: tuple[Path, ...] = (),
        **parameters,
    ) -> None:
        self.params_file = tmp_path / 'agent_1.params.yaml'
        values = {**TEAM, **parameters}
        self.params_file.write_text(yaml.safe_dump({'/agent_1/formation_agent': {'ros__parameters': values}}))
        ros_args = ['--ros-args', '-r', '__ns:=/agent_1', '--params-file', str(self.params_file)]
        for path in params_files:  # after the team's: the later file wins
            ros_args += ['--params-file', str(path)]
        if python_prelude is None:
            command = [sys.executable, '-m', 'formation_agent.ros.main', *ros_args]
        else:  # the test changes something inside the process first (a fault), then runs main
            script = (
                f'{python_prelude}\nimport sys\nfrom formation_agent.ros.main import main\n'
                'sys.exit(main(sys.argv))\n'
            )
            command = [sys.executable, '-c', script, *ros_args]
        self.stdout_path = tmp_path / 'agent_1.out'
        self.stderr_path = tmp_path / 'agent_1.err'
        with open(self.stdout_path, 'w') as out, open(self.stderr_path, 'w') as err:
            self.process = subprocess.Popen(
                command, stdout=out, stderr=err, env=agent_environment(domain_id, tmp_path / 'ros_log')
            )

    @property
    def stderr(self) -> str:
        return self.stderr_path.read_text()

    def signal(self, signum: int) -> None:
        self.process.send_signal(signum)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
            self.process.wait(timeout=10)


class Bench:
    """Robots 1 and 2, the coordinator and agent 2, around agent 1 (one node, spun by the test)."""

    def __init__(self, context, *, robot: str = 'holonomic', pose_type: str = 'pose') -> None:
        import rclpy
        from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
        from nav_msgs.msg import Odometry
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Float64MultiArray, String

        from formation_msgs_py.codec import decode_agent_report, decode_status
        from formation_msgs_py.qos import PROTOCOL_QOS
        from formation_msgs_py.topics import (
            REPORT_TOPIC,
            STATUS_TOPIC,
            STEP_TOPIC,
            robot_command_topic,
            robot_odom_topic,
            robot_pose_topic,
            trigger_info_topic,
        )

        self.node = rclpy.create_node('bench', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.pose_type = pose_type
        # Robot states: position (x, y), heading θ, body twist (v, ω) for Odometry.
        self.robots = {
            1: {'xy': (0.0, 0.0), 'theta': 0.0, 'twist': (0.0, 0.0)},
            2: {'xy': (0.5, 0.3), 'theta': 0.0, 'twist': (0.0, 0.0)},
        }
        self.silent: set[int] = set()  # robots whose poses stopped
        self.last_pose_at: dict[int, float] = {}  # time.time() each robot's pose was last published
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        kind, topic = (PoseStamped, robot_pose_topic) if pose_type == 'pose' else (Odometry, robot_odom_topic)
        self._pose_kind = kind
        self._pose_pubs = {
            robot: self.node.create_publisher(kind, topic(robot), reliable) for robot in self.robots
        }
        self._pose_timer = self.node.create_timer(0.01, self._publish_poses)
        self.commands: list[tuple[float, object]] = []  # (arrival wall time, message)
        command_kind = TwistStamped if robot == 'holonomic' else Twist
        self._command_sub = self.node.create_subscription(
            command_kind,
            robot_command_topic(1),
            lambda msg: self.commands.append((time.time(), msg)),
            QoSProfile(depth=1000),
        )
        self.step_pub = self.node.create_publisher(Float64MultiArray, STEP_TOPIC, PROTOCOL_QOS)
        self.statuses = []
        self.reports = []
        self._status_sub = self.node.create_subscription(
            Float64MultiArray,
            STATUS_TOPIC,
            lambda msg: self.statuses.append(decode_status(msg)),
            PROTOCOL_QOS,
        )
        self._report_sub = self.node.create_subscription(
            String, REPORT_TOPIC, lambda msg: self.reports.append(decode_agent_report(msg)), PROTOCOL_QOS
        )
        self.infos = []
        self._info_sub = self.node.create_subscription(
            Float64MultiArray, trigger_info_topic(1, 2), self.infos.append, PROTOCOL_QOS
        )
        self.info_pub = self.node.create_publisher(Float64MultiArray, trigger_info_topic(2, 1), PROTOCOL_QOS)
        self.epoch: float | None = None

    def _publish_poses(self) -> None:
        from builtin_interfaces.msg import Time

        now = time.time()
        stamp = Time(sec=int(now), nanosec=int((now - int(now)) * 1e9))
        for robot, state in self.robots.items():
            if robot in self.silent:
                continue
            msg = self._pose_kind()
            msg.header.stamp = stamp
            msg.header.frame_id = 'world'
            pose = msg.pose if self.pose_type == 'pose' else msg.pose.pose
            pose.position.x, pose.position.y = state['xy']
            pose.orientation.z, pose.orientation.w = (
                math.sin(state['theta'] / 2),
                math.cos(state['theta'] / 2),
            )
            if self.pose_type == 'odom':
                msg.child_frame_id = f'robot_{robot}'
                msg.twist.twist.linear.x, msg.twist.twist.angular.z = state['twist']
            self._pose_pubs[robot].publish(msg)
            self.last_pose_at[robot] = now

    def spin_until(self, predicate, *, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f'bench: timed out after {timeout} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)

    def start(self, *, timeout: float = 30.0) -> float:
        """Wait until the agent is connected, then Step 0 on the wall clock; returns its epoch."""
        from formation_msgs_py.codec import encode_step
        from formation_msgs_py.lockstep import DISCOVERY_STEP, STEP_FLAG_REALTIME, Step

        self.spin_until(
            lambda: any(s.step_index == DISCOVERY_STEP and s.ready for s in self.statuses),
            timeout=timeout,
            what='agent 1 to be connected (Status ready during discovery)',
        )
        self.epoch = time.time()
        self.step_pub.publish(
            encode_step(Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=self.epoch))
        )
        return self.epoch

    def finish(self) -> None:
        from formation_msgs_py.codec import encode_step
        from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME, Step

        t = time.time() - self.epoch
        self.step_pub.publish(
            encode_step(Step(index=1, time=t, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=self.epoch))
        )

    def send_info(self, info) -> None:
        from formation_msgs_py.codec import encode_trigger_info

        self.info_pub.publish(encode_trigger_info(info))

    def wait_for_exit(self, agent: AgentProcess, *, timeout: float = 20.0) -> int:
        self.spin_until(lambda: agent.process.poll() is not None, timeout=timeout, what='agent 1 to exit')
        self.spin_for(0.5)  # what it sent last is taken
        return agent.process.returncode

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()


@pytest.fixture
def robot_domain() -> int:
    """A ROS domain from DOMAIN_POOL, locked for the test (waits while all are in use)."""
    DOMAIN_LOCKS.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + 300.0
    while True:
        for domain in DOMAIN_POOL:
            handle = open(DOMAIN_LOCKS / f'{domain}.lock', 'w')  # noqa: SIM115 - held while the test runs
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.close()
                continue
            try:
                yield domain
            finally:
                handle.close()
            return
        if time.monotonic() > deadline:
            pytest.fail(
                f'every ROS domain in {DOMAIN_POOL.start}-{DOMAIN_POOL.stop - 1} stayed in use for 300 s'
            )
        time.sleep(0.5)


@pytest.fixture
def bench(robot_domain, tmp_path):
    """`bench(robot=..., pose_type=...) -> Bench`, on the test's own domain."""
    import rclpy

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=robot_domain)
    benches = []

    def build(**options) -> Bench:
        benches.append(Bench(context, **options))
        return benches[-1]

    try:
        yield build
    finally:
        for made in benches:
            made.close()
        rclpy.shutdown(context=context)


@pytest.fixture
def agent_process(tmp_path, robot_domain):
    """`agent_process(**parameters) -> AgentProcess`, agent 1 on the test's own domain; killed
    after the test."""
    agents = []

    def start(**parameters) -> AgentProcess:
        agents.append(AgentProcess(tmp_path, robot_domain, **parameters))
        return agents[-1]

    yield start
    for agent in agents:
        agent.kill()
