"""Inspecting a live ROS graph without ros2cli: topics with their endpoints, readable echo.

- `discover_topics`: every topic with its types, publisher and subscriber counts and node names
  (this tool's own node left out), after waiting for discovery to settle.
- `format_message`: a message as YAML-like text. The formation's Float64MultiArray topics are
  decoded with `formation_msgs_py.codec` (TriggerInfo on `/agent_<i>/trigger_info/to_<j>`, Step,
  Status, WorldState) and shown as their fields; a message that breaks its layout is shown raw,
  with the decoder's complaint. Every other type is shown field by field, like `ros2 topic echo`.
- `echo_qos`: a subscription QoS every current publisher of a topic is compatible with.
"""

from __future__ import annotations

import dataclasses
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from formation_msgs_py.codec import decode_status, decode_step, decode_trigger_info, decode_world_state
from formation_msgs_py.errors import MessageError
from formation_msgs_py.topics import STATE_TOPIC, STATUS_TOPIC, STEP_TOPIC
from formation_sim.runtime.errors import InspectError
from formation_sim.runtime.nodes.intruders import UNKNOWN_NODE  # an endpoint seen before its node's name

TRIGGER_INFO_TOPIC = re.compile(r'^/agent_(\d+)/trigger_info/to_(\d+)$')
FLOAT_ARRAY = 'std_msgs/msg/Float64MultiArray'
DECODERS: dict[str, tuple[str, Callable]] = {
    STEP_TOPIC: ('Step', decode_step),
    STATUS_TOPIC: ('Status', decode_status),
    STATE_TOPIC: ('WorldState', decode_world_state),
}


# ------------------------------------------------------------------------------- plain values


def to_plain(value: Any) -> Any:
    """rclpy messages, formation dataclasses, arrays -> dicts, lists and numbers (for YAML)."""
    if hasattr(value, 'get_fields_and_field_types'):
        return {name: to_plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        return to_plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {to_plain(k): to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)) or type(value).__name__ == 'array':  # array.array from rclpy
        return [to_plain(v) for v in value]
    if isinstance(value, bytes):
        return list(value)
    return value


class _Dumper(yaml.SafeDumper):
    pass


def _float(dumper: yaml.SafeDumper, value: float) -> yaml.Node:
    # repr: the shortest text that reads back to the same double (yaml's own drops digits).
    if math.isnan(value):
        text = '.nan'
    elif math.isinf(value):
        text = '.inf' if value > 0 else '-.inf'
    else:
        text = repr(value)
    return dumper.represent_scalar('tag:yaml.org,2002:float', text)


def _list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flow = all(isinstance(item, (int, float)) and not isinstance(item, bool) for item in data)
    return dumper.represent_sequence('tag:yaml.org,2002:seq', data, flow_style=flow)


_Dumper.add_representer(float, _float)
_Dumper.add_representer(list, _list)


def to_yaml(value: Any) -> str:
    return yaml.dump(to_plain(value), Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)


def format_message(topic: str, msgtype: str, msg: Any) -> str:
    """The message as YAML-like text; formation payloads decoded (see the module docstring)."""
    kind, decoder = None, None
    if msgtype == FLOAT_ARRAY:
        if TRIGGER_INFO_TOPIC.match(topic):
            kind, decoder = 'TriggerInfo', decode_trigger_info
        elif topic in DECODERS:
            kind, decoder = DECODERS[topic]
    if decoder is not None:
        try:
            return f'# {kind} (formation layout, decoded)\n' + to_yaml(decoder(msg))
        except MessageError as error:
            return f'# not a valid {kind}: {error}\n' + to_yaml(msg)
    return to_yaml(msg)


# ------------------------------------------------------------------------------------ the graph


@dataclass(frozen=True, kw_only=True)
class TopicInfo:
    name: str
    types: tuple[str, ...]
    publishers: tuple[str, ...]  # fully qualified node names, one entry per publisher
    subscribers: tuple[str, ...]


def _node_name(info) -> str:
    namespace = info.node_namespace.rstrip('/')
    return f'{namespace}/{info.node_name}'


def topic_infos(node) -> list[TopicInfo]:
    """Every topic the node sees, without the node's own endpoints."""
    own = _node_name_of(node)
    result = []
    for name, types in sorted(node.get_topic_names_and_types()):
        publishers = tuple(
            sorted(n for n in map(_node_name, node.get_publishers_info_by_topic(name)) if n != own)
        )
        subscribers = tuple(
            sorted(n for n in map(_node_name, node.get_subscriptions_info_by_topic(name)) if n != own)
        )
        if publishers or subscribers:
            result.append(
                TopicInfo(name=name, types=tuple(types), publishers=publishers, subscribers=subscribers)
            )
    return result


def _node_name_of(node) -> str:
    return f'{node.get_namespace().rstrip("/")}/{node.get_name()}'


def discover_topics(node, *, wait: float, settle: float = 0.5) -> list[TopicInfo]:
    """Topics after discovery: polls until nothing changed for `settle` s and every endpoint's
    node is named, at most `wait` s."""
    deadline = time.monotonic() + wait
    last, stable_since = None, time.monotonic()
    while True:
        current = topic_infos(node)
        now = time.monotonic()
        if current != last:
            last, stable_since = current, now
        named = not any(
            UNKNOWN_NODE in name for info in current for name in info.publishers + info.subscribers
        )
        if now >= deadline or (current and named and now - stable_since >= settle):
            return current
        time.sleep(0.05)


def format_topics(topics: list[TopicInfo], *, verbose: bool = False) -> str:
    if not topics:
        return '(no topics: nothing discovered in this domain)\n'
    width = max(len(topic.name) for topic in topics)
    lines = []
    for topic in topics:
        lines.append(
            f'{topic.name:<{width}}  [{", ".join(topic.types)}]  '
            f'publishers: {len(topic.publishers)}  subscribers: {len(topic.subscribers)}'
        )
        if verbose:
            for role, nodes in (('publisher', topic.publishers), ('subscriber', topic.subscribers)):
                for name in nodes:
                    lines.append(f'    {role}: {name}')
    return '\n'.join(lines) + '\n'


def echo_qos(node, topic: str, depth: int = 100):
    """Reliable / transient local only if every publisher offers it (else a reader would not match)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    offered = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    reliable = bool(offered) and all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    durable = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if durable else DurabilityPolicy.VOLATILE,
    )


def wait_for_topic(node, topic: str, *, timeout: float) -> str:
    """The topic's type once a publisher of it is discovered."""
    deadline = time.monotonic() + timeout
    while True:
        types = dict(node.get_topic_names_and_types()).get(topic)
        if types and node.get_publishers_info_by_topic(topic):
            if len(types) > 1:
                raise InspectError(f'topic {topic} is published with several types {types}; echo needs one')
            return types[0]
        if time.monotonic() > deadline:
            known = sorted(name for name, _ in node.get_topic_names_and_types())
            raise InspectError(f'no publisher of {topic} found within {timeout} s (topics seen: {known})')
        time.sleep(0.05)
