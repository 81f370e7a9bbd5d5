"""The simulator node: the physical world of a distributed run, and the lock-step time keeper.

It holds the exact `World`, serves every agent's sensing service `/agent_<i>/sense`, applies the
commands agents publish, and publishes what tools want to see: `/clock` (rounded to ns, for tools
only), the exact state `/formation/state` and `/formation/ground_truth` at a sample period (pure
evaluations, the world itself only advances from event to event), and `/formation/sensing_log`.

Lock-step protocol (docs/MESSAGES.md): after discovery the simulator publishes Step 0 at t = 0;
every agent due at a step senses, commands, broadcasts and reports a Status; agents that receive
triggering information report again.  A step is settled when every due agent has reported its
trigger, every command sent has been applied and every triggering-information message sent has
been received (cumulative counters, so equality cannot be transient).  Then the world advances to
the smallest next time reported (the exact float, carried by the next Step) and the agents that
reported exactly that time trigger.

Wall-clock mode (`clock_mode:=realtime`, as on robots): Step 0 carries the wall-clock epoch of
t = 0 and agents keep their own timers.  The world then advances to the wall-clock time of each
sensing request and each command as it arrives (still only event to event), and the run reports
how late every trigger was against the time its agent had planned.

Faults (README, "Reliability"): an agent whose command writer loses DDS liveliness (its process
died, or the network no longer reaches it) is declared lost after `LIVELINESS_LEASE` +
`LOST_GRACE` s, and so is a recorder whose heartbeat writer does (frozen, it acknowledges
nothing); the run then stops.  Lock-step waits for a recorder that falls more than
`RECORDER_LAG` steps behind.  Whenever a run stops early, after step 0 (an agent lost, a protocol
violation, a stall, SIGINT/SIGTERM), the simulator ends it as at the horizon (a final Step, the
samples, the final reports) and writes summary.json with what happened up to then and
`extra.failure` saying what went wrong, where and when.  Exit status: 0 done, 1 failed, 3 an
agent or the recorder lost, 130 interrupted.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rclpy
from geometry_msgs.msg import Accel, PoseArray, Twist
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from formation_agent.ros.process import EXECUTORS, EXIT_PEER_LOST, StopSignals, make_executor
from formation_msgs_py.qos import LIVELINESS_LEASE, LOST_GRACE, PROTOCOL_QOS, READER_QOS, SIMULATOR_QOS
from formation_msgs_py.codec import (
    MessageError,
    decode_agent_report,
    decode_command,
    decode_status,
    encode_pose_array,
    encode_sensed_state,
    encode_step,
    encode_world_state,
    ros_time,
    sensing_refusal,
)
from formation_msgs_py.lockstep import (
    DISCOVERY_STEP,
    STEP_FLAG_FINAL,
    STEP_FLAG_REALTIME,
    AgentReport,
    Status,
    Step,
    WorldState,
)
from formation_msgs_py.topics import (
    CLOCK_TOPIC,
    GROUND_TRUTH_TOPIC,
    MARKERS_TOPIC,
    RECORDER_TOPIC,
    REPORT_TOPIC,
    SCENARIO_TOPIC,
    SENSING_LOG_TOPIC,
    STATE_TOPIC,
    STATUS_TOPIC,
    STEP_TOPIC,
    command_topic,
    sense_service,
    trigger_info_topic,
)
from formation_sim.sim.engine import Sampler, build_agent, due_twice, rounding_floor
from formation_sim.sim.files import write_atomically
from formation_sim.analysis.markers import MARKERS_TYPE, FormationMarkers, LiveMarkerArray
from formation_sim.model.scenario import Scenario, dump_scenario_text, load_scenario
from formation_sim.sim.record import RunRecord
from formation_sim.sim.summary import write_summary
from formation_sim.sim.world import World

GRAPH_FILE = 'graph.json'

CLOCK_MODES = ('lockstep', 'realtime')

RECORDER_LAG = 2
"""Steps the lock-step may run ahead of what a recorder has written (its heartbeat says which step).

Lock-step at full speed outruns a recorder (one Python process taking every message): on a loaded
2-core machine 3 runs of 4 lost hundreds of view and Status messages, the writers' keep-last
histories turning over before the recorder had them.  Held within a few steps of it, what is
outstanding stays far below the writers' depths (24 runs of 24 complete since, views kept deeper)."""


EXIT_FAILED = 1
EXIT_AGENT_LOST = EXIT_PEER_LOST  # 3
EXIT_INTERRUPTED = 130


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


class SimulatorError(RuntimeError):
    """The distributed run cannot go on: a protocol violation, a stall, or a dead peer."""

    kind = 'protocol'  # extra.failure.kind in summary.json


class StallError(SimulatorError):
    """No step settled within the stall timeout."""

    kind = 'stall'


class DiscoveryError(SimulatorError):
    """The agents did not all connect within the discovery timeout."""

    kind = 'discovery'


class ConnectivityLostError(SimulatorError):
    """An edge of the graph reached the communication radius Δ in the true world."""

    kind = 'connectivity_lost'

    def __init__(self, message: str, *, time: float, edge: tuple[int, int], length: float) -> None:
        super().__init__(message)
        self.time = time
        self.edge = edge
        self.length = length


class RecorderLostError(SimulatorError):
    """A recorder stopped showing signs of life (or left) before the end of the run."""

    kind = 'recorder_lost'


class AgentLostError(SimulatorError):
    """One or more agents stopped showing signs of life (or left) before the end of the run."""

    kind = 'agent_lost'

    def __init__(self, message: str, *, agents: list[int]) -> None:
        super().__init__(message)
        self.agents = agents


def _ids(agents: list[int], *, most: int = 20) -> str:
    """Agent ids for a message, the first `most` of a long list."""
    shown = ', '.join(map(str, agents[:most]))
    return shown + (f', … ({len(agents)} in all)' if len(agents) > most else '')


def formation_topics(scenario: Scenario) -> list[tuple[str, str]]:
    """Every topic of a run of `scenario` with its type, as a recorder wants them."""
    array = 'std_msgs/msg/Float64MultiArray'
    double = scenario.dynamics == 'double'
    command_type = 'geometry_msgs/msg/Accel' if double else 'geometry_msgs/msg/Twist'
    topics = [
        (STEP_TOPIC, array),
        (STATUS_TOPIC, array),
        (STATE_TOPIC, array),
        (GROUND_TRUTH_TOPIC, 'geometry_msgs/msg/PoseArray'),
        (SENSING_LOG_TOPIC, 'std_msgs/msg/String'),
        (CLOCK_TOPIC, 'rosgraph_msgs/msg/Clock'),
        (REPORT_TOPIC, 'std_msgs/msg/String'),
        (SCENARIO_TOPIC, 'std_msgs/msg/String'),
        (MARKERS_TOPIC, MARKERS_TYPE),
    ]
    for i in scenario.agent_ids:
        topics.append((command_topic(i, double=double), command_type))
        for j in scenario.neighbours(i):
            topics.append((trigger_info_topic(i, j), array))
    return topics


def agent_parameters(scenario: Scenario, agent_id: int, *, horizon: float, extra_subscribers: int = 0) -> dict:
    """ROS parameters of agent `agent_id`'s node (what that agent knows of the scenario)."""
    neighbours = scenario.neighbours(agent_id)
    gains = scenario.gains
    params = {
        'agent_id': int(agent_id),
        'neighbour_ids': [int(j) for j in neighbours],
        'neighbour_offsets': [float(v) for d in neighbours.values() for v in d],
        'dimension': scenario.dimension,
        'delta': float(scenario.delta),
        'horizon': float(horizon),
        'extra_subscribers': int(extra_subscribers),
    }
    if scenario.dynamics == 'single':
        params.update(algorithm='eta1', alpha=float(gains.alpha), beta=float(gains.beta))
    else:
        params.update(
            algorithm='eta2',
            alpha_d=float(gains.alpha_d),
            beta_d=float(gains.beta_d),
            k1=float(gains.k1),
            k2=float(gains.k2),
            k3=float(gains.k3),
        )
    return params


@dataclass
class _AgentBook:
    """What the simulator knows of one agent: its latest status and what it received from it."""

    neighbours: tuple[int, ...]
    status: Status | None = None
    expected_triggers: int = 0
    commands_received: int = 0
    sensed_at_step: int = -1
    trigger_times: list[float] = field(default_factory=list)
    lateness: list[float] = field(default_factory=list)  # wall clock: trigger time - planned time
    report: AgentReport | None = None  # its latest report (rejected and injected messages)
    alive: bool = False  # its command writer is matched and alive (DDS liveliness)
    lost: tuple[float, str] | None = None  # (monotonic time, how) once its command writer went away
    lease_expired: bool = False  # how it went: its lease expired (else its writer was deleted)


class FormationSimulatorNode(Node):
    """World, sensing services and lock-step clock of a distributed formation run."""

    def __init__(
        self, *, scenario: Scenario | None = None, parameter_overrides: list[Parameter] | None = None, context=None
    ) -> None:
        super().__init__('formation_simulator', parameter_overrides=parameter_overrides or [], context=context)
        source = self.declare_parameter('scenario', '').value
        horizon = float(self.declare_parameter('horizon', 0.0).value)
        self.out_dir = str(self.declare_parameter('out_dir', '').value)
        self.sample_period = float(self.declare_parameter('sample_period', 0.01).value)
        self.viz_period = float(self.declare_parameter('viz_period', 0.04).value)
        self.extra_subscribers = int(self.declare_parameter('extra_subscribers', 0).value)
        # Nodes outside the run that must hear every Step (monitors, fault injectors): step 0 waits.
        self.step_listeners = int(self.declare_parameter('step_listeners', 0).value)
        self.progress_period = float(self.declare_parameter('progress_period', 1.0).value)
        self.stall_timeout = float(self.declare_parameter('stall_timeout', 60.0).value)
        self.discovery_timeout = float(self.declare_parameter('discovery_timeout', 120.0).value)
        self.clock_mode = str(self.declare_parameter('clock_mode', 'lockstep').value)
        if self.clock_mode not in CLOCK_MODES:
            raise SimulatorError(f'clock_mode must be one of {CLOCK_MODES}, got {self.clock_mode!r}')
        self.realtime = self.clock_mode == 'realtime'
        self.executor_kind = str(self.declare_parameter('executor', 'events').value)
        if self.executor_kind not in EXECUTORS:
            raise SimulatorError(f'executor must be one of {EXECUTORS}, got {self.executor_kind!r}')
        if scenario is None:
            if not source:
                raise SimulatorError("parameter 'scenario' is required (a built-in name or a YAML path)")
            scenario = load_scenario(source)
        self.scenario = scenario
        self.horizon = scenario.horizon if horizon <= 0.0 else horizon
        if not math.isfinite(self.horizon):
            raise SimulatorError(f'horizon must be finite, got {self.horizon!r}')
        if not (math.isfinite(self.sample_period) and self.sample_period >= 0.0):
            raise SimulatorError(f'sample_period must be >= 0 (0: events only), got {self.sample_period!r}')
        if not (math.isfinite(self.viz_period) and self.viz_period >= 0.0):
            raise SimulatorError(f'viz_period must be >= 0 (0: every sample), got {self.viz_period!r}')
        if scenario.dimension > 3:
            raise SimulatorError(f'distributed runs carry commands in geometry_msgs: p <= 3, got p = {scenario.dimension}')
        self.world = World.from_scenario(scenario)
        # The agents' threshold, the very same floats, to stop where the engine stops.
        self._threshold_model = build_agent(scenario, scenario.agent_ids[0])
        self.double = scenario.dynamics == 'double'
        # Ground truth of connectivity: every sample checks ||x_i - x_j|| < Δ on every edge.
        index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
        self._edge_rows = (
            np.array([index[e.i] for e in scenario.edges], dtype=int),
            np.array([index[e.j] for e in scenario.edges], dtype=int),
        )
        self.agents = {i: _AgentBook(neighbours=tuple(scenario.neighbours(i))) for i in scenario.agent_ids}

        self._step_pub = self.create_publisher(Float64MultiArray, STEP_TOPIC, SIMULATOR_QOS)
        self._state_pub = self.create_publisher(Float64MultiArray, STATE_TOPIC, SIMULATOR_QOS)
        start = WorldState(time=0.0, agent_ids=scenario.agent_ids, positions=scenario.positions, velocities=scenario.velocities)
        self._truth_pub = self.create_publisher(PoseArray, GROUND_TRUTH_TOPIC, view_qos(encode_pose_array(start)))
        self._log_pub = self.create_publisher(String, SENSING_LOG_TOPIC, SIMULATOR_QOS)
        self._clock_pub = self.create_publisher(Clock, CLOCK_TOPIC, SIMULATOR_QOS)
        # For tools: the scenario once (so a bag is self-contained), a Foxglove view per sample.
        self._scenario_pub = self.create_publisher(String, SCENARIO_TOPIC, SIMULATOR_QOS)
        self._markers = FormationMarkers(scenario)
        self._marker_array = LiveMarkerArray(self._markers)
        view = self._markers.to_ros(self._markers.markers(scenario.positions), time=0.0)
        self._markers_pub = self.create_publisher(MarkerArray, MARKERS_TOPIC, view_qos(view))
        self._tool_publishers = (
            self._state_pub,
            self._truth_pub,
            self._log_pub,
            self._clock_pub,
            self._scenario_pub,
            self._markers_pub,
        )
        self._status_sub = self.create_subscription(Float64MultiArray, STATUS_TOPIC, self._on_status, READER_QOS)
        self._report_sub = self.create_subscription(String, REPORT_TOPIC, self._on_report, READER_QOS)
        command_type = Accel if self.double else Twist
        # One command writer per agent: its DDS liveliness is the agent's sign of life.
        self._command_subs = {
            i: self.create_subscription(
                command_type,
                command_topic(i, double=self.double),
                lambda msg, agent=i: self._on_command(msg, agent),
                READER_QOS,
                event_callbacks=SubscriptionEventCallbacks(
                    liveliness=lambda info, agent=i: self._on_agent_liveliness(agent, info)
                ),
            )
            for i in self.agents
        }
        self._services = [
            self.create_service(Trigger, sense_service(i), lambda request, response, agent=i: self._on_sense(agent))
            for i in self.agents
        ]
        # The recorders' heartbeat writers (one per extra subscriber): their liveliness says the
        # recorder still takes and acknowledges what the run publishes.  A frozen recorder lets
        # every reliable keep-last writer of the run overwrite what it did not acknowledge.
        self._recorder_sub = self.create_subscription(
            String,
            RECORDER_TOPIC,
            self._on_recorder,
            READER_QOS,
            event_callbacks=SubscriptionEventCallbacks(liveliness=self._on_recorder_liveliness),
        )
        self._recorders_alive = 0
        self._recorded_steps: dict[str, int] = {}  # recorder node -> the latest step it recorded
        self._recorder_lost: tuple[float, str] | None = None  # (monotonic time, how)
        self._recorder_lease_expired = False
        self.published: dict[str, int] = {}  # topic -> messages this node published there

        self.step: Step | None = None
        self.finished = False
        self.failure: Exception | None = None
        self.sensing_calls = 0
        self.steps = 0
        self._due: set[int] = set()
        self._sampler = Sampler(self.world, self.sample_period, on_sample=self._on_sample)
        self._unpublished = 0  # samples at the end of the record not yet published for tools
        self._next_viz = 0.0  # sim time of the next ground truth and marker view
        self._created = time.monotonic()
        self._started: float | None = None
        self._last_progress = self._created
        self._last_advance = self._created
        self._epoch = 0.0
        self._finished_at: float | None = None
        self.graph: dict = {}
        self.rejected: dict[str, int] = {}  # malformed messages the simulator itself refused
        self.failure_info: dict | None = None  # extra.failure of summary.json once the run failed
        self._timer = self.create_timer(0.1, self._tick)

    # -- discovery ------------------------------------------------------------------------------

    def _connected(self) -> bool:
        return not self._discovery_gaps()

    def _discovery_gaps(self) -> list[str]:
        """What discovery still waits for (empty: step 0 can go)."""
        n, extra = len(self.agents), self.extra_subscribers
        gaps = []

        def count(what: str, have: int, want: int) -> None:
            if have < want:
                gaps.append(f'{what} {have}/{want}')

        count(f'{STEP_TOPIC} readers', self._step_pub.get_subscription_count(), n + extra + self.step_listeners)
        for pub in self._tool_publishers:
            count(f'{pub.topic_name} readers', pub.get_subscription_count(), extra)
        count(f'{STATUS_TOPIC} writers', self._status_sub.get_publisher_count(), n)
        count(f'{REPORT_TOPIC} writers', self._report_sub.get_publisher_count(), n)
        count(f'{RECORDER_TOPIC} writers (recorders)', self._recorder_sub.get_publisher_count(), extra)
        unmatched = [i for i, sub in self._command_subs.items() if sub.get_publisher_count() < 1]
        expired = [i for i, book in self.agents.items() if book.lost is not None]
        not_ready = [
            i for i, book in self.agents.items()
            if book.status is None or book.status.step_index != DISCOVERY_STEP or not book.status.ready
        ]  # fmt: skip
        for what, agents in (
            ('agents whose command writer is not matched', unmatched),
            ('agents whose liveliness lease expired', expired),
            ('agents not ready (their own endpoints unmatched)', not_ready),
        ):
            if agents:
                gaps.append(f'{what}: {_ids(agents)}')
        return gaps

    def _tick(self) -> None:
        now = time.monotonic()
        if not self.finished:
            self._check_lost(now)
        if self.step is None:
            if self._connected():
                self._start()
            elif now - self._created > self.discovery_timeout:
                raise DiscoveryError(
                    f'discovery did not complete within {self.discovery_timeout} s; still missing: '
                    + '; '.join(self._discovery_gaps())
                )
            return
        if self.finished:
            return
        if self.realtime:
            self._realtime_tick()
        elif now - self._last_advance > self.stall_timeout:
            raise StallError(f'no progress for {self.stall_timeout} s at {self._describe_wait()}')
        if self.progress_period > 0.0 and now - self._last_progress >= self.progress_period:
            self._last_progress = now
            self._print_progress()

    # -- faults -----------------------------------------------------------------------------------

    def _on_agent_liveliness(self, agent: int, info) -> None:
        book = self.agents[agent]
        if info.alive_count > 0:
            book.alive = True
            book.lost = None
        elif book.alive and book.lost is None and not self.finished:
            # A lease that expired: the process died or the network lost it.  A writer deleted:
            # the agent left (its process exited) before the end of the run.
            book.lease_expired = info.not_alive_count_change > 0
            how = f'no sign of life for {LIVELINESS_LEASE} s (DDS liveliness lease)' if book.lease_expired else 'its node left the graph'
            book.lost = (time.monotonic(), how)

    def _on_recorder_liveliness(self, info) -> None:
        if info.alive_count >= self._recorders_alive:
            self._recorders_alive = info.alive_count
            self._recorder_lost = None
        elif self._recorder_lost is None:  # also after the end: no more waiting for its acknowledgements
            self._recorder_lease_expired = info.not_alive_count_change > 0
            how = f'no sign of life for {LIVELINESS_LEASE} s (DDS liveliness lease: stopped or frozen?)' if self._recorder_lease_expired else 'it left the graph'
            self._recorder_lost = (time.monotonic(), how)

    def _check_lost(self, now: float) -> None:
        self._check_recorder_lost(now)
        # During discovery a lease may expire while a busy machine starts many processes: discovery
        # waits for the agent to come back (bounded by its timeout); an agent that left counts.
        lost = {
            i: book.lost
            for i, book in self.agents.items()
            if book.lost is not None and not (self.step is None and book.lease_expired)
        }
        # After a short grace, so that what a lost agent sent before it went is handled first,
        # and agents lost together (one process) are named together.
        if not lost or now - min(at for at, _ in lost.values()) <= LOST_GRACE:
            return
        where = 'during discovery' if self.step is None else f'at t={self.world.time!r} (step {self.step.index})'
        agents = sorted(lost)
        names = f'agent {agents[0]}' if len(agents) == 1 else f'agents {", ".join(map(str, agents))}'
        hows = '; '.join(sorted({how for _, how in lost.values()}))
        raise AgentLostError(f'{names} lost {where}: {hows}; the run stops', agents=agents)

    def _on_recorder(self, msg: String) -> None:
        """A recorder's heartbeat: the latest step it has written (flow control, `RECORDER_LAG`)."""
        try:
            beat = json.loads(msg.data)
            name, step = str(beat['recorder']), beat['step']
            if beat.get('version') != 1 or isinstance(step, bool) or not isinstance(step, int):
                raise ValueError(f'version {beat.get("version")!r}, step {step!r}')
        except (ValueError, KeyError, TypeError) as error:
            self._reject(RECORDER_TOPIC, 'field', f'recorder heartbeat {msg.data[:80]!r}: {error}')
            return
        self._recorded_steps[name] = max(step, self._recorded_steps.get(name, -1))
        self._advance_if_settled()

    def _recorder_behind(self) -> bool:
        """More than RECORDER_LAG steps are not yet in some recorder's bag (lock-step waits)."""
        if self.extra_subscribers < 1:
            return False
        recorded = sorted(self._recorded_steps.values())[: self.extra_subscribers]
        return len(recorded) < self.extra_subscribers or recorded[0] < self.step.index - RECORDER_LAG

    def _check_recorder_lost(self, now: float) -> None:
        lost = self._recorder_lost
        if lost is None or (self.step is None and self._recorder_lease_expired) or now - lost[0] <= LOST_GRACE:
            return
        where = 'during discovery' if self.step is None else f'at t={self.world.time!r} (step {self.step.index})'
        raise RecorderLostError(
            f'the recorder lost {where}: {lost[1]}; what it did not acknowledge is overwritten, so the run stops'
        )

    def _on_report(self, msg: String) -> None:
        try:
            report = decode_agent_report(msg)
        except MessageError as error:
            self._reject(REPORT_TOPIC, error.reason, str(error))
            return
        book = self.agents.get(report.agent)
        if book is None:
            self._reject(REPORT_TOPIC, 'field', f'report of agent {report.agent}, not in the scenario')
            return
        if book.report is None or not book.report.final:
            book.report = report

    def _reject(self, topic: str, reason: str, detail: str) -> None:
        count = self.rejected.get(reason, 0) + 1
        self.rejected[reason] = count
        if count <= 3 or count % 100 == 0:
            self.get_logger().warning(f'rejected a message on {topic} ({reason}, {count} so far): {detail}')

    def final_reports_in(self) -> bool:
        """Every agent still alive has sent its final report."""
        return all(book.report is not None and book.report.final for book in self.agents.values() if book.lost is None)

    def fail(self, error: BaseException) -> None:
        """Note why the run stops early (extra.failure of the summary)."""
        if self.failure_info is not None:
            return
        if isinstance(error, SimulatorError):
            kind = error.kind
        elif isinstance(error, (KeyboardInterrupt, ExternalShutdownException)):
            kind = 'interrupted'
        else:
            kind = 'error'
        self.failure_info = {
            'kind': kind,
            'message': str(error) or ('stopped by a signal (SIGINT/SIGTERM)' if kind == 'interrupted' else type(error).__name__),
            'agents': list(getattr(error, 'agents', getattr(error, 'edge', []))),
            'time': getattr(error, 'time', self.world.time),
            'step': None if self.step is None else self.step.index,
            'wall_time': time.monotonic() - (self._started or self._created),  # since t = 0 began
            'detected_by': 'simulator',
        }
        if isinstance(error, ConnectivityLostError):
            self.failure_info.update(edge=list(error.edge), length=error.length)

    def _publish(self, publisher, msg) -> None:
        publisher.publish(msg)
        self.published[publisher.topic_name] = self.published.get(publisher.topic_name, 0) + 1

    def _print_progress(self) -> None:
        events = sum(len(book.trigger_times) for book in self.agents.values())
        try:
            print(
                f'progress t={self.world.time:.6f} horizon={self.horizon:g} events={events} steps={self.steps} '
                f'wall={time.monotonic() - (self._started or self._created):.1f}s',
                flush=True,
            )
        except OSError:  # nobody reads any more (the orchestrator died): carry on without progress
            self.progress_period = 0.0

    def _describe_wait(self) -> str:
        lines = [f'step {self.step.index} (t={self.step.time!r}, due {sorted(self._due)})']
        if self.extra_subscribers:
            lines.append(f'recorders at steps {self._recorded_steps or "none yet"} (RECORDER_LAG {RECORDER_LAG})')
        for i, book in self.agents.items():
            lines.append(f'agent {i}: status {book.status}, expected triggers {book.expected_triggers}, commands received {book.commands_received}')
        return '; '.join(lines)

    def _start(self) -> None:
        self._started = time.monotonic()
        if self.progress_period > 0.0:
            with contextlib.suppress(OSError):
                print(f'progress discovery done in {self._started - self._created:.1f} s; t=0 ({self.clock_mode})', flush=True)
        self.graph = self.snapshot_graph()
        self._publish(self._scenario_pub, String(data=dump_scenario_text(self.scenario.replace(horizon=self.horizon))))
        self._sampler.event()
        if self.realtime:
            self.destroy_timer(self._timer)  # samples and the horizon need a finer tick
            self._timer = self.create_timer(min(0.1, self.sample_period or 0.1), self._tick)
            self._epoch = time.time()
            self.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=self._epoch)
            self._due = set(self.agents)
            self._publish(self._step_pub, encode_step(self.step))
            self.publish_samples()
            return
        self._publish_step(Step(index=0, time=0.0, due=tuple(sorted(self.agents))))  # t^i_1 = 0

    # -- wall clock -----------------------------------------------------------------------------

    def _wall_time(self) -> float:
        """Sim time now on the wall clock, never before the world's time nor after the horizon."""
        return min(self.horizon, max(self.world.time, time.time() - self._epoch))

    def _realtime_event(self) -> float:
        """Advance the world to now (an event: a sensing or a command arrives)."""
        t = self._wall_time()
        self._sampler.grid_until(t)
        self.world.advance(t)
        self._sampler.event()
        self.publish_samples()
        self.steps += 1
        return t

    def _realtime_tick(self) -> None:
        t = self._wall_time()
        self._sampler.grid_until(t)
        if t >= self.horizon:
            self.world.advance(self.horizon)
            self._sampler.event()
            self.graph = self.snapshot_graph()
            self.step = Step(index=1, time=self.horizon, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=self._epoch)
            self._publish(self._step_pub, encode_step(self.step))
            self.finished = True
            self._finished_at = time.monotonic()
        self.publish_samples()

    def _sense_realtime(self, agent: int):
        book = self.agents[agent]
        if self.finished:  # asked after the horizon: the final state, not counted
            return encode_sensed_state(self.world.sense(agent, book.neighbours))
        t = self._realtime_event()
        book.trigger_times.append(t)
        book.expected_triggers += 1
        self.sensing_calls += 1
        log = {'version': 1, 'agent': agent, 'step': 0, 'time': t}
        self._publish(self._log_pub, String(data=json.dumps(log, separators=(',', ':'))))
        return encode_sensed_state(self.world.sense(agent, book.neighbours))

    # -- lock-step ------------------------------------------------------------------------------

    def _publish_step(self, step: Step) -> None:
        self.step = step
        self._due = set(step.due)
        for i in step.due:
            self.agents[i].expected_triggers += 1
            self.agents[i].trigger_times.append(step.time)
        self._last_advance = time.monotonic()
        self._publish(self._step_pub, encode_step(step))

    def _on_status(self, msg: Float64MultiArray) -> None:
        try:
            status = decode_status(msg)
        except MessageError as error:  # not from a working agent: the stall timeout covers the rest
            self._reject(STATUS_TOPIC, error.reason, str(error))
            return
        book = self.agents.get(status.agent)
        if book is None:
            raise SimulatorError(f'status from agent {status.agent}, which is not in the scenario {sorted(self.agents)}')
        previous = book.status
        if previous is not None and (
            status.step_index < previous.step_index
            or status.info_sent < previous.info_sent
            or status.info_received < previous.info_received
            or status.triggers < previous.triggers
        ):
            raise SimulatorError(f'agent {status.agent}: status went backwards from {previous} to {status}')
        if status.triggers > book.expected_triggers:
            raise SimulatorError(
                f'agent {status.agent} reports {status.triggers} triggers, but was due {book.expected_triggers} times'
            )
        if previous is None or status.triggers > previous.triggers:
            self._check_planned(status, book)
        book.status = status
        self._advance_if_settled()

    def _check_planned(self, status: Status, book: _AgentBook) -> None:
        """A new trigger: lock-step, it must be the step's time; wall clock, how late it came."""
        if status.triggers == 0:
            return
        t = book.trigger_times[status.triggers - 1]
        if self.realtime:
            book.lateness.append(t - status.last_planned)
        elif status.last_planned != t:
            raise SimulatorError(
                f'agent {status.agent} triggered for t={status.last_planned!r} at step time t={t!r}'
            )

    def _on_command(self, msg, agent: int) -> None:
        book = self.agents[agent]
        if self.finished:
            # The run is over (or stopped): the world no longer moves.  A lock-step trigger whose
            # sensing was answered before a stop still completes (its information is out, and in
            # the bag): counted, its command acting from the last instant on moves nothing.
            due = not self.realtime and agent in self._due and book.sensed_at_step == self.step.index
            if due and book.commands_received < book.expected_triggers:
                book.commands_received += 1
            return
        if self.realtime and self.step is not None:
            if not self.finished:
                control = decode_command(msg, self.scenario.dimension)
                self._realtime_event()  # the command acts from its arrival on
                self.world.set_control(agent, control)
                book.commands_received += 1
            return
        if self.step is None or agent not in self._due or book.commands_received >= book.expected_triggers:
            raise SimulatorError(
                f'agent {agent} sent a command outside its triggering time '
                f'(step {None if self.step is None else self.step.index}, due {sorted(self._due)})'
            )
        # u_i (single) or u^d_i (double): the world closes q' = u^d_i - k3 q_i itself (uxdouble).
        self.world.set_control(agent, decode_command(msg, self.scenario.dimension))
        book.commands_received += 1
        # The tools' samples up to this step go out now, while the agents plan (the simulator
        # would otherwise keep a sensing request of the step waiting).
        self.publish_samples()
        self._advance_if_settled()

    def _on_sense(self, agent: int):
        book = self.agents[agent]
        if self.finished:  # asked after the end: the final state, not counted
            return encode_sensed_state(self.world.sense(agent, book.neighbours))
        if self.realtime and self.step is not None:
            return self._sense_realtime(agent)
        index = -1 if self.step is None else self.step.index
        if self.step is None or agent not in self._due or book.sensed_at_step == index:
            reason = f'agent {agent} is not due to sense at step {index} (due: {sorted(self._due)})'
            self.failure = SimulatorError(reason)
            return sensing_refusal(reason)
        book.sensed_at_step = index
        self.sensing_calls += 1
        sensed = self.world.sense(agent, book.neighbours)
        log = {'version': 1, 'agent': agent, 'step': index, 'time': self.world.time}
        self._publish(self._log_pub, String(data=json.dumps(log, separators=(',', ':'))))
        return encode_sensed_state(sensed)

    def _settled(self) -> bool:
        sent = received = 0
        for i, book in self.agents.items():
            status = book.status
            if status is None or not status.ready or status.triggers != book.expected_triggers:
                return False
            if i in self._due and status.step_index != self.step.index:
                return False
            if status.commands_sent != book.commands_received:
                return False
            sent += status.info_sent
            received += status.info_received
        if received > sent:
            raise SimulatorError(f'agents report {received} messages received but only {sent} sent')
        return sent == received

    def _advance_if_settled(self) -> None:
        if self.realtime or self.step is None or self.finished or not self._settled():
            return
        if self._recorder_behind():
            return  # the recorder's next heartbeat comes back here
        t = self.step.time
        t_next = min(book.status.next_time for book in self.agents.values())
        if t_next < t:
            laggards = [i for i, book in self.agents.items() if book.status.next_time < t]
            raise SimulatorError(f'agents {laggards} ask to trigger at t={t_next!r}, before the current t={t!r}')
        due = tuple(sorted(i for i, book in self.agents.items() if book.status.next_time == t_next))
        if t_next == t:
            # News at this instant put agents on their threshold already: they trigger at this
            # very instant, in a further step (as the in-process engine does).
            twice = [i for i in due if self.agents[i].trigger_times and self.agents[i].trigger_times[-1] == t]
            if twice:
                raise SimulatorError(due_twice(twice[0], self._threshold_model, t))
            self.steps += 1
            self._publish_step(Step(index=self.step.index + 1, time=t, due=due))
            return
        self.steps += 1
        if t_next > self.horizon:
            self._sampler.grid_until(self.horizon)
            self.world.advance(self.horizon)
            self._sampler.event()
            self.graph = self.snapshot_graph()
            self.finished = True
            self._finished_at = time.monotonic()
            self._publish_step(Step(index=self.step.index + 1, time=self.horizon, flags=STEP_FLAG_FINAL))
            self.publish_samples()
            return
        self._sampler.grid_until(t_next)
        self.world.advance(t_next)
        self._sampler.event()
        if (problem := rounding_floor(self._threshold_model, self.world)) is not None:
            raise SimulatorError(problem)
        self._publish_step(Step(index=self.step.index + 1, time=t_next, due=due))

    # -- samples (pure evaluations; they never move the world) --------------------------------

    def _on_sample(self, t: float, x: np.ndarray, q: np.ndarray | None) -> None:
        self._unpublished += 1
        self._check_connectivity(t, x)

    def publish_samples(self) -> None:
        """For tools: the exact state at every sample not yet published; /clock, ground truth and
        the marker view at most every `viz_period` of sim time (a view costs ~1 ms)."""
        count, self._unpublished = self._unpublished, 0
        samples = self._sampler
        last = len(samples.times) - 1
        for k in range(last + 1 - count, last + 1):
            t, x = samples.times[k], samples.positions[k]
            state = WorldState(
                time=t, agent_ids=self.scenario.agent_ids, positions=x, velocities=samples.velocities[k] if self.double else None
            )
            self._publish(self._state_pub, encode_world_state(state))
            if t >= self._next_viz or (self.finished and k == last):
                self._next_viz = t + self.viz_period
                self._publish(self._clock_pub, Clock(clock=ros_time(t)))
                self._publish(self._truth_pub, encode_pose_array(state))
                self._publish(self._markers_pub, self._marker_array.update(self._markers.markers(x), time=t))

    def _check_connectivity(self, t: float, x: np.ndarray) -> None:
        """Theorems 1 (i) and 2 (i): every edge stays shorter than Δ. Stop at the first that does not."""
        rows_i, rows_j = self._edge_rows
        lengths = np.linalg.norm(x[rows_i] - x[rows_j], axis=1)
        worst = int(np.argmax(lengths))
        if lengths[worst] >= self.scenario.delta:
            edge = self.scenario.edges[worst]
            # After t = 0, an agent not ready never heard from some neighbour: its information was
            # lost (it triggers only at events, so nothing repeats it), and the agent waits.
            waiting = [
                i for i, book in self.agents.items()
                if book.status is not None and book.status.step_index >= 0 and not book.status.ready
            ]  # fmt: skip
            hint = (
                f'; agents {waiting} are still waiting for a neighbour\'s triggering information (lost?)'
                if waiting
                else ''
            )
            raise ConnectivityLostError(
                f'edge ({edge.i}, {edge.j}) reached the communication radius at t={t!r}: '
                f'||x_{edge.i} - x_{edge.j}|| = {lengths[worst]:.6g} >= Δ = {self.scenario.delta:g}{hint}',
                time=t,
                edge=(edge.i, edge.j),
                length=float(lengths[worst]),
            )

    # -- results --------------------------------------------------------------------------------

    def snapshot_graph(self) -> dict:
        """Publishers, subscriptions, services and clients of every node in the graph."""
        graph = {}
        for name, namespace in self.get_node_names_and_namespaces():
            key = f'{namespace.rstrip("/")}/{name}'
            graph[key] = {
                'publishers': sorted(t for t, _ in self.get_publisher_names_and_types_by_node(name, namespace)),
                'subscriptions': sorted(t for t, _ in self.get_subscriber_names_and_types_by_node(name, namespace)),
                'services': sorted(s for s, _ in self.get_service_names_and_types_by_node(name, namespace)),
                'clients': sorted(s for s, _ in self.get_client_names_and_types_by_node(name, namespace)),
            }
        return graph

    def record(self):
        """The run as a `RunRecord` (the same schema as the in-process engine's)."""
        return RunRecord(
            scenario=self.scenario,
            horizon=self.horizon,
            mode='distributed',
            # A trigger counts once its command has acted on the world (a run stopped early may
            # have sensed for a trigger that never completed).
            trigger_times={i: list(book.trigger_times[: book.commands_received]) for i, book in self.agents.items()},
            sample_times=np.array(self._sampler.times),
            sample_positions=np.array(self._sampler.positions),
            sample_velocities=np.array(self._sampler.velocities) if self._sampler.velocities else None,
            messages_sent=sum(self._information_sent(i) for i in self.agents),
            sensing_calls=self.sensing_calls,
            wall_time=(self._finished_at or time.monotonic()) - (self._started or self._created),
            extra={
                'clock': self.clock_mode,
                'steps': self.steps,
                'discovery_wall_time': (self._started or self._created) - self._created,
                'reached_time': self.world.time,
                'failure': self.failure_info,
                **self._message_counts(),
                **(self._lateness() if self.realtime else {}),
            },
        )

    def _message_counts(self) -> dict:
        """Rejected messages per reason and agent, and faults injected, from the agents' reports."""
        by_agent = {str(i): dict(book.report.rejected) for i, book in self.agents.items() if book.report and book.report.rejected}
        by_reason: dict[str, int] = {}
        for counts in (*by_agent.values(), self.rejected):
            for reason, n in counts.items():
                by_reason[reason] = by_reason.get(reason, 0) + n
        reports = [book.report for book in self.agents.values() if book.report is not None]
        return {
            'rejected_messages': {
                'total': sum(by_reason.values()),
                'by_reason': dict(sorted(by_reason.items())),
                'by_agent': by_agent,
                'simulator': dict(self.rejected),
            },
            'injected_faults': {
                'dropped': sum(r.dropped for r in reports),
                'delayed': sum(r.delayed for r in reports),
                'by_agent': {str(r.agent): {'dropped': r.dropped, 'delayed': r.delayed} for r in reports if r.dropped or r.delayed},
            },
            'late_information': sum(r.late for r in reports),
            'reports_missing': sorted(i for i, book in self.agents.items() if book.report is None or not book.report.final),
            'published': self._published(),
        }

    def _information_sent(self, agent: int) -> int:
        """Triggering-information messages `agent` published: as its final report counts them, else
        as its latest Status does.  A Status lags when a run stops between an agent's trigger and
        the news of its due neighbours, which it waits for before reporting (one message per
        neighbour fewer than the bag holds, seen after SIGINT); a final report never does."""
        book = self.agents[agent]
        if book.report is not None and book.report.final:
            return sum(book.report.published.get(trigger_info_topic(agent, j), 0) for j in book.neighbours)
        return book.status.info_sent if book.status is not None else 0

    def _published(self) -> dict[str, int]:
        """Messages published per topic by this node and by every agent whose final report came
        (the others' are unknown: reports_missing), from step 0 on: what a recorder must hold."""
        counts = dict(self.published)
        for book in self.agents.values():
            if book.report is not None and book.report.final:
                for topic, n in book.report.published.items():
                    counts[topic] = counts.get(topic, 0) + n
        return dict(sorted(counts.items()))

    def _lateness(self) -> dict:
        """Wall clock: how late triggers came against the times agents had planned them."""
        per_agent = {
            str(i): {'max': max(book.lateness), 'mean': float(np.mean(book.lateness))}
            for i, book in self.agents.items()
            if book.lateness
        }
        return {
            'lateness': per_agent,
            'max_lateness': max((entry['max'] for entry in per_agent.values()), default=0.0),
        }

    def wait_for_delivery(self, executor, timeout_sec: float = 5.0) -> None:
        self.publish_samples()
        self._wait_acknowledged(executor, (self._step_pub, *self._tool_publishers), timeout_sec)

    def _wait_acknowledged(self, executor, publishers, timeout_sec: float) -> None:
        """Wait (bounded) until every reader acknowledged what `publishers` wrote; not for a
        recorder that lost its liveliness meanwhile (a frozen one would hold each wait up to the
        end: what it lacks is counted against the bag after the run)."""
        deadline = time.monotonic() + timeout_sec
        pending = list(publishers)
        while pending and self._recorder_lost is None and time.monotonic() < deadline:
            pending = [pub for pub in pending if not pub.wait_for_all_acked(rclpy.duration.Duration(seconds=0.05))]
            executor.spin_once(timeout_sec=0.0)

    def stop_agents(self, executor) -> None:
        """The run failed: a final Step sends the agents home, with their final reports."""
        if self.step is None or not rclpy.ok():
            return
        flags = STEP_FLAG_FINAL | (STEP_FLAG_REALTIME if self.realtime else 0)
        self.finished = True
        self._publish(self._step_pub, encode_step(Step(index=self.step.index + 1, time=self.world.time, flags=flags, epoch=self._epoch)))
        self.publish_samples()
        self.collect_final_reports(executor)
        # A live agent's final report says it got the final Step; a lost agent is still matched
        # as a reader (until DDS drops it) and would only hold the wait up: tools' topics only.
        publishers = self._tool_publishers
        if not self.final_reports_in():
            publishers = (self._step_pub, *publishers)
        self._wait_acknowledged(executor, publishers, 5.0)  # as at the horizon: the bag ends where the summary does

    def collect_final_reports(self, executor, timeout_sec: float = 3.0) -> None:
        """After the final step: wait (bounded) for every live agent's last report."""
        deadline = time.monotonic() + timeout_sec
        while not self.final_reports_in() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)


def write_results(node: FormationSimulatorNode) -> None:
    """summary.json (through formation_sim.sim.summary) and graph.json into the node's out_dir."""
    out = Path(node.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_summary(node.record(), out)
    write_atomically(out / GRAPH_FILE, json.dumps(node.graph, indent=1, sort_keys=True) + '\n')


def main(args: Sequence[str] | None = None) -> int:
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    status = 0
    with StopSignals() as stop:
        try:
            node = FormationSimulatorNode()
            executor = make_executor(node.executor_kind)
            executor.add_node(node)
            while not node.finished:
                executor.spin_once(timeout_sec=0.1)
                stop.check()
                if node.failure is not None:
                    raise node.failure
            node.collect_final_reports(executor)
            node.wait_for_delivery(executor)
            if node.progress_period > 0.0:
                node._print_progress()
            if node.out_dir:
                try:
                    write_results(node)
                except OSError as error:  # e.g. a full disk: the run itself went well
                    _tell(f'formation_sim: cannot write the results: {error}')
                    status = EXIT_FAILED
        except (KeyboardInterrupt, ExternalShutdownException) as error:
            status = EXIT_INTERRUPTED
            _stop_and_write(node, executor, error)
        except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
            if stop.received.is_set() or not rclpy.ok():  # stopped on purpose while it failed
                status = EXIT_INTERRUPTED
                _stop_and_write(node, executor, KeyboardInterrupt())
                return status
            _tell(f'formation_sim: {error}')
            if not isinstance(error, (AgentLostError, RecorderLostError, ConnectivityLostError)):
                with contextlib.suppress(OSError):
                    traceback.print_exc(file=sys.stderr)
            status = EXIT_AGENT_LOST if isinstance(error, (AgentLostError, RecorderLostError)) else EXIT_FAILED
            _stop_and_write(node, executor, error)
        finally:
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return status


def _stop_and_write(node: FormationSimulatorNode | None, executor, error: BaseException) -> None:
    """A run stopped early after step 0 (a failure, SIGINT/SIGTERM): a final Step at the instant
    it stopped, the samples up to it and the agents' final reports, as at the horizon, so that the
    bag ends where the summary does; then the summary of what happened, and why it stopped."""
    if node is None:
        return
    node.fail(error)
    if executor is not None:
        try:
            node.stop_agents(executor)
        except Exception as problem:  # noqa: BLE001 - the original failure is what matters
            _tell(f'formation_sim: could not stop the agents: {problem}')
    if node.step is None or not node.out_dir:
        return
    try:
        write_results(node)
    except Exception as problem:  # noqa: BLE001 - the original failure is what matters
        _tell(f'formation_sim: could not write the partial results: {problem}')


def _tell(line: str) -> None:
    """A line on stderr (the run's log), if it can still be written (the disk may be full)."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr, flush=True)


if __name__ == '__main__':
    sys.exit(main())
