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
wall time since the Step's epoch, as a robot would, and triggers at once (from the executor, not
by recursion) when its triggering time has already passed.  When it triggers:
`formation_agent.ros.stepping`; its counts, Status and report: `formation_agent.ros.reporting`;
discovery: `formation_agent.ros.discovery`.  All algorithmic decisions are taken by the core
object (`formation_agent.core.eta`).

Every way out sends the zero command first (`leave`): the final Step, a lost simulator or
coordinator (DDS liveliness, exit status 3), SIGINT/SIGTERM (130), a stale pose, a freeze
(`formation_agent.ros.staleness`) or any other error (1); an error raised outside the executor's
reach stops the robot and the triggers at once (`_fail`).  Bad messages are refused and counted
(`formation_agent.ros.inbox`); faults can be injected for tests (`formation_agent.ros.faults`);
parameters: `formation_agent.ros.config`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray

from formation_agent.core.errors import PoseError
from formation_agent.core.eta import make_agent
from formation_agent.core.time_warp import WarpedAgent
from formation_agent.ros.commands import PlantOutput, RobotOutput
from formation_agent.ros.config import read_config
from formation_agent.ros.discovery import Discovery, SimulatorWatch
from formation_agent.ros.errors import AgentNodeError, PeerLostError, PredictionError
from formation_agent.ros.faults import FaultInjection, InjectedFaults
from formation_agent.ros.inbox import STAMP_AHEAD_TOLERANCE, Rejections, read_info
from formation_agent.ros.outbox import Outbox
from formation_agent.ros.reporting import AgentCounts, agent_status
from formation_agent.ros.sensing import PoseSensing, ServiceSensing
from formation_agent.ros.staleness import Staleness
from formation_agent.ros.stepping import (
    STEP_REPEAT,
    STEP_TAKE,
    Arrivals,
    StepGate,
    TriggerSchedule,
    refuse_lock_step,
)
from formation_msgs_py.codec import decode_step, encode_trigger_info, tag_refused
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import AgentReport, Step
from formation_msgs_py.qos import READER_QOS
from formation_msgs_py.tags import Signer, Verifier, agent_writer
from formation_msgs_py.topics import AGENT_NODE, STEP_TOPIC, trigger_info_topic

__all__ = [
    'DELIVERY_TIMEOUT',
    'NODE_NAME',
    'AgentNodeError',
    'FormationAgentNode',
    'PeerLostError',
    'PredictionError',
]

NODE_NAME = AGENT_NODE
DELIVERY_TIMEOUT = 4.0
"""Seconds a leaving node waits, at most, for its readers to acknowledge what it published (its
last messages too: zero command, report): Fast DDS repairs a message lost on the way at the
writer's next heartbeat (every 3 s by default, 0.1 s in a run: `formation_sim.runtime`'s
fastdds_profile.xml), and a recorder must get it before the writer is gone."""

WRITER_LOOK_PERIOD = 0.2
"""Seconds between an agent's looks at whether its pose topics still have writers (sensing from
poses): when a pose goes stale, its message says since when a topic has none (`Staleness`)."""


class _NodeTimers:
    """A node's one-shot timers for `TriggerSchedule` (a timer destroyed once it fired)."""

    def __init__(self, node: Node) -> None:
        self._node = node

    def arm(self, delay: float, callback):
        return self._node.create_timer(delay, callback)

    def cancel(self, handle) -> None:
        self._node.destroy_timer(handle)


def _make_core(config):
    """The agent's ETA-1 or ETA-2 core (`formation_agent.core.eta`) from its parameters; with a time
    warp, run in the paper's time and seen in real time (`WarpedAgent`)."""
    core = make_agent(
        agent_id=config.agent_id,
        neighbours=config.neighbours,
        delta=config.delta,
        algorithm=config.algorithm,
        gains=config.gains,
        safety=config.safety,
        trigger_rule=config.trigger_rule,
    )
    return core if config.time_warp is None else WarpedAgent(core, config.time_warp)


def _make_faults(node: FormationAgentNode) -> InjectedFaults:
    """The faults injected on arriving triggering information (parameters inject_*): none by default."""
    config = node.config
    injection = FaultInjection(
        agent_id=config.agent_id,
        loss=config.inject_loss,
        delay_ms=config.inject_delay_ms,
        jitter_ms=config.inject_jitter_ms,
        seed=config.inject_seed,
    )
    return InjectedFaults(node, injection, hand_on=node._on_info, changed=node.counts.changed)


def _make_staleness(node: FormationAgentNode) -> Staleness | None:
    """Sensing from poses: why a pose is stale, and no command after a freeze (None otherwise)."""
    if node.config.sensing != 'poses':
        return None
    return Staleness(
        book=node.sensing.book,
        period=1.0 / node.config.command_rate,
        count_writers=node.count_publishers,
        schedule=node.schedule,
        take=node.sensing.readers.take,
    )


def _make_output(node: FormationAgentNode) -> PlantOutput | RobotOutput:
    """Where the agent's commands go (parameter `robot`): a simulator's plant, or a robot whose
    commands the agent's `Staleness` guards."""
    config = node.config
    if config.robot == 'none':
        return PlantOutput(node, config)
    if not config.double and math.isfinite(config.limits.linear_acceleration):
        node.get_logger().warning(
            'max_linear_acceleration applies to ETA-2 only (ETA-1 velocity commands change stepwise at '
            'triggers): ignored'
        )
    return RobotOutput(node, config, node.sensing, on_failure=node._fail, guard=node.staleness.check_command)


def _report(node: FormationAgentNode, *, final: bool, failure: str | None) -> AgentReport:
    """The agent's AgentReport: its counts, what it refused, injected and clipped."""
    output = node.output
    plant = (output.publisher.topic_name, output.sent) if isinstance(output, PlantOutput) else None
    report = node.counts.report(
        final=final,
        failure=failure,
        rejected=node.reject.counts,
        dropped=node.faults.dropped,
        delayed=node.faults.delayed,
        robot_commands=output.robot_commands,
        saturation=output.saturation,
        plant=plant,
    )
    if node.config.safety is None:
        return report
    return replace(  # the safety layer's counts, for summary.json's extra.safety
        report,
        safety_interventions=node.core.safety_interventions,
        safety_last_intervention=node.core.safety_last_intervention,
    )


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
        self.neighbour_ids = config.neighbour_ids
        self.core = core if core is not None else _make_core(config)
        self.counts = AgentCounts(agent_id=config.agent_id)
        self.schedule = TriggerSchedule(agent_id=config.agent_id, timers=_NodeTimers(self))
        self.arrivals = Arrivals(schedule=self.schedule, counts=self.counts)
        self.step_gate = StepGate(agent_id=config.agent_id)
        self.reject = Rejections(self.get_logger(), changed=self.counts.changed)
        self.signer, self.verifier = _tags(config)  # the run's tag (docs/HOSTILE_TRAFFIC.md, Tags)
        self.faults = _make_faults(self)
        self.sensing = (
            PoseSensing(self, config, reject=self.reject)
            if config.sensing == 'poses'
            else ServiceSensing(self)
        )
        self.staleness = _make_staleness(self)
        if self.staleness is not None:
            self._writer_looks = self.create_timer(
                WRITER_LOOK_PERIOD, lambda: self.staleness.look(time.time())
            )
        self.output = _make_output(self)
        self._create_endpoints()
        self.step: Step | None = None
        self.finished = False
        self.failure: Exception | None = None
        self.settled = Future()  # done once finished or failed: the process's loop looks at once (main)
        self.ended_at_horizon = False  # its poses stopped after the horizon: no failure (`_fail`)
        self._report_timer = self.create_timer(0.5, self._publish_report_if_dirty)
        self.simulator = SimulatorWatch(config.agent_id)
        self.end_watch = _EndWatch(self)
        self._discovery: Discovery | None = Discovery(self)

    def _create_endpoints(self) -> None:
        self.outbox = Outbox(self, self.counts, self.neighbour_ids, signer=self.signer)
        self.info_publishers = self.outbox.info
        self.status_publisher = self.outbox.status
        self.report_publisher = self.outbox.report
        self.info_subscriptions = [
            self.create_subscription(
                Float64MultiArray,
                trigger_info_topic(j, self.agent_id),
                lambda msg, sender=j: _on_info(self, msg, sender),
                READER_QOS,
            )
            for j in self.neighbour_ids
        ]
        self.step_subscription = self.create_subscription(
            Float64MultiArray,
            STEP_TOPIC,
            self._on_step,
            READER_QOS,
            # self.end_watch is made after this subscription: looked up when the event comes
            event_callbacks=SubscriptionEventCallbacks(
                liveliness=lambda info: self.end_watch.on_keeper_liveliness(info)  # noqa: PLW0108 - see above
            ),
        )

    def destroy_node(self) -> None:
        self.sensing.close()  # pose sensing's readers live on a node of their own
        super().destroy_node()

    @property
    def rejected(self) -> dict[str, int]:
        return self.reject.counts

    def _fail(self, error: Exception) -> None:
        """The stop decision for an error raised outside the executor's reach: the zero command at
        once and no trigger after it (a timer or callback already queued finds the agent stopped);
        the first error is kept for `check` to raise, a stale pose explained (`Staleness`)."""
        self.schedule.stop()
        self.output.stop()
        now = time.time()
        if self.staleness is not None and self.staleness.after_horizon(
            error, now, horizon=self.config.horizon
        ):
            # The robots stopped at the horizon and the final Step is on its way: the end of the
            # run, not a fault (issue 19).  Stopped, the agent leaves on that Step (or its loss).
            if not self.ended_at_horizon:
                self.ended_at_horizon = True
                self.get_logger().info(
                    f'agent {self.agent_id}: poses stopped after the horizon t={self.config.horizon:g} (the '
                    'robots stopped at the end of the run): robot stopped, waiting for the final Step'
                )
            return
        if self.failure is None:
            stale = self.staleness is not None and isinstance(error, PoseError)
            self.failure = self.staleness.explain(error, now) if stale else error
            self.settled.set_result(False)

    def connected(self) -> bool:
        """Every endpoint this agent needs is matched with its peer (and the extra listeners)."""
        return self._discovery is None or next(self._discovery.gaps(), None) is None

    def discovery_gaps(self) -> list[str]:
        """What discovery still waits for, one phrase per endpoint (empty: connected)."""
        return [] if self._discovery is None else list(self._discovery.gaps())

    # -- steps ----------------------------------------------------------------------------------

    def _on_step(self, msg: Float64MultiArray) -> None:
        if (step := _next_step(self, msg)) is None:
            return
        if self._discovery is not None:
            self._discovery.close()
            self._discovery = None
        self.step = step
        if step.final:
            self.finished = True
            self.faults.closed = True
            self.schedule.stop()
            self.output.stop()  # the zero command before anything else
            self._publish_report(final=True)
            self.settled.set_result(True)
            return
        if step.realtime:
            self.schedule.start(step.epoch)
            self.end_watch.start(step.epoch)
            self.sensing.start(step.epoch)
            self.output.start(step.epoch)
            self._sense_now()  # t^i_1 = 0
            return
        refuse_lock_step(step, config=self.config, loss=self.faults.injection.loss)
        self.schedule.due_neighbours = tuple(j for j in step.due if j in self.info_publishers)
        if self.schedule.check_step(step):
            self._sense_now()
        else:
            self._report_if_complete()

    # -- triggers -------------------------------------------------------------------------------

    def _sense_now(self) -> None:
        """Ask for this agent's sensing; the trigger completes when the answer arrives."""
        if self.finished or not self.schedule.begin():
            self.schedule.cancel()
            return
        if self.staleness is not None and (stale := self.staleness.trigger_refusal(time.time())) is not None:
            self._fail(stale)  # after a freeze: the zero command, not one from state that old
            return
        self.sensing.request(self._on_sensed)

    def _on_sensed(self, sensed) -> None:
        # rclpy runs a client future's done callbacks outside the executor and only warns about
        # what they raise: keep the error for the spin loop to raise (see `check`).
        try:
            self._trigger(sensed)
        except Exception as error:  # noqa: BLE001 - re-raised by check()
            self._fail(error)

    def _trigger(self, sensed_getter) -> None:
        if self.finished or self.schedule.stopped:  # the final step or a stop came while sensing
            self.schedule.abandon()
            return
        sensed = sensed_getter()
        t = self.schedule.sensed_time(sensed, step=self.step)
        out = _core_trigger(self, t, sensed)
        self.schedule.triggered(t)
        self.counts.triggered(t)
        self.output.publish(t, tuple(float(v) for v in out.control), sensed)
        self.counts.commands_sent += 1
        for info in out.infos:
            self.outbox.publish_info(info.receiver, encode_trigger_info(info))
            self.counts.info_sent += 1
        self.arrivals.triggered(sensed, core=self.core)  # what waited for this trigger
        self._knowledge_changed()

    def _knowledge_changed(self) -> None:
        """Lock-step: a Status once the step is complete; wall clock: re-plan at once."""
        self.counts.status_due = True
        if self.schedule.wall_clock:
            self._replan()
        else:
            self._report_if_complete()

    def check(self) -> None:
        """Raise what went wrong outside the executor's reach."""
        if self.failure is not None:
            raise self.failure
        lost = self.simulator.lost(self.step, finished=self.finished)
        if lost is not None:
            raise PeerLostError(lost)

    # -- arriving triggering information ---------------------------------------------------------

    def _on_info(self, msg: Float64MultiArray, sender: int) -> None:
        info = read_info(
            msg,
            sender=sender,
            agent_id=self.agent_id,
            algorithm=self.config.algorithm,
            dimension=self.config.dimension,
            heard=self.schedule.heard,
            reject=self.reject,
            latest=_latest_stamp(self),
        )
        # Held while this agent triggers at that instant itself: its own sensing comes first, then
        # the neighbours' information (DESIGN.md, "Time and exactness"), and its status must not
        # report the step before it has triggered.
        if info is not None and self.arrivals.arrive(info, core=self.core):
            self._knowledge_changed()  # as on a robot: every piece of news re-plans at once

    # -- status -----------------------------------------------------------------------------------

    def _report_if_complete(self) -> None:
        """Lock-step: one Status per step, once the agent has all it will get at the step.

        That is its own trigger if it is due, and the information of every neighbour the Step
        lists as due (which may arrive before the Step itself).  Information stamped at a later
        step waits for that Step.  An agent whose knowledge did not change stays silent: its
        last Status still holds.
        """
        step = self.step
        if (
            step is not None
            and not self.finished
            and self.counts.status_due
            and self.schedule.complete_at(step)
        ):
            self.publish_status(step_index=step.index, ready=True)

    def _replan(self) -> None:
        """Wall clock: report the next triggering time and set a timer for it."""
        self.publish_status(step_index=self.step.index, ready=True)
        self.schedule.cancel()
        if self.core.ready and not self.finished:
            self.schedule.arm(self._sense_now)  # past due: at once, from the executor

    def publish_status(self, *, step_index: int, ready: bool) -> None:
        """The agent's Status at `step_index` (DISCOVERY_STEP: its readiness during discovery)."""
        status = agent_status(
            self.counts,
            schedule=self.schedule,
            core=self.core,
            step_index=step_index,
            ready=ready,
            horizon=self.config.horizon,
        )
        self.outbox.publish_status(status)

    # -- reports and leaving ----------------------------------------------------------------------

    def report(self, *, final: bool = False, failure: str | None = None) -> AgentReport:
        return _report(self, final=final, failure=failure)

    def _publish_report(self, *, final: bool = False, failure: str | None = None) -> None:
        self.outbox.publish_report(self.report(final=final, failure=failure))

    def _publish_report_if_dirty(self) -> None:
        # Not before step 0: a recorder may not be matched yet, and every report it must hold
        # counts (news from discovery go out with the first report after it).
        if self.counts.report_due and not self.finished and self.step is not None:
            self._publish_report()

    def leave(
        self, *, failure: str | None = None, deadline: float | Callable[[], float] | None = None
    ) -> None:
        """On the way out, whatever the reason: the zero command, the final report if not yet sent
        (with `failure`, why the agent stops early), and the delivery of everything it published
        (until `deadline`, time.monotonic(), or what the callable says now; default
        DELIVERY_TIMEOUT from now)."""
        if not rclpy.ok(context=self.context):
            return  # a context shut down by someone else cannot publish
        self.finished = True
        self.schedule.stop()
        self.output.stop()
        if not self.counts.final_sent:
            self._publish_report(final=True, failure=failure)
        self.wait_for_delivery(time.monotonic() + DELIVERY_TIMEOUT if deadline is None else deadline)

    def wait_for_delivery(self, deadline: float | Callable[[], float]) -> None:
        """Let reliable writers hand over what they still hold before the node goes away (until
        `deadline`, time.monotonic())."""
        self.outbox.wait_for_delivery(deadline, self.output.publisher)


def _core_trigger(node: FormationAgentNode, t: float, sensed):
    """The core's trigger; with the safety layer also the other robots within R that the same
    sensing answer holds (docs/SAFETY.md), as the engine hands them."""
    if node.config.safety is None:
        return node.core.trigger(t, sensed)
    return node.core.trigger(t, sensed, nearby=sensed.nearby)


def _next_step(node: FormationAgentNode, msg: Float64MultiArray) -> Step | None:
    """The Step in `msg` if `node` takes it (`StepGate`): a malformed one, or one that cannot be
    the run's next, is refused and counted; a repeat, or any Step after the end, is ignored.  With
    the run's key, a Step without its valid tag is refused first (`_tag_refused`)."""
    if _tag_refused(node, STEP_TOPIC, msg):
        return None
    try:
        step = decode_step(msg)
    except MessageError as error:
        node.reject(STEP_TOPIC, error.reason, str(error))
        return None
    if node.finished:
        return None  # the run is over for this agent: nothing a Step says can change that
    verdict = node.step_gate.judge(step)
    if verdict != STEP_TAKE:
        if verdict != STEP_REPEAT:  # a Step that cannot be the run's next one: refused, counted
            node.reject(STEP_TOPIC, *verdict)
        return None
    return step


def _tags(config) -> tuple[Signer | None, Verifier]:
    """With the run's key, what the agent sends is tagged and what it reads without a valid tag
    is refused before the algorithm sees it (`_tag_refused`)."""
    signer = Signer(config.key, writer=agent_writer(config.agent_id)) if config.key else None
    return signer, Verifier(config.key)


def _on_info(node: FormationAgentNode, msg, sender: int) -> None:
    """A neighbour's triggering information: its tag checked, then on to the fault injection."""
    if not _tag_refused(node, trigger_info_topic(sender, node.agent_id), msg):
        node.faults.arrive(msg, sender)


def _tag_refused(node: FormationAgentNode, topic: str, msg) -> bool:
    """Whether `msg` lacks the run's valid tag for `topic` (`codec.tag_refused`: refused and
    counted by the agent)."""
    return tag_refused(node.verifier, topic, msg, node.reject)


def _latest_stamp(node: FormationAgentNode) -> float:
    """The latest stamp a neighbour of `node` can give now: the horizon, and on the wall clock the
    agent's own run time plus STAMP_AHEAD_TOLERANCE (`formation_agent.ros.inbox`)."""
    latest = node.config.horizon
    if node.schedule.wall_clock:
        latest = min(latest, time.time() - node.schedule.epoch + STAMP_AHEAD_TOLERANCE)
    return latest


class _EndWatch:
    """The end of a wall-clock run as one agent sees it on its own (issue 28): nothing keeps its
    robot moving past the run's horizon or a keeper that shows no sign of life."""

    def __init__(self, node: FormationAgentNode) -> None:
        self._node = node
        self._timer = None
        self._keeper_stop: float | None = None  # when the robot was stopped for a silent keeper

    def start(self, epoch: float) -> None:
        """Step 0 on the wall clock: the horizon is armed on the agent's own clock."""
        delay = max(0.0, epoch + self._node.config.horizon - time.time())
        self._timer = self._node.create_timer(delay, self._at_horizon)

    def _at_horizon(self) -> None:
        """The run's horizon on this agent's own clock: no trigger and no command from now on,
        whatever Step comes or does not (a forged Step kept robots moving 7.6 s past the end); the
        agent leaves on the final Step (or the keeper's loss)."""
        node = self._node
        node.destroy_timer(self._timer)
        if self._stop():
            node.get_logger().info(
                f'agent {node.agent_id}: the horizon t={node.config.horizon:g} on its own clock: robot '
                'stopped, waiting for the final Step'
            )

    def on_keeper_liveliness(self, info) -> None:
        """The keeper's Step writer changed liveliness (`SimulatorWatch`).  On the wall clock a
        robot would go on moving under its last command: the moment the keeper shows no sign of
        life (frozen, or gone) the robot gets its zero and no trigger follows, within the lease of
        the keeper's last sign of life (a frozen coordinator's robots got theirs after 1.21-1.24 s,
        the lease plus LOST_GRACE); the agent leaves after LOST_GRACE (`check`)."""
        node = self._node
        node.simulator.on_liveliness(info)
        if info.alive_count > 0 and self._keeper_stop is not None and not node.finished:
            # Back within the grace: a stopped agent cannot rejoin (its neighbours predict with the
            # command it had), so it leaves with the cause named instead of waiting for a final Step.
            node._fail(
                AgentNodeError(
                    f'agent {node.agent_id}: the time keeper (writer of {STEP_TOPIC}) showed no sign of '
                    f'life and came back {time.monotonic() - self._keeper_stop:.2f} s after this agent '
                    'stopped its robot for it: a stopped agent cannot rejoin the run (if this agent was '
                    'stopped or starved itself, the keeper only looked silent)'
                )
            )
            return
        if node.simulator.lost_at is not None and node.schedule.wall_clock and self._stop():
            self._keeper_stop = time.monotonic()
            node.get_logger().warning(
                f'agent {node.agent_id}: the time keeper (writer of {STEP_TOPIC}) shows no sign of life: '
                'robot stopped'
            )

    def _stop(self) -> bool:
        """The zero command and no trigger after it; False if the agent had stopped already."""
        node = self._node
        if node.finished or node.schedule.stopped:
            return False
        node.schedule.stop()
        node.output.stop()
        return True


if __name__ == '__main__':  # the command moved to formation_agent.ros.main: say so, not nothing
    raise SystemExit(
        'formation_agent.ros.node holds the node; the command is `python -m formation_agent.ros.main` '
        '(formation_agent)'
    )
