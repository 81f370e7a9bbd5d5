"""formation_sim.bag.recovery: a recovered bag keeps what rosbag2 needs to play it as recorded
(each topic's offered QoS and type hash, ros_distro jazzy), also for MCAP files written elsewhere."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import yaml

from formation_sim.bag.recovery import reindex

ARRAY_HASH = (
    'RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f'  # as rclpy 7.1.6 advertises it
)

KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from formation_sim.bag.io import BagWriter

    forever = QosTime(sec=9223372036, nsec=854775807)
    latched = Qos(QosHistory.UNKNOWN, 0, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                  forever, forever, QosLiveliness.AUTOMATIC, QosTime(sec=1, nsec=0), False)
    bag = BagWriter(sys.argv[1])
    bag.open()
    bag.add_topic('/formation/step', 'std_msgs/msg/Float64MultiArray',
                  offered_qos_profiles=[latched, latched])
    for k in range(10):
        bag.write('/formation/step', k, bytes(24))
    bag.flush()
    bag.write('/formation/step', 10, bytes(24))  # never flushed
    os.kill(os.getpid(), signal.SIGKILL)
""")


def _information(bag):
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def test_a_killed_recorders_bag_keeps_its_offered_qos_and_type_hash(tmp_path):
    bag = tmp_path / 'bag'
    killed = subprocess.run(
        [sys.executable, '-c', KILLED_WRITER, str(bag)], capture_output=True, timeout=120, check=False
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr.decode()

    recovery = reindex(bag)

    assert recovery.rewritten and recovery.message_counts == {'/formation/step': 10}
    info = _information(bag)
    assert info['ros_distro'] == 'jazzy' and info['version'] == 9
    (topic,) = info['topics_with_message_count']
    assert topic['topic_metadata']['type_description_hash'] == ARRAY_HASH
    assert [
        (p['reliability'], p['durability'], p['liveliness_lease_duration'])
        for p in topic['topic_metadata']['offered_qos_profiles']
    ] == [('reliable', 'transient_local', {'sec': 1, 'nsec': 0})] * 2


def test_an_mcap_file_without_type_hashes_gets_them_from_its_schemas(tmp_path):
    """rosbags' own writer (as the recorder used before) stores no topic_type_hash in its channels."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    bag = tmp_path / 'bag'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(
            '/formation/step', 'std_msgs/msg/Float64MultiArray', typestore=get_typestore(Stores.ROS2_JAZZY)
        )
        writer.write(connection, 3, bytes(24))
    (bag / 'metadata.yaml').unlink()

    reindex(bag)

    (topic,) = _information(bag)['topics_with_message_count']
    assert topic['topic_metadata']['type_description_hash'] == ARRAY_HASH
    assert topic['message_count'] == 1 and topic['topic_metadata']['offered_qos_profiles'] == []
