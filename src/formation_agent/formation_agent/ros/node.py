"""The agent node: a thin ROS 2 shell around one ROS-free ETA-1/ETA-2 agent.

An agent node touches only what a real robot would have:

* its sensing service client `sense` (std_srvs/Trigger, relative: `/agent_<i>/sense`), called
  only at the agent's own triggering times;
* its command publisher: `cmd_vel` (geometry_msgs/Twist, linear = u_i, eq. uxsingle) for single
  integrators, `cmd_accel` (geometry_msgs/Accel, linear = u^d_i) for double integrators.  The
  velocity feedback -k3 q_i(t) of (uxdouble) needs q_i continuously, so the plant closes it
  (here the simulator's world; on a robot its low-level controller);
* one triggering-information topic per edge and direction: it publishes
  `/agent_<i>/trigger_info/to_<j>` and subscribes `/agent_<j>/trigger_info/to_<i>`;
* the lock-step topics `/formation/step` (in) and `/formation/status` (out), see docs/MESSAGES.md.

Two clocks: in lock-step sim time (default) the simulator's Step messages say when it is the
agent's turn, and the run reproduces the in-process engine bit for bit.  In wall-clock mode
(Step 0 flagged realtime) the agent keeps its own timer on wall time since the Step's epoch, as a
robot would, and triggers at once when its triggering time has already passed.

It never sees ground truth or another agent's sensing. All algorithmic decisions are taken by the
core object (`formation_agent.core.eta`); this module only moves messages.

Robustness (README, "Reliability"): a triggering-information or Step message that breaks its layout
or cannot be true (wrong sender for its topic, another receiver, the wrong dimension, time going
backwards, a duplicate) is rejected before the core sees it, logged, and counted per reason in the
agent's reports on `/formation/agent_report`; the node keeps running.  Every protocol topic has a
DDS liveliness lease (`LIVELINESS_LEASE`): an agent whose simulator dies leaves with exit status 3
instead of waiting forever.  For experiments, `inject_loss` / `inject_delay_ms` drop or delay
triggering information on arrival (a test facility, seeded by `inject_seed`).
"""

from __future__ import annotations

import argparse
import contextlib
import heapq
import math
import random
import sys
import time
import traceback
from collections.abc import Sequence

import rclpy
from geometry_msgs.msg import Accel, Twist
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from formation_agent.core.eta import ALGORITHM_GAINS, make_agent
from formation_msgs_py.codec import (
    MessageError,
    decode_sensed_state,
    decode_step,
    decode_trigger_info,
    encode_acceleration_command,
    encode_agent_report,
    encode_status,
    encode_trigger_info,
    encode_velocity_command,
)
from formation_msgs_py.lockstep import (
    DISCOVERY_STEP,
    REJECT_DIMENSION,
    REJECT_DUPLICATE,
    REJECT_RECEIVER,
    REJECT_SENDER,
    REJECT_TIME_BACKWARDS,
    AgentReport,
    Status,
    Step,
)
from formation_msgs_py.topics import (
    REPORT_TOPIC,
    STATUS_TOPIC,
    STEP_TOPIC,
    agent_namespace,
    trigger_info_topic,
)
from formation_msgs_py.qos import LIVELINESS_LEASE, LOST_GRACE, PROTOCOL_QOS
from formation_msgs_py.types import TriggerInfo
from formation_agent.ros.process import EXECUTORS, EXIT_PEER_LOST, StopSignals, make_executor

NODE_NAME = 'formation_agent'


class AgentNodeError(ValueError):
    """Bad agent parameters or a violation of the lock-step protocol seen by an agent."""


class PeerLostError(RuntimeError):
    """A peer the agent depends on (the simulator) stopped showing signs of life."""


class FaultInjection:
    """Test facility: drop or delay triggering information on arrival, as a bad network would.

    Each message is dropped with probability `loss`; a kept one is handed on after `delay_ms` plus
    a uniform extra in [0, `jitter_ms`].  Messages of one edge stay in order (a reliable DDS writer
    never reorders).  The random stream is seeded per agent, so a run's drop pattern depends only
    on (seed, agent, arrival order).
    """

    def __init__(self, *, agent_id: int, loss: float, delay_ms: float, jitter_ms: float, seed: int) -> None:
        if not (math.isfinite(loss) and 0.0 <= loss <= 1.0):
            raise AgentNodeError(f'agent {agent_id}: inject_loss must be a probability in [0, 1], got {loss!r}')
        for name, value in (('inject_delay_ms', delay_ms), ('inject_jitter_ms', jitter_ms)):
            if not (math.isfinite(value) and value >= 0.0):
                raise AgentNodeError(f'agent {agent_id}: {name} must be a finite number >= 0, got {value!r}')
        self.loss = loss
        self.delay = delay_ms / 1000.0
        self.jitter = jitter_ms / 1000.0
        self._random = random.Random(f'formation-inject:{seed}:{agent_id}')
        self._last_due: dict[int, float] = {}

    @property
    def active(self) -> bool:
        return self.loss > 0.0 or self.delay > 0.0 or self.jitter > 0.0

    def drop(self) -> bool:
        return self.loss > 0.0 and self._random.random() < self.loss

    def due(self, sender: int, now: float) -> float:
        """When a message of edge sender -> this agent arriving at `now` is handed on."""
        extra = self._random.uniform(0.0, self.jitter) if self.jitter > 0.0 else 0.0
        due = max(now + self.delay + extra, self._last_due.get(sender, -math.inf))
        self._last_due[sender] = due
        return due


class FormationAgentNode(Node):
    """One agent: senses, commands and broadcasts at its triggering times, listens to neighbours."""

    def __init__(
        self,
        *,
        namespace: str | None = None,
        start_parameter_services: bool = True,
        parameter_overrides: list[Parameter] | None = None,
        core=None,
        context=None,
    ) -> None:
        """Parameters come from ROS (command line, params file) or `parameter_overrides`.

        `core` replaces the ETA agent built from the parameters (any object with the
        trigger/receive/next_trigger_time/ready interface of `formation_agent.core.eta`).
        """
        super().__init__(
            NODE_NAME,
            namespace=namespace,
            start_parameter_services=start_parameter_services,
            parameter_overrides=parameter_overrides or [],
            context=context,
        )
        self._read_parameters()
        self.core = core if core is not None else make_agent(
            agent_id=self.agent_id,
            neighbours=self.neighbours,
            delta=self.delta,
            algorithm=self.algorithm,
            gains=self.gains,
        )
        double = self.algorithm == 'eta2'
        self._encode_command = encode_acceleration_command if double else encode_velocity_command
        self._command_pub = self.create_publisher(
            Accel if double else Twist, 'cmd_accel' if double else 'cmd_vel', PROTOCOL_QOS
        )
        self._sense = self.create_client(Trigger, 'sense')
        self._info_pubs = {
            j: self.create_publisher(Float64MultiArray, f'trigger_info/to_{j}', PROTOCOL_QOS)
            for j in self.neighbour_ids
        }
        self._info_subs = [
            self.create_subscription(
                Float64MultiArray,
                trigger_info_topic(j, self.agent_id),
                lambda msg, sender=j: self._on_arrival(msg, sender),
                PROTOCOL_QOS,
            )
            for j in self.neighbour_ids
        ]
        self._status_pub = self.create_publisher(Float64MultiArray, STATUS_TOPIC, PROTOCOL_QOS)
        self._report_pub = self.create_publisher(String, REPORT_TOPIC, PROTOCOL_QOS)
        self._step_sub = self.create_subscription(
            Float64MultiArray,
            STEP_TOPIC,
            self._on_step,
            PROTOCOL_QOS,
            event_callbacks=SubscriptionEventCallbacks(liveliness=self._on_simulator_liveliness),
        )
        self.step: Step | None = None
        self.finished = False
        self.info_sent = 0
        self.info_received = 0
        self.commands_sent = 0
        self.triggers = 0
        self.trigger_times: list[float] = []
        self._sensing = False  # a sensing request is in flight
        self._held: list[TriggerInfo] = []  # information stamped at a time this agent is due
        self._dirty = False  # knowledge changed since the last Status
        self._due_neighbours: tuple[int, ...] = ()  # lock-step: neighbours due at the current step
        self._next_time = 0.0  # t^i_1 = 0
        self._last_trigger = -math.inf
        self._planned = 0.0  # the time the trigger in progress (or the last one) was planned for
        self._epoch: float | None = None  # wall-clock mode: Unix time of t = 0
        self._sensed = None  # the last SensedState, to re-base late information
        self._due_timer = None
        self.late_infos = 0
        self.failure: Exception | None = None
        # Bad messages and injected faults, reported on REPORT_TOPIC.
        self.rejected: dict[str, int] = {}
        self.dropped = 0
        self.delayed = 0
        self._last_stamp: dict[int, float] = {}  # sender -> stamp of its last accepted information
        self._report_dirty = False
        self._final_report_sent = False
        self._report_timer = self.create_timer(0.5, self._publish_report_if_dirty)
        self._delay_line: list[tuple[float, int, int, Float64MultiArray]] = []  # (due, seq, sender, msg)
        self._delay_seq = 0
        self._delay_timer = None
        self._simulator_seen = False
        self._simulator_lost_at: float | None = None
        self._simulator_lease_expired = False
        self._discovery = self.create_timer(0.1, self._announce)

    # -- parameters -------------------------------------------------------------------------

    def _param(self, name: str, kind: Parameter.Type):
        if not self.has_parameter(name):
            self.declare_parameter(name, kind)
        try:
            parameter = self.get_parameter(name)
        except ParameterUninitializedException:
            parameter = None
        if parameter is None or parameter.type_ == Parameter.Type.NOT_SET:
            raise AgentNodeError(f'{self.get_fully_qualified_name()}: parameter {name!r} ({kind.name}) is required')
        return parameter.value

    def _read_parameters(self) -> None:
        name = self.get_fully_qualified_name()
        self.agent_id = int(self._param('agent_id', Parameter.Type.INTEGER))
        self.algorithm = self._param('algorithm', Parameter.Type.STRING)
        if self.algorithm not in ALGORITHM_GAINS:
            raise AgentNodeError(f'{name}: algorithm must be one of {sorted(ALGORITHM_GAINS)}, got {self.algorithm!r}')
        self.dimension = int(self._param('dimension', Parameter.Type.INTEGER))
        if not 1 <= self.dimension <= 3:
            raise AgentNodeError(
                f'{name}: dimension must be 1, 2 or 3 (commands travel as geometry_msgs), got {self.dimension}'
            )
        self.neighbour_ids = tuple(int(j) for j in self._param('neighbour_ids', Parameter.Type.INTEGER_ARRAY))
        offsets = [float(v) for v in self._param('neighbour_offsets', Parameter.Type.DOUBLE_ARRAY)]
        p = self.dimension
        if len(offsets) != p * len(self.neighbour_ids):
            raise AgentNodeError(
                f'{name}: neighbour_offsets must hold dimension * len(neighbour_ids) = '
                f'{p} * {len(self.neighbour_ids)} values (d_ij per neighbour), got {len(offsets)}'
            )
        if len(set(self.neighbour_ids)) != len(self.neighbour_ids):
            raise AgentNodeError(f'{name}: neighbour_ids repeat an id: {list(self.neighbour_ids)}')
        self.neighbours = {j: tuple(offsets[k * p : (k + 1) * p]) for k, j in enumerate(self.neighbour_ids)}
        self.delta = float(self._param('delta', Parameter.Type.DOUBLE))
        self.horizon = float(self._param('horizon', Parameter.Type.DOUBLE))
        if not (math.isfinite(self.horizon) and self.horizon > 0.0):
            raise AgentNodeError(f'{name}: horizon must be a finite number > 0, got {self.horizon!r}')
        self.gains = {
            gain: float(self._param(gain, Parameter.Type.DOUBLE)) for gain in ALGORITHM_GAINS[self.algorithm]
        }
        # Listeners besides the protocol peers (a recorder) that must be matched before step 0.
        self.extra_subscribers = int(self.declare_parameter('extra_subscribers', 0).value)
        # Test facility (README, "Reliability"): faults injected on arriving triggering information.
        self.injection = FaultInjection(
            agent_id=self.agent_id,
            loss=float(self.declare_parameter('inject_loss', 0.0).value),
            delay_ms=float(self.declare_parameter('inject_delay_ms', 0.0).value),
            jitter_ms=float(self.declare_parameter('inject_jitter_ms', 0.0).value),
            seed=int(self.declare_parameter('inject_seed', 0).value),
        )
        expected = agent_namespace(self.agent_id)
        if self.get_namespace() != expected:
            # Its relative names (sense, cmd_vel, trigger_info/to_<j>) must resolve under it.
            raise AgentNodeError(
                f'{name}: agent {self.agent_id} must run in namespace {expected} '
                f'(e.g. --ros-args -r __ns:={expected}, or formation_agent --agents {self.agent_id})'
            )

    # -- discovery ------------------------------------------------------------------------------

    def connected(self) -> bool:
        """Every endpoint this agent needs is matched with its peer (and the extra listeners)."""
        listeners = 1 + self.extra_subscribers
        return (
            all(pub.get_subscription_count() >= listeners for pub in self._info_pubs.values())
            and all(sub.get_publisher_count() >= 1 for sub in self._info_subs)
            and self._sense.service_is_ready()
            and self._command_pub.get_subscription_count() >= listeners
            and self._status_pub.get_subscription_count() >= listeners
            and self._report_pub.get_subscription_count() >= listeners
            and self._step_sub.get_publisher_count() >= 1
        )

    def _announce(self) -> None:
        if self.step is None and self._status_pub.get_subscription_count() >= 1:
            self._publish_status(step_index=DISCOVERY_STEP, ready=self.connected())

    # -- lock-step ------------------------------------------------------------------------------

    def _on_step(self, msg: Float64MultiArray) -> None:
        try:
            step = decode_step(msg)
        except MessageError as error:
            self._reject(STEP_TOPIC, error.reason, str(error))
            return
        if self.step is not None and step.index <= self.step.index:
            return  # a repeat of a step already handled
        if self._discovery is not None:
            self.destroy_timer(self._discovery)
            self._discovery = None
        self.step = step
        if step.final:
            self.finished = True
            self._cancel_due_timer()
            self._publish_report(final=True)
            return
        if step.realtime:
            self._epoch = step.epoch
            self._sense_now()  # t^i_1 = 0
            return
        if self.injection.loss > 0.0:
            # Lock-step counts every message: one dropped on purpose would stall the run.
            raise AgentNodeError(
                f'agent {self.agent_id}: inject_loss={self.injection.loss!r} needs wall-clock mode '
                '(lock-step waits for every message sent; a dropped one stalls the run)'
            )
        if step.time > self._next_time:
            raise AgentNodeError(
                f'agent {self.agent_id}: step {step.index} at t={step.time!r} skips its triggering time '
                f'{self._next_time!r}'
            )
        due = step.time == self._next_time  # the exact float this agent reported
        if due != (self.agent_id in step.due):
            raise AgentNodeError(
                f'agent {self.agent_id}: step {step.index} at t={step.time!r} lists due agents {list(step.due)}, '
                f'but this agent reported its next triggering time {self._next_time!r}'
            )
        self._due_neighbours = tuple(j for j in step.due if j in self._info_pubs)
        if due:
            self._sense_now()
        else:
            self._report_if_complete()

    def _sense_now(self) -> None:
        """Ask for this agent's sensing; the trigger completes when the answer arrives."""
        self._cancel_due_timer()
        if self._sensing or self.finished:
            return
        self._sensing = True
        self._planned = self._next_time
        self._sense.call_async(Trigger.Request()).add_done_callback(self._on_sensed)

    def _cancel_due_timer(self) -> None:
        if self._due_timer is not None:
            self.destroy_timer(self._due_timer)
            self._due_timer = None

    def _on_sensed(self, future) -> None:
        # rclpy runs a client future's done callbacks outside the executor and only warns about
        # what they raise: keep the error for the spin loop to raise (see `check`).
        try:
            self._trigger(future)
        except Exception as error:  # noqa: BLE001 - re-raised by check()
            self.failure = error

    def check(self) -> None:
        """Raise what went wrong outside the executor's reach."""
        if self.failure is not None:
            raise self.failure
        lost = self._simulator_lost_at
        # During discovery a lease may expire on a machine busy starting many processes: keep
        # waiting for step 0 (a simulator that left deletes its writer, which does count).
        waiting = self.step is None and self._simulator_lease_expired
        if lost is not None and not self.finished and not waiting and time.monotonic() - lost > LOST_GRACE:
            where = 'during discovery' if self.step is None else f'after step {self.step.index} (t={self.step.time!r})'
            how = f'no sign of life for {LIVELINESS_LEASE} s (liveliness lease)' if self._simulator_lease_expired else 'it left the graph'
            raise PeerLostError(f'agent {self.agent_id}: the simulator (writer of {STEP_TOPIC}) is lost {where}: {how}')

    def _on_simulator_liveliness(self, info) -> None:
        if info.alive_count > 0:
            self._simulator_seen = True
            self._simulator_lost_at = None
        elif self._simulator_seen and self._simulator_lost_at is None:
            self._simulator_lost_at = time.monotonic()
            self._simulator_lease_expired = info.not_alive_count_change > 0  # else: writer deleted

    def _trigger(self, future) -> None:
        if self.finished:  # the final step came while sensing (the horizon, or a failed run)
            self._sensing = False
            return
        sensed = decode_sensed_state(future.result())
        # Lock-step: the step's exact time; wall clock: when the world was actually sensed.
        t = self.step.time if self._epoch is None else sensed.stamp
        if sensed.agent != self.agent_id or sensed.stamp != t:
            raise AgentNodeError(
                f'agent {self.agent_id} asked to sense at t={t!r} and got the state of agent '
                f'{sensed.agent} at t={sensed.stamp!r}'
            )
        out = self.core.trigger(t, sensed)
        self._sensing = False
        self._sensed = sensed
        self._last_trigger = t
        self.triggers += 1
        self.trigger_times.append(t)
        self._command_pub.publish(self._encode_command(tuple(float(v) for v in out.control)))
        self.commands_sent += 1
        for info in out.infos:
            self._info_pubs[info.receiver].publish(encode_trigger_info(info))
            self.info_sent += 1
        held, self._held = self._held, []
        for info in held:
            self._receive(info)
        self._dirty = True
        if self._epoch is None:
            self._report_if_complete()
        else:
            self._replan()

    # -- arriving triggering information ---------------------------------------------------------

    def _on_arrival(self, msg: Float64MultiArray, sender: int) -> None:
        """The network's side: injected faults act here, before the message is even read."""
        if not self.injection.active:
            self._on_info(msg, sender)
            return
        if self.injection.drop():
            self.dropped += 1
            self._report_dirty = True
            return
        if self.injection.delay == 0.0 and self.injection.jitter == 0.0:
            self._on_info(msg, sender)
            return
        now = time.monotonic()
        due = self.injection.due(sender, now)
        self._delay_seq += 1
        heapq.heappush(self._delay_line, (due, self._delay_seq, sender, msg))
        self._arm_delay_timer(now)

    def _arm_delay_timer(self, now: float) -> None:
        if self._delay_timer is not None:
            self.destroy_timer(self._delay_timer)
            self._delay_timer = None
        if self._delay_line:
            self._delay_timer = self.create_timer(max(self._delay_line[0][0] - now, 0.0), self._release_delayed)

    def _release_delayed(self) -> None:
        now = time.monotonic()
        while self._delay_line and self._delay_line[0][0] <= now:
            _, _, sender, msg = heapq.heappop(self._delay_line)
            self.delayed += 1
            self._report_dirty = True
            if not self.finished:
                self._on_info(msg, sender)
        self._arm_delay_timer(now)

    def _reject(self, topic: str, reason: str, detail: str) -> None:
        """Count and log a message that cannot be used; the node carries on without it."""
        count = self.rejected.get(reason, 0) + 1
        self.rejected[reason] = count
        self._report_dirty = True
        if count <= 3 or count % 100 == 0:  # the first few of each kind, then a trickle
            self.get_logger().warning(f'rejected a message on {topic} ({reason}, {count} so far): {detail}')

    def _implausible(self, info: TriggerInfo, sender: int) -> tuple[str, str] | None:
        """Why `info`, well formed, cannot be the next information of `sender` for this agent."""
        if info.sender != sender:
            return REJECT_SENDER, f'information from agent {info.sender} on the topic of agent {sender}'
        if info.receiver != self.agent_id:
            return REJECT_RECEIVER, f'information for agent {info.receiver}, not {self.agent_id}'
        kind_ok = (info.rel_velocity is None) == (self.algorithm == 'eta1')
        if len(info.control) != self.dimension or not kind_ok:
            return REJECT_DIMENSION, (
                f'{"ETA-1" if info.rel_velocity is None else "ETA-2"} information of dimension '
                f'{len(info.control)}; this agent runs {self.algorithm.upper()} with p = {self.dimension}'
            )
        last = self._last_stamp.get(sender)
        if info.stamp < 0.0 or (last is not None and info.stamp < last):
            previous = 't = 0' if last is None else f'its previous one at t={last!r}'
            return REJECT_TIME_BACKWARDS, f'agent {sender} stamped t={info.stamp!r}, before {previous}'
        if info.stamp == last:
            return REJECT_DUPLICATE, f'agent {sender} already sent information stamped t={last!r}'
        return None

    def _on_info(self, msg: Float64MultiArray, sender: int) -> None:
        topic = trigger_info_topic(sender, self.agent_id)
        try:
            info = decode_trigger_info(msg)
        except MessageError as error:
            self._reject(topic, error.reason, str(error))
            return
        if (problem := self._implausible(info, sender)) is not None:
            self._reject(topic, *problem)
            return
        self._last_stamp[sender] = info.stamp
        due = self._epoch is None and self._next_time > self._last_trigger  # not yet triggered at
        if self._sensing or (due and info.stamp >= self._next_time):
            # This agent triggers at that instant itself: its own sensing comes first, then the
            # neighbours' information (DESIGN.md, "Time and exactness"); and its status must not
            # report the step before it has triggered.
            self._held.append(info)
            return
        self._receive(info)
        self._dirty = True
        if self._epoch is None:
            self._report_if_complete()
        else:
            self._replan()  # as on a robot: every piece of news re-plans at once

    def _receive(self, info: TriggerInfo) -> None:
        if info.stamp < self._last_trigger:  # only on the wall clock: it crossed our trigger
            info = self._rebased(info)
            self.late_infos += 1
            self._report_dirty = True
        self.core.receive(info)
        self.info_received += 1

    def _rebased(self, info: TriggerInfo) -> TriggerInfo:
        """Late information re-anchored at this agent's own last trigger.

        The neighbour's new input has acted since info.stamp, but what it did is already in what
        this agent sensed at its trigger (exact); from then on both inputs are constant. So the
        edge is anchored at the trigger with the sensed relative state and the neighbour's new
        input, which is exactly what a prediction from that instant needs.
        """
        sensed = self._sensed
        j = info.sender
        rel_velocity = None
        if sensed.rel_velocities is not None:
            rel_velocity = tuple(-v for v in sensed.rel_velocities[j])
        return TriggerInfo(
            sender=j,
            receiver=self.agent_id,
            stamp=self._last_trigger,
            control=info.control,
            rel_position=tuple(-v for v in sensed.rel_positions[j]),  # x_j - x_i, exact negation
            rel_velocity=rel_velocity,
        )

    def _report_if_complete(self) -> None:
        """Lock-step: one Status per step, once the agent has all it will get at the step.

        That is its own trigger if it is due, and the information of every neighbour the Step
        lists as due (which may arrive before the Step itself).  Information stamped at a later
        step waits for that Step.  An agent whose knowledge did not change stays silent: its
        last Status still holds.
        """
        step = self.step
        if step is None or self.finished or self._sensing or not self._dirty:
            return
        if step.time == self._next_time and self._last_trigger < step.time:
            return  # due: its own trigger comes first
        stamps = self._last_stamp
        if any(stamps.get(j) != step.time for j in self._due_neighbours):
            return
        if any(stamp > step.time for stamp in stamps.values()):
            return
        self._publish_status(step_index=step.index, ready=True)

    def _replan(self) -> None:
        """Wall clock: report the next triggering time and set a timer for it (or trigger now)."""
        self._publish_status(step_index=self.step.index, ready=True)
        self._cancel_due_timer()
        if not self.core.ready or self.finished or math.isinf(self._next_time):
            return
        delay = self._epoch + self._next_time - time.time()
        if delay <= 0.0:
            self._sense_now()  # already due: trigger at once
        else:
            self._due_timer = self.create_timer(delay, self._sense_now)

    def _publish_status(self, *, step_index: int, ready: bool) -> None:
        self._dirty = False
        if step_index != DISCOVERY_STEP:
            # A next time is only defined once the agent has triggered and heard every neighbour.
            ready = bool(self.core.ready)
            if ready:
                self._next_time = float(self.core.next_trigger_time(self.horizon))
        status = Status(
            agent=self.agent_id,
            step_index=step_index,
            next_time=self._next_time if ready or step_index == DISCOVERY_STEP else math.inf,
            info_sent=self.info_sent,
            info_received=self.info_received,
            commands_sent=self.commands_sent,
            triggers=self.triggers,
            ready=ready,
            last_planned=self._planned,
        )
        self._status_pub.publish(encode_status(status))

    # -- reports ----------------------------------------------------------------------------------

    def report(self, *, final: bool = False) -> AgentReport:
        return AgentReport(
            agent=self.agent_id,
            final=final,
            rejected=dict(self.rejected),
            dropped=self.dropped,
            delayed=self.delayed,
            late=self.late_infos,
        )

    def _publish_report(self, *, final: bool = False) -> None:
        self._report_dirty = False
        self._final_report_sent = final
        self._report_pub.publish(encode_agent_report(self.report(final=final)))

    def leave(self) -> None:
        """On the way out, whatever the reason: the final report, if not yet sent, and its delivery."""
        if not self._final_report_sent and rclpy.ok(context=self.context):
            self._publish_report(final=True)
            self._report_pub.wait_for_all_acked(Duration(seconds=1.0))

    def _publish_report_if_dirty(self) -> None:
        if self._report_dirty and not self.finished:
            self._publish_report()

    def wait_for_delivery(self, timeout_sec: float = 1.0) -> None:
        """Let reliable writers hand over what they still hold before the node goes away."""
        for pub in (self._status_pub, self._report_pub, self._command_pub, *self._info_pubs.values()):
            pub.wait_for_all_acked(Duration(seconds=timeout_sec))


# -- entry point ------------------------------------------------------------------------------

def _parse(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='formation_agent',
        description='Run formation agent nodes (one per agent; several share an executor with --agents).',
        epilog='Parameters come from ROS arguments, e.g. --ros-args --params-file agents.yaml, '
        'keyed by node name /agent_<i>/formation_agent.',
    )
    parser.add_argument(
        '--executor',
        choices=EXECUTORS,
        default='events',
        help='rclpy executor: events (rclpy.experimental.EventsExecutor, default) or single (SingleThreadedExecutor)',
    )
    parser.add_argument(
        '--agents',
        help='comma-separated agent ids to run in this process, each in namespace /agent_<i> '
        '(default: one node whose namespace and parameters come from the ROS arguments)',
    )
    return parser.parse_args(list(argv))


def main(args: Sequence[str] | None = None) -> int:
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[FormationAgentNode] = []
    status = 0
    with StopSignals() as stop:
        try:
            options = _parse(rclpy.utilities.remove_ros_args(args if args is not None else sys.argv)[1:])
            if options.agents:
                ids = [int(text) for text in options.agents.split(',') if text.strip()]
                packed = len(ids) > 1
                for agent_id in ids:
                    nodes.append(
                        FormationAgentNode(
                            namespace=agent_namespace(agent_id),
                            start_parameter_services=not packed,
                            parameter_overrides=[Parameter('agent_id', Parameter.Type.INTEGER, agent_id)],
                        )
                    )
            else:
                nodes.append(FormationAgentNode())
            executor = make_executor(options.executor)
            for node in nodes:
                executor.add_node(node)
            while not all(node.finished for node in nodes):
                executor.spin_once(timeout_sec=0.1)
                stop.check()
                for node in nodes:
                    node.check()
            for node in nodes:
                node.wait_for_delivery()
        except (KeyboardInterrupt, ExternalShutdownException):
            status = 130
        except PeerLostError as error:
            print(f'formation_agent: {error}', file=sys.stderr, flush=True)
            status = EXIT_PEER_LOST
        except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
            if stop.received.is_set() or not rclpy.ok():  # stopped on purpose while it failed
                return 130
            print(f'formation_agent: {error}', file=sys.stderr, flush=True)
            traceback.print_exc(file=sys.stderr)
            status = 1
        finally:
            for node in nodes:
                with contextlib.suppress(Exception):  # a context shut down by a signal cannot publish
                    node.leave()
                node.destroy_node()
            rclpy.try_shutdown()
    return status


if __name__ == '__main__':
    sys.exit(main())
