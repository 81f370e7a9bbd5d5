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
core object (`formation_agent.eta`); this module only moves messages.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import traceback
from collections.abc import Sequence

import rclpy
from geometry_msgs.msg import Accel, Twist
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from formation_msgs_py.codec import (
    decode_sensed_state,
    decode_step,
    decode_trigger_info,
    encode_acceleration_command,
    encode_status,
    encode_trigger_info,
    encode_velocity_command,
)
from formation_msgs_py.lockstep import DISCOVERY_STEP, Status, Step
from formation_msgs_py.types import TriggerInfo

NODE_NAME = 'formation_agent'
STEP_TOPIC = '/formation/step'
STATUS_TOPIC = '/formation/status'

# Every message of the protocol matters, and a reader that matches a writer late must still get
# what was written before: reliable + transient local.  Depth bounds what may be outstanding; the
# lock-step never has more than one message per edge and step in flight.
PROTOCOL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=32,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


class AgentNodeError(ValueError):
    """Bad agent parameters or a violation of the lock-step protocol seen by an agent."""


def agent_namespace(agent_id: int) -> str:
    return f'/agent_{agent_id}'


def trigger_info_topic(sender: int, receiver: int) -> str:
    return f'{agent_namespace(sender)}/trigger_info/to_{receiver}'


def sense_service(agent_id: int) -> str:
    return f'{agent_namespace(agent_id)}/sense'


def command_topic(agent_id: int, *, double: bool) -> str:
    return f'{agent_namespace(agent_id)}/{"cmd_accel" if double else "cmd_vel"}'


def build_core(
    *,
    agent_id: int,
    neighbours: dict,
    delta: float,
    algorithm: str,
    gains: dict[str, float],
):
    """The ROS-free agent object (imported here so that tests may pass their own core)."""
    from formation_agent.eta import Eta1Agent, Eta2Agent

    if algorithm == 'eta1':
        return Eta1Agent(
            agent_id=agent_id, neighbours=neighbours, delta=delta, alpha=gains['alpha'], beta=gains['beta']
        )
    return Eta2Agent(
        agent_id=agent_id,
        neighbours=neighbours,
        delta=delta,
        alpha_d=gains['alpha_d'],
        beta_d=gains['beta_d'],
        k1=gains['k1'],
        k2=gains['k2'],
        k3=gains['k3'],
    )


_GAINS = {'eta1': ('alpha', 'beta'), 'eta2': ('alpha_d', 'beta_d', 'k1', 'k2', 'k3')}


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
        trigger/receive/next_trigger_time/ready interface of `formation_agent.eta`).
        """
        super().__init__(
            NODE_NAME,
            namespace=namespace,
            start_parameter_services=start_parameter_services,
            parameter_overrides=parameter_overrides or [],
            context=context,
        )
        self._read_parameters()
        self.core = core if core is not None else build_core(
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
                lambda msg, sender=j: self._on_info(msg, sender),
                PROTOCOL_QOS,
            )
            for j in self.neighbour_ids
        ]
        self._status_pub = self.create_publisher(Float64MultiArray, STATUS_TOPIC, PROTOCOL_QOS)
        self._step_sub = self.create_subscription(Float64MultiArray, STEP_TOPIC, self._on_step, PROTOCOL_QOS)
        # Statuses are published once per burst of delivered messages: the guard condition runs
        # after the executor has handled what was ready together.
        self._flush = self.create_guard_condition(self._publish_status_if_dirty)

        self.step: Step | None = None
        self.finished = False
        self.info_sent = 0
        self.info_received = 0
        self.commands_sent = 0
        self.triggers = 0
        self.trigger_times: list[float] = []
        self._sensing = False  # a sensing request is in flight
        self._held: list[TriggerInfo] = []  # information stamped at a time this agent is due
        self._dirty = False
        self._next_time = 0.0  # t^i_1 = 0
        self._last_trigger = -math.inf
        self._planned = 0.0  # the time the trigger in progress (or the last one) was planned for
        self._epoch: float | None = None  # wall-clock mode: Unix time of t = 0
        self._sensed = None  # the last SensedState, to re-base late information
        self._due_timer = None
        self.late_infos = 0
        self.failure: Exception | None = None
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
        if self.algorithm not in _GAINS:
            raise AgentNodeError(f'{name}: algorithm must be one of {sorted(_GAINS)}, got {self.algorithm!r}')
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
            gain: float(self._param(gain, Parameter.Type.DOUBLE)) for gain in _GAINS[self.algorithm]
        }
        # Listeners besides the protocol peers (a recorder) that must be matched before step 0.
        self.extra_subscribers = int(self.declare_parameter('extra_subscribers', 0).value)
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
            and self._step_sub.get_publisher_count() >= 1
        )

    def _announce(self) -> None:
        if self.step is None and self._status_pub.get_subscription_count() >= 1:
            self._publish_status(step_index=DISCOVERY_STEP, ready=self.connected())

    # -- lock-step ------------------------------------------------------------------------------

    def _on_step(self, msg: Float64MultiArray) -> None:
        step = decode_step(msg)
        if self.step is not None and step.index <= self.step.index:
            return  # a repeat of a step already handled
        if self._discovery is not None:
            self.destroy_timer(self._discovery)
            self._discovery = None
        self.step = step
        if step.final:
            self.finished = True
            self._cancel_due_timer()
            return
        if step.realtime:
            self._epoch = step.epoch
            self._sense_now()  # t^i_1 = 0
            return
        if step.time > self._next_time:
            raise AgentNodeError(
                f'agent {self.agent_id}: step {step.index} at t={step.time!r} skips its triggering time '
                f'{self._next_time!r}'
            )
        if step.time == self._next_time:  # the exact float this agent reported
            self._sense_now()
        else:
            self._publish_status(step_index=step.index, ready=True)

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

    def _trigger(self, future) -> None:
        sensed = decode_sensed_state(future.result())
        if self.finished:  # wall-clock mode: the horizon passed while sensing
            self._sensing = False
            return
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
        if self._epoch is None:
            self._publish_status(step_index=self.step.index, ready=True)
        else:
            self._replan()

    def _on_info(self, msg: Float64MultiArray, sender: int) -> None:
        info = decode_trigger_info(msg)
        if info.sender != sender or info.receiver != self.agent_id:
            raise AgentNodeError(
                f'agent {self.agent_id}: topic {trigger_info_topic(sender, self.agent_id)} carried '
                f'information from agent {info.sender} to agent {info.receiver}'
            )
        due = self._epoch is None and self._next_time > self._last_trigger  # not yet triggered at
        if self._sensing or (due and info.stamp >= self._next_time):
            # This agent triggers at that instant itself: its own sensing comes first, then the
            # neighbours' information (DESIGN.md, "Time and exactness"); and its status must not
            # report the step before it has triggered.
            self._held.append(info)
            return
        self._receive(info)
        self._dirty = True
        self._flush.trigger()

    def _receive(self, info: TriggerInfo) -> None:
        if info.stamp < self._last_trigger:  # only on the wall clock: it crossed our trigger
            info = self._rebased(info)
            self.late_infos += 1
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

    def _publish_status_if_dirty(self) -> None:
        if not self._dirty or self._sensing or self.finished:
            return
        if self._epoch is not None:
            self._replan()
        else:
            self._publish_status(step_index=DISCOVERY_STEP if self.step is None else self.step.index, ready=True)

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

    def wait_for_delivery(self, timeout_sec: float = 2.0) -> None:
        """Let reliable writers hand over what they still hold before the node goes away."""
        for pub in (self._status_pub, self._command_pub, *self._info_pubs.values()):
            pub.wait_for_all_acked(rclpy.duration.Duration(seconds=timeout_sec))


# -- entry point ------------------------------------------------------------------------------


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog='formation_agent',
        description='Run formation agent nodes (one per agent; several share an executor with --agents).',
        epilog='Parameters come from ROS arguments, e.g. --ros-args --params-file agents.yaml, '
        'keyed by node name /agent_<i>/formation_agent.',
    )
    parser.add_argument(
        '--agents',
        help='comma-separated agent ids to run in this process, each in namespace /agent_<i> '
        '(default: one node whose namespace and parameters come from the ROS arguments)',
    )
    return parser.parse_args(list(argv))


def main(args: Sequence[str] | None = None) -> int:
    rclpy.init(args=args)
    nodes: list[FormationAgentNode] = []
    status = 0
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
        executor = SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        while not all(node.finished for node in nodes):
            executor.spin_once(timeout_sec=0.5)
            for node in nodes:
                node.check()
        for node in nodes:
            node.wait_for_delivery()
    except (KeyboardInterrupt, ExternalShutdownException):
        status = 130
    except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
        print(f'formation_agent: {error}', file=sys.stderr, flush=True)
        traceback.print_exc(file=sys.stderr)
        status = 1
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return status


if __name__ == '__main__':
    sys.exit(main())
