"""Encodings of the formation messages over standard Jazzy types: bit-exact round trips, clear errors."""

from __future__ import annotations

import json
import math
import re
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from formation_msgs_py.codec import (
    AGENT_REPORT_VERSION,
    LAYOUT_VERSION,
    MAX_NEARBY,
    decode_agent_report,
    decode_command,
    decode_odometry,
    decode_pose_stamped,
    decode_sensed_state,
    decode_status,
    decode_step,
    decode_trigger_info,
    decode_world_state,
    encode_acceleration_command,
    encode_agent_report,
    encode_body_velocity,
    encode_pose_array,
    encode_sensed_state,
    encode_status,
    encode_step,
    encode_trigger_info,
    encode_velocity_command,
    encode_world_state,
    encode_world_velocity,
    ros_time,
    sensing_refusal,
)
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import (
    LAYOUT_REASONS,
    REJECT_REASONS,
    SATURATION_KINDS,
    STEP_FLAG_FINAL,
    AgentReport,
    Saturation,
    Status,
    Step,
    WorldState,
)
from formation_msgs_py.types import SensedState, TriggerInfo

pytestmark = pytest.mark.ros

# Values whose bits are easy to lose: negative zero, the smallest denormal, a long mantissa,
# the largest double, and a value that is not a short decimal.
AWKWARD = (-0.0, 5e-324, -2.2250738585072014e-308, 0.1 + 0.2, 1.7976931348623157e308, -1 / 3)


def bits(values) -> list[bytes]:
    return [struct.pack('<d', float(v)) for v in values]


def through_wire(msg):
    """Serialize and deserialize with rclpy's CDR, as the middleware does."""
    from rclpy.serialization import deserialize_message, serialize_message

    return deserialize_message(serialize_message(msg), type(msg))


def eta2_info() -> TriggerInfo:
    return TriggerInfo(
        sender=3,
        receiver=1,
        stamp=0.30000000000000004,
        control=AWKWARD[:3],
        rel_position=AWKWARD[3:],
        rel_velocity=(math.pi, -math.e, 2.0**-1074),
    )


@pytest.mark.parametrize('with_velocity', [False, True])
def test_trigger_info_round_trips_bit_for_bit_over_cdr(with_velocity):
    info = eta2_info()
    if not with_velocity:
        info = TriggerInfo(
            sender=info.sender,
            receiver=info.receiver,
            stamp=info.stamp,
            control=info.control,
            rel_position=info.rel_position,
        )
    msg = through_wire(encode_trigger_info(info))
    back = decode_trigger_info(msg)
    assert back == info
    for field in ('control', 'rel_position', 'rel_velocity'):
        original = getattr(info, field)
        if original is None:
            assert getattr(back, field) is None
        else:
            assert bits(getattr(back, field)) == bits(original)
    assert bits([back.stamp]) == bits([info.stamp])


def test_trigger_info_layout_labels_name_the_fields():
    msg = encode_trigger_info(eta2_info())
    labels = [(dim.label, dim.size) for dim in msg.layout.dim]
    assert labels == [
        ('version', 1),
        ('kind', 1),
        ('sender', 1),
        ('receiver', 1),
        ('stamp', 1),
        ('p', 1),
        ('control', 3),
        ('rel_position', 3),
        ('rel_velocity', 3),
    ]
    assert sum(size for _, size in labels) == len(msg.data)
    assert list(msg.data[:6]) == [LAYOUT_VERSION, 2, 3, 1, 0.30000000000000004, 3]


def _array(values):
    from std_msgs.msg import Float64MultiArray

    return Float64MultiArray(data=[float(v) for v in values])


@pytest.mark.parametrize(
    ('values', 'complaint', 'reason'),
    [
        ([2, 1, 1, 2, 0.0, 1, 0.0, 0.0], 'layout version 2.0 is not supported', 'version'),
        ([1, 1, 1, 2, 0.0, 2, 0.0, 0.0, 0.0], 'kind 1 with p=2 needs 10 values, got 9', 'length'),
        ([1, 2, 1, 2, 0.0, 1, 0.0, 0.0], 'kind 2 with p=1 needs 9 values, got 8', 'length'),
        ([1, 3, 1, 2, 0.0, 1, 0.0, 0.0], 'kind must lie in [1, 2], got 3', 'field'),
        ([1, 1, 1.5, 2, 0.0, 1, 0.0, 0.0], 'sender must be an integer, got 1.5', 'field'),
        ([1, 1, 2, 2, 0.0, 1, 0.0, 0.0], 'sender and receiver are both agent 2', 'field'),
        ([1, 1, -1, 2, 0.0, 1, 0.0, 0.0], 'sender must lie in [0, 2147483647], got -1', 'field'),
        ([1, 1, 1, 2, 0.0, 1, math.nan, 0.0], 'must be finite, got nan', 'non_finite'),
        ([1, 1, 1, 2, math.inf, 1, 0.0, 0.0], 'must be finite, got inf', 'non_finite'),
        ([1, 1, 1, 2, 0.0], 'the header alone has 6', 'length'),
        ([1, 1, 1, 2, 0.0, 0, 0.0, 0.0], 'p must lie in [1, 8], got 0', 'field'),
    ],
)
def test_malformed_trigger_info_is_rejected_with_the_rule_broken(values, complaint, reason):
    with pytest.raises(MessageError) as error:
        decode_trigger_info(_array(values))
    assert complaint in str(error.value)
    assert error.value.reason == reason
    assert reason in LAYOUT_REASONS


def test_trigger_info_with_mismatched_vectors_cannot_be_encoded():
    info = TriggerInfo(sender=1, receiver=2, stamp=0.0, control=(1.0, 2.0), rel_position=(1.0,))
    with pytest.raises(MessageError, match=r'1->2: rel_position has 1 components, control has 2'):
        encode_trigger_info(info)
    bad = TriggerInfo(sender=1, receiver=2, stamp=0.0, control=(math.inf,), rel_position=(1.0,))
    with pytest.raises(MessageError, match='control.*must be finite'):
        encode_trigger_info(bad)


def double_state() -> SensedState:
    return SensedState(
        agent=2,
        stamp=1.0000000000000002,
        rel_positions={1: (-0.0, 5e-324), 3: (0.1 + 0.2, -1 / 3)},
        rel_velocities={1: (2.2250738585072014e-308, -0.0), 3: (1e308, -4.9e-324)},
        velocity=(math.pi, -0.0),
    )


@pytest.mark.parametrize('double', [False, True])
def test_sensed_state_round_trips_bit_for_bit_over_cdr(double):
    state = double_state()
    if not double:
        state = SensedState(agent=state.agent, stamp=state.stamp, rel_positions=state.rel_positions)
    response = through_wire(encode_sensed_state(state))
    assert response.results[0].successful
    back = decode_sensed_state(response)
    assert back == state
    for j, vector in state.rel_positions.items():
        assert bits(back.rel_positions[j]) == bits(vector)
    if double:
        for j, vector in state.rel_velocities.items():
            assert bits(back.rel_velocities[j]) == bits(vector)
        assert bits(back.velocity) == bits(state.velocity)
    assert bits([back.stamp]) == bits([state.stamp])


def test_sensed_state_json_is_compact_and_versioned():
    import json

    text = encode_sensed_state(double_state()).results[0].reason
    assert ' ' not in text
    assert json.loads(text)['version'] == LAYOUT_VERSION


def _response(text: str, success: bool = True):
    from rcl_interfaces.msg import SetParametersResult
    from rcl_interfaces.srv import SetParameters

    return SetParameters.Response(results=[SetParametersResult(successful=success, reason=text)])


@pytest.mark.parametrize(
    ('text', 'complaint'),
    [
        ('not json', 'sensed state is not JSON'),
        ('[1]', 'must be a JSON object'),
        ('{"version":2,"agent":1,"stamp":0.0,"rel_positions":{}}', 'version 2 is not supported'),
        ('{"version":1,"agent":1,"rel_positions":{}}', "missing field 'stamp'"),
        ('{"version":1,"agent":true,"stamp":0.0,"rel_positions":{}}', 'agent must be an integer id'),
        ('{"version":1,"agent":1,"stamp":NaN,"rel_positions":{}}', 'stamp must be finite'),
        (
            '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"x":[1.0]}}',
            "neighbour id 'x' is not an integer",
        ),
        (
            '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"2":[1.0],"3":[1.0,2.0]}}',
            'rel_positions[3] has 2 components, expected 1',
        ),
        (
            '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"2":["a"]}}',
            'rel_positions[2][0] must be a number',
        ),
        (
            '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"2":[1.0]},"velocity":[0.0]}',
            'rel_velocities and velocity come together',
        ),
        (
            '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"2":[1.0]},"rel_velocities":{"3":[0.0]},"velocity":[0.0]}',
            'rel_velocities for [3] but rel_positions for [2]',
        ),
        ('{"version":1,"agent":1,"stamp":0.0,"rel_positions":{},"extra":1}', "unknown fields ['extra']"),
    ],
)
def test_malformed_sensed_state_is_rejected_with_the_rule_broken(text, complaint):
    with pytest.raises(MessageError) as error:
        decode_sensed_state(_response(text))
    assert complaint in str(error.value)


def test_refused_sensing_carries_the_reason():
    with pytest.raises(MessageError, match='sensing refused: agent 7 is unknown'):
        decode_sensed_state(through_wire(sensing_refusal('agent 7 is unknown')))


def test_non_finite_sensed_values_cannot_be_encoded():
    state = SensedState(agent=1, stamp=0.0, rel_positions={2: (math.nan,)})
    with pytest.raises(MessageError, match=r'sensed x_1 - x_2\[0\] must be finite'):
        encode_sensed_state(state)


def test_nearby_robots_round_trip_bit_for_bit_and_stay_absent_without_the_layer():
    # The safety layer's other robots within R (docs/SAFETY.md): the very floats, keyed by id.
    state = SensedState(
        agent=2,
        stamp=0.30000000000000004,
        rel_positions={1: (0.1 + 0.2, -1 / 3)},
        nearby={7: (-0.0, 5e-324), 4: (1e-300, 2.0**-1074 * 3)},
    )
    back = decode_sensed_state(through_wire(encode_sensed_state(state)))
    assert back == state and list(back.nearby) == [7, 4]
    for j, vector in state.nearby.items():
        assert bits(back.nearby[j]) == bits(vector)
    empty = SensedState(agent=2, stamp=0.0, rel_positions={1: (1.0, 0.0)}, nearby={})
    assert decode_sensed_state(encode_sensed_state(empty)).nearby == {}
    # Without the layer the answer is the earlier layout, key for key: older agents read it.
    off = SensedState(agent=2, stamp=0.0, rel_positions={1: (1.0, 0.0)})
    assert 'nearby' not in encode_sensed_state(off).results[0].reason
    assert decode_sensed_state(encode_sensed_state(off)).nearby is None


_NEAR = '{"version":1,"agent":1,"stamp":0.0,"rel_positions":{"2":[1.0,0.0]},"nearby":%s}'


@pytest.mark.parametrize(
    ('nearby', 'complaint', 'reason'),
    [
        ('{"3":[NaN,0.0]}', 'nearby[3][0] must be finite', 'field'),
        ('{"3":[1e999,0.0]}', 'nearby[3][0] must be finite', 'field'),
        ('{"3":[%s,0.0]}' % ('9' * 400), 'nearby[3][0] must be finite', 'field'),
        ('{"3":[1.0]}', 'nearby[3] has 1 components, expected 2', 'field'),
        ('{"3":"x"}', 'nearby[3] must be a list of numbers', 'field'),
        ('[[1.0,0.0]]', 'nearby must map neighbour ids to vectors', 'field'),
        ('{"03":[1.0,0.0]}', "id '03' is not written canonically", 'field'),
        ('{"1":[1.0,0.0]}', 'nearby robot 1 is the agent itself, one of its neighbours', 'field'),
        ('{"2":[1.0,0.0]}', 'nearby robot 2 is the agent itself, one of its neighbours', 'field'),
        ('{"-4":[1.0,0.0]}', 'nearby robot -4 is the agent itself, one of its neighbours or not an', 'field'),
        (
            json.dumps({str(j): [1.0, 0.0] for j in range(3, 4 + MAX_NEARBY)}),
            f'{MAX_NEARBY + 1} nearby robots, at most {MAX_NEARBY}',
            'length',
        ),
    ],
)
def test_a_hostile_nearby_list_is_refused_with_the_rule_broken(nearby, complaint, reason):
    with pytest.raises(MessageError) as error:
        decode_sensed_state(_response(_NEAR % nearby))
    assert complaint in str(error.value) and error.value.reason == reason


def test_nearby_lists_that_break_the_rules_cannot_be_encoded():
    many = dict.fromkeys(range(3, 4 + MAX_NEARBY), (1.0, 0.0))
    with pytest.raises(MessageError, match=f'{MAX_NEARBY + 1} nearby robots, at most {MAX_NEARBY}'):
        encode_sensed_state(SensedState(agent=1, stamp=0.0, rel_positions={}, nearby=many))
    bad = SensedState(agent=1, stamp=0.0, rel_positions={}, nearby={3: (math.inf, 0.0)})
    with pytest.raises(MessageError, match=r'sensed nearby x_1 - x_3\[0\] must be finite'):
        encode_sensed_state(bad)


def test_agent_report_carries_the_safety_counts_only_with_the_layer():
    report = AgentReport(
        agent=3, final=True, rejected={}, safety_interventions=17, safety_last_intervention=0.1 + 0.2
    )
    back = decode_agent_report(through_wire(encode_agent_report(report)))
    assert back == report and bits([back.safety_last_intervention]) == bits([0.1 + 0.2])
    never = AgentReport(agent=3, final=True, rejected={}, safety_interventions=0)
    assert decode_agent_report(encode_agent_report(never)) == never
    off = AgentReport(agent=3, final=True, rejected={})
    assert 'safety' not in encode_agent_report(off).data
    assert decode_agent_report(encode_agent_report(off)).safety_interventions is None
    body = json.loads(encode_agent_report(report).data)
    for bad, complaint in [
        ({'interventions': -1, 'last_intervention': None}, 'safety interventions must be a count'),
        ({'interventions': 1, 'last_intervention': 'x'}, 'safety last_intervention must be a number'),
        ({'interventions': 1}, "safety must hold exactly ['interventions', 'last_intervention']"),
    ]:
        with pytest.raises(MessageError, match=re.escape(complaint)):
            decode_agent_report(SimpleNamespace(data=json.dumps({**body, 'safety': bad})))


def test_step_and_status_round_trip_including_infinite_next_time():
    step = Step(index=12, time=0.1 + 0.2, flags=STEP_FLAG_FINAL, epoch=1795311615.054476)
    back = decode_step(through_wire(encode_step(step)))
    assert back == step and back.final and not back.realtime and back.due == ()
    assert bits([back.time, back.epoch]) == bits([step.time, step.epoch])
    due = Step(index=3, time=2.5, due=(1, 7, 2**31 - 1))
    assert decode_step(through_wire(encode_step(due))) == due
    for next_time in (math.inf, 5e-324, 7.123456789012345):
        status = Status(
            agent=4,
            step_index=-1,
            next_time=next_time,
            info_sent=2**40,
            info_received=3,
            commands_sent=5,
            triggers=5,
            ready=True,
            last_planned=0.30000000000000004,
        )
        assert decode_status(through_wire(encode_status(status))) == status


@pytest.mark.parametrize(
    ('values', 'complaint'),
    [
        ([1, 0, 0.0, 0, 0, 0, 0, 0, 1], 'expected 10 values'),
        ([1, 0, 0, math.nan, 0, 0, 0, 0, 1, 0.0], 'next_time must be a time or +inf, got nan'),
        ([1, 0, 0, -math.inf, 0, 0, 0, 0, 1, 0.0], 'next_time must be a time or +inf, got -inf'),
        ([1, 0, 0, 1.0, -1, 0, 0, 0, 1, 0.0], 'info_sent_total must lie in'),
        ([1, 0, 0, 1.0, 0, 0.5, 0, 0, 1, 0.0], 'info_received_total must be an integer, got 0.5'),
        ([1, 0, 0, 1.0, 0, 0, 0, 0, 2, 0.0], 'ready must be 0 or 1, got 2.0'),
        ([1, 0, -2, 1.0, 0, 0, 0, 0, 1, 0.0], 'step_index must lie in [-1,'),
        ([1, 0, 0, 1.0, 0, 0, 0, 0, 1, math.inf], 'last_planned[0] must be finite, got inf'),
    ],
)
def test_malformed_status_is_rejected(values, complaint):
    with pytest.raises(MessageError) as error:
        decode_status(_array(values))
    assert complaint in str(error.value)


def test_malformed_step_is_rejected():
    with pytest.raises(
        MessageError,
        match=r"expected 5 values \['version', 'step_index', 'time', 'flags', 'epoch'\] "
        'and the due agent ids, got 3',
    ):
        decode_step(_array([1, 0, 0.0]))
    with pytest.raises(MessageError, match='must be finite'):
        decode_step(_array([1, 0, math.inf, 0, 0.0]))
    with pytest.raises(MessageError, match='step index must lie in'):
        decode_step(_array([1, -1, 0.0, 0, 0.0]))
    with pytest.raises(MessageError, match='step flags must be an integer, got 0.5'):
        decode_step(_array([1, 0, 0.0, 0.5, 0.0]))
    with pytest.raises(MessageError, match='step 4 due agent must be an integer, got 2.5'):
        decode_step(_array([1, 4, 0.0, 0, 0.0, 1, 2.5]))
    with pytest.raises(
        MessageError, match=r'step 4: due agent ids must be sorted and distinct, got \[3, 3\]'
    ):
        decode_step(_array([1, 4, 0.0, 0, 0.0, 3, 3]))


def test_agent_report_round_trips_and_omits_zero_counts():
    report = AgentReport(
        agent=4,
        final=True,
        rejected={'sender': 2, 'time_backwards': 1},
        dropped=7,
        delayed=30,
        late=1,
        published={'/agent_4/cmd_vel': 12, '/formation/status': 30},
    )
    msg = through_wire(encode_agent_report(report))
    assert '"rejected":{"sender":2,"time_backwards":1}' in msg.data
    assert decode_agent_report(msg) == report
    assert report.rejected_total == 3
    quiet = AgentReport(agent=1, final=False, rejected={'length': 0})
    assert decode_agent_report(encode_agent_report(quiet)).rejected == {}
    assert set(LAYOUT_REASONS) < set(REJECT_REASONS)


def test_agent_report_carries_saturation_and_failure_exactly():
    clipped = {
        'linear_speed': Saturation(count=12, largest_requested=0.41000000000000003, allowed=0.22),
        'angular_speed': Saturation(count=3, largest_requested=3.0000000000000004, allowed=2.84),
    }
    report = AgentReport(
        agent=2,
        final=True,
        rejected={},
        robot_commands=1500,
        saturation=clipped,
        failure='agent 2: the pose of robot 3 on /agent_3/robot/pose is 0.734 s old',
    )
    msg = through_wire(encode_agent_report(report))
    assert json.loads(msg.data)['version'] == AGENT_REPORT_VERSION == 3
    assert '"linear_speed":{"count":12,"largest_requested":0.41000000000000003,"allowed":0.22}' in msg.data
    assert decode_agent_report(msg) == report
    unclipped = AgentReport(
        agent=2,
        final=False,
        rejected={},
        saturation={'linear_speed': Saturation(count=0, largest_requested=0.0, allowed=1.0)},
    )
    assert json.loads(encode_agent_report(unclipped).data)['saturation'] == {}
    assert set(SATURATION_KINDS) == {'linear_speed', 'angular_speed', 'linear_acceleration', 'steering'}


_V3 = '"robot_commands":0,"saturation":{},"failure":null,"published":{}'


@pytest.mark.parametrize(
    ('text', 'complaint'),
    [
        ('[1]', 'must be a JSON object'),
        ('{"version":2}', 'version 2 is not supported (expected 3)'),
        (
            '{"version":3,"agent":1,"final":false,"rejected":{},"dropped":0,"delayed":0,' + _V3 + '}',
            "missing fields ['late']",
        ),
        (
            '{"version":3,"agent":1,"final":false,"rejected":{},"dropped":-1,"delayed":0,"late":0,'
            + _V3
            + '}',
            'dropped must be a count',
        ),
        (
            '{"version":3,"agent":1,"final":false,"rejected":{"x":1.5},"dropped":0,"delayed":0,"late":0,'
            + _V3
            + '}',
            "rejected['x'] must be a count",
        ),
        (
            '{"version":3,"agent":1,"final":0,"rejected":{},"dropped":0,"delayed":0,"late":0,'
            + _V3
            + ',"z":1}',
            "unknown fields ['z']",
        ),
        (
            '{"version":3,"agent":1,"final":true,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{"warp":{"count":1,"largest_requested":2.0,"allowed":1.0}},"failure":null,"published":{}}',
            "saturation['warp']: unknown kind",
        ),
        (
            '{"version":3,"agent":1,"final":true,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{"linear_speed":{"count":1,"largest_requested":2.0}},"failure":null,"published":{}}',
            "must hold exactly ['count', 'largest_requested', 'allowed']",
        ),
        (
            '{"version":3,"agent":1,"final":true,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{"linear_speed":{"count":1,"largest_requested":Infinity,"allowed":1.0}},"failure":null,"published":{}}',
            'largest_requested must be finite',
        ),
        (
            '{"version":3,"agent":1,"final":true,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{},"failure":7,"published":{}}',
            'failure must be null or a string, got 7',
        ),
        (
            '{"version":3,"agent":1,"final":false,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{},"failure":null,"published":{"/t":-2}}',
            "published['/t'] must be a count",
        ),
        (
            '{"version":3,"agent":1,"final":false,"rejected":{},"dropped":0,"delayed":0,"late":0,"robot_commands":0,'
            '"saturation":{},"failure":null,"published":[]}',
            'published malformed',
        ),
    ],
)
def test_malformed_agent_report_is_rejected(text, complaint):
    from std_msgs.msg import String

    with pytest.raises(MessageError) as error:
        decode_agent_report(String(data=text))
    assert complaint in str(error.value)


@pytest.mark.parametrize('double', [False, True])
def test_world_state_round_trips_bit_for_bit(double):
    rng = np.random.default_rng(7)
    positions = rng.normal(size=(3, 2))
    positions[0, 0] = -0.0
    velocities = rng.normal(size=(3, 2)) if double else None
    state = WorldState(
        time=9.999999999999998, agent_ids=(1, 2, 5), positions=positions, velocities=velocities
    )
    back = decode_world_state(through_wire(encode_world_state(state)))
    assert back.agent_ids == state.agent_ids
    assert bits(back.positions.ravel()) == bits(positions.ravel())
    assert bits([back.time]) == bits([state.time])
    if double:
        assert bits(back.velocities.ravel()) == bits(velocities.ravel())
    else:
        assert back.velocities is None


def test_world_state_length_is_checked():
    with pytest.raises(MessageError, match=r'n=2, p=2, double=0 needs 11 values, got 10'):
        decode_world_state(_array([1, 0.0, 2, 2, 0, 1, 2, 0.0, 0.0, 0.0]))


def test_commands_carry_the_first_p_linear_components_exactly():
    control = (0.1 + 0.2, -0.0)
    twist = through_wire(encode_velocity_command(control))
    assert bits(decode_command(twist, 2)) == bits(control)
    accel = through_wire(encode_acceleration_command((5e-324,)))
    assert bits(decode_command(accel, 1)) == bits((5e-324,))
    with pytest.raises(MessageError, match='only the first 2 linear components may be set'):
        decode_command(encode_velocity_command((1.0, 2.0, 3.0)), 2)
    with pytest.raises(MessageError, match='geometry_msgs carries 1 to 3 components, got 4'):
        encode_velocity_command((0.0,) * 4)


def test_ros_time_rounds_to_the_nanosecond():
    stamp = ros_time(1.9999999996)
    assert (stamp.sec, stamp.nanosec) == (2, 0)
    stamp = ros_time(3.0000000014)
    assert (stamp.sec, stamp.nanosec) == (3, 1)
    with pytest.raises(MessageError, match='finite and >= 0'):
        ros_time(-1.0)


def test_pose_array_pads_missing_axes():
    state = WorldState(time=0.5, agent_ids=(1, 2), positions=np.array([[1.0, 2.0], [3.0, 4.0]]))
    poses = encode_pose_array(state).poses
    assert [(p.position.x, p.position.y, p.position.z) for p in poses] == [(1.0, 2.0, 0.0), (3.0, 4.0, 0.0)]


# -- robots ---------------------------------------------------------------------------------------


def _pose_stamped(
    position=(1.0, 2.0, 0.0), orientation=(0.0, 0.0, 0.0, 1.0), frame='world', stamp=(1700000000, 250000000)
):
    from geometry_msgs.msg import PoseStamped

    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = position
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = orientation
    return msg


def test_robot_poses_decode_with_stamp_frame_and_body_twist():
    from nav_msgs.msg import Odometry

    half = math.sqrt(0.5)  # 90 degrees about z
    pose = decode_pose_stamped(through_wire(_pose_stamped(orientation=(0.0, 0.0, half, half), frame='mocap')))
    assert pose.stamp == 1700000000.25 and pose.frame == 'mocap' and pose.position == (1.0, 2.0, 0.0)
    assert pose.orientation == pytest.approx((0.0, 0.0, half, half), abs=1e-16) and pose.linear is None
    odom = Odometry()
    odom.header.frame_id = 'world'
    odom.child_frame_id = 'base_link'
    odom.pose.pose = _pose_stamped().pose
    odom.twist.twist.linear.x = 0.22
    odom.twist.twist.angular.z = -2.84
    decoded = decode_odometry(through_wire(odom))
    assert (
        decoded.linear == (0.22, 0.0, 0.0)
        and decoded.angular == (0.0, 0.0, -2.84)
        and decoded.frame == 'world'
    )


@pytest.mark.parametrize(
    ('changes', 'complaint'),
    [
        ({'position': (math.nan, 0.0, 0.0)}, 'pose position[0] must be finite, got nan'),
        (
            {'orientation': (0.0, 0.0, 0.0, 0.0)},
            'pose: orientation must be a unit quaternion, got (0.0, 0.0, 0.0, 0.0)',
        ),
        ({'orientation': (0.0, 0.0, 0.0, math.inf)}, 'pose orientation[3] must be finite, got inf'),
    ],
)
def test_a_pose_that_cannot_be_a_pose_is_refused(changes, complaint):
    with pytest.raises(MessageError) as error:
        decode_pose_stamped(_pose_stamped(**changes))
    assert complaint in str(error.value)


def test_robot_commands_carry_their_frame_and_values_bit_for_bit():
    velocity = (0.1 + 0.2, -1e-300)
    msg = through_wire(encode_world_velocity(velocity, frame_id='world', stamp=1700000000.5))
    assert msg.header.frame_id == 'world' and (msg.header.stamp.sec, msg.header.stamp.nanosec) == (
        1700000000,
        500000000,
    )
    assert (msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z) == (0.1 + 0.2, -1e-300, 0.0)
    body = through_wire(encode_body_velocity(0.22, -2.84))
    assert (body.linear.x, body.linear.y, body.angular.z, body.angular.x) == (0.22, 0.0, -2.84, 0.0)
    with pytest.raises(MessageError, match=r'body velocity\[1\] must be finite, got nan'):
        encode_body_velocity(0.0, math.nan)


# -- the sensing request's and answer's tags (issue 28) ---------------------------------------------


def test_a_sensing_request_carries_its_callers_tag_over_the_wire_and_only_it_passes():
    from formation_msgs_py.codec import check_sensing_request, sensing_request
    from formation_msgs_py.errors import TagError
    from formation_msgs_py.lockstep import FORGED, REPLAYED, UNTAGGED
    from formation_msgs_py.tags import Signer, Verifier

    key, service = bytes(range(32)), '/agent_2/sense'
    verifier = Verifier(key)
    agent_2 = Signer(key, writer='agent_2')
    first = through_wire(sensing_request(agent_2, service))
    check_sensing_request(verifier, service, first, caller='agent_2')
    refused = {
        UNTAGGED: through_wire(sensing_request(None, service)),  # ros2 service call, a stranger
        FORGED: through_wire(sensing_request(Signer(bytes(32), writer='agent_2'), service)),  # another key
        REPLAYED: first,  # the agent's own request again
    }
    for reason, request in refused.items():
        with pytest.raises(TagError) as caught:
            check_sensing_request(verifier, service, request, caller='agent_2')
        assert caught.value.reason == reason
    other = sensing_request(Signer(key, writer='agent_3'), service)  # a node of the run, not agent 2
    with pytest.raises(TagError, match="only 'agent_2'"):
        check_sensing_request(verifier, service, other, caller='agent_2')
    mangled = sensing_request(agent_2, service)
    mangled.parameters[0].name = 'other'  # something that is not the tag parameter
    with pytest.raises(TagError, match='is not tag1:'):
        check_sensing_request(verifier, service, mangled, caller='agent_2')
    assert verifier.refused == {UNTAGGED: 1, FORGED: 3, REPLAYED: 1}
    check_sensing_request(Verifier(None), service, sensing_request(None, service), caller='agent_2')  # no key


def test_a_tagged_sensing_answer_decodes_as_the_untagged_one_and_its_tag_is_checked():
    from formation_msgs_py.codec import check_sensing_answer, tag_sensing_answer
    from formation_msgs_py.errors import TagError
    from formation_msgs_py.tags import Signer, Verifier

    key, service, state = bytes(range(32)), '/agent_2/sense', double_state()
    answer = through_wire(tag_sensing_answer(encode_sensed_state(state), Signer(key, writer='sim'), service))
    verifier = Verifier(key)
    check_sensing_answer(verifier, service, answer)
    assert decode_sensed_state(answer) == state
    with pytest.raises(TagError, match='without the run'):
        check_sensing_answer(verifier, service, encode_sensed_state(state))  # another server's answer
    changed = tag_sensing_answer(encode_sensed_state(state), Signer(key, writer='sim'), service)
    changed.results[0].reason = changed.results[0].reason.replace('"agent":', '"agent": ')
    with pytest.raises(TagError, match='not the run key'):
        check_sensing_answer(verifier, service, changed)
    refusal = tag_sensing_answer(sensing_refusal('not due'), Signer(key, writer='sim'), service)
    with pytest.raises(MessageError, match=r'^sensing refused: not due$'):
        decode_sensed_state(refusal)


@pytest.mark.parametrize('results', [0, 2])
def test_a_sensing_answer_must_hold_one_result(results):
    from rcl_interfaces.srv import SetParameters

    response = SetParameters.Response(results=encode_sensed_state(double_state()).results * results)
    with pytest.raises(MessageError, match=f'holds one rcl_interfaces/SetParametersResult, got {results}'):
        decode_sensed_state(response)
