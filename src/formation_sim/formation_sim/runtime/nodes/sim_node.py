"""The simulator node of the `exact` backend: the time keeper holding the exact world.

A `time_keeper.TimeKeeperNode` (discovery, Step, liveliness, Status and reports, failures; the
books in `run_book`, summary.json through `run_end`), as the coordinator is, that holds a
`SimulatorWorld` (a `world.World`): the exact world (`exact_world.ExactWorld`), every agent's
sensing service `/agent_<i>/sense`, the commands agents publish applied, and what tools want to
see (`sim_view.SimulatorView`): `/clock` (rounded to ns, for tools only), the exact state
`/formation/state` and `/formation/ground_truth` at a sample period (pure evaluations, the world
itself only advances from event to event), and `/formation/sensing_log`.

Lock-step protocol (docs/MESSAGES.md; `LockStep`): after discovery the simulator publishes Step 0 at t = 0;
every agent due at a step senses, commands, broadcasts and reports a Status; agents that receive
triggering information report again.  A step is settled when every due agent has reported its
trigger, every command sent has been applied and every triggering-information message sent has
been received (cumulative counters, so equality cannot be transient).  Then the world advances to
the smallest next time reported (the exact float, carried by the next Step) and the agents that
reported exactly that time trigger.

Wall-clock mode (`clock_mode:=realtime`, as on robots; `WallClock`): Step 0 carries the wall-clock epoch of
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
agent or the recorder lost, 5 an operator stopped the run (`/formation/stop`, `operator_stop`), 130
interrupted.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import NoReturn

import numpy as np
from geometry_msgs.msg import Accel, Twist
from rcl_interfaces.srv import SetParameters
from rclpy.event_handler import SubscriptionEventCallbacks
from std_msgs.msg import Float64MultiArray

from formation_agent.ros.parameters import DOUBLE, STRING, ParameterSpec
from formation_agent.ros.process import exit_process
from formation_msgs_py.codec import (
    check_array,
    check_sensing_request,
    decode_command,
    decode_trigger_info,
    encode_sensed_state,
    encode_step,
    sensing_refusal,
    tag_sensing_answer,
)
from formation_msgs_py.errors import MessageError, TagError
from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME, Step
from formation_msgs_py.qos import READER_QOS
from formation_msgs_py.tags import agent_writer
from formation_msgs_py.topics import SIMULATOR_NODE, command_topic, sense_service, trigger_info_topic
from formation_msgs_py.types import SensedState
from formation_sim.model.scenario import Scenario
from formation_sim.runtime.contract import SIMULATOR_FILE
from formation_sim.runtime.errors import CoordinatorError, DuplicateAgentError, StallError
from formation_sim.runtime.nodes import keeper_main
from formation_sim.runtime.nodes.exact_world import ExactWorld
from formation_sim.runtime.nodes.intruders import SensingCalls, intrusions, simulator_watched
from formation_sim.runtime.nodes.run_end import write_results  # noqa: F401 - likewise
from formation_sim.runtime.nodes.sim_view import SimulatorView, view_qos  # noqa: F401 - view_qos: docs/MESSAGES.md
from formation_sim.runtime.nodes.time_keeper import (
    TIME_KEEPER_PARAMETERS,
    TimeKeeperNode,
    graph_of,
    graph_writers,
    run_extra,
)
from formation_sim.sim.engine import due_twice
from formation_sim.sim.record import RunRecord

CLOCK_MODES = ('lockstep', 'realtime')
SimulatorError = CoordinatorError

SIMULATOR_PARAMETERS = (
    *TIME_KEEPER_PARAMETERS,
    ParameterSpec(
        name='clock_mode',
        type=STRING,
        default='lockstep',
        choices=CLOCK_MODES,
        description='lockstep: sim time from event to event, exact; realtime: the wall clock, as on robots',
    ),
    ParameterSpec(
        name='viz_period',
        type=DOUBLE,
        default=0.04,
        low=0.0,
        high=math.inf,
        high_open=True,
        description='/clock, ground truth and markers at most every this much sim time [s] (0: every sample)',
    ),
    ParameterSpec(
        name='stall_timeout',
        type=DOUBLE,
        default=60.0,
        low=0.0,
        low_open=True,
        description=(
            'a lock-step step not settled after this many seconds '
            "ends the run, naming every agent's last Status"
        ),
    ),
)
"""The simulator's parameters (`formation_sim --help`; docs/PARAMETERS.md)."""

RECORDER_LAG = 2
"""Steps the lock-step may run ahead of what a recorder has written (its heartbeat says which step).

Lock-step at full speed outruns a recorder (one Python process taking every message): on a loaded
2-core machine 3 runs of 4 lost hundreds of view and Status messages, the writers' keep-last
histories turning over before the recorder had them.  Held within a few steps of it, what is
outstanding stays far below the writers' depths (24 runs of 24 complete since, views kept deeper)."""


class SimulatorWorld:
    """The exact world of a distributed run (a `world.World`): the exact integration, every
    agent's sensing service, the tools' view; paced by its clock (`pacing`): the lock-step
    (`LockStep`) or the wall clock (`WallClock`)."""

    PARAMETERS: Sequence[ParameterSpec] = SIMULATOR_PARAMETERS
    COMMAND = 'formation_sim'
    PARAMS_FILE = SIMULATOR_FILE
    NODE_NAME = SIMULATOR_NODE
    DESCRIPTION = (
        'The simulator of a formation run (formation run, '
        "backend exact): the exact world, every agent's sensing "
        'service, the lock-step clock (or the wall clock), the '
        "tools' topics; writes summary.json and graph.json "
        'into out_dir.'
    )
    serves_sensing = True
    batched_spin = False  # one event per look: lock-step settles a step in the callback that completes it
    watched_writer = 'command'

    @staticmethod
    def problems(values: dict, scenario: Scenario) -> list[str]:
        return []

    @staticmethod
    def clock_mode_of(values: dict) -> str:
        return values['clock_mode']

    def __init__(self, keeper: TimeKeeperNode) -> None:
        """The exact world, its sampler, the tools' view of it and its clock, held by `keeper`."""
        self.keeper = keeper
        scenario = keeper.scenario
        self.viz_period = keeper.parameter_values['viz_period']
        # Moved and sampled as the engine does it, stopped where the engine stops.
        self.exact = ExactWorld(scenario, sample_period=keeper.sample_period, on_sample=self.on_sample)
        self.sampler = self.exact.sampler
        self.view = view = SimulatorView(
            keeper,
            scenario=scenario,
            velocities=self.exact.world.velocities,
            viz_period=self.viz_period,
            publish=keeper.publish,
        )
        keeper.tool_publishers = [
            view.state_pub,
            view.truth_pub,
            view.log_pub,
            view.clock_pub,
            keeper.scenario_pub,
            view.markers_pub,
        ]
        self.due_agents: set[int] = set()  # the agents due at the step (wall clock: all of them)
        self.sensing = Sensing(self)
        self.pacing: LockStep | WallClock = WallClock(self) if keeper.realtime else LockStep(self)

    def watch_agents(self) -> dict:
        """One command reader per agent: it applies the agent's commands, and its writer's DDS
        liveliness is the agent's sign of life."""
        keeper = self.keeper
        command_type = Accel if keeper.double else Twist
        return {
            i: keeper.create_subscription(
                command_type,
                command_topic(i, double=keeper.double),
                lambda msg, agent=i: self._on_command(msg, agent),
                READER_QOS,
                event_callbacks=SubscriptionEventCallbacks(
                    liveliness=lambda info, agent=i: keeper.on_agent_liveliness(agent, info)
                ),
            )
            for i in keeper.agents
        }

    def gaps(self) -> list[str]:
        return []

    def check_start(self) -> str:
        return ''

    def extra(self) -> dict:
        return {}

    def agent_failed(self, agent: int, failure: str) -> None:
        """Lock-step: its liveliness or the stall timeout decides what follows."""

    def stop_robots(self, *, why: str) -> list[int]:
        """The exact world has no robots: it stops with the final Step."""
        return []

    def stop_unreported_robots(self) -> None:
        """No robots."""

    @property
    def reached_time(self) -> float:
        return self.exact.world.time

    def begin(self) -> None:
        self.sampler.event()
        self.pacing.begin()

    def tick(self) -> None:
        self.pacing.tick()

    def after_status(self) -> None:
        self.pacing.after_status()

    def _on_command(self, msg, agent: int) -> None:
        keeper = self.keeper
        if keeper.finished:
            # The run is over (or stopped): the world no longer moves (a lock-step trigger whose
            # sensing was answered before a stop still completes: `LockStep.command_after_end`).
            self.pacing.command_after_end(agent)
            return
        if keeper.step is None:
            raise self.command_refused(agent)
        self.pacing.command(msg, agent)

    def command_refused(self, agent: int) -> SimulatorError:
        """Agent `agent`'s command came outside its triggering time: the protocol is broken."""
        step = self.keeper.step
        return SimulatorError(
            f'agent {agent} sent a command outside its triggering time '
            f'(step {None if step is None else step.index}, due {sorted(self.due_agents)})'
        )

    # -- samples (pure evaluations; they never move the world) --------------------------------

    def on_sample(self, t: float, x: np.ndarray, q: np.ndarray | None) -> None:
        """Each sample: every edge checked against Δ (ConnectivityLostError)."""
        self.keeper.book.check_connectivity(t, x)

    def publish_samples(self) -> None:
        """For tools: the samples not yet published (`SimulatorView.publish_samples`)."""
        self.view.publish_samples(self.sampler, finished=self.keeper.finished)

    def flush(self) -> None:
        self.publish_samples()

    def after_final_step(self, executor) -> None:
        """The world stopped with the final Step: nothing more to wait for."""

    # -- results --------------------------------------------------------------------------------

    def record(self) -> RunRecord:
        """The run as a `RunRecord` (the same schema as the in-process engine's)."""
        keeper = self.keeper
        return RunRecord(
            scenario=keeper.scenario,
            horizon=keeper.horizon,
            mode='distributed',
            # A trigger counts once its command has acted on the world (a run stopped early may
            # have sensed for a trigger that never completed).
            trigger_times={
                i: list(book.trigger_times[: book.commands_received]) for i, book in keeper.agents.items()
            },
            samples=self.sampler.samples(),
            messages_sent=sum(keeper.book.information_sent(i) for i in keeper.agents),
            sensing_calls=self.sensing.sensing_calls,
            wall_time=keeper.marks.since_start(keeper.marks.finished_at or time.monotonic()),
            extra={
                **run_extra(self.keeper, self.exact.world.time),
                **self.sensing.calls.extra(),
                **(
                    keeper.book.lateness({i: book.trigger_times for i, book in keeper.agents.items()})
                    if keeper.realtime
                    else {}
                ),
            },
        )


class LockStep:
    """The lock-step clock of the exact world `world` (the module's "Lock-step protocol"): a
    step settled, the world advances to the next time reported and the next Step goes out; an
    agent senses at its turn only; a step not settled within `stall_timeout` s ends the run."""

    def __init__(self, world: SimulatorWorld) -> None:
        self.world = world
        self.keeper = world.keeper
        self.stall_timeout = self.keeper.parameter_values['stall_timeout']
        self._last_advance = self.keeper.marks.created

    def begin(self) -> None:
        self.publish_step(Step(index=0, time=0.0, due=tuple(sorted(self.keeper.agents))))  # t^i_1 = 0

    def tick(self) -> None:
        if time.monotonic() - self._last_advance > self.stall_timeout:
            raise StallError(f'no progress for {self.stall_timeout} s at {self._describe_wait()}')

    def _describe_wait(self) -> str:
        keeper = self.keeper
        step = keeper.step
        recorders = (
            f'recorders at steps {keeper.recorders.recorded_steps or "none yet"} '
            f'(RECORDER_LAG {RECORDER_LAG}); '
            if keeper.extra_subscribers
            else ''
        )
        return (
            f'step {step.index} (t={step.time!r}, due {sorted(self.world.due_agents)}); {recorders}'
            + keeper.book.waiting_description()
        )

    def publish_step(self, step: Step) -> None:
        keeper = self.keeper
        keeper.step = step
        self.world.due_agents = set(step.due)
        keeper.book.mark_due(step.due, step.time)
        self._last_advance = time.monotonic()
        keeper.publish(keeper.step_pub, encode_step(step))

    def after_status(self) -> None:
        self._advance_if_settled()

    def sense(self, agent: int):
        """Agent `agent`'s sensing call in a step: answered once, at its turn."""
        world, keeper = self.world, self.keeper
        book, index = keeper.agents[agent], keeper.step.index
        if agent not in world.due_agents or book.sensed_at_step == index:
            return _out_of_turn(world, agent, index)
        book.sensed_at_step = index
        world.sensing.sensing_calls += 1
        sensed = sensed_state(world, agent)
        world.view.log_sensing(agent, index, world.exact.world.time)
        return encode_sensed_state(sensed)

    def command(self, msg, agent: int) -> None:
        """Agent `agent`'s command at its trigger: it acts from the step's time on."""
        world, keeper = self.world, self.keeper
        book = keeper.agents[agent]
        if agent not in world.due_agents or book.commands_received >= book.expected_triggers:
            raise world.command_refused(agent)
        # u_i (single) or u^d_i (double): the world closes q' = u^d_i - k3 q_i itself (uxdouble).
        world.exact.world.set_control(agent, decode_command(msg, keeper.scenario.dimension))
        book.commands_received += 1
        # The tools' samples up to this step go out now, while the agents plan (the simulator
        # would otherwise keep a sensing request of the step waiting).
        world.publish_samples()
        self._advance_if_settled()

    def command_after_end(self, agent: int) -> None:
        """A trigger whose sensing was answered before a stop still completes (its information is
        out, and in the bag): counted, its command acting from the last instant on moves nothing."""
        book, step = self.keeper.agents[agent], self.keeper.step
        due = agent in self.world.due_agents and book.sensed_at_step == step.index
        if due and book.commands_received < book.expected_triggers:
            book.commands_received += 1

    def _advance_if_settled(self) -> None:
        world, keeper = self.world, self.keeper
        if keeper.step is None or keeper.finished:
            return
        if not keeper.book.settled(keeper.step.index, world.due_agents):
            return
        if keeper.recorders.behind(keeper.step.index, recorders=keeper.extra_subscribers, lag=RECORDER_LAG):
            return  # lock-step waits: the recorder's next heartbeat comes back here
        t = keeper.step.time
        t_next, due = keeper.book.next_due(t)
        if t_next == t:
            # News at this instant put agents on their threshold already: they trigger at this
            # very instant, in a further step (as the in-process engine does).
            twice = [
                i for i in due if keeper.agents[i].trigger_times and keeper.agents[i].trigger_times[-1] == t
            ]
            if twice:
                raise SimulatorError(due_twice(twice[0], world.exact.threshold_model, t))
            keeper.steps += 1
            self.publish_step(Step(index=keeper.step.index + 1, time=t, due=due))
            return
        keeper.steps += 1
        if t_next > keeper.horizon:
            world.exact.advance(keeper.horizon)
            keeper.marks.finish(time.monotonic())
            keeper.graph = graph_of(keeper)
            keeper.finished = True
            self.publish_step(Step(index=keeper.step.index + 1, time=keeper.horizon, flags=STEP_FLAG_FINAL))
            world.publish_samples()
            return
        world.exact.advance(t_next)
        if (problem := world.exact.floor_problem()) is not None:
            raise SimulatorError(problem)
        self.publish_step(Step(index=keeper.step.index + 1, time=t_next, due=due))


class WallClock:
    """The wall clock of the exact world `world` (clock_mode realtime, as on robots, the module's
    "Wall-clock mode"): Step 0 carries the epoch of t = 0, the world advances to the wall-clock
    time of each sensing call and command as it arrives, the final Step goes at the horizon."""

    def __init__(self, world: SimulatorWorld) -> None:
        self.world = world
        self.keeper = world.keeper

    def begin(self) -> None:
        world, keeper = self.world, self.keeper
        keeper.retick(min(0.1, keeper.sample_period or 0.1))  # samples, the horizon: finer
        keeper.epoch = time.time()
        keeper.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=keeper.epoch)
        world.due_agents = set(keeper.agents)
        keeper.publish(keeper.step_pub, encode_step(keeper.step))
        world.publish_samples()

    def _now(self) -> float:
        """Sim time now on the wall clock, never before the world's time nor after the horizon."""
        return min(self.keeper.horizon, max(self.world.exact.world.time, time.time() - self.keeper.epoch))

    def event(self) -> float:
        """Advance the world to now (an event: a sensing or a command arrives)."""
        t = self._now()
        self.world.exact.advance(t)
        self.world.publish_samples()
        self.keeper.steps += 1
        return t

    def tick(self) -> None:
        world, keeper = self.world, self.keeper
        t = self._now()
        if t < keeper.horizon:
            world.sampler.grid_until(t)
        else:  # the horizon (the wall time is never past it)
            world.exact.advance(keeper.horizon)
            keeper.marks.finish(time.monotonic())
            keeper.graph = graph_of(keeper)
            keeper.step = Step(
                index=1, time=keeper.horizon, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=keeper.epoch
            )
            keeper.publish(keeper.step_pub, encode_step(keeper.step))
            keeper.finished = True
        world.publish_samples()

    def after_status(self) -> None:
        """The wall clock waits for no step to settle."""

    def sense(self, agent: int):
        """Agent `agent`'s sensing call, answered at the wall-clock time it arrives."""
        world = self.world
        t = self.event()
        # A trigger may follow (its Status may come before its information).
        self.keeper.agents[agent].expected_triggers += 1
        world.sensing.calls.asked(agent, t)  # a trigger once the agent's information stamped t follows
        world.view.log_sensing(agent, 0, t)
        return encode_sensed_state(sensed_state(world, agent))

    def command(self, msg, agent: int) -> None:
        """Agent `agent`'s command: it acts from its arrival on."""
        control = decode_command(msg, self.keeper.scenario.dimension)
        self.event()
        self.world.exact.world.set_control(agent, control)
        self.keeper.agents[agent].commands_received += 1

    def command_after_end(self, agent: int) -> None:
        """After the horizon the world no longer moves: nothing counts."""


class Sensing:
    """Every agent's sensing service `/agent_<i>/sense` on the exact world `world`: the state it
    senses (`sensed_state`), at its turn (`LockStep.sense`) or as the call arrives
    (`WallClock.sense`: the agents' triggering information says which calls were triggers); a
    call out of turn refused (`_out_of_turn`)."""

    def __init__(self, world: SimulatorWorld) -> None:
        keeper = world.keeper
        self.world = world
        self.sensing_calls = 0  # the calls answered for a trigger
        self.calls = SensingCalls(keeper.agents)  # which calls were triggers, which foreign (issue 28)
        self._services = [
            keeper.create_service(SetParameters, sense_service(i), _answers(world, i)) for i in keeper.agents
        ]
        self._info_subs = _trigger_readers(world) if keeper.realtime else {}

    def on_sense(self, agent: int):
        world, keeper = self.world, self.world.keeper
        if keeper.finished:  # asked after the end: the final state, not counted
            return encode_sensed_state(sensed_state(world, agent))
        if keeper.step is None:  # before step 0: nobody's turn
            return _out_of_turn(world, agent, -1)
        return world.pacing.sense(agent)


def sensed_state(world: SimulatorWorld, agent: int) -> SensedState:
    """What `agent` senses now: its neighbours' relative states, and with the safety layer the
    other robots within its sensing radius, the very floats the engine hands
    `trigger(nearby=...)` (`World.nearby`, docs/SAFETY.md)."""
    neighbours = world.keeper.agents[agent].neighbours
    sensed = world.exact.world.sense(agent, neighbours)
    safety = world.keeper.scenario.safety
    if safety is None:
        return sensed
    return replace(sensed, nearby=world.exact.world.nearby(agent, safety.sensing_radius, exclude=neighbours))


def _trigger_readers(world: SimulatorWorld) -> dict:
    """Wall clock: per agent, a reader of its triggering information to its first neighbour,
    whose stamps say which sensing calls were its triggers (`SensingCalls`)."""
    return {
        i: world.keeper.create_subscription(
            Float64MultiArray,
            trigger_info_topic(i, min(book.neighbours)),
            lambda msg, agent=i: _on_trigger_info(world, msg, agent),
            READER_QOS,
        )
        for i, book in world.keeper.agents.items()
    }


def _on_trigger_info(world: SimulatorWorld, msg, agent: int) -> None:
    """Agent `agent`'s triggering information: the sensing call answered at its stamp was its
    trigger (a message that is not its layout, or not its own, or without the run's valid tag,
    changes nothing: agent j refuses and counts it)."""
    try:
        check_array(
            world.keeper.verifier, trigger_info_topic(agent, min(world.keeper.agents[agent].neighbours)), msg
        )
    except TagError:
        return
    try:
        info = decode_trigger_info(msg)
    except MessageError:
        return  # the agents refuse and count it; the run's triggers are the agents' own stamps
    if info.sender == agent and world.sensing.calls.triggered(agent, info.stamp):
        world.keeper.agents[agent].trigger_times.append(info.stamp)
        world.sensing.sensing_calls += 1


def _answers(world: SimulatorWorld, agent: int):
    """The callback of agent `agent`'s sensing service."""
    return lambda request, response: _sense_call(world, agent, request)


def _sense_call(world: SimulatorWorld, agent: int, request):
    """A call of agent `agent`'s sensing service: with the run's key refused unless it carries
    agent `agent`'s tag (`_untagged_call`), and answered with the simulator's tag."""
    answer = _untagged_call(world, agent, request)
    if answer is None:
        answer = world.sensing.on_sense(agent)
    return tag_sensing_answer(answer, world.keeper.signer, sense_service(agent))


def _untagged_call(world: SimulatorWorld, agent: int, request):
    """The refusal of a sensing call for `agent` without agent `agent`'s valid tag (the run's key
    only; else None): counted as a foreign call and as a foreign message, the caller named from
    the graph in the first warnings; never a trigger, and the run goes on."""
    keeper, calls = world.keeper, world.sensing.calls
    try:
        check_sensing_request(keeper.verifier, sense_service(agent), request, caller=agent_writer(agent))
    except TagError as error:
        calls.foreign_call(agent)
        detail = str(error)
        if calls.foreign[agent] <= 3 and 'stranger' in (found := _callers(world, agent)):
            detail = f'{found["stranger"].text()}: {detail}'
        keeper.reject(sense_service(agent), error.reason, detail)
        return sensing_refusal(f'{error}: refused')
    return None


def _callers(world: SimulatorWorld, agent: int) -> dict:
    """What the graph says of the callers of `agent`'s sensing service (`intrusions` by kind)."""
    (watched,) = [w for w in simulator_watched(world.keeper.scenario) if w.mangled and w.agent == agent]
    return {i.kind: i for i in intrusions(watched, graph_writers(world.keeper, watched))}


def _out_of_turn(world: SimulatorWorld, agent: int, index: int):
    """Lock-step: a sensing call for `agent` that is not its turn (`index`: the step).  Agent
    `agent`'s own is a protocol violation that ends the run; but without the run's key any node
    can call the service (a request names no caller), so the graph is asked first: with a
    stranger calling it, the call is refused (or, at the agent's own step, answered again with
    the same state) and counted as foreign, the stranger named; two processes claiming the agent
    end the run.  With the key a stranger's call never comes here (`_untagged_call`)."""
    due = agent in world.due_agents
    reason = f'agent {agent} is not due to sense at step {index} (due: {sorted(world.due_agents)})'
    found = _callers(world, agent)
    if 'duplicate' in found:
        duplicate = found['duplicate']
        world.keeper.failure = DuplicateAgentError(
            duplicate.text(), nodes=[w.node for w in duplicate.writers], agents=[agent]
        )
        return sensing_refusal(str(world.keeper.failure))
    if 'stranger' not in found:
        world.keeper.failure = SimulatorError(reason)
        return sensing_refusal(reason)
    world.sensing.calls.foreign_call(agent)
    if world.sensing.calls.foreign[agent] <= 3:
        world.keeper.get_logger().warning(
            f'{found["stranger"].text()}: a call out of turn ({reason}) counted as foreign'
        )
    if due and world.keeper.step is not None and world.keeper.agents[agent].sensed_at_step == index:
        return encode_sensed_state(sensed_state(world, agent))  # the same again
    return sensing_refusal(f'{reason}: refused')


class FormationSimulatorNode(TimeKeeperNode):
    """The simulator: a time keeper holding the exact world (`SimulatorWorld`, its `world`)."""

    def __init__(self, *, scenario: Scenario | None = None, parameter_overrides=None, context=None) -> None:
        super().__init__(
            world_class=SimulatorWorld,
            scenario=scenario,
            parameter_overrides=parameter_overrides,
            context=context,
        )


def main(args: Sequence[str] | None = None) -> int:
    """The simulator until its run ends (`keeper_main.main`); its exit status."""
    return keeper_main.main(args, world_class=SimulatorWorld)


def entry_point() -> NoReturn:
    """The `formation_sim` console script: `main()`, then `exit_process` (a plain entry point's
    `sys.exit(main())` would run the interpreter's finalization and C++ static destructors after
    rclpy's shutdown)."""
    exit_process(main())


if __name__ == '__main__':
    entry_point()
