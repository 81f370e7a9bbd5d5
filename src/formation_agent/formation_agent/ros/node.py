"""The agent node: a thin ROS 2 shell around one ROS-free ETA-1/ETA-2 agent.

An agent node touches only what a real robot would have:

* where it senses, at its own triggering times only (`sensing`): the simulator's sensing service,
  or the latest poses of its robot and its neighbours' (`formation_agent.ros.sensing`);
* where its commands go (`robot`): the simulator's plant (`cmd_vel` u_i / `cmd_accel` u^d_i), or
  a robot's velocity command, world-frame or (v, ω) (`formation_agent.ros.commands`);
* one triggering-information topic per edge and direction: it publishes
  `/agent_<i>/trigger_info/to_<j>` and subscribes `/agent_<j>/trigger_info/to_<i>`;
* the lock-step topics `/formation/step` (in) and `/formation/status` (out), and its report on
  `/formation/agent_report` (docs/MESSAGES.md).

This module holds the protocol.  Two clocks: in lock-step sim time (default) the simulator's Step
messages say when it is the agent's turn, and the run reproduces the in-process engine bit for
bit.  In wall-clock mode (Step 0 flagged realtime; robots always) the agent keeps its own timer on
wall time since the Step's epoch, as a robot would, and triggers at once when its triggering time
has already passed.  All algorithmic decisions are taken by the core object
(`formation_agent.core.eta`).

Every way out sends the zero command first (`leave`): the final Step, a lost simulator or
coordinator (DDS liveliness, exit status 3), SIGINT/SIGTERM (130), a stale pose or any other
error (1).  Bad messages are refused and counted (`formation_agent.ros.inbox`); faults can be
injected for tests (`formation_agent.ros.faults`); parameters: `formation_agent.ros.config`.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterator

import rclpy
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, String

from formation_agent.core.crossing import PRECISION_HINT, CrossingError
from formation_agent.core.eta import make_agent
from formation_agent.ros.commands import PlantOutput, RobotOutput
from formation_agent.ros.config import read_config
from formation_agent.ros.faults import FaultInjection, InjectedFaults
from formation_agent.ros.inbox import Rejections, implausible
from formation_agent.ros.sensing import PoseSensing, ServiceSensing
from formation_msgs_py.codec import (
    MessageError,
    decode_step,
    decode_trigger_info,
    encode_agent_report,
    encode_status,
    encode_trigger_info,
)
from formation_msgs_py.lockstep import DISCOVERY_STEP, AgentReport, Status, Step
from formation_msgs_py.qos import KEEPER_LEASE_GRACE, LIVELINESS_LEASE, LOST_GRACE, PROTOCOL_QOS, READER_QOS
from formation_msgs_py.topics import REPORT_TOPIC, STATUS_TOPIC, STEP_TOPIC, trigger_info_topic
from formation_msgs_py.types import TriggerInfo

NODE_NAME = 'formation_agent'
DELIVERY_TIMEOUT = 4.0
"""Seconds a leaving node waits, at most, for its readers to acknowledge what it published (its
last messages too: zero command, report): Fast DDS repairs a message lost on the way at the
writer's next heartbeat (every 3 s by default, 0.1 s in a run: `formation_sim.runtime`'s
fastdds_profile.xml), and a recorder must get it before the writer is gone."""

DISCOVERY_CHECK = 0.1
"""Seconds between an agent's looks at its endpoints during discovery: it announces its Status
(step −1) when its readiness changes, not every look (reliable, transient local: a simulator that
matches later still gets the latest), and once ready again every DISCOVERY_REANNOUNCE seconds
until step 0: a sign of life for a simulator that saw its liveliness lease lapse meanwhile (a
machine starting 1000 agents is slow to assert it)."""

DISCOVERY_REANNOUNCE = 1.0

DISCOVERY_LOG_AFTER = 2.0
DISCOVERY_LOG_PERIOD = 5.0
"""An agent not yet connected says what it waits for after DISCOVERY_LOG_AFTER seconds, then
every DISCOVERY_LOG_PERIOD seconds."""


class AgentNodeError(ValueError):
    """A violation of the lock-step protocol seen by an agent."""


class PeerLostError(RuntimeError):
    """A peer the agent depends on (the simulator) stopped showing signs of life."""


class PredictionError(RuntimeError):
    """The agent's certified search cannot resolve its next triggering time in double precision."""


class FormationAgentNode(Node):
    """One agent: senses, commands and broadcasts at its triggering times, listens to neighbours."""

    def __init__(
        self,
        *,
        namespace: str | None = None,
        start_parameter_services: bool = True,
        enable_rosout: bool = True,
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
            enable_rosout=enable_rosout,
            parameter_overrides=parameter_overrides or [],
            context=context,
        )
        config = self.config = read_config(self)
        self.agent_id = config.agent_id
        self.algorithm = config.algorithm
        self.dimension = config.dimension
        self.neighbour_ids = config.neighbour_ids
        self.horizon = config.horizon
        self.core = core if core is not None else make_agent(
            agent_id=config.agent_id, neighbours=config.neighbours, delta=config.delta, algorithm=config.algorithm,
            gains=config.gains,
        )  # fmt: skip
        self._report_dirty = False
        self.reject = Rejections(self.get_logger(), changed=self._report_changed)
        injection = FaultInjection(
            agent_id=config.agent_id, loss=config.inject_loss, delay_ms=config.inject_delay_ms,
            jitter_ms=config.inject_jitter_ms, seed=config.inject_seed,
        )  # fmt: skip
        self.faults = InjectedFaults(self, injection, hand_on=self._on_info, changed=self._report_changed)
        if config.sensing == 'poses':
            self.sensing = PoseSensing(self, config, reject=self.reject)
        else:
            self.sensing = ServiceSensing(self)
        if config.robot == 'none':
            self.output = PlantOutput(self, config)
        else:
            self.output = RobotOutput(self, config, self.sensing, on_failure=self._fail)
            if not config.double and math.isfinite(config.limits.linear_acceleration):
                self.get_logger().warning(
                    'max_linear_acceleration applies to ETA-2 only (ETA-1 velocity commands change stepwise at triggers): ignored'
                )
        self._info_pubs = {
            j: self.create_publisher(Float64MultiArray, f'trigger_info/to_{j}', PROTOCOL_QOS) for j in self.neighbour_ids
        }
        self._info_subs = [
            self.create_subscription(
                Float64MultiArray,
                trigger_info_topic(j, self.agent_id),
                lambda msg, sender=j: self.faults.arrive(msg, sender),
                READER_QOS,
            )
            for j in self.neighbour_ids
        ]
        self._status_pub = self.create_publisher(Float64MultiArray, STATUS_TOPIC, PROTOCOL_QOS)
        self._report_pub = self.create_publisher(String, REPORT_TOPIC, PROTOCOL_QOS)
        self._step_sub = self.create_subscription(
            Float64MultiArray,
            STEP_TOPIC,
            self._on_step,
            READER_QOS,
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
        self._last_stamp: dict[int, float] = {}  # sender -> stamp of its last accepted information
        self._final_report_sent = False
        self.published: dict[str, int] = {}  # topic -> messages published from step 0 on (commands: self.output)
        self._report_timer = self.create_timer(0.5, self._publish_report_if_dirty)
        self._simulator_seen = False
        self._simulator_lost_at: float | None = None
        self._simulator_lease_expired = False
        self._created = time.monotonic()
        self._announced: bool | None = None  # the readiness of the last discovery Status
        self._next_announcement = 0.0
        self._next_discovery_log = self._created + DISCOVERY_LOG_AFTER
        self._discovery = self.create_timer(DISCOVERY_CHECK, self._announce)

    def destroy_node(self) -> None:
        self.sensing.close()  # pose sensing's readers live on a node of their own
        super().destroy_node()

    @property
    def rejected(self) -> dict[str, int]:
        return self.reject.counts

    def _fail(self, error: Exception) -> None:
        """Keep the first error raised outside the executor's reach for `check` to raise."""
        if self.failure is None:
            self.failure = error

    # -- discovery ------------------------------------------------------------------------------

    def connected(self) -> bool:
        """Every endpoint this agent needs is matched with its peer (and the extra listeners)."""
        return next(self._gaps(), None) is None

    def discovery_gaps(self) -> list[str]:
        """What discovery still waits for, one phrase per endpoint (empty: connected)."""
        return list(self._gaps())

    def _gaps(self) -> Iterator[str]:
        """What discovery still waits for, one at a time (`connected` stops at the first: with
        many agents in one process, every look at a match count costs)."""
        extra = self.config.extra_subscribers
        listeners = 1 + extra
        others = ['a recorder'] if extra == 1 else [f'{extra} listeners'] if extra else []

        def readers(publisher, peer: str) -> Iterator[str]:
            have = publisher.get_subscription_count()
            if have < listeners:
                yield f'readers of {publisher.topic_name}: {have} of {listeners} ({", ".join([peer, *others])})'

        for j, publisher in self._info_pubs.items():
            yield from readers(publisher, f'agent {j}')
        for j, subscription in zip(self.neighbour_ids, self._info_subs):
            if subscription.get_publisher_count() < 1:
                yield f'a writer of {trigger_info_topic(j, self.agent_id)} (agent {j})'
        yield from readers(self.output.publisher, 'the robot' if self.config.robot != 'none' else 'the simulator')
        yield from readers(self._status_pub, 'the simulator or coordinator')
        yield from readers(self._report_pub, 'the simulator or coordinator')
        if self._step_sub.get_publisher_count() < 1:
            yield f'a writer of {STEP_TOPIC} (the simulator or coordinator)'
        # Last: whether a service is there is looked up in the whole ROS graph (rmw_fastrtps
        # walks every endpoint it knows), where a match count is one number.
        yield from self.sensing.gaps()

    def _announce(self) -> None:
        """During discovery: a Status (step −1) whenever the agent's readiness changes and every
        DISCOVERY_REANNOUNCE seconds once ready, and now and then a log line saying what it still
        waits for."""
        if self.step is not None:
            return
        now = time.monotonic()
        logging = now >= self._next_discovery_log
        gaps = self.discovery_gaps() if logging else list(itertools.islice(self._gaps(), 1))
        ready = not gaps
        changed = ready != self._announced
        if changed or (ready and now >= self._next_announcement):
            self._announced = ready
            self._next_announcement = now + DISCOVERY_REANNOUNCE
            self._publish_status(step_index=DISCOVERY_STEP, ready=ready)
            if ready and changed:
                self.get_logger().info(
                    f'agent {self.agent_id}: every endpoint matched {time.monotonic() - self._created:.1f} s after the node '
                    'started; waiting for step 0'
                )
        if gaps and logging:
            self._next_discovery_log = now + DISCOVERY_LOG_PERIOD
            self.get_logger().info(
                f'agent {self.agent_id}: discovery for {now - self._created:.0f} s, still waiting for: {"; ".join(gaps)}'
            )

    # -- steps ----------------------------------------------------------------------------------

    def _on_step(self, msg: Float64MultiArray) -> None:
        try:
            step = decode_step(msg)
        except MessageError as error:
            self.reject(STEP_TOPIC, error.reason, str(error))
            return
        if self.step is not None and step.index <= self.step.index:
            return  # a repeat of a step already handled
        if self._discovery is not None:
            self.destroy_timer(self._discovery)
            self._discovery = None
        self.step = step
        if step.final:
            self.finished = True
            self.faults.closed = True
            self._cancel_due_timer()
            self.output.stop()  # the zero command before anything else
            self._publish_report(final=True)
            return
        if step.realtime:
            self._epoch = step.epoch
            self.sensing.start(step.epoch)
            self.output.start(step.epoch)
            self._sense_now()  # t^i_1 = 0
            return
        if self.config.wall_clock_only:
            raise AgentNodeError(
                f'agent {self.agent_id}: sensing: {self.config.sensing} with robot: {self.config.robot} runs on the '
                f'wall clock (Step 0 flagged realtime), but step {step.index} is lock-step'
            )
        if self.faults.injection.loss > 0.0:
            # Lock-step counts every message: one dropped on purpose would stall the run.
            raise AgentNodeError(
                f'agent {self.agent_id}: inject_loss={self.faults.injection.loss!r} needs wall-clock mode '
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

    # -- triggers -------------------------------------------------------------------------------

    def _sense_now(self) -> None:
        """Ask for this agent's sensing; the trigger completes when the answer arrives."""
        self._cancel_due_timer()
        if self._sensing or self.finished:
            return
        self._sensing = True
        self._planned = self._next_time
        self.sensing.request(self._on_sensed)

    def _cancel_due_timer(self) -> None:
        if self._due_timer is not None:
            self.destroy_timer(self._due_timer)
            self._due_timer = None

    def _on_sensed(self, sensed) -> None:
        # rclpy runs a client future's done callbacks outside the executor and only warns about
        # what they raise: keep the error for the spin loop to raise (see `check`).
        try:
            self._trigger(sensed)
        except Exception as error:  # noqa: BLE001 - re-raised by check()
            self._fail(error)

    def _trigger(self, sensed_getter) -> None:
        if self.finished:  # the final step came while sensing (the horizon, or a failed run)
            self._sensing = False
            return
        sensed = sensed_getter()
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
        self.output.publish(t, tuple(float(v) for v in out.control), sensed)
        self.commands_sent += 1
        for info in out.infos:
            self._publish(self._info_pubs[info.receiver], encode_trigger_info(info))
            self.info_sent += 1
        held, self._held = self._held, []
        for info in held:
            self._receive(info)
        self._dirty = True
        if self._epoch is None:
            self._report_if_complete()
        else:
            self._replan()

    def check(self) -> None:
        """Raise what went wrong outside the executor's reach."""
        if self.failure is not None:
            raise self.failure
        lost = self._simulator_lost_at
        # During discovery a lease may expire on a machine busy starting many processes: keep
        # waiting for step 0 (a simulator that left deletes its writer, which does count).
        waiting = self.step is None and self._simulator_lease_expired
        lockstep = self.step is not None and not self.step.realtime
        grace = KEEPER_LEASE_GRACE if lockstep and self._simulator_lease_expired else LOST_GRACE
        if lost is not None and not self.finished and not waiting and time.monotonic() - lost > grace:
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

    # -- arriving triggering information ---------------------------------------------------------

    def _on_info(self, msg: Float64MultiArray, sender: int) -> None:
        topic = trigger_info_topic(sender, self.agent_id)
        try:
            info = decode_trigger_info(msg)
        except MessageError as error:
            self.reject(topic, error.reason, str(error))
            return
        problem = implausible(
            info, sender=sender, agent_id=self.agent_id, algorithm=self.algorithm, dimension=self.dimension,
            last_stamp=self._last_stamp.get(sender),
        )  # fmt: skip
        if problem is not None:
            self.reject(topic, *problem)
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
            self._report_changed()
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

    # -- status -----------------------------------------------------------------------------------

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
                try:
                    self._next_time = float(self.core.next_trigger_time(self.horizon))
                except CrossingError as error:
                    raise PredictionError(f'agent {self.agent_id}: {error}; {PRECISION_HINT}') from error
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
        self._publish(self._status_pub, encode_status(status))

    # -- reports and leaving ----------------------------------------------------------------------

    def report(self, *, final: bool = False, failure: str | None = None) -> AgentReport:
        published = dict(self.published)
        if isinstance(self.output, PlantOutput) and self.output.sent:
            published[self.output.publisher.topic_name] = self.output.sent
        return AgentReport(
            agent=self.agent_id,
            final=final,
            rejected=dict(self.reject.counts),
            dropped=self.faults.dropped,
            delayed=self.faults.delayed,
            late=self.late_infos,
            robot_commands=self.output.robot_commands,
            saturation=self.output.saturation,
            failure=failure,
            published=published,
        )

    def _report_changed(self) -> None:
        self._report_dirty = True

    def _publish_report(self, *, final: bool = False, failure: str | None = None) -> None:
        self._report_dirty = False
        self._final_report_sent = final
        self._count_published(self._report_pub)  # a report counts itself
        self._report_pub.publish(encode_agent_report(self.report(final=final, failure=failure)))

    def _publish(self, publisher, msg) -> None:  # noqa: ANN001
        self._count_published(publisher)
        publisher.publish(msg)

    def _count_published(self, publisher) -> None:  # noqa: ANN001
        """Count what a recorder must hold: everything from step 0 on, when it is matched for sure
        (the simulator starts step 0 only once every agent has matched all its listeners)."""
        if self.step is not None:
            topic = publisher.topic_name
            self.published[topic] = self.published.get(topic, 0) + 1

    def _publish_report_if_dirty(self) -> None:
        # Not before step 0: a recorder may not be matched yet, and every report it must hold
        # counts (news from discovery go out with the first report after it).
        if self._report_dirty and not self.finished and self.step is not None:
            self._publish_report()

    def leave(self, *, failure: str | None = None, deadline: float | None = None) -> None:
        """On the way out, whatever the reason: the zero command, the final report if not yet sent
        (with `failure`, why the agent stops early), and the delivery of everything it published
        (until `deadline`, time.monotonic(); default DELIVERY_TIMEOUT from now)."""
        if not rclpy.ok(context=self.context):
            return  # a context shut down by someone else cannot publish
        self.finished = True
        self._cancel_due_timer()
        self.output.stop()
        if not self._final_report_sent:
            self._publish_report(final=True, failure=failure)
        self.wait_for_delivery(time.monotonic() + DELIVERY_TIMEOUT if deadline is None else deadline)

    def wait_for_delivery(self, deadline: float) -> None:
        """Let reliable writers hand over what they still hold before the node goes away (until
        `deadline`, time.monotonic())."""
        pending = [self._status_pub, self._report_pub, self.output.publisher, *self._info_pubs.values()]
        while pending and time.monotonic() < deadline:
            pending = [pub for pub in pending if not pub.wait_for_all_acked(Duration(seconds=0.05))]


if __name__ == '__main__':  # the command moved to formation_agent.ros.main: say so instead of doing nothing
    raise SystemExit('formation_agent.ros.node holds the node; the command is `python -m formation_agent.ros.main` (formation_agent)')
