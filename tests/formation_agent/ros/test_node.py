"""The agent node: parameters checked up front; bad messages rejected and counted; injected faults."""

from __future__ import annotations

import math
import time

import pytest

pytestmark = pytest.mark.ros

DOMAIN_ID = 96

GOOD = {
    'agent_id': 1,
    'algorithm': 'eta1',
    'dimension': 2,
    'neighbour_ids': [2, 3],
    'neighbour_offsets': [0.0, -2.0, -2.0, 0.0],
    'delta': 4.0,
    'horizon': 10.0,
    'alpha': 10.0,
    'beta': 1.0,
}


def make_node(ros, **changes):
    from rclpy.parameter import Parameter

    from formation_agent.ros.node import FormationAgentNode

    values = {**GOOD, **changes}
    overrides = [Parameter(name, value=value) for name, value in values.items() if value is not None]
    node = FormationAgentNode(
        namespace='agent_1', context=ros, parameter_overrides=overrides, start_parameter_services=False
    )
    node.destroy_node()
    return node


def test_good_parameters_give_the_agent_its_neighbours(ros):
    node = make_node(ros)
    assert node.config.neighbours == {2: (0.0, -2.0), 3: (-2.0, 0.0)}
    assert node.config.gains == {
        'alpha': 10.0,
        'beta': 1.0,
        'speed_scale': 1.0,
        'threshold_floor': 0.0,
    }  # the paper's
    # c0 + α e^{-κβt}, the paper's triggering rule (formation_agent.core.trigger)
    assert node.config.trigger_rule == 'exponential'


@pytest.mark.parametrize(
    ('changes', 'complaint'),
    [
        ({'delta': None}, "parameter 'delta' (double) is required: communication radius Δ [m]"),
        ({'beta': None}, "parameter 'beta' (double) is required"),
        ({'algorithm': 'eta3'}, "parameter 'algorithm' (string) must be one of 'eta1', 'eta2', got 'eta3'"),
        ({'dimension': 4}, "parameter 'dimension' (int)"),  # rclpy's own range check, [1, 3]
        (
            {'neighbour_offsets': [0.0, -2.0, -2.0]},
            'neighbour_offsets must hold dimension * len(neighbour_ids) = 2 * 2 values',
        ),
        ({'neighbour_ids': [2, 2]}, 'neighbour_ids repeat an id: [2, 2]'),
        ({'neighbour_ids': [1, 2]}, 'neighbour_ids hold the agent itself (1)'),
        ({'horizon': float('inf')}, 'horizon must be a finite number > 0, got inf'),
        ({'algorithm': 'eta2'}, "parameter 'alpha_d' (double) is required"),
        ({'agent_id': 7}, 'agent 7 must run in namespace /agent_7, not /agent_1'),
        ({'inject_loss': 1.5}, "parameter 'inject_loss' (double)"),  # rclpy's own range check, [0, 1]
        ({'inject_delay_ms': -1.0}, "parameter 'inject_delay_ms' (double) must be >= 0, got -1.0"),
        ({'inject_jitter_ms': float('nan')}, "parameter 'inject_jitter_ms' (double) must be >= 0, got nan"),
        ({'speed_scale': 0.0}, "parameter 'speed_scale' (double)"),
        ({'speed_scale': float('nan')}, "parameter 'speed_scale' (double)"),
        ({'threshold_floor': float('nan')}, "parameter 'threshold_floor' (double) must be >= 0, got nan"),
        ({'trigger_rule': 'cubic'}, "trigger_rule: must be one of ['exponential'"),
        ({'trigger_rule': 'cubic'}, "or an import path package.module:Class, got 'cubic'"),
        ({'trigger_rule': 'no_such_module:Rule'}, "trigger_rule: cannot import 'no_such_module'"),
    ],
)
def test_bad_parameters_are_rejected_with_the_rule_broken(ros, changes, complaint):
    from formation_agent.ros.errors import ParameterError

    with pytest.raises(ParameterError) as error:
        make_node(ros, **changes)
    assert complaint in str(error.value)
    assert str(error.value).startswith('/agent_1/formation_agent: ')


def test_a_key_file_others_may_read_or_that_is_no_key_is_refused_and_a_good_one_tags(ros, tmp_path):
    """The run's key (docs/HOSTILE_TRAFFIC.md, Tags): its file's rules named, with its mode."""
    import os

    from formation_agent.ros.parameters import ParameterError
    from formation_msgs_py.tags import new_key, write_key

    good = write_key(tmp_path / 'run.key', new_key())
    node = make_node(ros, key_file=str(good))
    assert node.signer is not None and node.signer.writer == 'agent_1' and node.verifier.required
    assert 'key' not in repr(node.config).replace('key_file', '')  # never printed
    assert make_node(ros).signer is None and not make_node(ros).verifier.required  # no key: as before
    shared = write_key(tmp_path / 'shared.key', new_key())
    os.chmod(shared, 0o640)
    for path, complaint in (
        (shared, f'key_file {shared}: must be readable by its owner only (mode 0600), got 0640'),
        (tmp_path / 'none.key', f'key_file {tmp_path / "none.key"}: cannot be read'),
    ):
        with pytest.raises(ParameterError) as error:
            make_node(ros, key_file=str(path))
        assert complaint in str(error.value)


def test_every_missing_parameter_is_named_at_once(ros):
    from formation_agent.ros.errors import ParameterError

    with pytest.raises(ParameterError) as error:
        make_node(ros, delta=None, horizon=None, alpha=None, beta=None, neighbour_offsets=None)
    named = [problem.split("'")[1] for problem in error.value.problems]
    assert named == ['neighbour_offsets', 'delta', 'horizon', 'alpha', 'beta'], error.value.problems
    assert all('is required' in problem for problem in error.value.problems)


@pytest.mark.parametrize(
    ('changes', 'complaint'),
    [
        ({'robot': 'holonomic'}, 'robot: holonomic needs sensing: poses'),
        (
            {
                'robot': 'unicycle',
                'sensing': 'poses',
                'control_point_distance': 0.1,
                'dimension': 3,
                'neighbour_offsets': [0.0] * 6,
            },
            'robot: unicycle: a unicycle moves in the plane: dimension p must be 2, got 3',
        ),
        (  # l's rule, declared once in the unicycle kind (it defaults to 0.1 m, as everywhere)
            {'robot': 'unicycle', 'sensing': 'poses', 'control_point_distance': 0.0},
            "parameter 'control_point_distance' (double) must be > 0, finite, got 0.0",
        ),
        ({'max_linear_speed': 0.22}, "max_linear_speed apply to a robot's command adapter"),
        (
            {'robot': 'holonomic', 'sensing': 'poses', 'max_linear_speed': 0.0},
            "parameter 'max_linear_speed' (double) must be > 0, got 0.0",
        ),
        ({'sensing': 'poses', 'pose_topic': '/vrpn/cf/pose'}, "pose_topic must hold '{id}'"),
        ({'sensing': 'poses', 'world_frame': ''}, "world_frame must name a frame, got ''"),
        (
            {'robot': 'tank'},
            "parameter 'robot' (string) must be one of 'none', 'holonomic', 'unicycle', 'car', got 'tank'",
        ),
    ],
)
def test_bad_robot_parameters_are_rejected_with_the_rule_broken(ros, changes, complaint):
    from formation_agent.ros.errors import ParameterError

    with pytest.raises(ParameterError) as error:
        make_node(ros, **changes)
    assert complaint in str(error.value)


def test_the_safety_parameters_give_the_core_its_layer(ros):
    from formation_agent.core.safety import SafetyConfig

    node = make_node(ros)
    assert node.config.safety is None and node.core.safety is None  # off by default (D = 0)
    node = make_node(ros, min_separation=0.3, sensing_radius=2.5, safety_gamma=3.0, safety_turn=0.0)
    expected = SafetyConfig(min_separation=0.3, sensing_radius=2.5, gamma=3.0, max_speed=0.5, turn=0.0)
    assert node.config.safety == expected and node.core.safety == expected


@pytest.mark.parametrize(
    ('changes', 'complaint'),
    [
        ({'min_separation': -0.1}, "parameter 'min_separation' (double) must be >= 0, got -0.1"),
        (
            {'min_separation': 0.25, 'sensing_radius': 0.5},
            'safety.sensing_radius: must exceed the guard radius ρ* = (2 v̄ + sqrt(4 v̄² + γ² D²)) / γ '
            '= 1.05902 m',
        ),
        (
            {'min_separation': 0.25, 'sensing': 'poses', 'other_robot_ids': [2, 5]},
            'other_robot_ids must name each other robot once, not the agent or a neighbour, got [2, 5]',
        ),
        (
            {'min_separation': 0.25, 'dimension': 3, 'neighbour_offsets': [0.0] * 6},
            'min_separation: the safety layer is planar, got dimension 3',
        ),
        ({'safety_turn': -1.0}, "parameter 'safety_turn' (double) must be >= 0, got -1.0"),
    ],
)
def test_bad_safety_parameters_are_rejected_with_the_rule_broken(ros, changes, complaint):
    from formation_agent.ros.parameters import ParameterError

    with pytest.raises(ParameterError) as error:
        make_node(ros, **changes)
    assert complaint in str(error.value)


def test_robot_parameters_have_their_documented_defaults(ros):
    node = make_node(ros)
    config = node.config
    assert (config.sensing, config.pose_type, config.pose_timeout, config.robot, config.world_frame) == (
        'service',
        'pose',
        0.5,
        'none',
        'world',
    )
    # l: 0.1 m, its kind's declared default, as the coordinator's and the robot's (it was 0 here).
    assert (config.command_rate, config.geometry.control_point_distance) == (50.0, 0.1)
    assert (
        math.inf
        == config.limits.linear_speed
        == config.limits.angular_speed
        == config.limits.linear_acceleration
    )
    assert (
        config.robot_pose_topic(3) == '/agent_3/robot/pose'
        and config.robot_command_topic == '/agent_1/robot/cmd_vel'
    )
    odom = make_node(ros, sensing='poses', pose_type='odom').config
    assert odom.robot_pose_topic(3) == '/agent_3/robot/odom'
    vrpn = make_node(ros, sensing='poses', pose_topic='/vrpn/cf{id}/pose').config
    assert vrpn.robot_pose_topic(12) == '/vrpn/cf12/pose'


# -- bad messages --------------------------------------------------------------------------------


@pytest.fixture
def live_node(ros):
    """An agent node (not yet stepped) that the test feeds messages by hand."""
    from rclpy.parameter import Parameter

    from formation_agent.ros.node import FormationAgentNode

    def build(**changes):
        values = {**GOOD, **changes}
        overrides = [Parameter(name, value=value) for name, value in values.items()]
        node = FormationAgentNode(
            namespace='agent_1', context=ros, parameter_overrides=overrides, start_parameter_services=False
        )
        nodes.append(node)
        return node

    nodes = []
    yield build
    for node in nodes:
        node.destroy_node()


@pytest.fixture
def discovery_clock(monkeypatch):
    """The clock by which an agent judges its simulator lost (formation_agent.ros.discovery's
    time.monotonic), stopped: it moves only when the test moves it, so the time a loaded machine
    takes between two lines of a test never counts against a grace of half a second."""
    from types import SimpleNamespace

    from formation_agent.ros import discovery

    now = [1000.0]
    monkeypatch.setattr(discovery, 'time', SimpleNamespace(monotonic=lambda: now[0]))
    return now


@pytest.fixture
def fake_simulator():
    """A node in a participant of its own, as the simulator's own process would be."""
    import rclpy

    other = rclpy.Context()
    rclpy.init(context=other, domain_id=DOMAIN_ID)
    simulator = rclpy.create_node('fake_simulator', context=other)
    try:
        yield simulator
    finally:
        simulator.destroy_node()
        rclpy.shutdown(context=other)


def _info_msg(values):
    from std_msgs.msg import Float64MultiArray

    return Float64MultiArray(data=[float(v) for v in values])


def _info(sender=2, receiver=1, stamp=0.0, control=(0.5, -0.5), rel_position=(1.0, 2.0), rel_velocity=None):
    from formation_msgs_py.codec import encode_trigger_info
    from formation_msgs_py.types import TriggerInfo

    info = TriggerInfo(
        sender=sender,
        receiver=receiver,
        stamp=stamp,
        control=control,
        rel_position=rel_position,
        rel_velocity=rel_velocity,
    )
    return encode_trigger_info(info)


def test_bad_trigger_information_is_rejected_counted_per_reason_and_never_reaches_the_core(live_node):
    node = live_node()
    received = []
    node.core.receive = received.append  # what the core would see
    arrivals = [
        (_info_msg([2, 1, 2, 1, 0.0, 2, 0.5, -0.5, 1.0, 2.0]), 2, 'version'),
        (_info_msg([1, 1, 2, 1, 0.0, 2, 0.5, -0.5, 1.0]), 2, 'length'),
        (_info_msg([1, 1, 2, 1, 0.0, 2, math.nan, -0.5, 1.0, 2.0]), 2, 'non_finite'),
        (_info_msg([1, 1, 2, 1, math.inf, 2, 0.5, -0.5, 1.0, 2.0]), 2, 'non_finite'),
        (_info(sender=3), 2, 'sender'),  # agent 3's information on agent 2's topic
        (_info(receiver=3), 2, 'receiver'),
        (_info(control=(0.5,), rel_position=(1.0,)), 2, 'dimension'),
        (_info(rel_velocity=(0.0, 0.0)), 2, 'dimension'),  # ETA-2 information for an ETA-1 agent
        (_info(stamp=-0.25), 2, 'time_backwards'),
        (_info(sender=3, stamp=0.0), 3, None),  # good: held until this agent's own trigger at t = 0
        (_info(sender=3, stamp=0.0), 3, 'duplicate'),
        (_info(stamp=0.5), 2, None),
        (_info(stamp=0.25), 2, 'time_backwards'),
        (_info(stamp=0.5), 2, 'duplicate'),
    ]
    expected: dict[str, int] = {}
    for msg, sender, reason in arrivals:
        node.faults.arrive(msg, sender)
        if reason is not None:
            expected[reason] = expected.get(reason, 0) + 1
        assert node.rejected == expected
    assert received == [], 'nothing reaches the core before this agent has triggered'
    assert [(info.sender, info.stamp) for info in node.arrivals.held] == [(3, 0.0), (2, 0.5)]
    assert node.counts.info_received == 0
    report = node.report(final=True)
    assert report.rejected == expected and report.rejected_total == 12 and report.final


def test_a_malformed_step_is_rejected_and_the_node_keeps_waiting(live_node):
    node = live_node()
    node._on_step(_info_msg([1, 0, 0.0]))
    node._on_step(_info_msg([7, 0, 0.0, 0, 0.0]))
    assert node.rejected == {'length': 1, 'version': 1}
    assert node.step is None and not node.finished


@pytest.mark.parametrize('end', ['final_step', 'failure'])
def test_the_final_step_or_a_failure_settles_the_node_for_its_process_loop(live_node, end):
    """`settled` ends the wait of `formation_agent.ros.main`'s loop (0.1 s of events per look):
    done once the node finishes or fails, never before; a failure is then raised by `check`."""
    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, Step

    node = live_node()
    node._on_step(_info_msg([1, 0, 0.0]))  # a malformed step: nothing settled
    assert not node.settled.done()
    if end == 'final_step':
        node._on_step(encode_step(Step(index=0, time=0.0, flags=STEP_FLAG_FINAL)))
        assert node.finished and node.settled.done() and node.counts.final_sent
        node.check()  # finished: nothing to raise
    else:
        node._fail(RuntimeError('the robot caught fire'))
        assert node.settled.done() and not node.finished
        with pytest.raises(RuntimeError, match='caught fire'):
            node.check()


def test_fault_injection_drops_everything_at_loss_one(live_node):
    node = live_node(inject_loss=1.0, inject_seed=3)
    for k in range(20):
        node.faults.arrive(_info(stamp=0.1 * k), 2)
    assert (
        node.faults.dropped == 20
        and node.faults.delayed == 0
        and node.arrivals.held == []
        and node.rejected == {}
    )


def test_fault_injection_delays_in_order_then_hands_on(ros, live_node):
    from rclpy.executors import SingleThreadedExecutor

    node = live_node(inject_delay_ms=30.0, inject_jitter_ms=20.0)
    for k in range(5):
        node.faults.arrive(_info(stamp=0.1 * k), 2)
    assert node.faults.delayed == 0 and node.arrivals.held == []  # still on the wire
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        for _ in range(200):
            if node.faults.delayed == 5:
                break
            executor.spin_once(timeout_sec=0.02)
    finally:
        executor.remove_node(node)
    assert node.faults.delayed == 5 and node.rejected == {}, (
        'a delayed message out of order would be time_backwards'
    )
    assert [info.stamp for info in node.arrivals.held] == [0.1 * k for k in range(5)]


def test_injected_faults_are_reproducible_per_seed_and_keep_each_edge_in_order():
    from formation_agent.ros.faults import FaultInjection

    def pattern(seed):
        injection = FaultInjection(agent_id=4, loss=0.1, delay_ms=5.0, jitter_ms=40.0, seed=seed)
        drops = [injection.drop() for _ in range(10_000)]
        dues = [injection.due(sender=1, now=0.001 * k) for k in range(1_000)]
        return drops, dues

    drops, dues = pattern(7)
    assert (drops, dues) == pattern(7)
    assert drops != pattern(8)[0]
    assert 900 < sum(drops) < 1100  # 10 % of 10 000 (binomial sd 30)
    assert all(a <= b for a, b in zip(dues, dues[1:])), 'a later message overtook an earlier one'
    assert all(due >= 0.001 * k + 0.005 for k, due in enumerate(dues))


def test_an_agent_whose_simulator_goes_away_leaves_with_peer_lost(ros, live_node, fake_simulator):
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray

    from formation_agent.ros.errors import PeerLostError
    from formation_msgs_py.qos import PROTOCOL_QOS
    from formation_msgs_py.topics import STEP_TOPIC

    node = live_node()
    simulator = fake_simulator
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        step_writer = simulator.create_publisher(Float64MultiArray, STEP_TOPIC, PROTOCOL_QOS)
        deadline = time.monotonic() + 20.0
        while not node.simulator.seen and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert node.simulator.seen, 'the step writer never matched'
        node.check()  # alive: nothing to report
        simulator.destroy_publisher(step_writer)  # as its process would on the way out
        with pytest.raises(
            PeerLostError,
            match=r'agent 1: the simulator \(writer of /formation/step\) is lost during discovery: '
            'it left the graph',
        ):
            while time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
                node.check()
    finally:
        executor.remove_node(node)


@pytest.mark.parametrize(
    ('flags', 'lease_lapsed', 'patience'), [(0, True, 3.0), (0, False, 0.5), ('realtime', True, 0.5)]
)
def test_a_lock_step_agent_leaves_the_end_of_a_run_to_a_simulator_whose_lease_lapsed(
    live_node, discovery_clock, flags, lease_lapsed, patience
):
    """In lock-step nothing moves while the simulator is silent: an agent gives a lapsed lease
    KEEPER_LEASE_GRACE before it leaves (the simulator ends the run itself); a writer that left
    the graph, or the wall clock (a robot would go on moving), gets LOST_GRACE."""
    from types import SimpleNamespace

    from formation_agent.ros.errors import PeerLostError
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step
    from formation_msgs_py.qos import KEEPER_LEASE_GRACE, LOST_GRACE

    assert (KEEPER_LEASE_GRACE, LOST_GRACE) == (3.0, 0.5)
    node = live_node()
    node.step = Step(index=7, time=1.25, flags=STEP_FLAG_REALTIME if flags == 'realtime' else 0)
    node.simulator.on_liveliness(SimpleNamespace(alive_count=1, not_alive_count_change=0))
    node.simulator.on_liveliness(
        SimpleNamespace(alive_count=0, not_alive_count_change=1 if lease_lapsed else 0)
    )
    # On the stopped clock (the wall clock left 0.05 s between these lines, which a loaded machine
    # once could use up): patient for exactly `patience`, lost the moment after.
    lost = node.simulator.lost_at
    discovery_clock[0] = lost + patience
    node.check()  # still patient
    discovery_clock[0] = lost + patience + 0.001
    how = 'no sign of life for 1.0 s' if lease_lapsed else 'it left the graph'
    with pytest.raises(
        PeerLostError,
        match=rf'agent 1: the simulator \(writer of /formation/step\) is lost after step 7 \(t=1.25\): {how}',
    ):
        node.check()


# -- discovery ---------------------------------------------------------------------------------------


def test_an_agent_in_discovery_names_each_endpoint_it_waits_for_until_the_simulator_is_there(
    ros, live_node, fake_simulator
):
    from geometry_msgs.msg import Twist
    from rcl_interfaces.srv import SetParameters
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray, String

    from formation_msgs_py.qos import PROTOCOL_QOS, READER_QOS
    from formation_msgs_py.topics import REPORT_TOPIC, STATUS_TOPIC, STEP_TOPIC

    node = live_node(extra_subscribers=1)
    alone = node.discovery_gaps()
    assert alone == [
        'readers of /agent_1/trigger_info/to_2: 0 of 2 (agent 2, a recorder)',
        'readers of /agent_1/trigger_info/to_3: 0 of 2 (agent 3, a recorder)',
        'a writer of /agent_2/trigger_info/to_1 (agent 2)',
        'a writer of /agent_3/trigger_info/to_1 (agent 3)',
        'readers of /agent_1/cmd_vel: 0 of 2 (the simulator, a recorder)',
        'readers of /formation/status: 0 of 2 (the simulator or coordinator, a recorder)',
        'readers of /formation/agent_report: 0 of 2 (the simulator or coordinator, a recorder)',
        'a writer of /formation/step (the simulator or coordinator)',
        'the sensing service /agent_1/sense (served by the simulator)',
    ]
    assert not node.connected()
    simulator = fake_simulator  # the simulator's side of it
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        simulator.create_publisher(Float64MultiArray, STEP_TOPIC, PROTOCOL_QOS)
        for topic, kind in (
            (STATUS_TOPIC, Float64MultiArray),
            (REPORT_TOPIC, String),
            ('/agent_1/cmd_vel', Twist),
        ):
            simulator.create_subscription(kind, topic, lambda msg: None, READER_QOS)
        simulator.create_service(SetParameters, '/agent_1/sense', lambda request, response: response)
        deadline = time.monotonic() + 20.0
        while len(node.discovery_gaps()) > 7 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        # What is left: the neighbours, and the second reader (a recorder) of each writer.
        assert node.discovery_gaps() == [
            'readers of /agent_1/trigger_info/to_2: 0 of 2 (agent 2, a recorder)',
            'readers of /agent_1/trigger_info/to_3: 0 of 2 (agent 3, a recorder)',
            'a writer of /agent_2/trigger_info/to_1 (agent 2)',
            'a writer of /agent_3/trigger_info/to_1 (agent 3)',
            'readers of /agent_1/cmd_vel: 1 of 2 (the simulator, a recorder)',
            'readers of /formation/status: 1 of 2 (the simulator or coordinator, a recorder)',
            'readers of /formation/agent_report: 1 of 2 (the simulator or coordinator, a recorder)',
        ]
    finally:
        executor.remove_node(node)


# -- robots ----------------------------------------------------------------------------------------


def test_robot_modes_refuse_lock_step(live_node):
    from formation_agent.ros.errors import AgentNodeError
    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import Step

    node = live_node(sensing='poses', robot='holonomic')
    with pytest.raises(
        AgentNodeError,
        match=r'agent 1: sensing: poses with robot: holonomic runs on the wall clock '
        r'\(Step 0 flagged realtime\), but step 0 is lock-step',
    ):
        node._on_step(encode_step(Step(index=0, time=0.0)))


@pytest.mark.parametrize('wall_clock', [False, True])
def test_the_plant_gets_a_zero_command_on_the_wall_clock_only(ros, live_node, wall_clock):
    """Lock-step: none (the simulated world stops with the run; a command outside a trigger is a
    protocol violation).  Wall clock: zero, as a robot would need."""
    from geometry_msgs.msg import Twist
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.qos import PROTOCOL_QOS

    node = live_node()
    received = []
    node.create_subscription(Twist, '/agent_1/cmd_vel', received.append, PROTOCOL_QOS)
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        if wall_clock:
            node.output.start(time.time())
        node.output.publish(0.0, (0.5, -0.25), None)
        node.output.stop()
        node.output.publish(0.1, (0.5, -0.25), None)  # nothing goes out after the stop
        deadline = time.monotonic() + 5.0
        while len(received) < 1 + wall_clock and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for _ in range(10):
            executor.spin_once(timeout_sec=0.01)
    finally:
        executor.remove_node(node)
    assert [(msg.linear.x, msg.linear.y) for msg in received] == [(0.5, -0.25)] + [(0.0, 0.0)] * wall_clock


# -- the wall clock ------------------------------------------------------------------------------


class _BehindCore:
    """A core whose next triggering time has always passed by the time it is asked (a computer
    that cannot keep up with the triggering times)."""

    ready = True

    def __init__(self) -> None:
        self.times: list[float] = []

    def trigger(self, t, sensed):
        from formation_agent.core.eta import TriggerOutput

        self.times.append(t)
        return TriggerOutput(time=t, control=(0.0, 0.0), infos=())

    def receive(self, info) -> None:
        raise AssertionError('no neighbour talks in this test')

    def next_trigger_time(self, horizon):
        return self.times[-1] - 1e-4


class _InstantSensing:
    """Sensing answered at once, in the caller's stack, as poses are (`PoseSensing`)."""

    def __init__(self) -> None:
        self.epoch = None

    def start(self, epoch) -> None:
        self.epoch = epoch

    def gaps(self):
        return []

    def close(self) -> None:
        """Nothing to destroy (PoseSensing destroys its readers' node)."""

    def request(self, on_sensed) -> None:
        from formation_msgs_py.types import SensedState

        t = time.time() - self.epoch
        on_sensed(lambda: SensedState(agent=1, stamp=t, rel_positions={2: (0.0, 0.0), 3: (0.0, 0.0)}))


def test_thousands_of_past_due_triggers_in_a_row_never_crash_the_agent(ros, live_node):
    """Issue 19: a unicycle square whose agents were always behind their triggering times died of
    'maximum recursion depth exceeded' (each past-due trigger called the next one).  Now each runs
    from the executor: thousands in a row, the agent alive, its Status finite."""
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.codec import decode_status, encode_step
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step
    from formation_msgs_py.qos import PROTOCOL_QOS
    from formation_msgs_py.topics import STATUS_TOPIC

    node = live_node(horizon=1000.0)  # it stops at its horizon on its own clock (issue 28)
    node.core, node.sensing = _BehindCore(), _InstantSensing()
    statuses = []
    node.create_subscription(
        type(node.status_publisher.msg_type()),
        STATUS_TOPIC,
        lambda m: statuses.append(decode_status(m)),
        PROTOCOL_QOS,
    )
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        node._on_step(encode_step(Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=time.time())))
        deadline = time.monotonic() + 120.0
        while len(node.core.times) < 3000 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
            node.check()
        for _ in range(20):
            executor.spin_once(timeout_sec=0.01)
    finally:
        executor.remove_node(node)
    times = node.core.times
    assert len(times) >= 3000 and node.failure is None
    assert times == sorted(times) and node.counts.triggers == len(times)
    assert statuses and all(
        math.isfinite(s.last_planned) and s.last_planned <= s.next_time + 1e-4 for s in statuses
    )


# -- hostile traffic (issue 28) -------------------------------------------------------------------


def _commands_of(ros, node, topic='/agent_1/cmd_vel'):
    from geometry_msgs.msg import Twist

    from formation_msgs_py.qos import PROTOCOL_QOS

    received = []
    node.create_subscription(
        Twist, topic, lambda msg: received.append((msg.linear.x, msg.linear.y)), PROTOCOL_QOS
    )
    return received


def _spin_until(executor, done, timeout=5.0):
    deadline = time.monotonic() + timeout
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.02)


def test_a_forged_wall_clock_step_never_hides_the_real_final_step(ros, live_node):
    """The finding: one forged Step (index 1, epoch 100 s earlier) was taken, the real final Step
    (index 1) then looked like a repeat, and the agents commanded on for 7.6 s after the end.
    Now the forged Step is refused and counted, and the final Step stops the agent."""
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME, Step

    node = live_node()
    commands = _commands_of(ros, node)
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    epoch = time.time()
    try:
        node._on_step(encode_step(Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=epoch)))
        node._on_step(encode_step(Step(index=1, time=0.0, flags=STEP_FLAG_REALTIME, epoch=epoch - 100.0)))
        assert node.rejected == {'step_order': 1} and node.schedule.epoch == epoch and not node.finished
        final = Step(index=1, time=10.0, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=epoch)
        node._on_step(encode_step(final))
        assert node.finished and node.schedule.stopped and node.counts.final_sent
        _spin_until(executor, lambda: commands)
    finally:
        executor.remove_node(node)
    assert commands == [(0.0, 0.0)], 'the zero command, and nothing after it'


def test_a_stamp_no_sender_can_give_is_refused_and_the_real_next_one_taken(live_node):
    """The finding: a forged TriggerInfo stamped 1e300 made agent 2's real messages look older
    (refused as time_backwards, counted against agent 2) and stalled the run 60 s."""
    node = live_node()
    node.faults.arrive(_info(stamp=1e300), 2)
    node.faults.arrive(_info(stamp=10.5), 2)  # after the horizon t = 10
    node.faults.arrive(_info(stamp=0.0), 2)  # the real one: held for the own trigger at t = 0
    assert node.rejected == {'future': 2}
    assert [(info.sender, info.stamp) for info in node.arrivals.held] == [(2, 0.0)]
    node.schedule.start(time.time())  # the wall clock: no stamp ahead of the own clock
    node.faults.arrive(_info(stamp=5.0), 2)
    assert node.rejected == {'future': 3}


def test_a_wall_clock_agent_stops_at_the_horizon_on_its_own_clock_without_a_final_step(ros, live_node):
    """No final Step comes (lost, or refused): at epoch + horizon the agent sends its zero and
    triggers no more; it still leaves on the final Step."""
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.codec import encode_step
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step

    node = live_node(horizon=0.3)
    commands = _commands_of(ros, node)
    executor = SingleThreadedExecutor(context=ros)
    executor.add_node(node)
    try:
        node._on_step(encode_step(Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=time.time())))
        _spin_until(executor, lambda: node.schedule.stopped)
        assert node.schedule.stopped and not node.finished
        _spin_until(executor, lambda: commands)
    finally:
        executor.remove_node(node)
    assert commands == [(0.0, 0.0)]


@pytest.mark.parametrize('wall_clock', [False, True])
def test_a_wall_clock_agent_stops_its_robot_the_moment_the_keeper_shows_no_sign_of_life(
    live_node, discovery_clock, wall_clock
):
    """The finding: a coordinator frozen 3 s gave the robots their zeros after 1.21-1.24 s (the
    bound is 1 s): the agents waited LOST_GRACE after the lease.  The robot stops at the lease now,
    and the agent leaves after the grace; lock-step moves nothing and keeps its patience."""
    from types import SimpleNamespace

    from formation_agent.ros.errors import AgentNodeError
    from formation_msgs_py.lockstep import STEP_FLAG_REALTIME, Step

    node = live_node()
    if wall_clock:
        node.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=time.time())
        node.schedule.start(node.step.epoch)
        node.output.start(node.step.epoch)
    else:
        node.step = Step(index=0, time=0.0)
    node.end_watch.on_keeper_liveliness(SimpleNamespace(alive_count=1, not_alive_count_change=0))
    assert not node.schedule.stopped
    node.end_watch.on_keeper_liveliness(SimpleNamespace(alive_count=0, not_alive_count_change=1))
    assert node.schedule.stopped == wall_clock and node.output._stopped == wall_clock
    node.check()  # within the grace (LOST_GRACE, 0.5 s, on the stopped discovery clock): still there
    # The keeper back within the grace: a wall-clock agent that stopped its robot for it leaves with
    # the cause named (it waited for a final Step that a test bench never sends: fresh-clone runs).
    node.end_watch.on_keeper_liveliness(SimpleNamespace(alive_count=1, not_alive_count_change=0))
    if wall_clock:
        with pytest.raises(AgentNodeError, match='showed no sign of life and came back .* cannot rejoin'):
            node.check()
    else:
        node.check()
