"""What tools see of the simulator's exact world (`sim_node`): never read by the agents.

`SimulatorView` publishes the exact state at every sample (`/formation/state`), and at most every
`viz_period` of sim time `/clock` (rounded to ns), the ground truth (`/formation/ground_truth`) and
the Foxglove markers (`/formation/markers`); and the sensing log (`/formation/sensing_log`).  The
samples are the simulator's `Sampler`'s (pure evaluations: the world only moves from event to
event); each goes out once, in order.
"""

from __future__ import annotations

import json
from collections.abc import Callable

from geometry_msgs.msg import PoseArray
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, String
from visualization_msgs.msg import MarkerArray

from formation_msgs_py.codec import encode_pose_array, encode_world_state, ros_time
from formation_msgs_py.lockstep import WorldState
from formation_msgs_py.qos import PROTOCOL_QOS, SIMULATOR_QOS
from formation_msgs_py.topics import (
    CLOCK_TOPIC,
    GROUND_TRUTH_TOPIC,
    MARKERS_TOPIC,
    SENSING_LOG_TOPIC,
    STATE_TOPIC,
)
from formation_sim.analysis.markers import FormationMarkers, LiveMarkerArray
from formation_sim.model.scenario import Scenario
from formation_sim.sim.engine import Sampler

VIEW_HISTORY_BYTES = 16 * 2**20


def view_qos(sample) -> QoSProfile:
    """SIMULATOR_QOS for a view (ground truth, markers) whose messages are like `sample`: as deep,
    unless its history (kept for late joiners: transient local) would hold more than
    VIEW_HISTORY_BYTES (a marker array of 300 agents is ~200 KB); never below PROTOCOL_QOS's 32.
    A shallow history lost views to a recorder a few hundred messages behind (README)."""
    size = max(1, len(serialize_message(sample)))
    return QoSProfile(
        history=SIMULATOR_QOS.history,
        depth=max(PROTOCOL_QOS.depth, min(SIMULATOR_QOS.depth, VIEW_HISTORY_BYTES // size)),
        reliability=SIMULATOR_QOS.reliability,
        durability=SIMULATOR_QOS.durability,
        liveliness=SIMULATOR_QOS.liveliness,
        liveliness_lease_duration=SIMULATOR_QOS.liveliness_lease_duration,
    )


class SimulatorView:
    """The tools' topics of a simulator: their writers (made by `node.create_publisher`) and what
    goes out on them, through `publish(writer, message)` (the node counts what it published)."""

    def __init__(
        self,
        node,
        *,
        scenario: Scenario,
        velocities,
        viz_period: float,
        publish: Callable[[object, object], None],
    ) -> None:
        self.scenario = scenario
        self.double = scenario.dynamics == 'double'
        self.viz_period = viz_period
        self._publish = publish
        self.state_pub = node.create_publisher(Float64MultiArray, STATE_TOPIC, SIMULATOR_QOS)
        start = WorldState(
            time=0.0, agent_ids=scenario.agent_ids, positions=scenario.positions, velocities=velocities
        )
        self.truth_pub = node.create_publisher(
            PoseArray, GROUND_TRUTH_TOPIC, view_qos(encode_pose_array(start))
        )
        self.log_pub = node.create_publisher(String, SENSING_LOG_TOPIC, SIMULATOR_QOS)
        self.clock_pub = node.create_publisher(Clock, CLOCK_TOPIC, SIMULATOR_QOS)
        # A Foxglove view per sample.
        self._markers = FormationMarkers(scenario)
        self._marker_array = LiveMarkerArray(self._markers)
        view = self._markers.to_ros(self._markers.markers(scenario.positions), time=0.0)
        self.markers_pub = node.create_publisher(MarkerArray, MARKERS_TOPIC, view_qos(view))
        self._sent = 0  # samples of the sampler published so far
        self._next_viz = 0.0  # sim time of the next ground truth and marker view

    def publish_samples(self, samples: Sampler, *, finished: bool) -> None:
        """The exact state at every sample not yet published; /clock, ground truth and the marker
        view at most every `viz_period` of sim time (a view costs ~1 ms), and at the last sample
        once the run has `finished`."""
        first, self._sent = self._sent, len(samples.times)
        last = len(samples.times) - 1
        for k in range(first, last + 1):
            t, x = samples.times[k], samples.positions[k]
            state = WorldState(
                time=t,
                agent_ids=self.scenario.agent_ids,
                positions=x,
                velocities=samples.velocities[k] if self.double else None,
            )
            self._publish(self.state_pub, encode_world_state(state))
            if t >= self._next_viz or (finished and k == last):
                self._next_viz = t + self.viz_period
                self._publish(self.clock_pub, Clock(clock=ros_time(t)))
                self._publish(self.truth_pub, encode_pose_array(state))
                self._publish(self.markers_pub, self._marker_array.update(self._markers.markers(x), time=t))

    def log_sensing(self, agent: int, step: int, t: float) -> None:
        """Agent `agent` sensed at step `step`, sim time `t`."""
        log = {'version': 1, 'agent': agent, 'step': step, 'time': t}
        self._publish(self.log_pub, String(data=json.dumps(log, separators=(',', ':'))))
