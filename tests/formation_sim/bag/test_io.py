"""formation_sim.bag.io: bags laid out as rosbag2 Jazzy writes them (metadata.yaml, MCAP channels,
the rosbag2 metadata record), read back by rosbags and by the mcap library, without ROS."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader

from formation_sim.bag.errors import TopicSpecError
from formation_sim.bag.io import BagWriter, read_bag, type_hash

SCENARIO, SCENARIO_TYPE = '/formation/scenario', 'std_msgs/msg/String'
STEP, STEP_TYPE = '/formation/step', 'std_msgs/msg/Float64MultiArray'
POSE, POSE_TYPE = '/agent_1/robot/pose', 'geometry_msgs/msg/PoseStamped'
INFINITE = QosTime(sec=9223372036, nsec=854775807)  # RMW_DURATION_INFINITE as Jazzy's graph reports it

# What the ROS graph of Jazzy reports for a publisher (history and depth are not discovered).
LATCHED = Qos(
    QosHistory.UNKNOWN,
    0,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    INFINITE,
    INFINITE,
    QosLiveliness.AUTOMATIC,
    QosTime(sec=1, nsec=0),
    False,
)
VOLATILE = Qos(
    QosHistory.UNKNOWN,
    0,
    QosReliability.BEST_EFFORT,
    QosDurability.VOLATILE,
    INFINITE,
    INFINITE,
    QosLiveliness.AUTOMATIC,
    INFINITE,
    False,
)

# The same profiles typed in as rosbag2 Jazzy's metadata.yaml holds them (rosbag2_storage/src/
# rosbag2_storage/qos.cpp, version 9: policies by name, durations as sec/nsec, in this order).
LATCHED_YAML = """
history: unknown
depth: 0
reliability: reliable
durability: transient_local
deadline: {sec: 9223372036, nsec: 854775807}
lifespan: {sec: 9223372036, nsec: 854775807}
liveliness: automatic
liveliness_lease_duration: {sec: 1, nsec: 0}
avoid_ros_namespace_conventions: false
"""

# RIHS01 hashes as rclpy 7.1.6 advertises them for these types (TopicEndpointInfo.topic_type_hash).
STRING_HASH = 'RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18'
ARRAY_HASH = 'RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f'


def _string(text: str) -> bytes:
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    return serialize_message(String(data=text))


def _write(path: Path) -> Path:
    with BagWriter(path) as bag:
        bag.set_custom_data('formation_timestamps', 'run time')
        bag.add_topic(SCENARIO, SCENARIO_TYPE, offered_qos_profiles=[LATCHED])
        bag.add_topic(STEP, STEP_TYPE)
        bag.set_offered_qos(STEP, [LATCHED, LATCHED])  # two publishers, learnt before the first message
        bag.add_topic(POSE, POSE_TYPE, offered_qos_profiles=[VOLATILE])  # never written to
        bag.write(SCENARIO, 0, _string('name: x'))
        bag.write(STEP, 5, _string('not a step, but bytes are bytes'))
    return path


def test_metadata_yaml_is_rosbag2_jazzys(tmp_path):
    bag = _write(tmp_path / 'bag')
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap' and info['ros_distro'] == 'jazzy'
    assert info['relative_file_paths'] == ['bag_0.mcap'] and [f['path'] for f in info['files']] == [
        'bag_0.mcap'
    ]
    assert info['custom_data'] == {'formation_timestamps': 'run time'}
    assert (info['compression_format'], info['compression_mode']) == ('', '')
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    latched = yaml.safe_load(LATCHED_YAML)
    assert topics[SCENARIO]['topic_metadata']['offered_qos_profiles'] == [latched]
    assert list(topics[SCENARIO]['topic_metadata']['offered_qos_profiles'][0]) == list(
        latched
    )  # rosbag2's key order
    assert topics[STEP]['topic_metadata']['offered_qos_profiles'] == [latched, latched]
    assert topics[POSE]['topic_metadata']['offered_qos_profiles'][0]['durability'] == 'volatile'
    assert topics[POSE]['message_count'] == 0  # a topic without messages is in the bag, with its QoS
    assert topics[SCENARIO]['topic_metadata']['type_description_hash'] == STRING_HASH
    assert topics[STEP]['topic_metadata']['type_description_hash'] == ARRAY_HASH
    assert {t['topic_metadata']['serialization_format'] for t in topics.values()} == {'cdr'}


def test_the_mcap_file_carries_what_rosbag2_storage_mcap_writes(tmp_path):
    bag = _write(tmp_path / 'bag')
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    hashes = {
        t['topic_metadata']['name']: t['topic_metadata']['type_description_hash']
        for t in info['topics_with_message_count']
    }
    with (bag / 'bag_0.mcap').open('rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        channels = {channel.topic: channel for channel in summary.channels.values()}
        assert {summary.schemas[c.schema_id].encoding for c in channels.values()} == {'ros2msg'}
        for topic, channel in channels.items():
            assert set(channel.metadata) == {'offered_qos_profiles', 'topic_type_hash'}
            assert channel.metadata['topic_type_hash'] == hashes[topic]
        assert yaml.safe_load(channels[SCENARIO].metadata['offered_qos_profiles']) == [
            yaml.safe_load(LATCHED_YAML)
        ]
        # rosbag2 reads the bag information from the 'rosbag2' record when metadata.yaml is gone.
        records = {record.name: record.metadata for record in reader.iter_metadata()}
        assert yaml.safe_load(records['rosbag2']['serialized_metadata']) == info


def test_rosbags_reads_the_offered_qos_back(tmp_path):
    bag = _write(tmp_path / 'bag')
    with Reader(bag) as reader:
        offered = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        assert {c.topic: c.digest for c in reader.connections}[STEP] == ARRAY_HASH
    assert offered == {SCENARIO: [LATCHED], STEP: [LATCHED, LATCHED], POSE: [VOLATILE]}
    assert [(m.topic, m.timestamp_ns) for m in read_bag(bag)] == [(SCENARIO, 0), (STEP, 5)]


def test_type_hash_from_a_stored_definition_is_the_advertised_one():
    from rosbags.typesys import Stores, get_typestore

    definition, _ = get_typestore(Stores.ROS2_JAZZY).generate_msgdef(STEP_TYPE, ros_version=2)
    assert type_hash(STEP_TYPE, definition=definition) == type_hash(STEP_TYPE) == ARRAY_HASH


def test_offered_qos_is_fixed_with_the_first_message(tmp_path):
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        assert not bag.has_channel(STEP)
        bag.write(STEP, 0, _string('x'))
        assert bag.has_channel(STEP)
        with pytest.raises(
            TopicSpecError,
            match="'/formation/step' already has messages in the bag: its offered QoS can no longer change",
        ):
            bag.set_offered_qos(STEP, [LATCHED])
        with pytest.raises(TopicSpecError, match="topic '/nowhere' was not added"):
            bag.set_offered_qos('/nowhere', [LATCHED])
