"""Tests of formation_sim.runtime.nodes.recorder: bag round trips, metadata, recovery, a live recording."""

from __future__ import annotations

import contextlib
import json
import math
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import Pose, PoseArray
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from formation_sim.bag.errors import (
    BagError,
    BagReadError,
    BagRecoveryError,
    TopicSpecError,
    UnknownMessageTypeError,
)
from formation_sim.bag.io import BagWriter, decode, read_bag
from formation_sim.bag.recovery import reindex
from formation_sim.runtime.nodes.recorder import parse_topic_spec
from formation_sim.runtime.nodes.sim_node import RECORDER_LAG

STEP = '/formation/step'
POSES = '/formation/poses'
STEP_TYPE = 'std_msgs/msg/Float64MultiArray'
POSES_TYPE = 'geometry_msgs/msg/PoseArray'


def step_bytes(k: int) -> bytes:
    return serialize_message(Float64MultiArray(data=[1.0, float(k), 0.1 * k]))


def poses_bytes(k: int) -> bytes:
    poses = PoseArray()
    poses.header.frame_id = 'world'
    poses.header.stamp.sec = k
    for agent in range(3):
        pose = Pose()
        pose.position.x = k + 0.25 * agent
        pose.position.y = -1.5 * agent
        pose.orientation.w = 1.0
        poses.poses.append(pose)
    return serialize_message(poses)


def interleaved(count: int) -> list[tuple[str, str, int, bytes]]:
    """Steps and pose arrays alternating, stamped k * 0.1 s."""
    messages = []
    for k in range(count):
        stamp = k * 100_000_000
        messages.append((STEP, STEP_TYPE, stamp, step_bytes(k)))
        messages.append((POSES, POSES_TYPE, stamp, poses_bytes(k)))
    return messages


def metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def test_round_trip_is_bit_identical(tmp_path: Path) -> None:
    written = interleaved(20)
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        bag.add_topic(POSES, POSES_TYPE)
        for topic, _, stamp, data in written:
            bag.write(topic, stamp, data)

    assert [tuple(m) for m in read_bag(tmp_path / 'bag')] == written


def test_an_unreadable_bag_raises_bag_read_error_naming_the_remedy(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        bag.write(STEP, 0, step_bytes(0))
    mcap = next((tmp_path / 'bag').glob('*.mcap'))
    (tmp_path / 'bag' / 'metadata.yaml').unlink()  # what a SIGKILLed recorder leaves
    with pytest.raises(
        BagReadError,
        match=(
            rf'no metadata.yaml \(it holds {mcap.name}\).*'
            rf'`formation recover {tmp_path / "bag"}` rebuilds it'
        ),
    ):
        list(read_bag(tmp_path / 'bag'))
    reindex(tmp_path / 'bag')
    mcap.write_bytes(b'not an mcap file' * 10)
    with pytest.raises(BagReadError, match='its MCAP file is not an MCAP file'):
        list(read_bag(tmp_path / 'bag'))
    assert issubclass(BagReadError, BagError)


def test_decode_gives_the_published_values(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        bag.add_topic(POSES, POSES_TYPE)
        bag.write(STEP, 7, step_bytes(3))
        bag.write(POSES, 7, poses_bytes(3))

    step, poses = (decode(m.rawdata, m.msgtype) for m in read_bag(tmp_path / 'bag'))
    assert list(step.data) == [1.0, 3.0, 0.1 * 3]
    assert poses.header.frame_id == 'world'
    assert [(p.position.x, p.position.y) for p in poses.poses] == [(3.0, 0.0), (3.25, -1.5), (3.5, -3.0)]


def test_metadata_is_version_9_mcap_with_counts(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        bag.add_topic(POSES, POSES_TYPE)
        for k in range(5):
            bag.write(STEP, 1_000 + k, step_bytes(k))
        bag.write(POSES, 2_000, poses_bytes(0))

    info = metadata(tmp_path / 'bag')
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['bag_0.mcap']
    assert (tmp_path / 'bag' / 'bag_0.mcap').read_bytes().startswith(b'\x89MCAP0\r\n')
    assert info['message_count'] == 6
    assert info['starting_time']['nanoseconds_since_epoch'] == 1_000
    assert info['duration']['nanoseconds'] == 1_000
    counts = {t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']}
    assert counts == {STEP: 5, POSES: 1}
    formats = {t['topic_metadata']['serialization_format'] for t in info['topics_with_message_count']}
    assert formats == {'cdr'}


def test_writer_never_overwrites(tmp_path: Path) -> None:
    (tmp_path / 'bag').mkdir()
    with pytest.raises(BagError, match='never overwrites'):
        BagWriter(tmp_path / 'bag').open()


def test_bad_input_is_named(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(STEP, STEP_TYPE)
        with pytest.raises(TopicSpecError, match=r"'/formation/other' was not added.*step"):
            bag.write('/formation/other', 0, step_bytes(0))
        with pytest.raises(BagError, match=r'int nanoseconds, got 0\.5'):
            bag.write(STEP, 0.5, step_bytes(0))
        with pytest.raises(BagError, match=r'\[0, 2\*\*63\) ns, got -1'):
            bag.write(STEP, -1, step_bytes(0))
        with pytest.raises(TopicSpecError, match=r"added with type 'std_msgs/msg/Float64Multi"):
            bag.add_topic(STEP, POSES_TYPE)
        with pytest.raises(TopicSpecError, match='must be absolute'):
            bag.add_topic('formation/step', STEP_TYPE)
        with pytest.raises(UnknownMessageTypeError, match="'std_msgs/Float64' is not of the form"):
            bag.add_topic('/x', 'std_msgs/Float64')
        with pytest.raises(UnknownMessageTypeError, match="'nope_msgs/msg/Nope' of topic '/x'"):
            bag.add_topic('/x', 'nope_msgs/msg/Nope')
        bag.add_topic(STEP, STEP_TYPE)  # the same topic again is fine
    with pytest.raises(BagError, match='is not open'):
        bag.write(STEP, 0, step_bytes(0))


def test_topic_spec_parsing() -> None:
    assert parse_topic_spec('/formation/step:std_msgs/msg/Float64MultiArray') == (STEP, STEP_TYPE)
    with pytest.raises(TopicSpecError, match="'/formation/step' is not of the form"):
        parse_topic_spec('/formation/step')
    with pytest.raises(TopicSpecError, match='must be absolute'):
        parse_topic_spec('step:std_msgs/msg/Float64MultiArray')


# --- recovery ----------------------------------------------------------------------------------

# The child lists the bytes it flushed: serialize_message leaves CDR padding bytes
# uninitialized, so the same message serialized again need not be the same bytes.
KILLED_WRITER = textwrap.dedent("""
    import json, os, signal, sys
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray
    from formation_sim.bag.io import BagWriter

    bag = BagWriter(sys.argv[1])
    bag.open()
    bag.add_topic('/formation/step', 'std_msgs/msg/Float64MultiArray')
    bag.add_topic('/formation/poses', 'geometry_msgs/msg/PoseArray')
    flushed = []
    for k in range(30):
        data = serialize_message(Float64MultiArray(data=[1.0, float(k), k / 10]))
        bag.write('/formation/step', k, data)
        flushed.append(data.hex())
        if k % 10 == 9:
            bag.flush()
    with open(sys.argv[2], 'w') as listing:
        json.dump(flushed, listing)
    bag.write('/formation/step', 10**12, b'never flushed')
    os.kill(os.getpid(), signal.SIGKILL)
""")


def test_reindex_recovers_a_killed_recorder(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    listing = tmp_path / 'flushed.json'
    run = subprocess.run(
        [sys.executable, '-c', KILLED_WRITER, str(bag), str(listing)],
        check=False,
        capture_output=True,
        timeout=120,
    )
    assert run.returncode == -signal.SIGKILL, run.stderr.decode()
    assert not (bag / 'metadata.yaml').exists()
    flushed = [
        (STEP, STEP_TYPE, k, bytes.fromhex(data)) for k, data in enumerate(json.loads(listing.read_text()))
    ]

    recovery = reindex(bag)

    assert recovery.rewritten
    # A topic's channel is written with its first message: POSES, which had none, is not in the file.
    assert recovery.message_counts == {STEP: 30}
    assert recovery.damaged_copy is not None
    assert recovery.damaged_copy.exists()
    assert [tuple(m) for m in read_bag(bag)] == flushed
    info = metadata(bag)
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['message_count'] == 30
    assert info['starting_time']['nanoseconds_since_epoch'] == 0
    assert info['duration']['nanoseconds'] == 29


def test_reindex_rebuilds_lost_metadata_as_the_writer_wrote_it(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    written = interleaved(7)  # once: rclpy leaves CDR padding unset, a second serialization may differ there
    with BagWriter(bag) as writer:
        writer.add_topic(STEP, STEP_TYPE)
        writer.add_topic(POSES, POSES_TYPE)
        for topic, _, stamp, data in written:
            writer.write(topic, 5 + stamp, data)
    original = metadata(bag)
    mcap_bytes = (bag / 'bag_0.mcap').read_bytes()
    (bag / 'metadata.yaml').unlink()

    recovery = reindex(bag)

    assert not recovery.rewritten
    assert (bag / 'bag_0.mcap').read_bytes() == mcap_bytes
    rebuilt = metadata(bag)
    for key in (
        'version',
        'storage_identifier',
        'relative_file_paths',
        'duration',
        'starting_time',
        'message_count',
        'topics_with_message_count',
    ):
        assert rebuilt[key] == original[key], key
    assert [tuple(m) for m in read_bag(bag)] == [(t, mt, 5 + s, d) for t, mt, s, d in written]


def test_reindex_of_a_file_cut_anywhere_keeps_a_prefix(tmp_path: Path) -> None:
    source = tmp_path / 'source'
    mcap = source / 'source_0.mcap'
    written: list[tuple[str, str, int, bytes]] = []
    flushed_at: dict[int, int] = {}  # file size after a flush -> messages written by then
    writer = BagWriter(source)
    writer.open()
    writer.add_topic(STEP, STEP_TYPE)
    writer.add_topic(POSES, POSES_TYPE)
    for batch in range(4):
        for topic, msgtype, stamp, data in interleaved(6 * (batch + 1))[12 * batch :]:
            writer.write(topic, stamp, data)
            written.append((topic, msgtype, stamp, data))
        writer.flush()
        flushed_at[mcap.stat().st_size] = len(written)
    writer.close()
    data_end = max(flushed_at)
    complete = mcap.read_bytes()

    # Cuts at every flush, and anywhere else in the data and in the summary written by close.
    rng = random.Random(20170710)
    cuts = sorted({*flushed_at, *rng.sample(range(1, len(complete)), 60)})
    recovered_counts = []
    for cut in cuts:
        bag = tmp_path / f'cut{cut}'
        bag.mkdir()
        (bag / 'cut.mcap').write_bytes(complete[:cut])
        try:
            reindex(bag)
        except BagRecoveryError:
            assert cut < min(flushed_at), cut  # only before the first chunk is complete
            recovered_counts.append(0)
            continue
        recovered = [tuple(m) for m in read_bag(bag)]
        assert recovered == written[: len(recovered)], cut
        if cut in flushed_at:
            assert len(recovered) == flushed_at[cut], cut
        if cut >= data_end:
            assert len(recovered) == len(written), cut
        recovered_counts.append(len(recovered))

    assert recovered_counts == sorted(recovered_counts)


def test_reindex_on_a_full_disk_changes_nothing_and_says_what_to_do(tmp_path: Path, small_disk) -> None:
    source = tmp_path / 'source'
    with BagWriter(source) as writer:
        writer.add_topic(STEP, STEP_TYPE)
        writer.add_topic(POSES, POSES_TYPE)
        for topic, _, stamp, data in interleaved(3500):
            writer.write(topic, stamp, data)
    complete = (source / 'source_0.mcap').read_bytes()
    assert len(complete) > 1_000_000
    bag = small_disk(1.5) / 'bag'
    bag.mkdir()
    cut = complete[: len(complete) - 100]  # the summary cut short: the copy would need ~1.2 MB more
    (bag / 'bag_0.mcap').write_bytes(cut)

    with pytest.raises(BagRecoveryError) as failed:
        reindex(bag)
    message = str(failed.value)
    assert 'cannot write the recovered copy bag_0.mcap.recovering: No space left on device' in message
    assert 'the bag is unchanged: free space, then recover it again' in message
    assert sorted(path.name for path in bag.iterdir()) == ['bag_0.mcap']  # no temporary left
    assert (bag / 'bag_0.mcap').read_bytes() == cut


def test_reindex_errors_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(BagRecoveryError, match=r'exactly one \.mcap file, found \[\]'):
        reindex(tmp_path)
    (tmp_path / 'x.mcap').write_bytes(b'\x89MCAP0\r\n\x01')
    with pytest.raises(BagRecoveryError, match='no complete MCAP chunk in its 9 bytes'):
        reindex(tmp_path)


# --- live recording ------------------------------------------------------------------------------


def recorder_command() -> list[str]:
    script = Path(sys.executable).with_name('formation_recorder')
    if script.exists():  # the console script of the installed package
        return [str(script)]
    return [sys.executable, '-m', 'formation_sim.runtime.nodes.recorder']


@contextlib.contextmanager
def ros_domain(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, domain_id: int):
    """A private ROS domain for this test: environment for children and a context for us."""
    import rclpy

    env = {
        'ROS_DOMAIN_ID': str(domain_id),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
        'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp',
    }
    from formation_sim.runtime.testing import hold_domain

    for key, value in env.items():
        monkeypatch.setenv(key, value)
    with hold_domain(domain_id):  # no run of another test picks it meanwhile
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain_id)
        try:
            yield context
        finally:
            rclpy.try_shutdown(context=context)


@contextlib.contextmanager
def recorder(tmp_path: Path, *parameters: str):
    """Run the recorder with `parameters` (name:=value); kill it if the test leaves it running."""
    arguments = [item for p in parameters for item in ('-p', p)]
    with (tmp_path / 'recorder.log').open('w') as log:
        process = subprocess.Popen(
            [*recorder_command(), '--ros-args', *arguments], stdout=log, stderr=subprocess.STDOUT
        )
        try:
            yield process
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()


def recorder_log(tmp_path: Path) -> str:
    return (tmp_path / 'recorder.log').read_text()


def wait_for_subscribers(publishers: list, process: subprocess.Popen, tmp_path: Path) -> None:
    deadline = time.monotonic() + 60
    while any(pub.get_subscription_count() < 1 for pub in publishers):
        assert process.poll() is None, recorder_log(tmp_path)
        assert time.monotonic() < deadline, f'no subscription: {recorder_log(tmp_path)}'
        time.sleep(0.05)


def stop(process: subprocess.Popen, sig: signal.Signals, tmp_path: Path) -> None:
    process.send_signal(sig)
    try:
        process.wait(timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f'the recorder ignored {sig.name}: {recorder_log(tmp_path)}')
    assert process.returncode == 0, recorder_log(tmp_path)


def reliable_keep_all():
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000, reliability=ReliabilityPolicy.RELIABLE)


@pytest.mark.ros
@pytest.mark.parametrize(('sig', 'domain_id'), [(signal.SIGINT, 151), (signal.SIGTERM, 152)])
def test_live_recording_keeps_every_message_in_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, sig: signal.Signals, domain_id: int
) -> None:
    import rclpy
    from rclpy.duration import Duration

    bag = tmp_path / 'bag'
    count = 40
    with (
        ros_domain(tmp_path, monkeypatch, domain_id) as context,
        recorder(
            tmp_path, f'output:={bag}', f"topics:=['{STEP}:{STEP_TYPE}','{POSES}:{POSES_TYPE}']"
        ) as process,
    ):
        node = rclpy.create_node('live_recording_test', context=context)
        step_pub = node.create_publisher(Float64MultiArray, STEP, reliable_keep_all())
        poses_pub = node.create_publisher(PoseArray, POSES, reliable_keep_all())
        wait_for_subscribers([step_pub, poses_pub], process, tmp_path)
        published_steps, published_poses = [], []
        for k in range(count):
            poses = PoseArray()
            poses.poses.append(Pose())
            poses.poses[0].position.x = float(k)
            # Published serialized, so the bytes compared are the bytes sent.
            published_steps.append(step_bytes(k))
            published_poses.append(serialize_message(poses))
            step_pub.publish(published_steps[-1])
            poses_pub.publish(published_poses[-1])
        # Acknowledged = in the recorder's reader queue; the recorder drains it on the signal.
        assert step_pub.wait_for_all_acked(Duration(seconds=30))
        assert poses_pub.wait_for_all_acked(Duration(seconds=30))
        advertised_hash = str(node.get_publishers_info_by_topic(STEP)[0].topic_type_hash)
        stop(process, sig, tmp_path)
        node.destroy_node()

    recorded = list(read_bag(bag))
    assert [m.rawdata for m in recorded if m.topic == STEP] == published_steps
    assert [m.rawdata for m in recorded if m.topic == POSES] == published_poses
    # Each step is stamped with its own simulation time, data[2] = 0.1 k.
    assert [m.timestamp_ns for m in recorded if m.topic == STEP] == [
        round(0.1 * k * 1e9) for k in range(count)
    ]
    hashes = {
        t['topic_metadata']['name']: t['topic_metadata']['type_description_hash']
        for t in metadata(bag)['topics_with_message_count']
    }
    assert hashes[STEP] == advertised_hash


@pytest.mark.ros
def test_live_prefix_discovery_with_node_clock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import rclpy
    from rclpy.duration import Duration

    bag = tmp_path / 'bag'
    started_ns = time.time_ns()
    with (
        ros_domain(tmp_path, monkeypatch, 153) as context,
        recorder(
            tmp_path, f'output:={bag}', 'prefix:=/formation/', "clock_topic:=''", 'discovery_period:=0.2'
        ) as process,
    ):
        node = rclpy.create_node('prefix_discovery_test', context=context)
        poses_pub = node.create_publisher(PoseArray, POSES, reliable_keep_all())
        elsewhere_pub = node.create_publisher(Float64MultiArray, '/elsewhere/step', reliable_keep_all())
        wait_for_subscribers([poses_pub], process, tmp_path)
        published = []
        for k in range(10):
            poses = PoseArray()
            poses.header.frame_id = f'frame{k}'
            published.append(serialize_message(poses))
            poses_pub.publish(published[-1])
            elsewhere_pub.publish(Float64MultiArray(data=[float(k)]))
        assert poses_pub.wait_for_all_acked(Duration(seconds=30))
        stop(process, signal.SIGINT, tmp_path)
        node.destroy_node()
    stopped_ns = time.time_ns()

    recorded = list(read_bag(bag))
    assert {m.topic for m in recorded} == {POSES}
    assert [m.rawdata for m in recorded] == published
    stamps = [m.timestamp_ns for m in recorded]
    assert stamps == sorted(stamps)
    assert started_ns <= stamps[0]
    assert stamps[-1] <= stopped_ns


# --------------------------------------------------------------------------- draining on stop


def publish_steps(publisher, first: int, count: int) -> list[bytes]:
    """Publish steps first .. first + count - 1 serialized; return the bytes sent."""
    sent = [step_bytes(k) for k in range(first, first + count)]
    for data in sent:
        publisher.publish(data)
    return sent


def finish(process: subprocess.Popen, tmp_path: Path) -> float:
    """Wait for a signalled recorder to exit by itself (status 0); return the seconds waited."""
    started = time.monotonic()
    try:
        process.wait(timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f'the recorder did not finish draining: {recorder_log(tmp_path)}')
    assert process.returncode == 0, recorder_log(tmp_path)
    return time.monotonic() - started


@pytest.mark.ros
def test_drain_keeps_messages_that_arrive_after_a_lull(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A burst right before SIGINT and one 0.3 s after it (a loaded publisher's late messages)."""
    import rclpy
    from rclpy.duration import Duration

    bag = tmp_path / 'bag'
    # A quiet period well above the lull, so a loaded test machine cannot make this flaky.
    with (
        ros_domain(tmp_path, monkeypatch, 140) as context,
        recorder(
            tmp_path, f'output:={bag}', f"topics:=['{STEP}:{STEP_TYPE}']", 'drain_quiet:=2.0'
        ) as process,
    ):
        node = rclpy.create_node('drain_lull_test', context=context)
        publisher = node.create_publisher(Float64MultiArray, STEP, reliable_keep_all())
        wait_for_subscribers([publisher], process, tmp_path)
        published = publish_steps(publisher, 0, 200)
        process.send_signal(signal.SIGINT)
        time.sleep(0.3)
        assert process.poll() is None, recorder_log(tmp_path)
        published += publish_steps(publisher, 200, 100)
        assert publisher.wait_for_all_acked(Duration(seconds=30)), recorder_log(tmp_path)
        assert finish(process, tmp_path) < 30.0
        node.destroy_node()

    assert [m.rawdata for m in read_bag(bag) if m.topic == STEP] == published
    assert metadata(bag)['message_count'] == len(published)
    assert 'drained' in recorder_log(tmp_path)


def _steps_until_exit(process, publisher, published: list) -> float:
    """A step every 0.05 s (appended to `published`) until the recorder exits; the seconds it took."""
    signalled = time.monotonic()
    deadline = signalled + 60
    while process.poll() is None and time.monotonic() < deadline:
        published += publish_steps(publisher, len(published), 1)
        time.sleep(0.05)
    return time.monotonic() - signalled


def _drained_under_steps(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, domain: int, name: str, *parameters: str
) -> tuple[float, list[bytes]]:
    """A recorder of the Steps into tmp_path/bag (with `parameters`) gets ten Steps, SIGINT, then
    a Step every 0.05 s until it exits (never quiet for 0.5 s): (seconds from the signal to its
    exit, the Steps published)."""
    import rclpy

    with (
        ros_domain(tmp_path, monkeypatch, domain) as context,
        recorder(
            tmp_path, f'output:={tmp_path / "bag"}', f"topics:=['{STEP}:{STEP_TYPE}']", *parameters
        ) as process,
    ):
        node = rclpy.create_node(name, context=context)
        publisher = node.create_publisher(Float64MultiArray, STEP, reliable_keep_all())
        wait_for_subscribers([publisher], process, tmp_path)
        published = publish_steps(publisher, 0, 10)
        process.send_signal(signal.SIGINT)
        waited = _steps_until_exit(process, publisher, published)
        finish(process, tmp_path)
        node.destroy_node()
    return waited, published


@pytest.mark.ros
def test_drain_ends_at_its_limit_while_messages_keep_coming(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = tmp_path / 'bag'
    waited, published = _drained_under_steps(
        tmp_path, monkeypatch, 141, 'drain_limit_test', 'drain_quiet:=0.5', 'drain_limit:=1.5'
    )

    assert 1.5 <= waited < 30.0
    assert 'drain limit reached' in recorder_log(tmp_path)
    recorded = [m.rawdata for m in read_bag(bag) if m.topic == STEP]
    assert len(recorded) >= 10 + 1.5 / 0.05 / 2  # the steps of the drain are kept
    assert recorded == published[: len(recorded)]  # in order, no gap


@pytest.mark.ros
def test_messages_of_an_endless_topic_do_not_hold_the_drain_up(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """External robots publish their poses on after the run: the recorder records them while it
    drains but ends once the run's own topics are quiet (before, Ctrl-C on an external run waited
    out the 5 s stop timeout: `drain cut short by a second stop signal after 5.04 s`)."""
    bag = tmp_path / 'bag'
    waited, published = _drained_under_steps(
        tmp_path,
        monkeypatch,
        35,
        'drain_endless_test',
        f"endless_topics:=['{STEP}']",
        'drain_quiet:=0.5',
        'drain_limit:=30.0',
    )

    assert (
        waited < 30.0
        and 'drained' in recorder_log(tmp_path)
        and 'drain limit reached' not in recorder_log(tmp_path)
    )
    recorded = [m.rawdata for m in read_bag(bag) if m.topic == STEP]
    assert len(recorded) >= 10 and recorded == published[: len(recorded)]


@pytest.mark.ros
def test_a_second_signal_ends_the_drain_and_keeps_what_is_queued(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import rclpy
    from rclpy.duration import Duration

    bag = tmp_path / 'bag'
    with (
        ros_domain(tmp_path, monkeypatch, 142) as context,
        recorder(
            tmp_path,
            f'output:={bag}',
            f"topics:=['{STEP}:{STEP_TYPE}']",
            'drain_quiet:=60.0',
            'drain_limit:=120.0',
        ) as process,
    ):
        node = rclpy.create_node('drain_interrupt_test', context=context)
        publisher = node.create_publisher(Float64MultiArray, STEP, reliable_keep_all())
        wait_for_subscribers([publisher], process, tmp_path)
        published = publish_steps(publisher, 0, 100)
        assert publisher.wait_for_all_acked(Duration(seconds=30))
        process.send_signal(signal.SIGINT)
        time.sleep(0.5)
        assert process.poll() is None, recorder_log(tmp_path)  # draining, 60 s quiet to go
        process.send_signal(signal.SIGTERM)
        assert finish(process, tmp_path) < 30.0
        node.destroy_node()

    assert 'drain cut short by a second stop signal' in recorder_log(tmp_path)
    assert [m.rawdata for m in read_bag(bag) if m.topic == STEP] == published


@pytest.mark.ros
@pytest.mark.parametrize('parameter', ['drain_quiet:=0.0', 'drain_limit:=-1.0', 'drain_quiet:=.nan'])
def test_drain_parameters_must_be_positive(tmp_path: Path, parameter: str) -> None:
    bag = tmp_path / 'bag'
    env = {
        **os.environ,
        'ROS_DOMAIN_ID': '143',
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
    }
    run = subprocess.run(
        [*recorder_command(), '--ros-args', '-p', f'output:={bag}', '-p', parameter],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    name, value = parameter.split(':=')
    assert run.returncode == 2, run.stderr
    assert (
        f"parameter '{name}' (double) must be > 0, finite, got {float(value.replace('.nan', 'nan'))!r}"
        in run.stderr
    )
    assert 'Traceback' not in run.stderr
    assert not bag.exists()


@pytest.mark.ros
def test_the_heartbeat_names_the_watched_topics_until_their_first_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A robot run's time keeper starts only once the recorder has had a message on each robot's
    pose topic (`watched_topics`): its heartbeat lists those still silent."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import String

    from formation_msgs_py.qos import READER_QOS
    from formation_msgs_py.topics import RECORDER_TOPIC

    pose, other = '/agent_2/robot/pose', '/other'
    with (
        ros_domain(tmp_path, monkeypatch, 147) as context,
        recorder(
            tmp_path,
            f'output:={tmp_path / "bag"}',
            f"topics:=['{pose}:{STEP_TYPE}', '{other}:{STEP_TYPE}']",
            f"watched_topics:=['{pose}']",
            'flush_period:=0.1',
        ) as process,
    ):
        node = rclpy.create_node('watch_test', context=context)
        beats: list[dict] = []
        node.create_subscription(
            String, RECORDER_TOPIC, lambda msg: beats.append(json.loads(msg.data)), READER_QOS
        )
        publishers = {
            name: node.create_publisher(Float64MultiArray, name, reliable_keep_all())
            for name in (pose, other)
        }
        wait_for_subscribers(list(publishers.values()), process, tmp_path)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def beat_once_recorded(count: int) -> dict:
            """The first heartbeat of a flush that wrote `count` messages: the recorder has taken the
            message sent last (the test once took the beat 0.5 s after sending, which a loaded
            machine could reach before the message had come)."""
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
                done = [beat for beat in beats if beat['recorded'] >= count]
                if done:
                    return done[0]
            pytest.fail(f'no heartbeat with {count} recorded: {beats[-3:]} {recorder_log(tmp_path)}')

        publishers[other].publish(Float64MultiArray(data=[1.0]))
        assert beat_once_recorded(1)['silent'] == [pose]  # a message on another topic is no sign
        publishers[pose].publish(Float64MultiArray(data=[2.0]))
        assert beat_once_recorded(2)['silent'] == []
        process.send_signal(signal.SIGINT)
        finish(process, tmp_path)
        executor.remove_node(node)
        node.destroy_node()


@pytest.mark.ros
def test_watched_topics_must_be_recorded(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    env = {
        **os.environ,
        'ROS_DOMAIN_ID': '143',
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
    }
    run = subprocess.run(
        [
            *recorder_command(),
            '--ros-args',
            '-p',
            f'output:={bag}',
            '-p',
            f"topics:=['{STEP}:{STEP_TYPE}']",
            '-p',
            "watched_topics:=['/agent_1/robot/pose']",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert run.returncode == 2, run.stderr
    assert (
        "parameter 'watched_topics' names topics that are not in 'topics': ['/agent_1/robot/pose']"
        in run.stderr
    )
    assert 'Traceback' not in run.stderr and not bag.exists()


# --------------------------------------------------------------------------- the run's time


class _Clocks:
    """A monotonic and a wall clock the test moves by hand (ns)."""

    def __init__(self, wall_ns: int) -> None:
        self.monotonic = 5_000_000_000
        self.wall = wall_ns

    def advance(self, seconds: float, *, wall_jump: float = 0.0) -> None:
        self.monotonic += round(seconds * 1e9)
        self.wall += round((seconds + wall_jump) * 1e9)


def test_lock_step_messages_are_stamped_with_the_latest_steps_sim_time() -> None:
    from formation_sim.runtime.nodes.recorder import RunClock

    clock = RunClock()
    assert clock.stamp_ns() == 0 and clock.step_index == -1  # before the first Step
    stamps = []
    for index, t in enumerate([0.0, 5.5e-7, 0.25, 0.25, 1.0]):
        assert clock.on_step([1.0, float(index), t, 0.0, 0.0])
        stamps.append(clock.stamp_ns())
    assert stamps == [0, 550, 250_000_000, 250_000_000, 1_000_000_000]
    assert clock.step_index == 4 and not clock.realtime
    assert (
        clock.on_step([1.0, 5.0, 2.0]) and clock.stamp_ns() == 2_000_000_000
    )  # [version, step, time] suffices
    assert (
        not clock.on_step([1.0, 6.0, -1.0])
        and not clock.on_step([1.0, 6.0, float('nan')])
        and not clock.on_step([1.0])
    )
    assert clock.stamp_ns() == 2_000_000_000 and clock.step_index == 5  # refused Steps change nothing


def test_wall_clock_messages_are_stamped_with_their_receive_time_since_the_epoch() -> None:
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME
    from formation_sim.runtime.nodes.recorder import RunClock

    epoch = 1_700_000_000.5
    clocks = _Clocks(wall_ns=round(epoch * 1e9) + 20_000_000)  # Step 0 arrives 20 ms after its epoch
    clock = RunClock(monotonic_ns=lambda: clocks.monotonic, wall_ns=lambda: clocks.wall)
    clocks.advance(0.3)
    assert clock.stamp_ns() == 0 and not clock.started  # discovery: before the run
    clocks.wall -= 300_000_000
    clocks.advance(-0.015)
    overtook = (
        clock.received_ns()
    )  # a message of the run that came 15 ms before Step 0 (5 ms after the epoch)
    clocks.advance(-0.3)
    discovery = clock.received_ns()  # one from well before the epoch
    clocks.advance(0.315)
    assert clock.on_step([1.0, 0.0, 0.0, float(STEP_FLAG_REALTIME), epoch])
    assert clock.realtime and clock.stamp_ns() == 20_000_000
    assert clock.stamp_ns(overtook) == 5_000_000 and clock.stamp_ns(discovery) == 0
    clocks.advance(1.25)
    assert clock.stamp_ns() == 1_270_000_000
    clocks.advance(0.5, wall_jump=-3.0)  # NTP steps the wall clock back: bag time goes on
    assert clock.stamp_ns() == 1_770_000_000
    assert clock.on_step(
        [1.0, 1.0, 8.0, float(STEP_FLAG_FINAL | STEP_FLAG_REALTIME), epoch]
    )  # the final Step
    assert clock.stamp_ns() == 1_770_000_000 and clock.step_index == 1
    clocks.advance(0.01)
    assert clock.stamp_ns() == 1_780_000_000


@pytest.mark.parametrize(
    't', [1e300, 1e11, 5e9, -1.0, -0.0 - 1e-300, float('inf'), float('-inf'), float('nan')]
)
def test_a_step_whose_time_no_bag_can_stamp_is_refused_and_changes_nothing(t) -> None:
    """Issue 28: one forged Step with t = 1e300 killed the recorder (OverflowError in its clock),
    t = 1e11 too (an uncaught BagError: a stamp past int64 nanoseconds)."""
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME
    from formation_sim.runtime.nodes.recorder import MAX_BAG_TIME, RunClock

    clock = RunClock()
    assert clock.on_step([1.0, 3.0, 0.5])
    assert not clock.on_step([1.0, 4.0, t])
    assert not clock.on_step([1.0, 4.0, 0.5, float(STEP_FLAG_REALTIME), t])  # as an epoch
    assert clock.stamp_ns() == 500_000_000 and clock.step_index == 3 and not clock.realtime
    # The largest time taken still stamps a bag, wall time minus it too.
    below = MAX_BAG_TIME * (1 - 1e-15)
    assert clock.on_step([1.0, 5.0, below]) and 0 <= clock.stamp_ns() < 2**63
    wall = RunClock(wall_ns=lambda: 2**62)
    assert wall.on_step([1.0, 0.0, 0.0, float(STEP_FLAG_REALTIME), below]) and 0 <= wall.stamp_ns() < 2**63


def test_any_step_data_leaves_the_run_clock_stamping_what_a_bag_holds() -> None:
    """Issue 28, property-based: Steps of any values (both clocks) never raise, and every stamp
    the clock gives afterwards is one a bag can write (int in [0, 2**63))."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME
    from formation_sim.runtime.nodes.recorder import RunClock

    floats = st.one_of(
        st.sampled_from([math.nan, math.inf, -math.inf, 1e300, 1e11, 4.7e9, -1.0, 0.0, 1.7e9]), st.floats()
    )
    flags = st.sampled_from([0.0, float(STEP_FLAG_REALTIME), float(STEP_FLAG_FINAL | STEP_FLAG_REALTIME)])
    steps = st.lists(
        st.one_of(st.lists(floats, max_size=8), st.tuples(floats, floats, floats, flags, floats).map(list))
    )

    @settings(max_examples=500, deadline=None)
    @given(steps)
    def feed(datas):
        clock = RunClock()
        for data in datas:
            clock.on_step(data)
            stamp = clock.stamp_ns()
            assert isinstance(stamp, int) and 0 <= stamp < 2**63

    feed()


def test_recorder_help_lists_every_parameter_and_bad_ones_are_named_at_once(tmp_path: Path) -> None:
    from formation_sim.runtime.nodes.recorder import RECORDER_PARAMETERS

    shown = subprocess.run([*recorder_command(), '--help'], capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0 and shown.stderr == ''
    rows = {
        line.split()[0]
        for line in shown.stdout.splitlines()
        if line.startswith('  ') and not line.startswith('  -')
    }
    assert rows == {spec.name for spec in RECORDER_PARAMETERS}
    env = {
        **os.environ,
        'ROS_DOMAIN_ID': '143',
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
    }
    bad = subprocess.run(
        [
            *recorder_command(),
            '--ros-args',
            '-p',
            'flush_period:=0.0',
            '-p',
            "topics:=['/a:std_msgs/msg/Nope']",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert bad.returncode == 2 and 'Traceback' not in bad.stderr
    assert "parameter 'output' (string) is required" in bad.stderr
    assert "parameter 'flush_period' (double) must be > 0, finite, got 0.0" in bad.stderr
    assert "parameter 'topics': message type 'std_msgs/msg/Nope' cannot be imported" in bad.stderr


@pytest.mark.ros
def test_each_topic_keeps_the_qos_its_publishers_offered(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As rosbag2 records them: one profile per publisher, transient local stays transient local."""
    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy

    bag = tmp_path / 'bag'
    latched = QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=5,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
        liveliness=LivelinessPolicy.AUTOMATIC,
        liveliness_lease_duration=Duration(seconds=1.0),
    )
    volatile = QoSProfile(
        depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
    )
    with (
        ros_domain(tmp_path, monkeypatch, 44) as context,
        recorder(
            tmp_path, f'output:={bag}', f"topics:=['{STEP}:{STEP_TYPE}','{POSES}:{POSES_TYPE}']"
        ) as process,
    ):
        node = rclpy.create_node('qos_recording_test', context=context)
        steps = [node.create_publisher(Float64MultiArray, STEP, latched) for _ in range(2)]
        poses = node.create_publisher(PoseArray, POSES, volatile)
        wait_for_subscribers([*steps, poses], process, tmp_path)
        steps[0].publish(step_bytes(0))
        poses.publish(poses_bytes(0))
        assert all(publisher.wait_for_all_acked(Duration(seconds=30)) for publisher in (steps[0], poses))
        stop(process, signal.SIGINT, tmp_path)
        node.destroy_node()

    offered = {
        t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
        for t in metadata(bag)['topics_with_message_count']
    }
    assert [(p['reliability'], p['durability'], p['liveliness_lease_duration']) for p in offered[STEP]] == [
        ('reliable', 'transient_local', {'sec': 1, 'nsec': 0})
    ] * 2
    assert [(p['reliability'], p['durability']) for p in offered[POSES]] == [('reliable', 'volatile')]


# --------------------------------------------------------------------------- bags of real runs


def _bag_of_a_run(bag: Path) -> dict[str, list]:
    """Per topic, its (bag time, message) in bag order, after checking what every run's bag must
    hold: the run's QoS on every topic (the scenario latched), Jazzy's distro and type hashes,
    stamps that never decrease on a topic."""
    from mcap.reader import make_reader

    info = metadata(bag)
    assert info['ros_distro'] == 'jazzy'
    topics = {t['topic_metadata']['name']: t['topic_metadata'] for t in info['topics_with_message_count']}
    for name, topic in topics.items():
        assert topic['offered_qos_profiles'], f'{name}: no offered QoS recorded'
        assert topic['type_description_hash'].startswith('RIHS01_'), name
    assert {p['durability'] for p in topics['/formation/scenario']['offered_qos_profiles']} == {
        'transient_local'
    }
    with next(bag.glob('*.mcap')).open('rb') as stream:
        channels = make_reader(stream).get_summary().channels.values()
        assert {c.topic: c.metadata['topic_type_hash'] for c in channels} == {
            n: t['type_description_hash'] for n, t in topics.items()
        }
    messages: dict[str, list] = {}
    for message in read_bag(bag):
        messages.setdefault(message.topic, []).append(
            (message.timestamp_ns, decode(message.rawdata, message.msgtype))
        )
    for name, stamped in messages.items():
        stamps = [stamp for stamp, _ in stamped]
        assert stamps == sorted(stamps), f'{name}: time stamps go backwards'
    return messages


def _trigger_infos(messages: dict[str, list]):
    from formation_msgs_py.codec import decode_trigger_info

    return [
        (stamp, decode_trigger_info(msg))
        for name, stamped in messages.items()
        if '/trigger_info/' in name
        for stamp, msg in stamped
    ]


def _assert_received_soon_after_their_trigger(messages: dict[str, list], *, within: float = 0.5) -> None:
    """Wall clock: each triggering message is received after its trigger, and soon (bag time = run
    time): within `within` seconds."""
    lags = [stamp - round(info.stamp * 1e9) for stamp, info in _trigger_infos(messages)]
    assert lags and min(lags) >= 0 and max(lags) < within * 1e9, (min(lags), max(lags))


def _epoch(messages: dict[str, list]) -> float:
    from formation_msgs_py.codec import decode_step

    return decode_step(messages[STEP][0][1]).epoch


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
def test_a_lock_step_bag_is_stamped_with_sim_time(distributed_single_run) -> None:
    from formation_msgs_py.codec import decode_step

    messages = _bag_of_a_run(distributed_single_run.bag)
    steps = [(stamp, decode_step(msg)) for stamp, msg in messages[STEP]]
    assert [stamp for stamp, _ in steps] == [round(step.time * 1e9) for _, step in steps]
    infos = _trigger_infos(messages)
    assert len(infos) == distributed_single_run.summary['messages_sent']
    # Information is sent at its own trigger, the step's time: bag time is its stamp t^i_k, or,
    # when it reached the recorder before its Step did (a loaded machine), an earlier Step's time,
    # one of those the recorder may lag behind (the simulator waits for it beyond that).
    step_times = [stamp for stamp, _ in steps]
    for stamp, info in infos:
        own = step_times.index(round(info.stamp * 1e9))
        assert stamp in step_times[max(0, own - RECORDER_LAG) : own + 1], (stamp, info)
    assert sum(stamp == round(info.stamp * 1e9) for stamp, info in infos) > 0.9 * len(infos)


def _run_with_bag(tmp_path: Path, scenario, domain_id: int, **options):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    result = FormationRun(
        scenario, out_dir=tmp_path / 'run', domain_id=domain_id, progress=False, timeout=240.0, **options
    ).run()
    assert result.ok, result.message
    return _bag_of_a_run(result.bag)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_real_time_bag_is_stamped_with_the_run_time_of_each_message(tmp_path: Path) -> None:
    from formation_msgs_py.codec import decode_status
    from formation_msgs_py.lockstep import DISCOVERY_STEP

    horizon = 3.0
    scenario = Path(__file__).parents[4] / 'benchmarks' / 'gentle_square.yaml'
    messages = _run_with_bag(tmp_path, scenario, 45, horizon=horizon, clock='realtime')
    # Within 1.5 s (0.5 s for the robots' run below, which runs alone): this run shares a loaded
    # machine with other tests, where a recorder or an agent can be held up for more than 0.5 s; a
    # bag stamped on sim time (0 until the final Step) still fails the lower bound.
    _assert_received_soon_after_their_trigger(messages, within=1.5)
    assert max(info.stamp for _, info in _trigger_infos(messages)) > horizon / 2  # spread over the run
    final_stamp = messages[STEP][-1][0]
    assert final_stamp >= (horizon - 0.01) * 1e9  # the final Step goes out at the horizon on the wall clock
    # Stamped 0: only what came before Step 0 (the agents' discovery announcements, the scenario).
    for name, stamped in messages.items():
        for stamp, msg in stamped:
            if stamp == 0:
                assert name == '/formation/scenario' or (
                    name == '/formation/status' and decode_status(msg).step_index == DISCOVERY_STEP
                ), name


@pytest.mark.alone  # a wall-clock bound: no other ROS test beside it (tests/conftest.py)
@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_robot_runs_bag_is_stamped_with_the_run_time_of_each_message(tmp_path: Path) -> None:
    from formation_sim.runtime.launch.plan import RobotOptions

    horizon = 3.0
    messages = _run_with_bag(
        tmp_path,
        'robots_square',
        46,
        horizon=horizon,
        backend='holonomic',
        robots=RobotOptions(model='holonomic'),
    )
    epoch = _epoch(messages)
    _assert_received_soon_after_their_trigger(messages)
    # A pose's bag time is when it came, since the epoch: right after its measurement (header stamp).
    poses = messages['/agent_1/robot/odom']
    measured = [
        (stamp, msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 - epoch) for stamp, msg in poses
    ]
    assert all(t < 0.05 for stamp, t in measured if stamp == 0)  # stamped 0: measured before the run began
    lags = [stamp / 1e9 - t for stamp, t in measured if stamp > 0]
    assert len(lags) > 100 * horizon / 2 and min(lags) >= -1e-3 and max(lags) < 0.5, (min(lags), max(lags))
    offered = {
        t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
        for t in metadata(tmp_path / 'run' / 'bag')['topics_with_message_count']
    }
    assert {p['durability'] for p in offered['/agent_1/robot/odom']} == {'volatile'}  # as the robot offers it
    assert {p['durability'] for p in offered['/formation/robots']} == {'transient_local'}


def test_a_step_without_the_runs_tag_is_no_clock_for_the_bag():
    """With the run's key, a Step without its valid tag moves no bag time (docs/HOSTILE_TRAFFIC.md,
    Tags); without a key every Step does, as before."""
    from types import SimpleNamespace

    from formation_msgs_py.codec import encode_step, tag_array
    from formation_msgs_py.lockstep import Step
    from formation_msgs_py.tags import Signer, Verifier, new_key
    from formation_sim.runtime.nodes.recorder import _untagged_step

    key, warned = new_key(), []
    node = SimpleNamespace(
        _verifier=Verifier(key),
        _clock_topic='/formation/step',
        get_logger=lambda: SimpleNamespace(warning=warned.append),
    )
    step = Step(index=1, time=0.5, flags=0, epoch=0.0, due=())
    assert _untagged_step(node, encode_step(step))
    assert warned and 'a Step that moves no bag time' in warned[0]
    signed = tag_array(encode_step(step), Signer(key, writer='formation_simulator'), '/formation/step')
    assert not _untagged_step(node, signed)
    assert _untagged_step(node, signed)  # the same Step again: a replay
    node._verifier = Verifier(None)
    assert not _untagged_step(node, encode_step(step))


# -- RunBag: what goes into the bag (ROS-free) -----------------------------------------------------


def _run_bag(output, *, clock_topic='/formation/step', warned=None):
    from formation_sim.runtime.nodes.recorder import RunBag

    bag = RunBag(
        str(output),
        clock_topic=clock_topic,
        warn=(warned if warned is not None else []).append,
        offered=lambda name: [],
        now_ns=lambda: 7,
    )
    bag.bag.add_topic('/formation/state', 'std_msgs/msg/Float64MultiArray')
    return bag


def test_what_comes_before_the_first_step_waits_and_is_stamped_with_its_time(tmp_path: Path) -> None:
    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import Step

    warned: list[str] = []
    run_bag = _run_bag(tmp_path / 'bag', warned=warned)
    early = serialize_message(Float64MultiArray(data=[1.0]))
    run_bag.take('/formation/state', early)
    assert run_bag.bag.message_count == 0  # held: the run's time is not known yet
    assert run_bag.clock.on_step(list(encode_step(Step(index=0, time=2.5)).data))
    run_bag.take('/formation/state', serialize_message(Float64MultiArray(data=[2.0])))
    run_bag.close()
    stamps = [(m.timestamp_ns, list(decode(m.rawdata, m.msgtype).data)) for m in read_bag(tmp_path / 'bag')]
    assert stamps == [(2_500_000_000, [1.0]), (2_500_000_000, [2.0])]  # the early one first
    assert run_bag.failure is None and run_bag.unwritable == 0
    assert warned == ['/formation/state: no publisher in the ROS graph yet: its offered QoS is not recorded']


def test_a_bag_that_cannot_be_written_stops_the_recording_and_says_how_to_recover(small_disk) -> None:
    run_bag = _run_bag(small_disk(1) / 'bag', clock_topic='')  # no clock topic: the node clock's stamp
    payload = serialize_message(Float64MultiArray(data=[0.5] * 8192))  # 64 KiB a message
    for _ in range(64):  # 4 MiB into 1 MiB
        run_bag.take('/formation/state', payload)
        if not run_bag.flush():
            break
    assert run_bag.failure is not None
    text = str(run_bag.failure)
    assert text.startswith(f'cannot write the bag {run_bag.bag.path}: ')
    assert text.endswith(
        f'recording stopped, {run_bag.flushed_count} messages are in the file '
        '(formation recover BAG rebuilds it, once there is space)'
    )
    run_bag.take('/formation/state', payload)  # ignored from now on
    assert not run_bag.flush()
    run_bag.close()  # says nothing more: the file stays as the last flush left it
