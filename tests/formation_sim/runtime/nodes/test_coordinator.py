"""The coordinator in one process (no other process is started): what it waits for, when it stops
a robot run, and that its summary is what `formation analyze` reads back from the same messages."""

from __future__ import annotations

import json
import math
import re
import struct
import time

import numpy as np
import pytest

from formation_sim.model.scenario import load_scenario

pytestmark = pytest.mark.ros

DOMAIN_ID = 162
EPOCH = 1_700_000_000.25


@pytest.fixture
def coordinator(ros):
    from formation_agent.ros.parameters import as_overrides
    from formation_sim.runtime.nodes.coordinator import FormationCoordinatorNode

    nodes = []

    def build(**parameters):
        defaults = {
            'robot': 'unicycle',
            'control_point_distance': 0.1,
            'robot_trajectory': 'true_odom',
            'backend': 'unicycle',
        }
        node = FormationCoordinatorNode(
            scenario=load_scenario('robots_square'),
            parameter_overrides=as_overrides({**defaults, **parameters}),
            context=ros,
        )
        nodes.append(node)
        return node

    yield build
    for node in nodes:
        node.destroy_node()


def _start(node, epoch: float) -> None:
    """The run as if Step 0 had gone out at `epoch`."""
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step

    node.marks.started = node.marks.created
    node.epoch = epoch
    node.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=epoch)


def _odometry(agent: int, t: float, *, epoch: float = EPOCH):
    """Robot `agent` of robots_square driving an arc: its exact state at run time t."""
    from nav_msgs.msg import Odometry

    from formation_sim.sim.robots import quaternion_from_yaw

    v, w = 0.05 * agent, 0.3
    yaw = 0.2 * agent + w * t
    x = 0.3 * agent + v / w * (math.sin(yaw) - math.sin(0.2 * agent))
    y = -0.2 * agent - v / w * (math.cos(yaw) - math.cos(0.2 * agent))
    msg = Odometry()
    stamp = epoch + t
    msg.header.stamp.sec = math.floor(stamp)
    msg.header.stamp.nanosec = round((stamp - math.floor(stamp)) * 1e9)
    msg.header.frame_id = 'world'
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = quaternion_from_yaw(yaw)[2:]
    msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
    return msg


def _raw(msg) -> bytes:
    """A message as the coordinator's raw pose readers take it: its serialized bytes."""
    from rclpy.serialization import serialize_message

    return serialize_message(msg)


def test_discovery_waits_for_every_agent_and_every_robot(coordinator):
    from formation_sim.runtime.nodes.time_keeper import discovery_gaps

    node = coordinator()
    gaps = discovery_gaps(node)
    assert 'agents whose triggering-information writer is not matched: 1, 2, 3, 4' in gaps
    assert (
        'robots whose robot/true_odom writer is not matched '
        '(not running, or a best-effort writer): 1, 2, 3, 4' in gaps
    )
    assert '/formation/robots readers 0/1' not in gaps  # no recorder asked for
    assert not node._connected()


def test_an_edge_at_delta_in_the_robots_poses_stops_the_run(coordinator):
    from formation_sim.runtime.errors import ConnectivityLostError

    node = coordinator()
    _start(node, time.time() - 0.5)
    scenario = node.scenario
    for agent in scenario.agent_ids:
        node.world._on_pose(_raw(_odometry(agent, 0.4, epoch=node.epoch)), agent)
    node.world.tick()  # the poses above: every edge shorter than Δ = 2
    far = _odometry(3, 0.45, epoch=node.epoch)
    far.pose.pose.position.x = 3.0  # robot 3's control point more than 2 m from its neighbours
    node.world._on_pose(_raw(far), 3)
    with pytest.raises(
        ConnectivityLostError, match=r'edge \(2, 3\) reached the communication radius at t=\d+\.\d+'
    ):
        node.world.tick()


def test_a_pose_that_is_not_its_message_is_rejected_and_counted_not_sampled(coordinator):
    node = coordinator()
    _start(node, time.time() - 0.5)
    good = _raw(_odometry(1, 0.4, epoch=node.epoch))
    node.world._on_pose(good[:40], 1)  # cut short: no Odometry
    node.world._on_pose(good, 1)
    assert node.rejected == {'length': 1} and len(node.world.poses.samples[1]) == 1


def test_nan_ahead_and_jumping_poses_are_refused_counted_and_never_checked_or_sampled(coordinator):
    """Issue 28: five NaN odometry poses were kept (the edge check blinded, summary.json not
    JSON); one stamped 0.4 s ahead gave max_edge_length 5.38 > Δ with no failure."""
    from formation_sim.runtime.errors import ConnectivityLostError

    node = _running(coordinator, max_linear_speed=0.5)
    for _ in range(5):
        nan = _odometry(2, 0.52, epoch=node.epoch)
        nan.pose.pose.position.x = math.nan
        node.world._on_pose(_raw(nan), 2)
    # 5 s ahead of the clock (the tolerance: 0.1 s; the pose was 0.4 s ahead, which a loaded
    # CI machine's delay between the run's start above and this line once used up), 3 m off.
    ahead = _odometry(3, time.time() - node.epoch + 5.0, epoch=node.epoch)
    ahead.pose.pose.position.x = 3.0
    node.world._on_pose(_raw(ahead), 3)
    jump = _odometry(4, 0.51, epoch=node.epoch)  # 2 m in 10 ms: beyond 0.5 m/s
    jump.pose.pose.position.x += 2.0
    node.world._on_pose(_raw(jump), 4)
    assert node.rejected == {'non_finite': 5, 'future': 1, 'jump': 1}
    assert node.world.poses.refused == node.rejected
    latest = node.world.poses.latest_positions()
    assert np.isfinite(latest).all() and all(
        len(samples) == 1 for samples in node.world.poses.samples.values()
    )
    node.world.tick()  # every edge as the real poses have it: shorter than Δ, no failure
    # NaN poses do not blind the edge check: with no speed limit, a real pose 3 m off stops the run.
    free = _running(coordinator)
    for _ in range(5):
        free.world._on_pose(_raw(nan), 2)
    far = _odometry(3, 0.53, epoch=free.epoch)
    far.pose.pose.position.x = 3.0
    free.world._on_pose(_raw(far), 3)
    with pytest.raises(ConnectivityLostError, match=r'edge \(\d, 3\) reached the communication radius'):
        free.world.tick()


def _report(agent: int, failure: str | None):
    from formation_msgs_py.codec import encode_agent_report
    from formation_msgs_py.lockstep import AgentReport

    return encode_agent_report(AgentReport(agent=agent, final=True, rejected={}, failure=failure))


def _running(coordinator, **parameters):
    """A coordinator 0.5 s into its run, every robot heard just now."""
    node = coordinator(**parameters)
    _start(node, time.time() - 0.5)
    for agent in node.scenario.agent_ids:
        node.world._on_pose(_raw(_odometry(agent, 0.5, epoch=node.epoch)), agent)
    return node


def test_a_robot_whose_poses_stop_ends_the_run_at_once_and_is_named(coordinator):
    from formation_sim.runtime.errors import RobotLostError

    # A silence of 5 s: a loaded machine may take a good part of a second between two lines here.
    node = _running(coordinator, pose_silence=5.0)
    node.world.tick()  # every robot heard: the run goes on
    node.world.poses.watch.heard[2] -= 6.0  # robot 2's latest pose came 6 s before the others'
    with pytest.raises(
        RobotLostError,
        match=(
            r'^robot 2 lost at t=\d+\.\d+ \(step 0\): no pose '
            r'on /agent_2/robot/true_odom for more than 5(\.0)? s'
        ),
    ):
        node.world.tick()


def test_an_agent_that_names_its_error_ends_the_run_at_once_and_a_silent_robot_is_named_first(coordinator):
    from formation_sim.runtime.errors import AgentFailedError, RobotLostError

    node = _running(coordinator, pose_silence=5.0)
    with pytest.raises(
        AgentFailedError,
        match=(
            r'^agent 1 stopped at t=\d+\.\d+ \(step 0\): the pose of robot 1 is 0\.51 s old; '
            r'the run stops$'
        ),
    ):
        node._on_report(_report(1, 'the pose of robot 1 is 0.51 s old'))
    node = _running(coordinator, pose_silence=5.0)
    node.world.poses.watch.heard[2] -= 3.0  # more than half the silence: robot 2's poses stopped first
    with pytest.raises(RobotLostError, match=r'^robot 2 lost at t=\d+\.\d+'):
        node._on_report(_report(1, 'the pose of robot 2 is 0.51 s old'))
    node.book.accept_report(decode_report(_report(3, 'the pose of robot 2 is 0.52 s old')))
    node.fail(RobotLostError('robot 2 lost', agents=[2]))
    node.note_what_followed()
    assert node.failure_info['kind'] == 'robot_lost' and node.failure_info['agents'] == [2]
    assert node.failure_info['followed'] == {
        '1': 'the pose of robot 2 is 0.51 s old',
        '3': 'the pose of robot 2 is 0.52 s old',
    }
    assert (
        node.failure_info['message']
        == 'robot 2 lost; then agents 1, 3 stopped: the pose of robot 2 is 0.51 s old'
    )


def decode_report(msg):
    from formation_msgs_py.codec import decode_agent_report

    return decode_agent_report(msg)


def test_an_agent_that_leaves_on_the_final_step_or_after_it_stops_nothing(coordinator):
    node = _running(coordinator)
    node.end_now()
    node._on_report(_report(1, None))  # its final report at the end: no failure
    node._on_report(_report(2, 'stopped by a signal'))  # after the final Step: the run has ended
    # (one without a failure before the final Step went out: a final Step from elsewhere, below)
    assert node.failure_info is None


def test_an_agent_whose_pose_went_stale_after_the_final_step_at_the_horizon_is_no_failure(
    coordinator, tmp_path
):
    """The race of a robot run's end: the robots stop publishing at the horizon, the final Step is
    on its way, an agent's command timer finds its own pose stale and the agent leaves naming it.
    The run reached its horizon: the agent is noted in extra.after_end, and `formation run`
    excuses its exit status (the agent's zero command went out first)."""
    import subprocess
    from pathlib import Path

    from formation_sim.runtime.launch.results import excused_after_end
    from formation_sim.runtime.launch.supervise import Child
    from formation_sim.runtime.nodes.time_keeper import run_extra
    from formation_sim.sim.summary import unstarted_summary

    node = _running(coordinator, horizon=0.5)
    node.world._end_at_horizon()  # the robots stop publishing here, the final Step goes out
    node._on_report(
        _report(
            2,
            'agent 2: the pose of robot 2 on /agent_2/robot/odom '
            'is 0.508 s old at t=0.981 (pose_timeout 0.5 s)',
        )
    )
    assert node.failure_info is None
    extra = run_extra(node, node.reached_time)
    assert extra['failure'] is None and extra['after_end'] == {
        '2': (
            'agent 2: the pose of robot 2 on /agent_2/robot/odom '
            'is 0.508 s old at t=0.981 (pose_timeout 0.5 s)'
        )
    }
    # a summary.json the time keeper could write (RunSummary refuses one with its keys missing)
    unstarted_summary(node.scenario, horizon=0.5, mode='robots', extra=extra).write(tmp_path / 'summary.json')

    def child(name: str, returncode: int) -> Child:
        process = subprocess.Popen(['true'])
        process.wait()
        process.returncode = returncode
        return Child(name=name, process=process, log=Path('/nonexistent'), expected_exit=True)

    failed, note = excused_after_end([child('agent_2', 1), child('agent_3', 1)], tmp_path / 'summary.json')
    assert [c.name for c in failed] == ['agent_3']  # no report of its failure after the end: a failure
    assert note.startswith(
        'agent_2 stopped after the run reached its horizon (not a failure of the run): agent 2: the pose'
    )


def test_the_final_step_goes_out_once_and_a_discovery_that_fails_leaves_a_summary(coordinator, tmp_path):
    from formation_sim.runtime.errors import DiscoveryError
    from formation_sim.runtime.nodes.keeper_main import stop_and_write

    node = _running(coordinator)
    node.end_now()
    node.end_now()
    assert node.published['/formation/step'] == 1
    node = coordinator(out_dir=str(tmp_path), discovery_timeout=0.01)
    time.sleep(0.02)  # the discovery timeout passes (not a synchronisation: the timeout is the input)
    with pytest.raises(DiscoveryError) as caught:
        node._tick()
    stop_and_write(node, None, caught.value)
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['mode'] == 'robots' and summary['extra']['started'] is False
    failure = summary['extra']['failure']
    assert failure['kind'] == 'discovery' and failure['message'].startswith(
        'discovery did not complete within 0.01 s; still missing: '
    )
    assert 'node_created' in summary['extra']['timestamps'] and 'step0' not in summary['extra']['timestamps']


def test_the_graph_leaves_out_a_node_that_left_between_the_listing_and_the_look_at_it():
    """A killed agent's test (1 run of 60 under load): agent 3, stopped by the orchestrator's
    SIGINT, left between the keeper's listing of the graph and its look at agent 3's endpoints;
    the error ('cannot get publisher names and types for nonexistent node') aborted the end of the
    run, and robot 2 got no zero command.  No ROS: the graph is a stub."""
    from rclpy.node import NodeNameNonExistentError

    from formation_sim.runtime.nodes.time_keeper import graph_of

    class _Graph:
        def get_node_names_and_namespaces(self):
            return [('formation_agent', '/agent_3'), ('formation_recorder', '/')]

        def _look(self, name, namespace):
            if namespace == '/agent_3':
                raise NodeNameNonExistentError('cannot get publisher names and types for nonexistent node')
            return [('/b', ['std_msgs/msg/String']), ('/a', ['std_msgs/msg/String'])]

        get_publisher_names_and_types_by_node = get_subscriber_names_and_types_by_node = _look
        get_service_names_and_types_by_node = get_client_names_and_types_by_node = _look

    ends = ('publishers', 'subscriptions', 'services', 'clients')
    assert graph_of(_Graph()) == {'/formation_recorder': {end: ['/a', '/b'] for end in ends}}


def test_a_run_whose_orderly_end_fails_still_sends_every_robot_its_zero(
    coordinator, tmp_path, monkeypatch, capsys
):
    """Whatever breaks the end of a run (the final reports never collected), every robot gets its
    zero command from the coordinator and the summary is written all the same."""
    from formation_sim.runtime.errors import AgentLostError
    from formation_sim.runtime.nodes import keeper_main

    def broken(node, executor):
        raise RuntimeError('cannot get publisher names and types for nonexistent node')

    class _Executor:  # the world's bounded wait spins it: time passes
        def spin_once(self, *, timeout_sec: float) -> None:
            time.sleep(timeout_sec)

    monkeypatch.setattr(keeper_main, 'stop_agents', broken)
    node = _running(coordinator, out_dir=str(tmp_path))
    keeper_main.stop_and_write(node, _Executor(), AgentLostError('agent 2 lost', agents=[2]))
    assert node.world.robot_stops.sent_all == [1, 2, 3, 4]
    err = capsys.readouterr().err
    assert 'formation_sim: could not stop the agents: cannot get publisher names' in err
    assert 'could not stop the robots' not in err
    summary = json.loads((tmp_path / 'summary.json').read_text())
    assert summary['extra']['failure']['kind'] == 'agent_lost'


def test_the_summary_is_what_analyze_reads_from_a_bag_of_the_same_messages(coordinator, tmp_path):
    from geometry_msgs.msg import Twist, Vector3
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from formation_msgs_py.codec import encode_agent_report, encode_status, encode_step, encode_trigger_info
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME, AgentReport, Status, Step
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.analysis.load import load_bag_run
    from formation_sim.analysis.report import bag_summary, diff_summaries
    from formation_sim.bag.io import BagWriter
    from formation_sim.model.scenario import dump_scenario_text
    from formation_sim.sim.summary import build_summary

    horizon = 1.0
    node = coordinator(horizon=horizon, sample_period=0.05)
    scenario = node.scenario
    messages = []  # (topic, type, message) in arrival order, for the bag

    def arrive(topic, msgtype, msg, handler=None):
        messages.append((topic, msgtype, msg))
        if handler is not None:
            handler(msg)

    for agent in scenario.agent_ids:  # poses before t = 0 reach the coordinator during discovery
        arrive(
            f'/agent_{agent}/robot/true_odom',
            'nav_msgs/msg/Odometry',
            _odometry(agent, -0.013),
            lambda m, a=agent: node.world._on_pose(_raw(m), a),
        )
    _start(node, EPOCH)
    arrive('/formation/step', 'std_msgs/msg/Float64MultiArray', encode_step(node.step))
    arrive(
        '/formation/scenario',
        'std_msgs/msg/String',
        String(data=dump_scenario_text(scenario.replace(horizon=horizon))),
    )
    arrive(
        '/formation/robots',
        'std_msgs/msg/String',
        String(data=json.dumps(node.world.robots, separators=(',', ':'))),
    )
    triggers = {
        1: [0.0, 0.31, 0.72],
        2: [0.0, 0.5],
        3: [0.0, 0.1234567],
        4: [0.0, 0.9, 1.02],
    }  # 1.02: after the horizon
    for k in range(-1, 108):  # 100 Hz, stamps a little off the grid
        t = k * 0.01 + 0.0031
        for agent in scenario.agent_ids:
            arrive(
                f'/agent_{agent}/robot/true_odom',
                'nav_msgs/msg/Odometry',
                _odometry(agent, t),
                lambda m, a=agent: node.world._on_pose(_raw(m), a),
            )
        if k == 50:  # issue 28: a NaN pose and one stamped ahead of every clock, both refused by both
            nan, ahead = _odometry(2, t + 0.001), _odometry(3, time.time() + 5.0 - EPOCH)
            nan.pose.pose.position.y, ahead.pose.pose.position.x = math.nan, 40.0
            for agent, forged in ((2, nan), (3, ahead)):
                arrive(
                    f'/agent_{agent}/robot/true_odom',
                    'nav_msgs/msg/Odometry',
                    forged,
                    lambda m, a=agent: node.world._on_pose(_raw(m), a),
                )
        for agent, times in triggers.items():
            for number, stamp in enumerate(times, start=1):
                if t - 0.01 < stamp <= t:
                    for j in scenario.neighbours(agent):
                        info = TriggerInfo(
                            sender=agent,
                            receiver=j,
                            stamp=stamp,
                            control=(0.01, -0.02),
                            rel_position=(1.0, 0.0),
                        )
                        watched = j == min(scenario.neighbours(agent))
                        arrive(
                            f'/agent_{agent}/trigger_info/to_{j}',
                            'std_msgs/msg/Float64MultiArray',
                            encode_trigger_info(info),
                            (lambda m, a=agent: node.world._on_info(m, a)) if watched else None,
                        )
                    status = Status(
                        agent=agent,
                        step_index=0,
                        next_time=math.inf,
                        info_sent=2 * number,
                        info_received=0,
                        commands_sent=0,
                        triggers=number,
                        ready=True,
                        last_planned=stamp - 0.004,
                    )
                    arrive(
                        '/formation/status',
                        'std_msgs/msg/Float64MultiArray',
                        encode_status(status),
                        node._on_status,
                    )
    node.world._end_at_horizon()
    arrive(
        '/formation/step',
        'std_msgs/msg/Float64MultiArray',
        encode_step(Step(index=1, time=horizon, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=EPOCH)),
    )
    for agent in scenario.agent_ids:
        published = {
            f'/agent_{agent}/trigger_info/to_{j}': len(triggers[agent]) for j in scenario.neighbours(agent)
        }
        report = AgentReport(agent=agent, final=True, rejected={}, published=published)
        arrive('/formation/agent_report', 'std_msgs/msg/String', encode_agent_report(report), node._on_report)
        # The robots' last commands (the coordinator does not read them): robot 4 was left turning.
        arrive(
            f'/agent_{agent}/robot/cmd_vel',
            'geometry_msgs/msg/Twist',
            Twist(angular=Vector3(z=0.3 if agent == 4 else 0.0)),
        )

    record = node.world.record()
    assert record.mode == 'robots' and record.trigger_times == {
        1: [0.0, 0.31, 0.72],
        2: [0.0, 0.5],
        3: [0.0, 0.1234567],
        4: [0.0, 0.9],
    }
    assert (
        record.sample_times[0] == 0.0
        and record.sample_times[-1] == horizon
        and 0.1234567 in record.sample_times
    )
    # Samples: the control points l = 0.1 ahead of the axles, interpolated between poses.
    k = int(np.flatnonzero(record.sample_times == 0.5)[0])
    x, y, yaw = _axle(2, 0.5)
    assert np.allclose(
        record.sample_positions[k, 1], [x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)], atol=1e-5
    )
    lateness = record.extra['lateness']['3']
    assert math.isclose(lateness['max'], 0.004, abs_tol=1e-12)

    with BagWriter(tmp_path / 'bag') as bag:
        for topic, msgtype, _ in messages:
            bag.add_topic(topic, msgtype)
        received = 0  # run time [ns] as the recorder stamps a message: when it got it, after its stamp
        for number, (topic, msgtype, msg) in enumerate(messages):
            if msgtype == 'nav_msgs/msg/Odometry' and msg.header.stamp.sec < EPOCH + 10.0:
                stamp = msg.header.stamp
                run_time = (stamp.sec - 1_700_000_000) * 10**9 + stamp.nanosec - 250_000_000  # - EPOCH
                received = max(received, run_time + 10_000_000)  # got 10 ms after its stamp
            bag.write(topic, max(received, 0) + number, serialize_message(msg))
    from_bag = load_bag_run(tmp_path / 'bag')
    assert from_bag.record.mode == 'robots'
    checks = {check.name: check for check in from_bag.checks}
    assert node.rejected == {'non_finite': 1, 'future': 1}
    assert checks['robot poses'].detail == (
        '2 poses on /agent_<i>/robot/true_odom refused as the coordinator and the agents refuse them, '
        "not sampled: {'future': 1, 'non_finite': 1}"
    )
    assert [name for name, check in checks.items() if not check.ok] == [
        "every robot's last command is a stop"
    ]
    assert (
        checks["every robot's last command is a stop"].detail
        == "3 robots stopped by their last command; still moving: ['4: [0.0, 0.0, 0.0, 0.0, 0.0, 0.3]']"
    )
    # Agent 4's trigger after the horizon is not a trigger of the run, but its Status counted it.
    assert (
        checks['status counters = bag'].ok
        and checks['one TriggerInfo per neighbour per trigger'].detail == '20 messages for 10 triggers'
    )
    differences, _ = diff_summaries(bag_summary(from_bag.record), build_summary(record))
    assert [d.key for d in differences if d.key != 'wall_time'] == []


def _axle(agent: int, t: float) -> tuple[float, float, float]:
    v, w = 0.05 * agent, 0.3
    yaw = 0.2 * agent + w * t
    return (
        0.3 * agent + v / w * (math.sin(yaw) - math.sin(0.2 * agent)),
        -0.2 * agent - v / w * (math.cos(yaw) - math.cos(0.2 * agent)),
        yaw,
    )


def test_any_value_on_any_topic_the_coordinator_reads_is_taken_or_refused_never_a_crash(coordinator):
    """Issue 28, property-based: Status, reports, triggering information, recorder heartbeats and
    poses carrying any values (NaN, ±inf, extreme times and ids, empty and huge arrays, damaged
    CDR) are taken or refused and counted; the only exceptions are the run's own named errors (a
    report that says its agent failed stops the run), and the poses kept stay finite."""
    from types import SimpleNamespace

    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from formation_msgs_py.lockstep import REJECT_REASONS
    from formation_sim.runtime.nodes.keeper_main import NAMED_ERRORS

    node = _running(coordinator)
    floats = st.one_of(
        st.sampled_from([math.nan, math.inf, -math.inf, 1e300, 1e11, -1.0, 0.0, 1.0, 2.0, 3.0]), st.floats()
    )
    arrays = st.one_of(st.lists(floats, max_size=24), st.just([1.0] * 50_000))
    texts = st.one_of(
        st.text(max_size=80),
        st.builds(
            lambda agent, failure, version: json.dumps(
                {
                    'version': version,
                    'agent': agent,
                    'final': True,
                    'rejected': {},
                    'published': {},
                    'failure': failure,
                }
            ),
            st.one_of(st.integers(-5, 10), floats),
            st.one_of(st.none(), st.text(max_size=10)),
            st.one_of(st.just(3), floats),
        ),
    )
    good = _raw(_odometry(1, 0.5, epoch=node.epoch))
    poses = st.one_of(
        st.binary(max_size=120),
        st.tuples(st.integers(0, len(good) - 8), floats).map(
            lambda edit: good[: edit[0]] + struct.pack('<d', edit[1]) + good[edit[0] + 8 :]
        ),
    )
    calls = st.one_of(
        st.tuples(st.just('status'), arrays),
        st.tuples(st.just('report'), texts),
        st.tuples(st.just('info'), arrays),
        st.tuples(st.just('recorder'), texts),
        st.tuples(st.just('pose'), poses),
    )

    @settings(max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
    @given(st.lists(calls, min_size=1, max_size=6), st.integers(1, 4))
    def feed(messages, agent):
        for kind, value in messages:
            try:
                if kind == 'status':
                    node._on_status(SimpleNamespace(data=value))
                elif kind == 'report':
                    node._on_report(SimpleNamespace(data=value))
                elif kind == 'info':
                    node.world._on_info(SimpleNamespace(data=value), agent)
                elif kind == 'recorder':
                    node._on_recorder(SimpleNamespace(data=value))
                else:
                    node.world._on_pose(value, agent)
            except NAMED_ERRORS:
                pass
        assert set(node.rejected) <= set(REJECT_REASONS)
        for samples in node.world.poses.samples.values():
            assert all(np.isfinite(s.position).all() and math.isfinite(s.time) for s in samples)

    feed()


# -- strangers in the graph (issue 28) ------------------------------------------------------------


def _look_until_raised(node, timeout=10.0):
    """Look at the graph until a look raises (discovery of the rogue takes a moment)."""
    from formation_sim.runtime.nodes.time_keeper import look_at_graph

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        look_at_graph(node, everything=True)
        time.sleep(0.05)
    pytest.fail('nothing found in the graph')


def test_an_outside_node_on_a_robots_command_topic_stops_the_run_and_is_named(ros, coordinator, tmp_path):
    """The finding: an outside node on /agent_2/robot/cmd_vel drove robot 2 6 cm, and nothing was
    flagged.  The coordinator sees it in the graph: the run fails, naming the node and its gid."""
    from geometry_msgs.msg import Twist

    from formation_msgs_py.qos import ROBOT_COMMAND_QOS
    from formation_sim.runtime.errors import ForeignWriterError
    from formation_sim.runtime.nodes.keeper_main import stop_and_write
    from formation_sim.runtime.nodes.time_keeper import look_at_graph

    node = _running(coordinator, out_dir=str(tmp_path))
    look_at_graph(node, everything=True)  # its own zero-command writers are no strangers
    ros_node = None
    try:
        import rclpy

        ros_node = rclpy.create_node('rogue', namespace='/outside', context=ros)
        ros_node.create_publisher(Twist, '/agent_2/robot/cmd_vel', ROBOT_COMMAND_QOS)
        with pytest.raises(ForeignWriterError) as caught:
            _look_until_raised(node)
    finally:
        if ros_node is not None:
            ros_node.destroy_node()
    message = str(caught.value)
    assert re.fullmatch(
        r"a node outside the run, /outside/rogue \(writer gid [0-9a-f]{32}\), writes robot 2's command "
        r'\(/agent_2/robot/cmd_vel\): the run stops',
        message,
    ), message
    stop_and_write(node, None, caught.value)
    summary = json.loads((tmp_path / 'summary.json').read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'foreign_writer' and failure['agents'] == [2] and failure['message'] == message
    assert summary['extra']['foreign_writers'][0]['writers'][0]['node'] == '/outside/rogue'


def test_a_second_process_claiming_an_agent_is_refused_before_step_0(ros, coordinator):
    """Two nodes named /agent_2/formation_agent writing agent 2's triggering information: two
    processes claim agent 2, both named, before anything is sent."""
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.qos import PROTOCOL_QOS
    from formation_msgs_py.topics import trigger_info_topic
    from formation_sim.runtime.errors import DuplicateAgentError

    node = coordinator()
    topic = trigger_info_topic(2, min(node.scenario.neighbours(2)))
    twins = [rclpy.create_node('formation_agent', namespace='/agent_2', context=ros) for _ in range(2)]
    try:
        for twin in twins:
            twin.create_publisher(Float64MultiArray, topic, PROTOCOL_QOS)
        with pytest.raises(DuplicateAgentError) as caught:
            _look_until_raised(node)
    finally:
        for twin in twins:
            twin.destroy_node()
    assert str(caught.value).startswith('two processes claim agent 2: /agent_2/formation_agent (writer gid ')
    assert f'both write {topic}' in str(caught.value) and node.step is None


def test_agents_that_took_more_information_than_was_sent_stop_the_run(coordinator):
    """Wall clock: forged, plausible triggering information was taken (agent 1: 813 events instead
    of ~81, and the run said done).  The coordinator compares the agents' Statuses at each look."""
    from formation_msgs_py.lockstep import Status
    from formation_sim.runtime.errors import ForeignInformationError
    from formation_sim.runtime.nodes.time_keeper import look_at_graph

    node = _running(coordinator)
    for agent, (sent, received) in {1: (20, 20), 2: (20, 20), 3: (20, 20), 4: (20, 20)}.items():
        node.agents[agent].status = Status(
            agent=agent,
            step_index=0,
            next_time=1.0,
            info_sent=sent,
            info_received=received,
            commands_sent=1,
            triggers=10,
            ready=True,
        )
    look_at_graph(node, everything=True)  # as many taken as sent
    node.agents[1].status = Status(
        agent=1,
        step_index=0,
        next_time=1.0,
        info_sent=20,
        info_received=200,
        commands_sent=1,
        triggers=90,
        ready=True,
    )
    with pytest.raises(
        ForeignInformationError, match=r'took 260 messages .* but sent only 80: 180 came from outside'
    ):
        look_at_graph(node, everything=True)


def test_a_coordinator_frozen_past_the_lease_names_its_freeze_not_the_robots(coordinator):
    """The finding: a coordinator frozen 3 s (SIGSTOP) said "robots 1, 2, 3, 4 lost" although the
    robots were fine.  Its own tick, 3 s late, names the freeze first (`blamed`, as its main does)."""
    from formation_sim.runtime.errors import KeeperFrozenError, RobotLostError
    from formation_sim.runtime.nodes.time_keeper import blamed

    node = _running(coordinator, pose_silence=0.5)
    now = time.monotonic()
    node.freeze.tick(now - 3.1)  # its last tick before the freeze
    for agent in node.scenario.agent_ids:
        node.world.poses.watch.heard[agent] -= 3.0  # every robot's latest pose taken before the freeze
    with pytest.raises(RobotLostError) as caught:
        node.world._check_robots()
    error = blamed(node, caught.value)
    assert isinstance(error, KeeperFrozenError) and error.kind == 'keeper_frozen'
    assert str(error).startswith('the coordinator itself was stopped or starved for 3.0')
    assert str(error).endswith(str(caught.value))


def test_an_agent_that_leaves_on_a_final_step_the_coordinator_did_not_send_stops_the_run(coordinator):
    """Agents stop on any final Step (stopping is safe): one forged mid-run sends them home early,
    and the run must not go on as if they had been lost, nor end done."""
    from formation_sim.runtime.errors import AgentFailedError

    node = _running(coordinator)
    with pytest.raises(
        AgentFailedError, match=r"agent 3 stopped .*: it left on a final Step its run's keeper did not send"
    ):
        node._on_report(_report(3, None))
    node.end_now()
    node._on_report(_report(2, None))  # after the real final Step: its own end
    assert node.after_end == {}


def test_with_the_runs_key_triggering_information_without_its_tag_is_no_trigger(coordinator, tmp_path):
    """docs/HOSTILE_TRAFFIC.md, Tags: the coordinator learns agent i's triggers from its information
    to its first neighbour; with the run's key a forged one is refused and counted, not a trigger."""
    from formation_msgs_py.codec import encode_trigger_info, tag_array
    from formation_msgs_py.tags import Signer, new_key, write_key
    from formation_msgs_py.topics import trigger_info_topic
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.runtime.nodes.coordinator import _tag_refused_info

    key = new_key()
    node = _running(coordinator, key_file=str(write_key(tmp_path / 'run.key', key)))
    first = min(node.agents[2].neighbours)
    topic = trigger_info_topic(2, first)

    def info(stamp):
        return encode_trigger_info(
            TriggerInfo(sender=2, receiver=first, stamp=stamp, control=(0.1, 0.0), rel_position=(1.0, 0.0))
        )

    for msg in (info(0.25), tag_array(info(0.3), Signer(new_key(), writer='agent_2'), topic)):
        assert _tag_refused_info(node, msg, 2)
    signed = tag_array(info(0.35), Signer(key, writer='agent_2'), topic)
    assert not _tag_refused_info(node, signed, 2)
    node.world._on_info(signed, 2)
    assert node.agents[2].trigger_times == [0.35]
    assert node.rejected == {'untagged': 1, 'forged': 1}


def test_what_formation_robots_says_is_what_formation_analyze_reads_back() -> None:
    """/formation/robots (`robots_description`, from the coordinator's parameters) read back as
    `formation analyze` reads it: the kind, the topic measured, the control point ahead of the
    robot's origin (a holonomic robot's is its origin) and the sample grid."""
    from pathlib import Path

    from formation_sim.analysis.load import _robots_description
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS, robots_description

    defaults = {spec.name: spec.default for spec in COORDINATOR_PARAMETERS}
    for model, offset in (('unicycle', 0.2), ('holonomic', 0.0)):
        values = {
            **defaults,
            'robot': model,
            'control_point_distance': 0.2,
            'robot_trajectory': 'odom',
            'sample_period': 0.05,
        }
        sent = json.loads(json.dumps(robots_description(values)))  # as the topic carries it
        assert _robots_description(Path('run.bag'), sent) == (model, 'odom', offset, 0.05)
        assert sent['max_linear_speed'] is None  # the default inf: no limit (JSON has no inf)
