"""Versioned encodings of the formation messages over standard Jazzy interface types.

Only standard types are used (std_msgs/Float64MultiArray, rcl_interfaces/SetParameters, geometry_msgs), so
any Jazzy installation can echo and record the traffic without building anything.  The layout of
every array is documented in docs/MESSAGES.md; the labels of `layout.dim` name the fields so that
`ros2 topic echo` is readable.  Floats travel as IEEE float64 (arrays) or as Python's shortest
round-trip repr (JSON), so every value is reproduced bit for bit.

ROS message classes are imported lazily: the module can be imported without ROS.
"""

from __future__ import annotations

import functools
import json
import math
from array import array
from collections.abc import Callable, Sequence

import numpy as np

from formation_msgs_py.errors import MessageError, TagError
from formation_msgs_py.lockstep import (
    REJECT_LENGTH,
    REJECT_NON_FINITE,
    REJECT_VERSION,
    SATURATION_KINDS,
    AgentReport,
    Saturation,
    Status,
    Step,
    WorldState,
)
from formation_msgs_py.tags import TAG_PREFIX, Signer, Verifier, split_text
from formation_msgs_py.topics import WORLD_FRAME
from formation_msgs_py.types import MAX_AGENT_ID, RobotPose, SensedState, TriggerInfo

LAYOUT_VERSION = 1
"""Version of every array layout and of the sensing JSON; bumped on any incompatible change."""

KIND_ETA1 = 1
KIND_ETA2 = 2

_MAX_ID = MAX_AGENT_ID  # also bounds the other small integer fields (step flags)
_MAX_COUNT = 2**53  # float64 holds every integer up to here exactly
MAX_NEARBY = 1024
"""The most robots one sensing answer reports nearby (the safety layer's filter enumerates pairs of
constraints: far more would not be computed within a trigger anyway)."""


# --------------------------------------------------------------------------------------------
# Field helpers


def _check_finite(name: str, values: Sequence[float]) -> None:
    for k, value in enumerate(values):
        if not math.isfinite(value):
            raise MessageError(f'{name}[{k}] must be finite, got {value!r}', reason=REJECT_NON_FINITE)


def _as_int(name: str, value: float, *, low: int, high: int) -> int:
    if not (math.isfinite(value) and float(value).is_integer()):
        raise MessageError(f'{name} must be an integer, got {value!r}')
    number = int(value)
    if not low <= number <= high:
        raise MessageError(f'{name} must lie in [{low}, {high}], got {number}')
    return number


def _check_version(what: str, value: float) -> None:
    if value != LAYOUT_VERSION:
        raise MessageError(
            f'{what}: layout version {value!r} is not supported (expected {LAYOUT_VERSION})',
            reason=REJECT_VERSION,
        )


def _float_array(fields: Sequence[tuple[str, Sequence[float]]]):
    """Float64MultiArray whose layout.dim has one labelled entry per field (size = its length)."""
    from std_msgs.msg import Float64MultiArray

    data = array('d')
    for _, values in fields:
        data.extend(values)  # array('d') converts ints and numpy floats to float64 exactly
    return Float64MultiArray(
        layout=_layout(tuple((label, len(values)) for label, values in fields)), data=data
    )


@functools.lru_cache(maxsize=256)
def _layout(shape: tuple[tuple[str, int], ...]):
    """The MultiArrayLayout of `shape` ((label, size) per field), built once per shape: a message
    only holds a reference to it and nothing mutates it, and building it was ~40 % of the cost of
    encoding a Status."""
    from std_msgs.msg import MultiArrayDimension, MultiArrayLayout

    dims = [MultiArrayDimension(label=label, size=size, stride=size) for label, size in shape]
    return MultiArrayLayout(dim=dims, data_offset=0)


def _data(what: str, msg) -> list[float]:
    data = getattr(msg, 'data', None)
    if data is None:
        raise MessageError(f'{what}: expected std_msgs/Float64MultiArray, got {type(msg).__name__}')
    return [float(v) for v in data]


# --------------------------------------------------------------------------------------------
# The run's tag (formation_msgs_py.tags): a Float64MultiArray carries it as the label of one more
# layout dimension of size 0 (its data unchanged), a String as its last line.


def tag_array(msg, signer: Signer | None, topic: str):
    """`msg` (a Float64MultiArray) tagged for `topic` by `signer` (None: untouched).  The layout is
    replaced, not changed: an encoder's layout is shared between messages (`_layout`)."""
    if signer is None:
        return msg
    from std_msgs.msg import MultiArrayDimension, MultiArrayLayout

    label = signer.tag_array(topic, msg.data)
    dims = [*msg.layout.dim, MultiArrayDimension(label=label, size=0, stride=0)]
    msg.layout = MultiArrayLayout(dim=dims, data_offset=msg.layout.data_offset)
    return msg


def array_tag(msg) -> str | None:
    """The tag a Float64MultiArray carries (None: none)."""
    dims = getattr(getattr(msg, 'layout', None), 'dim', None)
    label = dims[-1].label if dims else ''
    return label if isinstance(label, str) and label.startswith(TAG_PREFIX) else None


def check_array(verifier: Verifier, topic: str, msg) -> None:
    """TagError (counted by `verifier`) unless `msg` carries a valid tag for `topic`; nothing
    without a key."""
    if verifier.required:
        verifier.check_array(topic, getattr(msg, 'data', ()), array_tag(msg))


def tag_string(msg, signer: Signer | None, topic: str):
    """`msg` (a std_msgs/String) with its tag as its last line (None: untouched)."""
    if signer is not None:
        msg.data = signer.tag_string(topic, msg.data)
    return msg


def check_string(verifier: Verifier, topic: str, msg) -> None:
    if verifier.required:
        verifier.check_string(topic, getattr(msg, 'data', None) or '')


def tag_refused(
    verifier: Verifier,
    topic: str,
    msg,
    reject: Callable[[str, str, str], None],
    *,
    check: Callable[[Verifier, str, object], None] = check_array,
) -> bool:
    """Whether `msg` lacks the run's valid tag for `topic` (`check`: check_array or check_string):
    then `reject(topic, reason, text)` refuses and counts it (untagged and forged are foreign, a
    replay apart); never without a key."""
    try:
        check(verifier, topic, msg)
    except TagError as error:
        reject(topic, error.reason, str(error))
        return True
    return False


# --------------------------------------------------------------------------------------------
# TriggerInfo  <->  std_msgs/Float64MultiArray
#   [version, kind, sender, receiver, stamp, p, control(p), rel_position(p), rel_velocity(p)?]

_TRIGGER_HEADER = 6


def encode_trigger_info(info: TriggerInfo):
    """std_msgs/Float64MultiArray carrying `info` (kind 2 = ETA-2 when rel_velocity is set)."""
    p = len(info.control)
    vectors = [('control', info.control), ('rel_position', info.rel_position)]
    if info.rel_velocity is not None:
        vectors.append(('rel_velocity', info.rel_velocity))
    for name, values in vectors:
        if len(values) != p:
            raise MessageError(
                f'trigger info {info.sender}->{info.receiver}: {name} has {len(values)} components, '
                f'control has {p}'
            )
        _check_finite(f'trigger info {info.sender}->{info.receiver} {name}', values)
    if p < 1:
        raise MessageError(f'trigger info {info.sender}->{info.receiver}: empty control')
    _check_finite(f'trigger info {info.sender}->{info.receiver} stamp', [info.stamp])
    kind = KIND_ETA1 if info.rel_velocity is None else KIND_ETA2
    header = [
        ('version', [LAYOUT_VERSION]),
        ('kind', [kind]),
        ('sender', [info.sender]),
        ('receiver', [info.receiver]),
        ('stamp', [info.stamp]),
        ('p', [p]),
    ]
    return _float_array(header + vectors)


def decode_trigger_info(msg) -> TriggerInfo:
    """TriggerInfo from a Float64MultiArray; MessageError if it breaks the layout."""
    data = _data('trigger info', msg)
    if len(data) < _TRIGGER_HEADER:
        raise MessageError(
            f'trigger info: {len(data)} values, the header alone has {_TRIGGER_HEADER}', reason=REJECT_LENGTH
        )
    _check_version('trigger info', data[0])
    _check_finite('trigger info', data)
    kind = _as_int('trigger info kind', data[1], low=KIND_ETA1, high=KIND_ETA2)
    sender = _as_int('trigger info sender', data[2], low=0, high=_MAX_ID)
    receiver = _as_int('trigger info receiver', data[3], low=0, high=_MAX_ID)
    if sender == receiver:
        raise MessageError(f'trigger info: sender and receiver are both agent {sender}')
    p = _as_int('trigger info p', data[5], low=1, high=len(data))
    vectors = 2 if kind == KIND_ETA1 else 3
    expected = _TRIGGER_HEADER + vectors * p
    if len(data) != expected:
        raise MessageError(
            f'trigger info {sender}->{receiver}: kind {kind} with p={p} needs {expected} values, '
            f'got {len(data)}',
            reason=REJECT_LENGTH,
        )
    body = data[_TRIGGER_HEADER:]
    return TriggerInfo(
        sender=sender,
        receiver=receiver,
        stamp=data[4],
        control=tuple(body[0:p]),
        rel_position=tuple(body[p : 2 * p]),
        rel_velocity=tuple(body[2 * p : 3 * p]) if kind == KIND_ETA2 else None,
    )


# --------------------------------------------------------------------------------------------
# Sensing: rcl_interfaces/srv/SetParameters, a standard service type whose request can carry the
# run's tag (std_srvs/Trigger's request is empty; a type of our own would need rosidl, which the
# PyPI wheels lack).  Request: no parameter (no key), or one string parameter `tag`; response: one
# SetParametersResult (successful, reason = the SensedState as compact JSON, or why it was
# refused), with a key the simulator's tag as the reason's last line.

SENSE_TAG_PARAMETER = 'tag'
_SENSE_PAYLOAD = b'sense'  # the request's MAC covers the service's name, the caller and its sequence


def sense_reply_topic(service: str) -> str:
    """The name a sensing answer's tag is made for: its service's, as DDS names its replies."""
    return f'{service}/reply'


def sensing_request(signer: Signer | None, service: str):
    """An agent's request to `service`: tagged by `signer` (None: untagged)."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    if signer is None:
        return SetParameters.Request()
    value = ParameterValue(
        type=ParameterType.PARAMETER_STRING, string_value=signer.tag(service, _SENSE_PAYLOAD)
    )
    return SetParameters.Request(parameters=[Parameter(name=SENSE_TAG_PARAMETER, value=value)])


def _request_tag(request) -> str | None:
    """The tag a sensing request carries (None: no parameter; '' if it carries something else,
    which no tag parses as)."""
    from rcl_interfaces.msg import ParameterType

    parameters = list(getattr(request, 'parameters', None) or ())
    if not parameters:
        return None
    (first, *rest) = parameters
    if rest or first.name != SENSE_TAG_PARAMETER or first.value.type != ParameterType.PARAMETER_STRING:
        return ''
    return first.value.string_value


def check_sensing_request(verifier: Verifier, service: str, request, *, caller: str) -> None:
    """TagError (counted by `verifier`) unless `request` carries the run's tag for `service` from
    `caller` (only agent i asks for agent i's state); nothing without a key."""
    if verifier.required:
        verifier.check(service, _SENSE_PAYLOAD, _request_tag(request), writer=caller)


def tag_sensing_answer(response, signer: Signer | None, service: str):
    """`response` with the simulator's tag as its reason's last line (None: untouched)."""
    if signer is not None and len(response.results) == 1:
        result = response.results[0]
        result.reason = signer.tag_string(sense_reply_topic(service), result.reason)
    return response


def check_sensing_answer(verifier: Verifier, service: str, response) -> None:
    """TagError (counted by `verifier`) unless the answer carries the run's tag (a second server of
    `service`, or a copy, answered); nothing without a key."""
    if verifier.required:
        results = list(getattr(response, 'results', None) or ())
        verifier.check_string(sense_reply_topic(service), results[0].reason if len(results) == 1 else '')


def _sensing_response(successful: bool, text: str):
    from rcl_interfaces.msg import SetParametersResult
    from rcl_interfaces.srv import SetParameters

    return SetParameters.Response(results=[SetParametersResult(successful=successful, reason=text)])


def _vector_json(name: str, values: Sequence[float]) -> list[float]:
    vector = [float(v) for v in values]
    _check_finite(name, vector)
    return vector


def encode_sensed_state(state: SensedState):
    """The sensing answer: successful, the state as compact JSON."""
    body: dict = {
        'version': LAYOUT_VERSION,
        'agent': int(state.agent),
        'stamp': _vector_json(f'sensed state of agent {state.agent} stamp', [state.stamp])[0],
        'rel_positions': {
            str(j): _vector_json(f'sensed x_{state.agent} - x_{j}', v) for j, v in state.rel_positions.items()
        },
    }
    if state.rel_velocities is not None:
        body['rel_velocities'] = {
            str(j): _vector_json(f'sensed q_{state.agent} - q_{j}', v)
            for j, v in state.rel_velocities.items()
        }
    if state.velocity is not None:
        body['velocity'] = _vector_json(f'sensed q_{state.agent}', state.velocity)
    if state.nearby is not None:  # the safety layer's other robots within R (absent: layer off)
        if len(state.nearby) > MAX_NEARBY:
            raise MessageError(
                f'sensed state of agent {state.agent}: {len(state.nearby)} nearby robots, at most '
                f'{MAX_NEARBY}',
                reason=REJECT_LENGTH,
            )
        body['nearby'] = {
            str(j): _vector_json(f'sensed nearby x_{state.agent} - x_{j}', v) for j, v in state.nearby.items()
        }
    # repr floats: json writes the shortest string that reads back to the same double.
    text = json.dumps(body, separators=(',', ':'), allow_nan=False)
    return _sensing_response(True, text)


def sensing_refusal(reason: str):
    """The sensing answer telling the agent why it cannot sense."""
    return _sensing_response(False, reason)


def _json_number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MessageError(f'{name} must be a number, got {value!r}')
    try:
        number = float(value)
    except OverflowError:  # an integer past the doubles (JSON integers have no bound)
        number = math.inf
    if not math.isfinite(number):
        raise MessageError(f'{name} must be finite, got {value!r}')
    return number


def _json_vector(name: str, values, p: int | None) -> tuple[float, ...]:
    if not isinstance(values, list):
        raise MessageError(f'{name} must be a list of numbers, got {values!r}')
    vector = tuple(_json_number(f'{name}[{k}]', v) for k, v in enumerate(values))
    if not vector or (p is not None and len(vector) != p):
        raise MessageError(f'{name} has {len(vector)} components, expected {p or "at least 1"}')
    return vector


def _json_vectors(name: str, table, p: int | None) -> dict[int, tuple[float, ...]]:
    if not isinstance(table, dict):
        raise MessageError(f'{name} must map neighbour ids to vectors, got {table!r}')
    result = {}
    for key, values in table.items():
        try:
            j = int(key)
        except ValueError:
            raise MessageError(f'{name}: neighbour id {key!r} is not an integer') from None
        if str(j) != key:
            raise MessageError(f'{name}: neighbour id {key!r} is not written canonically')
        result[j] = _json_vector(f'{name}[{j}]', values, p)
        p = len(result[j])
    return result


def decode_sensed_state(response) -> SensedState:
    """SensedState from a sensing answer (its tag line, if any, dropped: `check_sensing_answer`
    checks it); MessageError if refused or malformed."""
    results = getattr(response, 'results', None)
    if results is None or len(results) != 1:
        raise MessageError(
            f'a sensing answer holds one rcl_interfaces/SetParametersResult, got '
            f'{"none" if results is None else len(results)}'
        )
    text = split_text(results[0].reason)[0]
    if not results[0].successful:
        raise MessageError(f'sensing refused: {text}')
    try:
        body = json.loads(text)
    except json.JSONDecodeError as error:
        raise MessageError(f'sensed state is not JSON ({error}): {text[:80]!r}') from None
    if not isinstance(body, dict):
        raise MessageError(f'sensed state must be a JSON object, got {text[:80]!r}')
    if body.get('version') != LAYOUT_VERSION:
        raise MessageError(
            f'sensed state: version {body.get("version")!r} is not supported (expected {LAYOUT_VERSION})'
        )
    unknown = set(body) - {
        'version',
        'agent',
        'stamp',
        'rel_positions',
        'rel_velocities',
        'velocity',
        'nearby',
    }
    if unknown:
        raise MessageError(f'sensed state: unknown fields {sorted(unknown)}')
    for key in ('agent', 'stamp', 'rel_positions'):
        if key not in body:
            raise MessageError(f'sensed state: missing field {key!r}')
    agent = body['agent']
    if isinstance(agent, bool) or not isinstance(agent, int) or not 0 <= agent <= _MAX_ID:
        raise MessageError(f'sensed state: agent must be an integer id, got {agent!r}')
    stamp = _json_number(f'sensed state of agent {agent} stamp', body['stamp'])
    rel_positions = _json_vectors(f'sensed state of agent {agent} rel_positions', body['rel_positions'], None)
    p = len(next(iter(rel_positions.values()))) if rel_positions else None
    rel_velocities = velocity = None
    if ('rel_velocities' in body) != ('velocity' in body):
        raise MessageError(f'sensed state of agent {agent}: rel_velocities and velocity come together')
    if 'velocity' in body:
        velocity = _json_vector(f'sensed state of agent {agent} velocity', body['velocity'], p)
        rel_velocities = _json_vectors(
            f'sensed state of agent {agent} rel_velocities', body['rel_velocities'], len(velocity)
        )
        if set(rel_velocities) != set(rel_positions):
            raise MessageError(
                f'sensed state of agent {agent}: rel_velocities for {sorted(rel_velocities)} but '
                f'rel_positions for {sorted(rel_positions)}'
            )
    return SensedState(
        agent=agent,
        stamp=stamp,
        rel_positions=rel_positions,
        rel_velocities=rel_velocities,
        velocity=velocity,
        nearby=_decode_nearby(agent, body, p, rel_positions),
    )


def _decode_nearby(agent: int, body: dict, p: int | None, rel_positions: dict) -> dict | None:
    """The sensed state's `nearby` (the safety layer's other robots within R), or None when absent:
    at most MAX_NEARBY robots, none of them the agent itself or one of `rel_positions`' neighbours,
    each with the neighbours' dimension."""
    if 'nearby' not in body:
        return None
    table = body['nearby']
    if isinstance(table, dict) and len(table) > MAX_NEARBY:
        raise MessageError(
            f'sensed state of agent {agent}: {len(table)} nearby robots, at most {MAX_NEARBY}',
            reason=REJECT_LENGTH,
        )
    nearby = _json_vectors(f'sensed state of agent {agent} nearby', table, p)
    if clash := sorted(j for j in nearby if j == agent or j in rel_positions or not 0 <= j <= _MAX_ID):
        raise MessageError(
            f'sensed state of agent {agent}: nearby robot {clash[0]} is the agent itself, one of its '
            'neighbours or not an agent id (nearby holds the other robots only)'
        )
    return nearby


# --------------------------------------------------------------------------------------------
# Lock-step: Step [version, step_index, time, flags, epoch, due(m)]  (m >= 0 agent ids)

_STEP_LABELS = ('version', 'step_index', 'time', 'flags', 'epoch')


def encode_step(step: Step):
    _check_finite(f'step {step.index} time and epoch', [step.time, step.epoch])
    values = [LAYOUT_VERSION, step.index, step.time, step.flags, step.epoch]
    return _float_array(
        [*((label, [value]) for label, value in zip(_STEP_LABELS, values)), ('due', step.due)]
    )


def decode_step(msg) -> Step:
    data = _data('step', msg)
    if len(data) < len(_STEP_LABELS):
        raise MessageError(
            f'step: expected {len(_STEP_LABELS)} values {list(_STEP_LABELS)} and the due agent ids, '
            f'got {len(data)}',
            reason=REJECT_LENGTH,
        )
    _check_version('step', data[0])
    _check_finite('step', data)
    index = _as_int('step index', data[1], low=0, high=_MAX_COUNT)
    due = tuple(_as_int(f'step {index} due agent', value, low=0, high=_MAX_ID) for value in data[5:])
    if any(a >= b for a, b in zip(due, due[1:])):
        raise MessageError(f'step {index}: due agent ids must be sorted and distinct, got {list(due)}')
    return Step(
        index=index,
        time=data[2],
        flags=_as_int('step flags', data[3], low=0, high=_MAX_ID),
        epoch=data[4],
        due=due,
    )


# Status [version, agent, step_index, next_time, info_sent, info_received, commands_sent,
#         triggers, ready, last_planned]

_STATUS_LABELS = (
    'version',
    'agent',
    'step_index',
    'next_time',
    'info_sent_total',
    'info_received_total',
    'commands_sent_total',
    'triggers_total',
    'ready',
    'last_planned',
)


def encode_status(status: Status):
    values = [
        LAYOUT_VERSION,
        status.agent,
        status.step_index,
        status.next_time,
        status.info_sent,
        status.info_received,
        status.commands_sent,
        status.triggers,
        1.0 if status.ready else 0.0,
        status.last_planned,
    ]
    return _float_array([(label, [value]) for label, value in zip(_STATUS_LABELS, values)])


def decode_status(msg) -> Status:
    data = _data('status', msg)
    if len(data) != len(_STATUS_LABELS):
        raise MessageError(
            f'status: expected {len(_STATUS_LABELS)} values {list(_STATUS_LABELS)}, got {len(data)}',
            reason=REJECT_LENGTH,
        )
    _check_version('status', data[0])
    agent = _as_int('status agent', data[1], low=0, high=_MAX_ID)
    next_time = data[3]
    if math.isnan(next_time) or next_time == -math.inf:
        raise MessageError(
            f'status of agent {agent}: next_time must be a time or +inf, got {next_time!r}',
            reason=REJECT_NON_FINITE,
        )
    counters = [
        _as_int(f'status of agent {agent} {label}', value, low=0, high=_MAX_COUNT)
        for label, value in zip(_STATUS_LABELS[4:8], data[4:8])
    ]
    ready = data[8]
    if ready not in (0.0, 1.0):
        raise MessageError(f'status of agent {agent}: ready must be 0 or 1, got {ready!r}')
    _check_finite(f'status of agent {agent} last_planned', [data[9]])
    return Status(
        agent=agent,
        step_index=_as_int(f'status of agent {agent} step_index', data[2], low=-1, high=_MAX_COUNT),
        next_time=next_time,
        info_sent=counters[0],
        info_received=counters[1],
        commands_sent=counters[2],
        triggers=counters[3],
        ready=ready == 1.0,
        last_planned=data[9],
    )


# --------------------------------------------------------------------------------------------
# AgentReport  <->  std_msgs/String (compact JSON), its own layout version
#   {"version":3,"agent":i,"final":false,"rejected":{"sender":2},"dropped":0,"delayed":0,"late":0,
#    "robot_commands":0,"saturation":{"linear_speed":{"count":3,"largest_requested":0.41,"allowed":0.22}},
#    "failure":null,"published":{"/agent_1/cmd_vel":3,...}}

AGENT_REPORT_VERSION = 3
"""Version of the AgentReport JSON: 2 added `robot_commands`, `saturation` and `failure`; 3 `published`."""

_REPORT_COUNTERS = ('dropped', 'delayed', 'late', 'robot_commands')
_REPORT_FIELDS = (
    'version',
    'agent',
    'final',
    'rejected',
    *_REPORT_COUNTERS,
    'saturation',
    'failure',
    'published',
)
_SATURATION_FIELDS = ('count', 'largest_requested', 'allowed')


def encode_agent_report(report: AgentReport):
    from std_msgs.msg import String

    saturation = {}
    for kind, clipped in sorted(report.saturation.items()):
        _check_finite(f'agent report saturation {kind}', (clipped.largest_requested, clipped.allowed))
        if clipped.count:
            saturation[kind] = {
                'count': int(clipped.count),
                'largest_requested': float(clipped.largest_requested),
                'allowed': float(clipped.allowed),
            }
    body = {
        'version': AGENT_REPORT_VERSION,
        'agent': int(report.agent),
        'final': bool(report.final),
        'rejected': {reason: int(n) for reason, n in sorted(report.rejected.items()) if n},
        **{name: int(getattr(report, name)) for name in _REPORT_COUNTERS},
        'saturation': saturation,
        'failure': None if report.failure is None else str(report.failure),
        'published': {topic: int(n) for topic, n in sorted(report.published.items())},
    }
    if report.safety_interventions is not None:  # only with the safety layer on: older readers unchanged
        last = report.safety_last_intervention
        if last is not None:
            _check_finite(f'agent report of agent {report.agent} safety last_intervention', [last])
        body['safety'] = {
            'interventions': int(report.safety_interventions),
            'last_intervention': None if last is None else float(last),
        }
    return String(data=json.dumps(body, separators=(',', ':')))


def _json_count(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _MAX_COUNT:
        raise MessageError(f'{name} must be a count (integer >= 0), got {value!r}')
    return value


def _decode_saturation(agent: int, table) -> dict[str, Saturation]:
    if not isinstance(table, dict):
        raise MessageError(f'agent report of agent {agent}: saturation must be an object, got {table!r}')
    saturation = {}
    for kind, clipped in table.items():
        what = f'agent report of agent {agent} saturation[{kind!r}]'
        if kind not in SATURATION_KINDS:
            raise MessageError(f'{what}: unknown kind (known: {list(SATURATION_KINDS)})')
        if not isinstance(clipped, dict) or set(clipped) != set(_SATURATION_FIELDS):
            raise MessageError(f'{what} must hold exactly {list(_SATURATION_FIELDS)}, got {clipped!r}')
        values = [_json_number(f'{what} {name}', clipped[name]) for name in _SATURATION_FIELDS[1:]]
        if any(value < 0.0 for value in values):
            raise MessageError(f'{what}: largest_requested and allowed must be >= 0, got {values}')
        saturation[kind] = Saturation(
            count=_json_count(f'{what} count', clipped['count']),
            largest_requested=values[0],
            allowed=values[1],
        )
    return saturation


def decode_agent_report(msg) -> AgentReport:
    text = getattr(msg, 'data', None)
    if not isinstance(text, str):
        raise MessageError(f'agent report: expected std_msgs/String, got {type(msg).__name__}')
    text, _ = split_text(text)  # its tag, if any, checked by the reader (formation_msgs_py.tags)
    try:
        body = json.loads(text)
    except json.JSONDecodeError as error:
        raise MessageError(f'agent report is not JSON ({error}): {text[:80]!r}') from None
    if not isinstance(body, dict):
        raise MessageError(f'agent report must be a JSON object, got {text[:80]!r}')
    if body.get('version') != AGENT_REPORT_VERSION:
        raise MessageError(
            f'agent report: version {body.get("version")!r} is not supported '
            f'(expected {AGENT_REPORT_VERSION})',
            reason=REJECT_VERSION,
        )
    known = set(_REPORT_FIELDS)
    if unknown := set(body) - known - {'safety'}:
        raise MessageError(f'agent report: unknown fields {sorted(unknown)}')
    if missing := known - set(body):
        raise MessageError(f'agent report: missing fields {sorted(missing)}')
    agent = _json_count('agent report agent', body['agent'])
    if (
        agent > _MAX_ID
        or not isinstance(body['final'], bool)
        or not all(isinstance(body[name], dict) for name in ('rejected', 'published'))
    ):
        raise MessageError(f'agent report: agent, final, rejected or published malformed: {text[:120]!r}')
    if body['failure'] is not None and not isinstance(body['failure'], str):
        raise MessageError(
            f'agent report of agent {agent}: failure must be null or a string, got {body["failure"]!r}'
        )
    rejected, published = (
        {
            str(key): _json_count(f'agent report of agent {agent} {name}[{key!r}]', n)
            for key, n in body[name].items()
        }
        for name in ('rejected', 'published')
    )
    return AgentReport(
        agent=agent,
        final=body['final'],
        rejected=rejected,
        **{
            name: _json_count(f'agent report of agent {agent} {name}', body[name])
            for name in _REPORT_COUNTERS
        },
        saturation=_decode_saturation(agent, body['saturation']),
        failure=body['failure'],
        published=published,
        **_decode_report_safety(agent, body.get('safety')),
    )


def _decode_report_safety(agent: int, table) -> dict:
    """An agent report's optional `safety` entry (the safety layer on): its counts as AgentReport fields."""
    if table is None:
        return {}
    what = f'agent report of agent {agent} safety'
    if not isinstance(table, dict) or set(table) != {'interventions', 'last_intervention'}:
        raise MessageError(f"{what} must hold exactly ['interventions', 'last_intervention'], got {table!r}")
    last = table['last_intervention']
    return {
        'safety_interventions': _json_count(f'{what} interventions', table['interventions']),
        'safety_last_intervention': None if last is None else _json_number(f'{what} last_intervention', last),
    }


# --------------------------------------------------------------------------------------------
# WorldState [version, time, n, p, double, agent_ids(n), positions(n*p), velocities(n*p)?]


def encode_world_state(state: WorldState):
    positions = np.asarray(state.positions, dtype=float)
    n = len(state.agent_ids)
    if positions.ndim != 2 or positions.shape[0] != n:
        raise MessageError(f'world state: positions {positions.shape} do not match {n} agents')
    fields = [
        ('version', [LAYOUT_VERSION]),
        ('time', [state.time]),
        ('n', [n]),
        ('p', [positions.shape[1]]),
        ('double', [0 if state.velocities is None else 1]),
        ('agent_ids', list(state.agent_ids)),
        ('positions', positions.ravel().tolist()),
    ]
    if state.velocities is not None:
        velocities = np.asarray(state.velocities, dtype=float)
        if velocities.shape != positions.shape:
            raise MessageError(
                f'world state: velocities {velocities.shape} do not match positions {positions.shape}'
            )
        fields.append(('velocities', velocities.ravel().tolist()))
    return _float_array(fields)


def decode_world_state(msg) -> WorldState:
    data = _data('world state', msg)
    if len(data) < 5:
        raise MessageError(f'world state: {len(data)} values, the header alone has 5', reason=REJECT_LENGTH)
    _check_version('world state', data[0])
    _check_finite('world state', data)
    n = _as_int('world state n', data[2], low=1, high=len(data))
    p = _as_int('world state p', data[3], low=1, high=len(data))
    double = _as_int('world state double', data[4], low=0, high=1)
    expected = 5 + n + (1 + double) * n * p
    if len(data) != expected:
        raise MessageError(
            f'world state: n={n}, p={p}, double={double} needs {expected} values, got {len(data)}',
            reason=REJECT_LENGTH,
        )
    ids = tuple(
        _as_int(f'world state agent_ids[{k}]', v, low=0, high=_MAX_ID) for k, v in enumerate(data[5 : 5 + n])
    )
    start = 5 + n
    positions = np.array(data[start : start + n * p]).reshape(n, p)
    velocities = np.array(data[start + n * p :]).reshape(n, p) if double else None
    return WorldState(time=data[1], agent_ids=ids, positions=positions, velocities=velocities)


# --------------------------------------------------------------------------------------------
# Commands: u_i on geometry_msgs/Twist (single), u^d_i on geometry_msgs/Accel (double)

_AXES = ('x', 'y', 'z')


def vector3_values(what: str, values: Sequence[float]) -> tuple[list[float], list[float]]:
    """(the values as floats, checked finite, and as a geometry_msgs/Vector3's x, y, z: 1 to 3
    components, the missing ones 0); for the message and the CDR encoders alike."""
    vector = [float(v) for v in values]
    if not 1 <= len(vector) <= 3:
        raise MessageError(f'{what}: geometry_msgs carries 1 to 3 components, got {len(vector)}')
    _check_finite(what, vector)
    return vector, vector + [0.0] * (3 - len(vector))


def _vector3(what: str, values: Sequence[float]):
    from geometry_msgs.msg import Vector3

    _, (x, y, z) = vector3_values(what, values)
    return Vector3(x=x, y=y, z=z)


def encode_velocity_command(control: Sequence[float]):
    """geometry_msgs/Twist with linear = u_i (eq. uxsingle), angular = 0."""
    from geometry_msgs.msg import Twist

    return Twist(linear=_vector3('velocity command', control))


def encode_acceleration_command(control: Sequence[float]):
    """geometry_msgs/Accel with linear = u^d_i, the event-triggered part of (uxdouble)."""
    from geometry_msgs.msg import Accel

    return Accel(linear=_vector3('acceleration command', control))


def decode_command(msg, dimension: int) -> tuple[float, ...]:
    """The first `dimension` linear components of a Twist/Accel; the others must be zero."""
    if not 1 <= dimension <= 3:
        raise MessageError(f'command: dimension must be 1 to 3, got {dimension}')
    linear = [float(getattr(msg.linear, axis)) for axis in _AXES]
    angular = [float(getattr(msg.angular, axis)) for axis in _AXES]
    _check_finite('command linear', linear)
    if any(linear[dimension:]) or any(angular):
        raise MessageError(
            f'command: only the first {dimension} linear components may be set, got linear={linear} '
            f'angular={angular}'
        )
    return tuple(linear[:dimension])


# --------------------------------------------------------------------------------------------
# Robots (README, "Running on robots"): poses in, velocity commands out.
#   geometry_msgs/PoseStamped or nav_msgs/Odometry -> RobotPose;
#   holonomic: geometry_msgs/TwistStamped, linear = velocity in the frame of header.frame_id;
#   differential drive: geometry_msgs/Twist in the body frame, linear.x = v, angular.z = ω.


def stamp_seconds(stamp) -> float:
    """builtin_interfaces/Time in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def pose_values(
    what: str, position: Sequence[float], orientation: Sequence[float]
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A pose's position (3) and orientation (x, y, z, w), checked (finite, a unit quaternion
    give or take its sender's rounding) and the quaternion normalised; for the decoders of
    messages and of serialized bytes (`formation_msgs_py.cdr`) alike."""
    position = tuple(float(v) for v in position)
    orientation = tuple(float(c) for c in orientation)
    _check_finite(f'{what} position', position)
    _check_finite(f'{what} orientation', orientation)
    norm = math.sqrt(sum(c * c for c in orientation))
    if not 0.5 < norm < 2.0:  # a unit quaternion, give or take its sender's rounding
        raise MessageError(
            f'{what}: orientation must be a unit quaternion, got {orientation} (norm {norm!r})'
        )
    return position, tuple(c / norm for c in orientation)


def twist_values(
    linear: Sequence[float], angular: Sequence[float]
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """An odometry's body twist (linear, angular: 3 each), checked finite."""
    linear = tuple(float(v) for v in linear)
    angular = tuple(float(v) for v in angular)
    _check_finite('odometry twist linear', linear)
    _check_finite('odometry twist angular', angular)
    return linear, angular


def _pose_fields(what: str, pose) -> tuple[tuple[float, ...], tuple[float, ...]]:
    o = pose.orientation
    return pose_values(what, (pose.position.x, pose.position.y, pose.position.z), (o.x, o.y, o.z, o.w))


def decode_pose_stamped(msg) -> RobotPose:
    """geometry_msgs/PoseStamped -> RobotPose (no twist)."""
    position, orientation = _pose_fields('pose', msg.pose)
    return RobotPose(
        stamp=stamp_seconds(msg.header.stamp),
        frame=msg.header.frame_id,
        position=position,
        orientation=orientation,
    )


def decode_odometry(msg) -> RobotPose:
    """nav_msgs/Odometry -> RobotPose with the body-frame twist (REP 105)."""
    position, orientation = _pose_fields('odometry pose', msg.pose.pose)
    twist = msg.twist.twist
    linear, angular = twist_values(
        (twist.linear.x, twist.linear.y, twist.linear.z), (twist.angular.x, twist.angular.y, twist.angular.z)
    )
    return RobotPose(
        stamp=stamp_seconds(msg.header.stamp),
        frame=msg.header.frame_id,
        position=position,
        orientation=orientation,
        linear=linear,
        angular=angular,
    )


def encode_world_velocity(velocity: Sequence[float], *, frame_id: str, stamp: float):
    """geometry_msgs/TwistStamped: a holonomic robot's velocity in the frame `frame_id`."""
    from geometry_msgs.msg import Twist, TwistStamped
    from std_msgs.msg import Header

    return TwistStamped(
        header=Header(stamp=ros_time(stamp), frame_id=frame_id),
        twist=Twist(linear=_vector3('world velocity', velocity)),
    )


def encode_body_velocity(linear: float, angular: float):
    """geometry_msgs/Twist in the body frame: a differential-drive robot's (v, ω)."""
    from geometry_msgs.msg import Twist, Vector3

    _check_finite('body velocity', (linear, angular))
    return Twist(linear=Vector3(x=float(linear)), angular=Vector3(z=float(angular)))


# --------------------------------------------------------------------------------------------
# Time for tools (/clock, headers): rounded to the nanosecond; never used by the algorithm.


def nanoseconds(seconds: float) -> int:
    """The nanoseconds nearest to `seconds` (finite, >= 0): a ROS time, as `ros_time` and the CDR
    encoders stamp it."""
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise MessageError(f'ROS time must be finite and >= 0, got {seconds!r}')
    return round(seconds * 1e9)


def ros_time(seconds: float):
    """builtin_interfaces/Time nearest to `seconds` (>= 0)."""
    from builtin_interfaces.msg import Time

    sec, nanosec = divmod(nanoseconds(seconds), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def encode_pose_array(state: WorldState, *, frame_id: str = WORLD_FRAME):
    """geometry_msgs/PoseArray of agent positions (p <= 3; missing axes 0) for visualisation."""
    from geometry_msgs.msg import Point, Pose, PoseArray
    from std_msgs.msg import Header

    positions = np.asarray(state.positions, dtype=float)
    if positions.shape[1] > 3:
        raise MessageError(f'PoseArray holds positions of dimension <= 3, got {positions.shape[1]}')
    poses = []
    for row in positions.tolist():
        row = row + [0.0] * (3 - len(row))
        poses.append(Pose(position=Point(x=row[0], y=row[1], z=row[2])))
    return PoseArray(header=Header(stamp=ros_time(state.time), frame_id=frame_id), poses=poses)
