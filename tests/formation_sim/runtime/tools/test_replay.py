"""`formation replay`: a checker node receives every recorded message once, in order, byte for byte."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import pytest

from formation_sim.bag.io import BagWriter, read_bag
from formation_sim.runtime.errors import ReplayError
from formation_sim.runtime.nodes.recorder import import_message_class
from formation_sim.runtime.tools.replay import BagPlayer, main_replay

REPLAY_DOMAINS = {'synthetic': 171, 'distributed': 173, 'live': 66, 'elsewhere': 67}


def _synthetic_bag(path: Path) -> Path:
    """Three topics, bursts of messages sharing a time stamp, no /clock; each message distinct."""
    from geometry_msgs.msg import Twist
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray, String

    with BagWriter(path) as bag:
        bag.add_topic('/formation/step', 'std_msgs/msg/Float64MultiArray')
        bag.add_topic('/agent_1/cmd_vel', 'geometry_msgs/msg/Twist')
        bag.add_topic('/formation/sensing_log', 'std_msgs/msg/String')
        for k in range(120):
            stamp = (k // 5) * 20_000_000  # 5 messages per stamp, 24 stamps over 0.46 s
            bag.write(
                '/formation/step',
                stamp,
                serialize_message(Float64MultiArray(data=[1.0, float(k), stamp / 1e9])),
            )
            if k % 2 == 0:
                twist = Twist()
                twist.linear.x = float(k)
                bag.write('/agent_1/cmd_vel', stamp, serialize_message(twist))
            if k % 3 == 0:
                bag.write('/formation/sensing_log', stamp, serialize_message(String(data=f'{{"k":{k}}}')))
    return path


def _aligned(data: bytes) -> bytes:
    """The payload as DDS delivers it: padded with zeros to a multiple of 4 bytes."""
    return data + bytes(-len(data) % 4)


class _Checker:
    """Raw subscriptions (reliable, keep all) to every topic of a bag, in a private domain."""

    def __init__(self, bag: Path, domain_id: int, *, clock: bool) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        self.rclpy = rclpy
        self.expected: dict[str, list[bytes]] = defaultdict(list)
        self.stamps: list[int] = []
        types = {}
        for message in read_bag(bag):
            self.expected[message.topic].append(_aligned(message.rawdata))
            types[message.topic] = message.msgtype
            if not self.stamps or self.stamps[-1] != message.timestamp_ns:
                self.stamps.append(message.timestamp_ns)
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node('replay_checker', context=self.context, start_parameter_services=False)
        qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1, reliability=ReliabilityPolicy.RELIABLE)
        self.received: dict[str, list[bytes]] = defaultdict(list)
        for topic, msgtype in types.items():
            self.node.create_subscription(
                import_message_class(msgtype),
                topic,
                lambda data, topic=topic: self.received[topic].append(bytes(data)),
                qos,
                raw=True,
            )
        self.clock: list[int] = []
        if clock:
            from rosgraph_msgs.msg import Clock

            self.node.create_subscription(
                Clock, '/clock', lambda msg: self.clock.append(msg.clock.sec * 10**9 + msg.clock.nanosec), qos
            )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    @property
    def total(self) -> int:
        return sum(map(len, self.expected.values()))

    def spin_until_done(self, process: subprocess.Popen, *, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while sum(map(len, self.received.values())) < self.total and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
            if process.poll() is not None and sum(map(len, self.received.values())) < self.total:
                # The player has left; what it published is on its way or lost: drain briefly.
                end = time.monotonic() + 2.0
                while time.monotonic() < end:
                    self.executor.spin_once(timeout_sec=0.05)
                break
        end = time.monotonic() + 0.3  # anything extra (duplicates) would arrive now
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)


def _replay(bag: Path, domain_id: int, tmp_path: Path, *arguments: str) -> subprocess.Popen:
    env = dict(
        os.environ,
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        ROS_LOG_DIR=str(tmp_path / 'ros_log'),
        RMW_IMPLEMENTATION='rmw_fastrtps_cpp',
    )
    log = (tmp_path / 'replay.log').open('w')
    command = [
        sys.executable,
        '-m',
        'formation_sim.cli',
        'replay',
        str(bag),
        '--domain-id',
        str(domain_id),
        '--wait-for-subscribers',
        '1',
        *arguments,
    ]
    return subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)


def _finish(process: subprocess.Popen, tmp_path: Path) -> str:
    try:
        process.wait(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return (tmp_path / 'replay.log').read_text()


def test_bad_rates_and_unknown_topics_are_refused(tmp_path):
    bag = _synthetic_bag(tmp_path / 'bag')
    with pytest.raises(
        ReplayError, match=r'rate must be a finite number >= 0 \(0: as fast as possible\), got -1.0'
    ):
        BagPlayer(None, bag, rate=-1.0)
    with pytest.raises(ReplayError, match=r"topics \['/nope'\] are not in"):
        BagPlayer(None, bag, topics=['/nope'])


def test_replay_of_a_missing_bag_exits_2(tmp_path, capsys):
    from formation_sim.cli import main

    assert main(['replay', str(tmp_path / 'missing')]) == 2
    assert 'no such bag' in capsys.readouterr().err


@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(180)
@pytest.mark.parametrize('speed', [['--as-fast-as-possible'], ['--rate', '5']], ids=['fast', 'rate5'])
def test_every_message_arrives_once_in_order_with_a_clock(tmp_path, speed):
    bag = _synthetic_bag(tmp_path / 'bag')
    checker = _Checker(bag, REPLAY_DOMAINS['synthetic'], clock=True)
    try:
        process = _replay(bag, REPLAY_DOMAINS['synthetic'], tmp_path, *speed)
        checker.spin_until_done(process, timeout=60)
        log = _finish(process, tmp_path)
        assert process.returncode == 0, log
        for topic, messages in checker.expected.items():
            assert checker.received[topic] == messages, (
                f'{topic}: {len(checker.received[topic])} received of {len(messages)}'
            )
        # The bag had no /clock: one per new time stamp, in order.
        assert checker.clock == checker.stamps
    finally:
        checker.close()


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_distributed_runs_bag_replays_completely(distributed_single_run, tmp_path):
    bag = distributed_single_run.bag
    checker = _Checker(bag, REPLAY_DOMAINS['distributed'], clock=False)  # /clock is one of the bag's topics
    try:
        process = _replay(bag, REPLAY_DOMAINS['distributed'], tmp_path, '--rate', '0')
        checker.spin_until_done(process, timeout=120)
        log = _finish(process, tmp_path)
        assert process.returncode == 0, log
        assert checker.total > 1000
        for topic, messages in checker.expected.items():
            assert checker.received[topic] == messages, (
                f'{topic}: {len(checker.received[topic])} received of {len(messages)}'
            )
    finally:
        checker.close()


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_replay_refuses_the_domain_of_a_live_run_on_this_machine(
    tmp_path, monkeypatch, wait_for_stepping, long_run_scenario
):
    """The run holds its domain's lock: the replay is refused before it publishes anything, and
    the run's bag holds only the run's own messages."""
    from formation_sim.cli import main
    from formation_sim.runtime.launch.orchestrate import FormationRun

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    domain = REPLAY_DOMAINS['live']
    bag = _synthetic_bag(tmp_path / 'old_bag')  # it has /formation/step and /agent_1/cmd_vel, as the run does
    run = FormationRun(
        long_run_scenario, out_dir=tmp_path / 'run', domain_id=domain, progress=False, timeout=240.0
    )
    results = []
    worker = threading.Thread(target=lambda: results.append(run.run()), daemon=True)
    worker.start()
    try:
        wait_for_stepping(run)
        with pytest.raises(ReplayError) as refused:
            main_replay(bag, domain_id=domain, rate=0.0)
        assert str(refused.value).startswith(
            f'ROS domain {domain} is held by another formation run: replaying there would '
        )
        assert main(['replay', str(bag), '--domain-id', str(domain), '--quiet']) == 2
    finally:
        run.interrupt()
        worker.join(timeout=120.0)
    (result,) = results
    assert result.exit_status == 130
    summary = json.loads(result.summary.read_text())
    assert summary['extra']['recording']['foreign'] == {}
    assert summary['extra']['recording']['complete'], summary['extra']['recording']


@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(180)
def test_replay_refuses_a_domain_whose_graph_shows_a_run_elsewhere(tmp_path, monkeypatch):
    """A run on another machine holds no lock here, but its nodes are in the domain's ROS graph."""
    import rclpy
    from std_msgs.msg import Float64MultiArray

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    domain = REPLAY_DOMAINS['elsewhere']
    bag = _synthetic_bag(tmp_path / 'bag')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        simulator = rclpy.create_node(
            'formation_simulator', context=context
        )  # as a remote run's would appear
        simulator.create_publisher(Float64MultiArray, '/formation/step', 10)
        with pytest.raises(ReplayError) as refused:
            main_replay(bag, domain_id=domain, rate=0.0)
        message = str(refused.value)
        assert message.startswith(f'ROS domain {domain} has a formation run live (/formation_simulator, ')
        assert (
            '/formation_simulator (writes /formation/step)' in message
            and 'choose another --domain-id' in message
        )
        simulator.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


@pytest.mark.ros
def test_replay_offers_the_recorded_qos_so_the_scenario_is_latched_for_late_joiners(tmp_path):
    """As ros2 bag play: each topic offered as its publishers offered it when recorded."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from std_msgs.msg import Float64MultiArray, String

    forever = QosTime(sec=9223372036, nsec=854775807)
    latched = Qos(
        QosHistory.UNKNOWN,
        0,
        QosReliability.RELIABLE,
        QosDurability.TRANSIENT_LOCAL,
        forever,
        forever,
        QosLiveliness.AUTOMATIC,
        QosTime(1, 0),
        False,
    )
    volatile = latched._replace(durability=QosDurability.VOLATILE, liveliness_lease_duration=forever)
    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/formation/scenario', 'std_msgs/msg/String', offered_qos_profiles=[latched])
        writer.add_topic(
            '/formation/state', 'std_msgs/msg/Float64MultiArray', offered_qos_profiles=[volatile]
        )
        writer.add_topic('/formation/status', 'std_msgs/msg/Float64MultiArray')  # recorded without QoS
        writer.write('/formation/scenario', 0, serialize_message(String(data='name: latched')))
        writer.write('/formation/state', 1, serialize_message(Float64MultiArray(data=[1.0])))
        writer.write('/formation/status', 2, serialize_message(Float64MultiArray(data=[2.0])))

    contexts = []
    for _ in range(2):
        contexts.append(rclpy.Context())
        rclpy.init(context=contexts[-1], domain_id=47)
    player_node = Node('bag_player', context=contexts[0], start_parameter_services=False)
    late = Node('late_joiner', context=contexts[1], start_parameter_services=False)
    try:
        result = BagPlayer(player_node, bag, rate=0.0, clock=False).play()  # nobody listens yet
        assert result.published == 3
        offered = {}
        deadline = time.monotonic() + 30
        while len(offered) < 3 and time.monotonic() < deadline:
            for topic in ('/formation/scenario', '/formation/state', '/formation/status'):
                if infos := late.get_publishers_info_by_topic(topic):
                    offered[topic] = infos[0].qos_profile
            time.sleep(0.05)
        assert offered['/formation/scenario'].durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert offered['/formation/scenario'].liveliness_lease_duration.nanoseconds == 10**9
        assert offered['/formation/state'].durability == DurabilityPolicy.VOLATILE
        assert (
            offered['/formation/status'].durability == DurabilityPolicy.TRANSIENT_LOCAL
        )  # none recorded: the player's default
        # A reader that comes after the replay still gets the scenario.
        got = []
        late.create_subscription(
            String,
            '/formation/scenario',
            got.append,
            QoSProfile(
                depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
            ),
        )
        executor = SingleThreadedExecutor(context=contexts[1])
        executor.add_node(late)
        deadline = time.monotonic() + 30
        while not got and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert [msg.data for msg in got] == ['name: latched']
    finally:
        player_node.destroy_node()
        late.destroy_node()
        for context in contexts:
            rclpy.try_shutdown(context=context)
