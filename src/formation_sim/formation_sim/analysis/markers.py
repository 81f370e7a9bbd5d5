"""A 3D view of the formation as `visualization_msgs/MarkerArray` (Foxglove, rviz).

For one state of the team it draws

- ``agents``: one sphere per agent (id = agent id), ``labels``: its id above it;
- ``edges``: one line per edge of the graph, coloured by how much of the communication radius Δ
  it uses (`edge_colour`: green when short, yellow at half of Δ, red at Δ, magenta beyond);
- ``desired``: the desired formation, the offsets τ_i of a solution of τ_i - τ_j = d_ij moved so
  that their centroid is the team's current centroid, as translucent spheres joined by grey
  lines (``desired_edges``).

The core (`FormationMarkers.markers`) is ROS-free and returns `MarkerSpec` descriptions; two
adapters turn them into a message: `to_ros` (rclpy's visualization_msgs, imported lazily) for a
live publisher, and `to_cdr` (rosbags' typestore, no ROS needed) for writing bags. Both give the
same CDR bytes. Positions of dimension p < 3 are drawn in the plane z = 0 (p = 1 on the x axis);
p > 3 is refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from formation_sim.analysis.errors import MarkerError
from formation_sim.model import theory

if TYPE_CHECKING:
    from formation_sim.model.scenario import Scenario

from formation_msgs_py.topics import MARKERS_TOPIC, STATE_TOPIC, WORLD_FRAME

MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
DEFAULT_FRAME = WORLD_FRAME

# visualization_msgs/Marker constants (type, action).
SPHERE = 2
LINE_STRIP = 4
LINE_LIST = 5
SPHERE_LIST = 7
TEXT_VIEW_FACING = 9
ADD = 0

RGBA = tuple[float, float, float, float]
Point3 = tuple[float, float, float]

_AGENT_PALETTE: tuple[RGBA, ...] = (
    (0.12, 0.47, 0.71, 1.0),
    (1.00, 0.50, 0.05, 1.0),
    (0.17, 0.63, 0.17, 1.0),
    (0.84, 0.15, 0.16, 1.0),
    (0.58, 0.40, 0.74, 1.0),
    (0.55, 0.34, 0.29, 1.0),
    (0.89, 0.47, 0.76, 1.0),
    (0.50, 0.50, 0.50, 1.0),
    (0.74, 0.74, 0.13, 1.0),
    (0.09, 0.75, 0.81, 1.0),
)
_DESIRED_COLOUR: RGBA = (0.6, 0.6, 0.6, 0.45)
_BROKEN_COLOUR: RGBA = (1.0, 0.0, 1.0, 1.0)


@dataclass(frozen=True, kw_only=True)
class MarkerSpec:
    """ROS-free description of one visualization_msgs/Marker (fields as in the message)."""

    ns: str
    id: int
    type: int
    scale: Point3
    colour: RGBA
    position: Point3 = (0.0, 0.0, 0.0)  # pose.position (spheres, text); lists use `points`
    points: tuple[Point3, ...] = ()
    colours: tuple[RGBA, ...] = ()  # per point (line lists), empty: `colour` for all
    text: str = ''


def agent_colour(index: int) -> RGBA:
    """Colour of the agent at row `index` (the same in the markers and the animation)."""
    return _AGENT_PALETTE[index % len(_AGENT_PALETTE)]


def edge_colour(length: float, delta: float) -> RGBA:
    """Green (length 0) to yellow (Δ/2) to red (Δ); magenta once the edge exceeds Δ (link lost)."""
    if not (math.isfinite(length) and length >= 0.0):
        raise MarkerError(f'edge length must be finite and >= 0, got {length!r}')
    if not (math.isfinite(delta) and delta > 0.0):
        raise MarkerError(f'communication radius Δ must be finite and > 0, got {delta!r}')
    ratio = length / delta
    if ratio > 1.0:
        return _BROKEN_COLOUR
    if ratio <= 0.5:
        return (2.0 * ratio, 1.0, 0.0, 1.0)
    return (1.0, 2.0 * (1.0 - ratio), 0.0, 1.0)


def _as_point(row: Sequence[float]) -> Point3:
    values = [float(v) for v in row] + [0.0] * (3 - len(row))
    return (values[0], values[1], values[2])


class FormationMarkers:
    """Markers of a scenario's team; precomputes the desired offsets once.

    >>> view = FormationMarkers(scenario)
    >>> specs = view.markers(positions)                   # ROS-free
    >>> publisher.publish(view.to_ros(specs, time=t))     # rclpy
    >>> bag.write(MARKERS_TOPIC, stamp_ns, view.to_cdr(specs, time=t))
    """

    def __init__(self, scenario: Scenario, *, frame_id: str = DEFAULT_FRAME) -> None:
        if scenario.dimension > 3:
            raise MarkerError(f'markers draw dimensions 1 to 3, the scenario has p = {scenario.dimension}')
        self.scenario = scenario
        self.frame_id = frame_id
        self.delta = float(scenario.delta)
        index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
        self._edges = [(index[edge.i], index[edge.j]) for edge in scenario.edges]
        tau = theory.formation_feasibility(scenario).tau
        self._offsets = tau - tau.mean(axis=0)  # desired positions relative to the centroid
        # Sizes follow Δ, so any scenario scale gives a readable picture.
        self.agent_diameter = self.delta / 20.0
        self.line_width = self.delta / 100.0

    def markers(self, positions: np.ndarray) -> list[MarkerSpec]:
        """Every marker for the team at `positions` ((n, p), rows in scenario order)."""
        x = np.asarray(positions, dtype=float)
        n, p = len(self.scenario.agent_ids), self.scenario.dimension
        if x.shape != (n, p):
            raise MarkerError(
                f'positions must have shape ({n}, {p}) for agents {list(self.scenario.agent_ids)}, got '
                f'{x.shape}'
            )
        if not np.all(np.isfinite(x)):
            raise MarkerError('positions must be finite')
        ids = self.scenario.agent_ids
        size = self.agent_diameter
        specs = [
            MarkerSpec(
                ns='agents',
                id=agent,
                type=SPHERE,
                scale=(size, size, size),
                colour=agent_colour(k),
                position=_as_point(x[k]),
            )
            for k, agent in enumerate(ids)
        ]
        for k, agent in enumerate(ids):
            above = _as_point(x[k])
            specs.append(
                MarkerSpec(
                    ns='labels',
                    id=agent,
                    type=TEXT_VIEW_FACING,
                    scale=(0.0, 0.0, 1.5 * size),  # text height is scale.z
                    colour=(1.0, 1.0, 1.0, 1.0),
                    position=(above[0], above[1] + 1.2 * size, above[2]),
                    text=str(agent),
                )
            )
        for e, (a, b) in enumerate(self._edges):
            length = float(np.linalg.norm(x[a] - x[b]))
            specs.append(
                MarkerSpec(
                    ns='edges',
                    id=e,
                    type=LINE_STRIP,
                    scale=(self.line_width, 0.0, 0.0),
                    colour=edge_colour(length, self.delta),
                    points=(_as_point(x[a]), _as_point(x[b])),
                )
            )
        desired = x.mean(axis=0) + self._offsets  # anchored at the team's centroid
        specs.append(
            MarkerSpec(
                ns='desired',
                id=0,
                type=SPHERE_LIST,
                scale=(size, size, size),
                colour=_DESIRED_COLOUR,
                points=tuple(_as_point(row) for row in desired),
            )
        )
        specs.append(
            MarkerSpec(
                ns='desired_edges',
                id=0,
                type=LINE_LIST,
                scale=(0.5 * self.line_width, 0.0, 0.0),
                colour=_DESIRED_COLOUR,
                points=tuple(_as_point(desired[v]) for pair in self._edges for v in pair),
            )
        )
        return specs

    # -- adapters ---------------------------------------------------------------------------------

    def _fields(self, spec: MarkerSpec, time: float) -> dict[str, Any]:
        """The Marker's fields as nested plain values (shared by both adapters)."""
        nanoseconds = _nanoseconds(time)
        return {
            'header': {
                'stamp': {'sec': nanoseconds // 1_000_000_000, 'nanosec': nanoseconds % 1_000_000_000},
                'frame_id': self.frame_id,
            },
            'ns': spec.ns,
            'id': int(spec.id),
            'type': spec.type,
            'action': ADD,
            'pose': {
                'position': dict(zip('xyz', spec.position)),
                'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0},
            },
            'scale': dict(zip('xyz', spec.scale)),
            'color': dict(zip('rgba', spec.colour)),
            'points': [dict(zip('xyz', point)) for point in spec.points],
            'colors': [dict(zip('rgba', colour)) for colour in spec.colours],
            'text': spec.text,
        }

    def to_ros(self, specs: Sequence[MarkerSpec], *, time: float):
        """visualization_msgs.msg.MarkerArray (rclpy) of `specs`, stamped with sim time `time`."""
        from builtin_interfaces.msg import Time
        from geometry_msgs.msg import Point
        from std_msgs.msg import ColorRGBA
        from visualization_msgs.msg import Marker, MarkerArray

        markers = []
        for spec in specs:
            fields = self._fields(spec, time)
            marker = Marker(
                ns=fields['ns'],
                id=fields['id'],
                type=fields['type'],
                action=fields['action'],
                text=fields['text'],
            )
            marker.header.stamp = Time(**fields['header']['stamp'])
            marker.header.frame_id = fields['header']['frame_id']
            for axis, value in fields['pose']['position'].items():
                setattr(marker.pose.position, axis, value)
            marker.pose.orientation.w = 1.0
            for axis, value in fields['scale'].items():
                setattr(marker.scale, axis, value)
            marker.color = ColorRGBA(**fields['color'])
            marker.points = [Point(**point) for point in fields['points']]
            marker.colors = [ColorRGBA(**colour) for colour in fields['colors']]
            markers.append(marker)
        return MarkerArray(markers=markers)

    def to_cdr(self, specs: Sequence[MarkerSpec], *, time: float, typestore=None) -> bytes:
        """CDR bytes of the MarkerArray of `specs` (rosbags; no ROS needed)."""
        from formation_sim.bag.io import jazzy_typestore

        store = typestore if typestore is not None else jazzy_typestore()
        markers = [
            build_message(store, 'visualization_msgs/msg/Marker', self._fields(spec, time)) for spec in specs
        ]
        array = build_message(store, MARKERS_TYPE, {'markers': markers})
        return bytes(store.serialize_cdr(array, MARKERS_TYPE))


class LiveMarkerArray:
    """The rclpy MarkerArray of a view, built once and then updated in place for each frame.

    A publisher serialises the message when it publishes, so one message object can be reused;
    updating it costs a fraction of building a new one (~0.7 ms for three agents), which matters
    to the simulator that publishes a view many times per second.
    """

    def __init__(self, view: FormationMarkers) -> None:
        self.view = view
        self._message = None
        self._layout: tuple[tuple[str, int, int], ...] = ()

    def update(self, specs: Sequence[MarkerSpec], *, time: float):
        """The MarkerArray of `specs` at sim time `time` (the same object on every call)."""
        layout = tuple((spec.ns, spec.id, len(spec.points)) for spec in specs)
        if self._message is None or layout != self._layout:
            self._message, self._layout = self.view.to_ros(specs, time=time), layout
            return self._message
        from builtin_interfaces.msg import Time

        nanoseconds = _nanoseconds(time)
        stamp = Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)
        for marker, spec in zip(self._message.markers, specs):
            marker.header.stamp = stamp
            position = marker.pose.position
            position.x, position.y, position.z = spec.position
            colour = marker.color
            colour.r, colour.g, colour.b, colour.a = spec.colour
            for point, (x, y, z) in zip(marker.points, spec.points):
                point.x, point.y, point.z = x, y, z
        return self._message


def _nanoseconds(time: float) -> int:
    if not (math.isfinite(time) and time >= 0.0):
        raise MarkerError(f'marker time must be finite and >= 0, got {time!r}')
    return round(time * 1e9)  # like formation_msgs_py.codec.ros_time


# -- rosbags messages from plain values -------------------------------------------------------------

_NUMPY_TYPES = {
    'bool': np.bool_,
    'byte': np.uint8,
    'char': np.uint8,
    'int8': np.int8,
    'uint8': np.uint8,
    'int16': np.int16,
    'uint16': np.uint16,
    'int32': np.int32,
    'uint32': np.uint32,
    'int64': np.int64,
    'uint64': np.uint64,
    'float32': np.float32,
    'float64': np.float64,
}


_DEFAULTS: dict[tuple[int, str], tuple[Any, Any]] = {}


def _default_base(name: str):
    if name in ('string', 'wstring'):
        return ''
    if name == 'bool':
        return False
    if name in ('float32', 'float64'):
        return 0.0
    return 0


def _build(store, descriptor, value):
    """A value of the field type `descriptor` (rosbags fielddefs) from a plain value or None."""
    from rosbags.typesys.base import Nodetype

    kind, detail = descriptor
    if kind == Nodetype.BASE:
        name = detail[0]
        return _default_base(name) if value is None else value
    if kind == Nodetype.NAME:
        if value is not None and not isinstance(value, dict):
            return value  # already a message object
        if not value:  # an all-default message: built once per store and type, then shared
            key = (id(store), detail)
            if key not in _DEFAULTS:  # the store is kept with it, so its id cannot be reused
                _DEFAULTS[key] = (store, build_message(store, detail, {}))
            return _DEFAULTS[key][1]
        return build_message(store, detail, value)
    element, length = detail
    items = list(value) if value is not None else []
    if kind == Nodetype.ARRAY and value is None:
        items = [None] * length
    if element[0] == Nodetype.BASE and element[1][0] in _NUMPY_TYPES:
        base = element[1][0]
        return np.array(
            [_default_base(base) if item is None else item for item in items], dtype=_NUMPY_TYPES[base]
        )
    return [_build(store, element, item) for item in items]


def build_message(store, msgtype: str, values: dict[str, Any]):
    """A rosbags message of `msgtype` with `values` set and every other field at its default."""
    if msgtype not in store.fielddefs:
        raise MarkerError(f'message type {msgtype!r} is not in the typestore')
    _, fields = store.fielddefs[msgtype]
    unknown = set(values) - {name for name, _ in fields}
    if unknown:
        raise MarkerError(f'{msgtype} has no fields {sorted(unknown)}')
    return store.types[msgtype](
        **{name: _build(store, descriptor, values.get(name)) for name, descriptor in fields}
    )


# -- a copy of a bag with the markers added ---------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class MarkedBag:
    path: Path
    messages: int  # messages copied from the source
    markers: int  # MarkerArray messages added (one per state)
    skipped_topics: tuple[str, ...]  # source topics whose type could not be stored


def _store_with(connections) -> tuple[Any, list[str]]:
    """A Jazzy typestore that also knows the source's non-standard types (from their stored definitions)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from formation_sim.bag.io import jazzy_typestore

    if all(connection.msgtype in jazzy_typestore().fielddefs for connection in connections):
        return jazzy_typestore(), []
    store = get_typestore(Stores.ROS2_JAZZY)  # a copy: the shared store stays standard
    unknown = []
    for connection in connections:
        if connection.msgtype in store.fielddefs:
            continue
        try:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        except Exception:  # noqa: BLE001 - any parse failure: the topic is left out and reported
            unknown.append(connection.topic)
    return store, unknown


def write_bag_with_markers(
    source: str | Path,
    target: str | Path,
    scenario: Scenario,
    *,
    state_topic: str = STATE_TOPIC,
    progress=None,
) -> MarkedBag:
    """Copy the bag `source` into the new bag `target`, adding a MarkerArray on MARKERS_TOPIC
    for every WorldState on `state_topic`, with the same bag timestamp and the state's time in
    its headers. Markers the source already had on MARKERS_TOPIC are replaced.
    """
    import yaml
    from rosbags.rosbag2 import Reader

    from formation_msgs_py.codec import decode_world_state
    from formation_sim.bag.io import BagWriter, decode, read_bag

    source, target = Path(source), Path(target)
    view = FormationMarkers(scenario)
    with Reader(source) as reader:
        connections = list(reader.connections)
        total = reader.message_count
    store, unknown = _store_with(connections)
    metadata = source / 'metadata.yaml'
    custom = {}
    if metadata.is_file():
        custom = (yaml.safe_load(metadata.read_text(encoding='utf-8')) or {}).get(
            'rosbag2_bagfile_information', {}
        ).get('custom_data') or {}
    copied = added = 0
    with BagWriter(target, typestore=store) as bag:
        for key, value in custom.items():
            bag.set_custom_data(str(key), str(value))
        bag.set_custom_data(
            'formation_markers',
            f'{MARKERS_TOPIC} added by formation analyze --markers from {source.resolve()}',
        )
        offered = {c.topic: list(getattr(c.ext, 'offered_qos_profiles', [])) for c in connections}
        for connection in connections:
            if connection.topic not in unknown and connection.topic != MARKERS_TOPIC:
                bag.add_topic(
                    connection.topic, connection.msgtype, offered_qos_profiles=offered[connection.topic]
                )
        # The simulator's own markers were offered as its state is (reliable, transient local).
        bag.add_topic(
            MARKERS_TOPIC,
            MARKERS_TYPE,
            offered_qos_profiles=offered.get(MARKERS_TOPIC) or offered.get(state_topic, []),
        )
        for number, message in enumerate(read_bag(source), start=1):
            if message.topic in unknown or message.topic == MARKERS_TOPIC:
                continue
            bag.write(message.topic, message.timestamp_ns, message.rawdata)
            copied += 1
            if message.topic == state_topic:
                state = decode_world_state(decode(message.rawdata, message.msgtype))
                if tuple(state.agent_ids) != scenario.agent_ids:
                    raise MarkerError(
                        f'a state of agents {list(state.agent_ids)} in {source}; the scenario has '
                        f'{list(scenario.agent_ids)}'
                    )
                bag.write(
                    MARKERS_TOPIC,
                    message.timestamp_ns,
                    view.to_cdr(view.markers(state.positions), time=state.time, typestore=store),
                )
                added += 1
            if progress is not None and number % 2000 == 0:
                progress(number, total)
    if progress is not None:
        progress(total, total)
    return MarkedBag(path=target, messages=copied, markers=added, skipped_topics=tuple(unknown))
