"""The simulator's view for tools without a node: every sample once, in order, as its exact state;
/clock, ground truth and markers at most every viz_period of sim time and at the last sample of a
finished run; the sensing log."""

from __future__ import annotations

import json

import numpy as np
import pytest

from formation_msgs_py.codec import decode_world_state
from formation_msgs_py.qos import PROTOCOL_QOS, SIMULATOR_QOS
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.nodes.exact_world import ExactWorld
from formation_sim.runtime.nodes.sim_view import VIEW_HISTORY_BYTES, SimulatorView, view_qos


class _Writer:
    def __init__(self, topic: str, qos) -> None:
        self.topic_name, self.qos = topic, qos


class _Node:
    """What the view asks of a node: writers; what it publishes goes to `sent`."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, object]] = []

    def create_publisher(self, msg_type, topic: str, qos) -> _Writer:
        return _Writer(topic, qos)

    def publish(self, writer: _Writer, msg) -> None:
        self.sent.append((writer.topic_name, msg))

    def take(self, topic: str) -> list:
        taken = [msg for name, msg in self.sent if name == topic]
        self.sent = [(name, msg) for name, msg in self.sent if name != topic]
        return taken


@pytest.fixture
def run():
    scenario = load_scenario('paper_double')
    exact = ExactWorld(scenario, sample_period=0.125)
    node = _Node()
    view = SimulatorView(
        node, scenario=scenario, velocities=exact.world.velocities, viz_period=0.25, publish=node.publish
    )
    exact.sampler.event()
    exact.world.set_control(1, [1.0, 0.5])
    return exact, node, view


def test_each_sample_goes_out_once_as_its_exact_state_and_views_at_most_every_viz_period(run):
    exact, node, view = run
    exact.advance(0.4)  # samples at 0, 0.125, 0.25, 0.375, 0.4
    view.publish_samples(exact.sampler, finished=False)
    states = [decode_world_state(msg) for msg in node.take('/formation/state')]
    assert [s.time for s in states] == exact.sampler.times
    for state, x, q in zip(states, exact.sampler.positions, exact.sampler.velocities):
        assert np.array_equal(state.positions, x) and np.array_equal(state.velocities, q)
    clocks = node.take('/clock')
    assert [c.clock.sec * 10**9 + c.clock.nanosec for c in clocks] == [0, 250_000_000]
    assert len(node.take('/formation/ground_truth')) == len(node.take('/formation/markers')) == 2
    view.publish_samples(exact.sampler, finished=False)
    assert node.sent == []  # nothing new: nothing again
    exact.advance(0.45)  # the run ends here: its last sample is viewed though within viz_period
    view.publish_samples(exact.sampler, finished=True)
    assert [decode_world_state(m).time for m in node.take('/formation/state')] == [0.45]
    assert [c.clock.nanosec for c in node.take('/clock')] == [450_000_000]


def test_the_sensing_log_goes_out_as_json(run):
    _, node, view = run
    view.log_sensing(2, 7, 0.5)
    (log,) = node.take('/formation/sensing_log')
    assert json.loads(log.data) == {'version': 1, 'agent': 2, 'step': 7, 'time': 0.5}


def test_a_view_keeps_at_most_16_mb_of_history_and_never_fewer_than_32_messages(run):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    _, _, view = run
    assert view.truth_pub.qos.depth == SIMULATOR_QOS.depth  # a small team's views: as deep as the rest
    sample = String(data='x' * 100_000)
    size, depth = len(serialize_message(sample)), view_qos(sample).depth
    assert PROTOCOL_QOS.depth < depth < SIMULATOR_QOS.depth
    assert depth * size <= VIEW_HISTORY_BYTES < (depth + 1) * size
    assert view_qos(String(data='x' * 2**20)).depth == PROTOCOL_QOS.depth  # 16 would fit: 32 kept
