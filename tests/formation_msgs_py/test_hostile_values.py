"""Issue 28, property-based: every decoder of what a topic or a service can carry, fed arbitrary
values of its message type (NaN, ±inf, extreme times, ids and stamps, empty and huge arrays, and
valid messages with any of their values replaced), either returns what it promises or refuses with
`MessageError` naming a reason of `REJECT_REASONS`; nothing else escapes.  What a decoder returns
holds only finite numbers."""

from __future__ import annotations

import json
import math
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formation_msgs_py import cdr
from formation_msgs_py.codec import (
    decode_agent_report,
    decode_sensed_state,
    decode_status,
    decode_step,
    decode_trigger_info,
    decode_world_state,
)
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import REJECT_REASONS

pytestmark = pytest.mark.ros  # the CDR examples are serialized by rclpy

EXAMPLES = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# Floats a hostile writer sends: every double, and the awkward ones more often.
EXTREME = st.sampled_from(
    [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e11, -1.0, -0.0, 0.0, 5e-324, 2.0**63, 2.0**31, 1.5]
)
FLOATS = st.one_of(EXTREME, st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 3).map(float))


def _valid() -> dict[str, list[float]]:
    """Valid messages' data to mutate: a trigger info 1 -> 2 (p = 2, ETA-2), a Step, a Status, a
    world state, as the encoders write them."""
    from formation_msgs_py.codec import encode_status, encode_step, encode_trigger_info, encode_world_state
    from formation_msgs_py.lockstep import Status, Step, WorldState
    from formation_msgs_py.types import TriggerInfo

    info = TriggerInfo(
        sender=1,
        receiver=2,
        stamp=0.25,
        control=(0.1, -0.2),
        rel_position=(1.0, 0.5),
        rel_velocity=(0.0, 1.0),
    )
    status = Status(
        agent=2,
        step_index=3,
        next_time=0.5,
        info_sent=4,
        info_received=5,
        commands_sent=6,
        triggers=2,
        ready=True,
        last_planned=0.25,
    )
    messages = {
        'trigger_info': encode_trigger_info(info),
        'step': encode_step(Step(index=3, time=0.75, flags=0, epoch=0.0, due=(1, 2))),
        'status': encode_status(status),
        'world_state': encode_world_state(
            WorldState(time=0.5, agent_ids=(1, 2), positions=np.array([[0.0, 1.0], [2.0, 3.0]]))
        ),
    }
    return {name: list(msg.data) for name, msg in messages.items()}


VALID = _valid()


def _mutated(name: str) -> st.SearchStrategy[list[float]]:
    """The valid layout of `name` with some values replaced, cut short or extended."""
    base = VALID[name]
    return st.tuples(
        st.lists(st.tuples(st.integers(0, len(base) - 1), FLOATS), max_size=4),
        st.integers(0, len(base) + 3),
        st.lists(FLOATS, max_size=6),
    ).map(lambda m: _apply(base, *m))


def _apply(base, replacements, keep, tail):
    data = list(base)
    for index, value in replacements:
        data[index] = value
    return data[:keep] + tail


def _arrays(name: str) -> st.SearchStrategy[list[float]]:
    return st.one_of(_mutated(name), st.lists(FLOATS, max_size=40), st.just([]), st.just([1.0] * 100_000))


def _finite(value) -> bool:
    """Every number inside `value` (a decoded message) is finite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    if hasattr(value, '__dataclass_fields__'):
        return all(_finite(getattr(value, name)) for name in value.__dataclass_fields__)
    return True


def _decodes_or_refuses(decoder, msg, *, finite=True):
    refused = None
    try:
        decoded = decoder(msg)
    except MessageError as error:
        refused = error
    if refused is not None:
        assert refused.reason in REJECT_REASONS and str(refused), refused  # a reason, and words
        return None
    if finite:
        assert _finite(decoded), decoded
    return decoded


@EXAMPLES
@given(_arrays('trigger_info'))
def test_trigger_info_decodes_or_is_refused_with_a_reason(data):
    _decodes_or_refuses(decode_trigger_info, SimpleNamespace(data=data))


@EXAMPLES
@given(_arrays('step'))
def test_a_step_decodes_or_is_refused_with_a_reason(data):
    step = _decodes_or_refuses(decode_step, SimpleNamespace(data=data), finite=False)
    if step is not None:
        assert math.isfinite(step.time) and step.index >= 0


@EXAMPLES
@given(_arrays('status'))
def test_a_status_decodes_or_is_refused_with_a_reason(data):
    _decodes_or_refuses(decode_status, SimpleNamespace(data=data), finite=False)


@EXAMPLES
@given(_arrays('world_state'))
def test_a_world_state_decodes_or_is_refused_with_a_reason(data):
    _decodes_or_refuses(decode_world_state, SimpleNamespace(data=data))


JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), FLOATS, st.integers(-(2**70), 2**70), st.text(max_size=8)),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


@EXAMPLES
@given(
    st.one_of(
        st.text(max_size=200),
        JSON_VALUES.map(json.dumps),
        st.fixed_dictionaries(
            {
                'version': st.one_of(st.just(3), FLOATS),
                'agent': st.one_of(st.just(2), st.integers(-(2**70), 2**70), FLOATS),
                'final': st.one_of(st.booleans(), JSON_VALUES),
                'rejected': st.one_of(
                    st.dictionaries(st.text(max_size=12), JSON_VALUES, max_size=3), JSON_VALUES
                ),
                'published': st.one_of(
                    st.dictionaries(st.text(max_size=12), JSON_VALUES, max_size=3), JSON_VALUES
                ),
                'failure': st.one_of(st.none(), st.text(max_size=20), JSON_VALUES),
            },
            optional={
                'dropped': JSON_VALUES,
                'saturation': JSON_VALUES,
                'late': JSON_VALUES,
                'safety': st.one_of(
                    JSON_VALUES,
                    st.fixed_dictionaries({'interventions': JSON_VALUES, 'last_intervention': JSON_VALUES}),
                ),
            },
        ).map(json.dumps),
    )
)
def test_an_agent_report_decodes_or_is_refused_with_a_reason(text):
    _decodes_or_refuses(decode_agent_report, SimpleNamespace(data=text), finite=False)


def _vectors(keys) -> st.SearchStrategy:
    """A JSON object of ids to vectors as a hostile simulator could write it."""
    return st.dictionaries(keys, st.lists(st.one_of(FLOATS, JSON_VALUES), max_size=3), max_size=4)


_IDS = st.one_of(st.integers(-3, 9).map(str), st.sampled_from(['01', ' 2', '2147483648', 'x', '']))


@EXAMPLES
@given(
    st.fixed_dictionaries(
        {
            'version': st.one_of(st.just(1), FLOATS),
            'agent': st.one_of(st.just(1), st.integers(-(2**40), 2**40), FLOATS),
            'stamp': st.one_of(FLOATS, JSON_VALUES),
            'rel_positions': st.one_of(_vectors(_IDS), JSON_VALUES),
        },
        optional={'nearby': st.one_of(_vectors(_IDS), JSON_VALUES), 'velocity': JSON_VALUES},
    ).map(lambda body: json.dumps(body, allow_nan=True))
)
def test_a_sensed_state_with_nearby_robots_decodes_or_is_refused_with_a_reason(text):
    # The simulator's sensing answer, the safety layer's nearby robots included (docs/SAFETY.md).
    state = _decodes_or_refuses(
        decode_sensed_state, SimpleNamespace(results=[SimpleNamespace(successful=True, reason=text)])
    )
    if state is not None and state.nearby is not None:
        assert state.agent not in state.nearby and not set(state.nearby) & set(state.rel_positions)
        assert len({len(v) for v in (*state.nearby.values(), *state.rel_positions.values())}) <= 1


_TEXT = st.one_of(
    st.text(max_size=120), st.sampled_from(['tag', 'tag1:agent_2:1:' + '0' * 64, 'tag1:::', ''])
)


@EXAMPLES
@given(
    st.lists(
        st.tuples(_TEXT, st.integers(0, 9), _TEXT, st.one_of(FLOATS, st.integers(-(2**63), 2**63 - 1))),
        max_size=4,
    )
)
def test_any_sensing_request_is_taken_only_with_the_callers_tag_and_else_refused_with_a_reason(parameters):
    """What `ros2 service call /agent_2/sense rcl_interfaces/srv/SetParameters` can send: any
    parameters of any type.  With the run's key it is refused with TagError (untagged, forged;
    foreign) and nothing else escapes; none of these is agent 2's tag."""
    from rcl_interfaces.msg import Parameter, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from formation_msgs_py.codec import check_sensing_request
    from formation_msgs_py.errors import TagError
    from formation_msgs_py.lockstep import FOREIGN_REASONS
    from formation_msgs_py.tags import Verifier

    request = SetParameters.Request(
        parameters=[
            Parameter(
                name=name,
                value=ParameterValue(type=kind, string_value=text, double_value=number, integer_value=0),
            )
            if isinstance(number, float)
            else Parameter(
                name=name, value=ParameterValue(type=kind, string_value=text, integer_value=number)
            )
            for name, kind, text, number in parameters
        ]
    )
    with pytest.raises(TagError) as refused:
        check_sensing_request(Verifier(bytes(32)), '/agent_2/sense', request, caller='agent_2')
    assert refused.value.reason in FOREIGN_REASONS


# -- robot poses and commands as CDR bytes -----------------------------------------------------


def _odometry_bytes() -> bytes:
    from nav_msgs.msg import Odometry
    from rclpy.serialization import serialize_message

    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 1_700_000_000, 5, 'world'
    msg.child_frame_id = 'base_link'
    msg.pose.pose.orientation.w = 1.0
    return serialize_message(msg)


def _pose_bytes() -> bytes:
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message

    msg = PoseStamped()
    msg.header.frame_id = 'world'
    msg.pose.orientation.w = 1.0
    return serialize_message(msg)


def _twist_stamped_bytes() -> bytes:
    from geometry_msgs.msg import TwistStamped
    from rclpy.serialization import serialize_message

    return serialize_message(TwistStamped())


def _bytes_like(valid: bytes) -> st.SearchStrategy[bytes]:
    """`valid` with doubles, words or bytes overwritten at any place, cut or extended; or any bytes."""
    edits = st.lists(
        st.tuples(
            st.integers(0, len(valid) - 1),
            st.one_of(
                FLOATS.map(lambda v: struct.pack('<d', v)),
                st.integers(0, 2**32 - 1).map(lambda v: struct.pack('<I', v)),
                st.binary(min_size=1, max_size=8),
            ),
        ),
        max_size=4,
    )

    def edit(args):
        changes, keep, tail = args
        data = bytearray(valid)
        for at, chunk in changes:
            data[at : at + len(chunk)] = chunk
        return bytes(data[:keep]) + tail

    return st.one_of(
        st.tuples(edits, st.integers(0, len(valid) + 8), st.binary(max_size=16)).map(edit),
        st.binary(max_size=64),
    )


CDR_CASES = {
    'odometry': (_odometry_bytes, (cdr.decode_odometry_cdr, cdr.odometry_fields)),
    'pose': (_pose_bytes, (cdr.decode_pose_stamped_cdr, cdr.pose_stamped_fields)),
    'twist_stamped': (_twist_stamped_bytes, (cdr.twist_stamped_fields, cdr.twist_fields)),
}


@pytest.mark.parametrize('name', sorted(CDR_CASES))
def test_cdr_decoders_decode_or_refuse_any_bytes_with_a_reason(name):
    make, decoders = CDR_CASES[name]

    @EXAMPLES
    @given(_bytes_like(make()))
    def check(data):
        for decoder in decoders:
            # The checked decoders return finite values only; the *_fields readers return what was sent.
            _decodes_or_refuses(decoder, data, finite=decoder.__name__.startswith('decode'))

    check()


@pytest.mark.parametrize('name', sorted(CDR_CASES))
def test_every_cut_of_a_valid_cdr_message_is_refused_as_too_short(name):
    """Every prefix of a valid message, cut anywhere before its end, is refused with the reason
    `length` by every decoder. A fresh-clone run's hypothesis search found the odometry message cut
    at 22 bytes (right after its frame id) raising struct.error from the child frame's length."""
    from formation_msgs_py.lockstep import REJECT_LENGTH

    make, decoders = CDR_CASES[name]
    valid = make()
    # twist_fields reads a plain Twist: a long enough cut of a TwistStamped is a Twist's size.
    for decoder in (d for d in decoders if d is not cdr.twist_fields):
        for cut in range(len(valid)):
            with pytest.raises(MessageError) as refused:
                decoder(valid[:cut])
            assert refused.value.reason == REJECT_LENGTH, (decoder.__name__, cut, refused.value)
