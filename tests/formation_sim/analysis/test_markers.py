"""formation_sim.analysis.markers: the Foxglove/rviz view of a formation state, and bags with it added."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from formation_sim.analysis.errors import MarkerError
from formation_sim.analysis.markers import (
    LINE_LIST,
    LINE_STRIP,
    MARKERS_TOPIC,
    MARKERS_TYPE,
    SPHERE,
    SPHERE_LIST,
    TEXT_VIEW_FACING,
    FormationMarkers,
    LiveMarkerArray,
    edge_colour,
    write_bag_with_markers,
)
from formation_sim.bag.errors import BagError
from formation_sim.bag.io import decode, read_bag
from formation_sim.model.scenario import load_scenario


def test_edge_colours_run_from_green_to_red_as_the_edge_nears_delta():
    assert edge_colour(0.0, 4.0) == (0.0, 1.0, 0.0, 1.0)
    assert edge_colour(2.0, 4.0) == (1.0, 1.0, 0.0, 1.0)
    assert edge_colour(4.0, 4.0) == (1.0, 0.0, 0.0, 1.0)
    assert edge_colour(4.0 + 1e-9, 4.0) == (1.0, 0.0, 1.0, 1.0)  # beyond Δ: the link is lost
    reds = [edge_colour(length, 4.0)[0] for length in np.linspace(0.0, 4.0, 9)]
    greens = [edge_colour(length, 4.0)[1] for length in np.linspace(0.0, 4.0, 9)]
    assert reds == sorted(reds) and greens == sorted(greens, reverse=True)


@pytest.mark.parametrize(
    ('length', 'delta', 'complaint'),
    [
        (-1.0, 4.0, 'edge length must be finite and >= 0, got -1.0'),
        (math.nan, 4.0, 'got nan'),
        (1.0, 0.0, 'Δ must be finite and > 0, got 0.0'),
    ],
)
def test_bad_edge_lengths_are_refused(length, delta, complaint):
    with pytest.raises(MarkerError, match=complaint):
        edge_colour(length, delta)


def test_markers_show_agents_edges_and_the_desired_formation_at_the_centroid():
    scenario = load_scenario('paper_single')
    x = np.array([[2.0, 4.0], [3.5, 7.0], [4.5, 5.5]])
    specs = FormationMarkers(scenario).markers(x)
    by_ns: dict[str, list] = {}
    for spec in specs:
        by_ns.setdefault(spec.ns, []).append(spec)
    agents = {spec.id: spec for spec in by_ns['agents']}
    assert set(agents) == {1, 2, 3} and all(spec.type == SPHERE for spec in agents.values())
    for k, agent in enumerate(scenario.agent_ids):
        assert agents[agent].position == (x[k, 0], x[k, 1], 0.0)
    assert [spec.text for spec in by_ns['labels']] == ['1', '2', '3'] and by_ns['labels'][
        0
    ].type == TEXT_VIEW_FACING
    edges = by_ns['edges']
    assert len(edges) == len(scenario.edges)
    for spec, edge in zip(edges, scenario.edges):
        a, b = x[scenario.index(edge.i)], x[scenario.index(edge.j)]
        assert spec.type == LINE_STRIP
        assert spec.points == ((a[0], a[1], 0.0), (b[0], b[1], 0.0))
        assert spec.colour == edge_colour(float(np.linalg.norm(a - b)), scenario.delta)
    (desired,) = by_ns['desired']
    assert desired.type == SPHERE_LIST
    goal = np.array(desired.points)[:, :2]
    assert np.allclose(goal.mean(axis=0), x.mean(axis=0), rtol=0.0, atol=1e-12)
    for edge in scenario.edges:  # the desired positions realise every d_ij
        assert np.allclose(
            goal[scenario.index(edge.i)] - goal[scenario.index(edge.j)], edge.d, rtol=0.0, atol=1e-12
        )
    (lines,) = by_ns['desired_edges']
    assert lines.type == LINE_LIST and len(lines.points) == 2 * len(scenario.edges)


def test_bad_states_are_refused_with_the_expected_shape():
    view = FormationMarkers(load_scenario('paper_single'))
    with pytest.raises(
        MarkerError, match=r'positions must have shape \(3, 2\) for agents \[1, 2, 3\], got \(2, 2\)'
    ):
        view.markers(np.zeros((2, 2)))
    with pytest.raises(MarkerError, match='positions must be finite'):
        view.markers(np.array([[0.0, 0.0], [1.0, math.inf], [2.0, 0.0]]))
    with pytest.raises(MarkerError, match='marker time must be finite and >= 0, got -1.0'):
        view.to_cdr(view.markers(np.zeros((3, 2))), time=-1.0)


def test_the_rosbags_and_rclpy_messages_carry_the_same_markers():
    from rclpy.serialization import deserialize_message, serialize_message
    from visualization_msgs.msg import MarkerArray

    scenario = load_scenario('paper_single')
    view = FormationMarkers(scenario)
    specs = view.markers(scenario.positions)
    stamp = 1.000000001
    from_rosbags = decode(view.to_cdr(specs, time=stamp), MARKERS_TYPE)
    from_rclpy = deserialize_message(serialize_message(view.to_ros(specs, time=stamp)), MarkerArray)
    assert len(from_rosbags.markers) == len(from_rclpy.markers) == len(specs)
    for a, b, spec in zip(from_rosbags.markers, from_rclpy.markers, specs):
        assert (
            (a.ns, a.id, a.type, a.text)
            == (b.ns, b.id, b.type, b.text)
            == (spec.ns, spec.id, spec.type, spec.text)
        )
        assert (
            (a.header.stamp.sec, a.header.stamp.nanosec)
            == (b.header.stamp.sec, b.header.stamp.nanosec)
            == (1, 1)
        )
        assert a.header.frame_id == b.header.frame_id == 'world'
        assert [(p.x, p.y, p.z) for p in a.points] == [(p.x, p.y, p.z) for p in b.points] == list(spec.points)
        assert (
            (a.pose.position.x, a.pose.position.y, a.pose.position.z)
            == (b.pose.position.x, b.pose.position.y, b.pose.position.z)
            == spec.position
        )
        assert (a.color.r, a.color.g, a.color.b, a.color.a) == (b.color.r, b.color.g, b.color.b, b.color.a)
        assert a.pose.orientation.w == b.pose.orientation.w == 1.0


def test_a_copy_of_a_bag_gets_one_marker_array_per_state(paper_single_record, write_run_bag, tmp_path):
    source = write_run_bag(paper_single_record, tmp_path / 'bag', scenario_topic=True)
    marked = write_bag_with_markers(source, tmp_path / 'marked', paper_single_record.scenario)
    original = list(read_bag(source))
    copied = [m for m in read_bag(tmp_path / 'marked') if m.topic != MARKERS_TOPIC]
    markers = [m for m in read_bag(tmp_path / 'marked') if m.topic == MARKERS_TOPIC]
    assert copied == original  # every message, its time stamp and bytes, in order
    states = [m for m in original if m.topic == '/formation/state']
    assert marked.markers == len(markers) == len(states) == len(paper_single_record.sample_times)
    assert [m.timestamp_ns for m in markers] == [m.timestamp_ns for m in states]
    last = decode(markers[-1].rawdata, MARKERS_TYPE)
    final = paper_single_record.sample_positions[-1]
    agents = {m.id: m for m in last.markers if m.ns == 'agents'}
    for k, agent in enumerate(paper_single_record.scenario.agent_ids):
        assert (agents[agent].pose.position.x, agents[agent].pose.position.y) == tuple(final[k])
    metadata = yaml.safe_load((tmp_path / 'marked' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information'
    ]
    assert 'formation_markers' in metadata['custom_data']
    with pytest.raises(BagError, match='never overwrites'):
        write_bag_with_markers(source, tmp_path / 'marked', paper_single_record.scenario)


def test_a_live_marker_array_updated_in_place_equals_a_new_one():
    from rclpy.serialization import deserialize_message, serialize_message
    from visualization_msgs.msg import MarkerArray

    scenario = load_scenario('paper_single')
    view = FormationMarkers(scenario)
    live = LiveMarkerArray(view)
    first = live.update(view.markers(scenario.positions), time=0.5)
    moved = scenario.positions + np.array(
        [[0.25, -1.0], [3.5, 0.125], [-2.0, 1.0]]
    )  # edge colours change too
    specs = view.markers(moved)
    again = live.update(specs, time=2.000000003)
    assert again is first  # reused, not rebuilt
    fresh = view.to_ros(specs, time=2.000000003)
    assert again == fresh
    # And through the wire (colours are float32 there), as messages: CDR padding bytes are not
    # zeroed, so the bytes of two equal messages may differ.
    wire = lambda message: deserialize_message(serialize_message(message), MarkerArray)  # noqa: E731 - a one-line helper beside its use
    assert wire(again) == wire(fresh)
