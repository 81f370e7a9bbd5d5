"""formation_sim.runtime.tools.graph, `formation topics` and `formation echo`: inspection without ros2cli."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from formation_msgs_py.codec import encode_status, encode_step, encode_trigger_info, encode_world_state
from formation_msgs_py.lockstep import Status, Step, WorldState
from formation_msgs_py.types import TriggerInfo
from formation_sim.runtime.tools.graph import TopicInfo, format_message, format_topics

INSPECT_DOMAIN = 172
ARRAY = 'std_msgs/msg/Float64MultiArray'
INFO = TriggerInfo(
    sender=1, receiver=2, stamp=0.1 + 0.2, control=(-512.1339139675468, 5e-324), rel_position=(-1.0, 1.5)
)


def test_trigger_info_is_decoded_and_floats_read_back_exactly():
    text = format_message('/agent_1/trigger_info/to_2', ARRAY, encode_trigger_info(INFO))
    assert text.startswith('# TriggerInfo (formation layout, decoded)\n')
    fields = yaml.safe_load(text)
    assert fields == {
        'sender': 1,
        'receiver': 2,
        'stamp': 0.30000000000000004,
        'control': [-512.1339139675468, 5e-324],
        'rel_position': [-1.0, 1.5],
        'rel_velocity': None,
    }


def test_lock_step_payloads_are_decoded_on_their_topics():
    step = yaml.safe_load(
        format_message('/formation/step', ARRAY, encode_step(Step(index=7, time=0.25, flags=1)))
    )
    assert step == {'index': 7, 'time': 0.25, 'flags': 1, 'epoch': 0.0, 'due': []}
    status = Status(
        agent=2,
        step_index=3,
        next_time=math.inf,
        info_sent=4,
        info_received=3,
        commands_sent=2,
        triggers=2,
        ready=True,
        last_planned=0.125,
    )
    decoded = yaml.safe_load(format_message('/formation/status', ARRAY, encode_status(status)))
    assert decoded['next_time'] == math.inf and decoded['last_planned'] == 0.125 and decoded['ready'] is True
    state = WorldState(
        time=1.5, agent_ids=(1, 2), positions=np.array([[0.0, 1.0], [2.0, 3.0]]), velocities=None
    )
    decoded = yaml.safe_load(format_message('/formation/state', ARRAY, encode_world_state(state)))
    assert decoded == {
        'time': 1.5,
        'agent_ids': [1, 2],
        'positions': [[0.0, 1.0], [2.0, 3.0]],
        'velocities': None,
    }


def test_a_message_breaking_its_layout_is_shown_raw_with_the_reason():
    from std_msgs.msg import Float64MultiArray

    text = format_message(
        '/agent_1/trigger_info/to_2', ARRAY, Float64MultiArray(data=[2.0, 1.0, 1.0, 2.0, 0.0, 1.0, 0.0, 0.0])
    )
    first, rest = text.split('\n', 1)
    assert (
        first == '# not a valid TriggerInfo: trigger info: layout version 2.0 is not supported (expected 1)'
    )
    assert yaml.safe_load(rest)['data'] == [2.0, 1.0, 1.0, 2.0, 0.0, 1.0, 0.0, 0.0]


def test_other_types_are_shown_field_by_field():
    from geometry_msgs.msg import Twist

    twist = Twist()
    twist.linear.x = 0.1
    fields = yaml.safe_load(format_message('/agent_1/cmd_vel', 'geometry_msgs/msg/Twist', twist))
    assert fields == {'linear': {'x': 0.1, 'y': 0.0, 'z': 0.0}, 'angular': {'x': 0.0, 'y': 0.0, 'z': 0.0}}
    # a TriggerInfo layout elsewhere is just an array
    assert 'layout' in yaml.safe_load(format_message('/elsewhere', ARRAY, encode_trigger_info(INFO)))


def test_topic_listing_counts_endpoints_and_names_nodes():
    topics = [
        TopicInfo(name='/a', types=(ARRAY,), publishers=('/x',), subscribers=()),
        TopicInfo(
            name='/longer_name', types=('std_msgs/msg/String',), publishers=(), subscribers=('/y', '/z')
        ),
    ]
    assert format_topics(topics).splitlines() == [
        f'/a            [{ARRAY}]  publishers: 1  subscribers: 0',
        '/longer_name  [std_msgs/msg/String]  publishers: 0  subscribers: 2',
    ]
    assert '    subscriber: /z' in format_topics(topics, verbose=True).splitlines()
    assert format_topics([]).startswith('(no topics')


# ------------------------------------------------------------------------------------- ROS


def _formation(tmp_path: Path, *arguments: str) -> subprocess.CompletedProcess:
    env = dict(
        os.environ,
        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
        ROS_LOG_DIR=str(tmp_path / 'ros_log'),
        RMW_IMPLEMENTATION='rmw_fastrtps_cpp',
    )
    return subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', *arguments],
        env=env,
        capture_output=True,
        text=True,
        timeout=90,
    )


@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(180)
def test_topics_and_echo_see_a_live_graph(tmp_path, monkeypatch):
    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.qos import PROTOCOL_QOS

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=INSPECT_DOMAIN)
    try:
        node = Node(
            'inspect_fixture',
            namespace='/agent_1',
            context=context,
            start_parameter_services=False,
            enable_rosout=False,
        )
        info_pub = node.create_publisher(Float64MultiArray, 'trigger_info/to_2', PROTOCOL_QOS)
        node.create_subscription(Twist, 'cmd_vel', lambda msg: None, PROTOCOL_QOS)
        info_pub.publish(encode_trigger_info(INFO))  # transient local: echo joins later and still gets it

        # Discovery is asynchronous: on a loaded machine the tool's look (it stops early once the
        # graph is stable and named) may not see both endpoints, or their node's name, yet (DDS can
        # announce an endpoint before its node's name), so look again, at most 5 times.
        for _ in range(5):
            listed = _formation(
                tmp_path, 'topics', '--domain-id', str(INSPECT_DOMAIN), '--verbose', '--wait', '10'
            )
            assert listed.returncode == 0, listed.stderr
            lines = listed.stdout.splitlines()
            both_listed = (
                sum(line.startswith(('/agent_1/trigger_info/to_2 ', '/agent_1/cmd_vel ')) for line in lines)
                == 2
            )
            if both_listed and '_NODE_NAME_UNKNOWN_' not in listed.stdout:
                break
        row = next(line for line in lines if line.startswith('/agent_1/trigger_info/to_2 '))
        assert row.split(None, 1)[1] == f'[{ARRAY}]  publishers: 1  subscribers: 0'
        assert lines[lines.index(row) + 1] == '    publisher: /agent_1/inspect_fixture'
        row = next(line for line in lines if line.startswith('/agent_1/cmd_vel '))
        assert row.split(None, 1)[1] == '[geometry_msgs/msg/Twist]  publishers: 0  subscribers: 1'
        assert not [line for line in lines if 'formation_topics_' in line]  # the tool leaves itself out

        echoed = _formation(
            tmp_path,
            'echo',
            '/agent_1/trigger_info/to_2',
            '--domain-id',
            str(INSPECT_DOMAIN),
            '--count',
            '1',
            '--timeout',
            '60',
        )
        assert echoed.returncode == 0, echoed.stderr
        text, separator, rest = echoed.stdout.partition('---\n')
        assert separator and rest == ''
        assert text.startswith('# TriggerInfo')
        assert yaml.safe_load(text)['stamp'] == INFO.stamp and yaml.safe_load(text)['control'] == list(
            INFO.control
        )

        missing = _formation(tmp_path, 'echo', '/nobody', '--domain-id', str(INSPECT_DOMAIN), '--wait', '1')
        assert missing.returncode == 1 and 'no publisher of /nobody found within 1.0 s' in missing.stderr
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
