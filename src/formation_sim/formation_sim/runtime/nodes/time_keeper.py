"""The time keeper of a distributed run, whatever its world: `TimeKeeperNode`.

It holds a world (`world.World`): the robots of a robot run (`coordinator.RobotWorld`, the node
`formation_coordinator`) or the exact world of the simulator (`sim_node.SimulatorWorld`, the node
`formation_simulator`), and the run's life cycle (docs/MESSAGES.md):

- **discovery**: Step 0 goes once every agent says it is ready and every endpoint of the node is
  matched (`extra_subscribers`, `step_listeners`, the world's own); a progress line says what is
  still missing, and a `DiscoveryError` after `discovery_timeout`;
- **the run**: the agents' Status and reports go into `run_book.RunBook`; agents and recorders are
  watched (DDS liveliness, `RunBook` and `run_book.RecorderBook` say when one is lost);
- **its end**: at the horizon (the world's), or early (`fail` notes why, `end_now` sends the agents
  home); `keeper_main.main` then drives `run_end` (final reports, delivery, summary.json).

What the keeper asks of its world, and when, is the table of `world`.
"""

from __future__ import annotations

import contextlib
import math
import time

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node, NodeNameNonExistentError
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, String

from formation_agent.ros.errors import ParameterError
from formation_agent.ros.parameters import DOUBLE, INTEGER, STRING, ParameterSpec, read_parameters
from formation_agent.ros.process import EXECUTORS
from formation_msgs_py.codec import (
    check_array,
    check_string,
    decode_agent_report,
    decode_status,
    encode_step,
    tag_array,
)
from formation_msgs_py.codec import tag_refused as refused_tag
from formation_msgs_py.errors import KeyFileError, MessageError
from formation_msgs_py.lockstep import DISCOVERY_STEP, STEP_FLAG_FINAL, STEP_FLAG_REALTIME, Step
from formation_msgs_py.qos import READER_QOS, SIMULATOR_QOS
from formation_msgs_py.tags import read_key, run_tags
from formation_msgs_py.topics import RECORDER_TOPIC, REPORT_TOPIC, SCENARIO_TOPIC, STATUS_TOPIC, STEP_TOPIC
from formation_sim.model.errors import ScenarioError
from formation_sim.model.scenario import Scenario, dump_scenario_text, load_scenario
from formation_sim.runtime.errors import DiscoveryError, ForeignWriterError, KeeperFrozenError
from formation_sim.runtime.nodes.intruders import (
    TOPICS_PER_LOOK,
    FreezeWatch,
    GraphWatch,
    Writer,
    foreign_information_error,
    information_excess,
    protocol_watched,
    robot_watched,
    simulator_watched,
)
from formation_sim.runtime.nodes.operator_stop import OperatorStop
from formation_sim.runtime.nodes.run_book import (
    RecorderBook,
    RunBook,
    RunMarks,
    add_what_followed,
    failure_extra,
    ids_text,
)
from formation_sim.runtime.nodes.world import World
from formation_sim.sim.engine import safety_extra

GRAPH_LOOK_PERIOD = 1.0  # [s] between a keeper's looks at its run's writers (`intruders.GraphWatch`)
TICK_PERIOD = 0.1  # [s] the keeper's tick: discovery, lost peers, the world's checks
EARLY_FINAL = "it left on a final Step its run's keeper did not send (forged, or another run's)"
LOOK_BUDGET = 0.02  # [s] a look at the graph stops after this long (2 % of a core at one look a second)
LOOK_ALL_MOST = 256  # topics looked at all at once just before step 0 (a large team: a slice, as later)

DISCOVERY_PROGRESS_AFTER = 2.0  # [s] a discovery that takes longer says what it waits for (progress lines)

TIME_KEEPER_PARAMETERS = (
    ParameterSpec(
        name='scenario',
        type=STRING,
        description='the scenario: a built-in name or a YAML path (formation run writes DIR/scenario.yaml)',
    ),
    ParameterSpec(
        name='horizon',
        type=DOUBLE,
        default=0.0,
        low=0.0,
        high=math.inf,
        high_open=True,
        description="the run ends at this time [s] (0: the scenario's horizon)",
    ),
    ParameterSpec(
        name='out_dir',
        type=STRING,
        default='',
        description="where summary.json and graph.json go ('': nowhere)",
    ),
    ParameterSpec(
        name='sample_period',
        type=DOUBLE,
        default=0.01,
        low=0.0,
        high=math.inf,
        high_open=True,
        description=(
            'spacing of the formation samples in summary.json [s] '
            '(simulator: 0 = at events only; robots: > 0)'
        ),
    ),
    ParameterSpec(
        name='extra_subscribers',
        type=INTEGER,
        default=0,
        low=0,
        description=(
            "listeners besides the run's own nodes (a recorder) that must match every topic before step 0"
        ),
    ),
    ParameterSpec(
        name='step_listeners',
        type=INTEGER,
        default=0,
        low=0,
        description=(
            'nodes outside the run (monitors, fault injectors) '
            'that must hear every Step: step 0 waits for them'
        ),
    ),
    ParameterSpec(
        name='progress_period',
        type=DOUBLE,
        default=1.0,
        low=0.0,
        description='a progress line on stdout every this many seconds (0: none)',
    ),
    ParameterSpec(
        name='discovery_timeout',
        type=DOUBLE,
        default=120.0,
        low=0.0,
        low_open=True,
        description='give up when the run is not connected after this long [s]',
    ),
    ParameterSpec(
        name='executor',
        type=STRING,
        default='events',
        choices=EXECUTORS,
        description='rclpy executor: events (EventsExecutor) or single (SingleThreadedExecutor)',
    ),
    ParameterSpec(
        name='key_file',
        type=STRING,
        default='',
        description=(
            "the run's key (docs/HOSTILE_TRAFFIC.md, Tags; formation run writes DIR/run.key, mode 0600): "
            "Steps are tagged, Statuses and reports without a valid tag refused; '': no tags"
        ),
    ),
)
"""What the coordinator and the simulator share."""


class TimeKeeperNode(Node):
    """The life cycle of a distributed run: discovery, step 0, the run watched, its end; the world
    is the object it holds (`self.world`, a `world.World` made from `world_class`)."""

    def __init__(
        self,
        *,
        world_class: type[World],
        scenario: Scenario | None = None,
        parameter_overrides: list[Parameter] | None = None,
        context=None,
    ) -> None:
        node_name = world_class.NODE_NAME
        super().__init__(node_name, parameter_overrides=parameter_overrides or [], context=context)
        values, scenario = _checked_parameters(self, world_class, scenario)
        self.parameter_values = values
        self.signer, self.verifier = run_tags(values['key_file'], writer=node_name)  # the run's tag
        self.out_dir = values['out_dir']
        self.sample_period = values['sample_period']
        self.extra_subscribers = values['extra_subscribers']
        # Nodes outside the run that must hear every Step (monitors, fault injectors): step 0 waits.
        self.step_listeners = values['step_listeners']
        self.progress_period = values['progress_period']
        self.discovery_timeout = values['discovery_timeout']
        self.executor_kind = values['executor']
        self.clock_mode = world_class.clock_mode_of(values)
        self.realtime = self.clock_mode == 'realtime'
        self.scenario = scenario
        self.horizon = scenario.horizon if values['horizon'] <= 0.0 else values['horizon']
        self.double = scenario.dynamics == 'double'
        self.book = RunBook(scenario, realtime=self.realtime, serves_sensing=world_class.serves_sensing)
        self.agents = self.book.agents

        self.step_pub = self.create_publisher(Float64MultiArray, STEP_TOPIC, SIMULATOR_QOS)
        # For tools: the scenario once (so a bag is self-contained).
        self.scenario_pub = self.create_publisher(String, SCENARIO_TOPIC, SIMULATOR_QOS)
        self.tool_publishers = [self.scenario_pub]
        self.status_sub, self.report_sub = agent_readers(
            self, on_status=self._on_status, on_report=self._on_report
        )
        # The recorders' heartbeat writers (one per extra subscriber): their liveliness says the
        # recorder still takes and acknowledges what the run publishes.  A frozen recorder lets
        # every reliable keep-last writer of the run overwrite what it did not acknowledge.
        self.recorder_sub = self.create_subscription(
            String,
            RECORDER_TOPIC,
            self._on_recorder,
            READER_QOS,
            event_callbacks=SubscriptionEventCallbacks(liveliness=self._on_recorder_liveliness),
        )
        self.recorders = RecorderBook()
        self.published: dict[str, int] = {}  # topic -> messages this node published there

        self.step: Step | None = None
        self.finished = False
        self.failure: Exception | None = None
        self.reached: float | None = None  # the run's time at its final Step, once sent
        self.steps = 0
        self.marks = RunMarks(created=time.monotonic())
        self._last_progress = self.marks.created
        self.epoch = 0.0
        self.graph: dict = {}
        self.failure_info: dict | None = None  # extra.failure of summary.json once the run failed
        # Agents that stopped on an error after the final Step at the horizon went out (a pose gone
        # stale past the end while the Step was on its way): extra.after_end, not a failure.
        self.after_end: dict[int, str] = {}
        self.world: World = world_class(self)  # its publishers (the tools' among `tool_publishers`), readers
        # One writer per agent whose DDS liveliness is the agent's sign of life.
        self.agent_writers = self.world.watch_agents()
        self._timer = self.create_timer(TICK_PERIOD, self._tick)
        self.graph_watch, self.freeze, self._graph_timer = watch_intruders(self)
        self.operator_stop = OperatorStop(self)  # /formation/stop, the run's emergency stop
        self.marks.mark('node_up', time.monotonic())
        self._next_discovery_progress = self.marks.created + DISCOVERY_PROGRESS_AFTER

    # -- the run's life cycle: discovery, step 0, the run, its end ------------------------------

    def _tick(self) -> None:
        now = time.monotonic()
        self.freeze.tick(now)
        if not self.finished:
            self._check_lost(now)
        if self.step is None:
            self._discovery_tick(now)
            return
        if self.finished:
            return
        self.world.tick()
        if self.progress_period > 0.0 and now - self._last_progress >= self.progress_period:
            self._last_progress = now
            self.print_progress()

    def _discovery_tick(self, now: float) -> None:
        """Before step 0: start once connected, give up after the discovery timeout, else say what
        is missing."""
        if self.book.all_ready() and self._connected():  # (cheap while agents are missing)
            self._start()
        elif now - self.marks.created > self.discovery_timeout:
            raise DiscoveryError(
                f'discovery did not complete within {self.discovery_timeout} s; still missing: '
                + '; '.join(discovery_gaps(self))
            )
        elif self.progress_period > 0.0 and now >= self._next_discovery_progress:
            self._next_discovery_progress = now + self.progress_period
            self._say(
                f'progress discovery {now - self.marks.created:.0f} s: waiting for '
                + '; '.join(discovery_gaps(self))
            )

    def _on_announcement(self, status) -> None:
        """An agent's discovery Status: step 0 goes at once when it was the last one missing."""
        now = time.monotonic()
        self.book.note_announcement(status)
        if self.book.all_announced():
            self.marks.mark('agents_announced', now, once=True)
        if self.book.all_ready():
            self.marks.mark('agents_ready', now, once=True)
            if self._connected():
                self._start()

    def _connected(self) -> bool:
        return not discovery_gaps(self)

    def _start(self) -> None:
        if self.operator_stop.requested:  # an operator stopped the run before it started: no Step 0
            return
        note = self.world.check_start()  # raises before anything is sent when the world breaks a hypothesis
        self.marks.start(time.monotonic())
        if self.progress_period > 0.0:
            self._say(
                f'progress discovery done in {self.marks.discovery_wall_time:.1f} s; '
                f'{note}t=0 ({self.clock_mode})'
            )
        look_at_graph(self, everything=True)  # no step 0 with two processes claiming an agent
        self.publish(
            self.scenario_pub, String(data=dump_scenario_text(self.scenario.replace(horizon=self.horizon)))
        )
        self.world.begin()

    def end_now(self) -> None:
        """The run stops early at this instant (after step 0): a final Step sends the agents home."""
        if self.finished:  # the final Step went out already (at once, when the run failed)
            return
        flags = STEP_FLAG_FINAL | (STEP_FLAG_REALTIME if self.realtime else 0)
        self.reached = self.reached_time
        self.marks.finish(time.monotonic())
        if not self.graph and not self.realtime:  # the graph now, before the final Step sends agents home
            self.graph = graph_of(self)
        self.finished = True
        self.publish(
            self.step_pub,
            encode_step(Step(index=self.step.index + 1, time=self.reached, flags=flags, epoch=self.epoch)),
        )
        if not self.graph:  # on the wall clock, the final Step first: agents leave after their reports
            self.graph = graph_of(self)

    def fail(self, error: BaseException) -> None:
        """Note why the run stops early (extra.failure of the summary): the first cause only."""
        if self.failure_info is None:
            self.failure_info = failure_extra(
                error,
                interrupted=isinstance(error, (KeyboardInterrupt, ExternalShutdownException)),
                time=self.reached_time,
                step=None if self.step is None else self.step.index,
                wall_time=self.marks.since_start(time.monotonic()),  # since t = 0 began
                detected_by=self.get_name().removeprefix('formation_'),
            )

    def note_what_followed(self) -> None:
        """After the first cause: the agents that then stopped on errors of their own (their
        final reports), in `extra.failure.followed` and after the first cause in its message."""
        add_what_followed(self.failure_info, self.book.failures())

    # -- the agents' messages -------------------------------------------------------------------

    def publish(self, publisher, msg) -> None:
        msg = tag_array(msg, self.signer, STEP_TOPIC) if publisher is self.step_pub else msg
        publisher.publish(msg)
        self.published[publisher.topic_name] = self.published.get(publisher.topic_name, 0) + 1

    def _on_status(self, msg: Float64MultiArray) -> None:
        try:
            status = decode_status(msg)
        except MessageError as error:  # not from a working agent: the stall timeout covers the rest
            self.reject(STATUS_TOPIC, error.reason, str(error))
            return
        self.book.accept_status(status)
        if self.step is None and status.step_index == DISCOVERY_STEP:
            self._on_announcement(status)
            return
        self.world.after_status()

    def _on_report(self, msg: String) -> None:
        try:
            report = decode_agent_report(msg)
        except MessageError as error:
            self.reject(REPORT_TOPIC, error.reason, str(error))
            return
        if (refusal := self.book.accept_report(report)) is not None:
            self.reject(REPORT_TOPIC, 'field', refusal)
            return
        if report.final and self.step is not None and (report.failure or not self.finished):
            if not self.finished:  # no failure named: it left on a final Step from elsewhere
                self.world.agent_failed(report.agent, report.failure or EARLY_FINAL)
            elif self.failure_info is None:  # after the run reached its end: no fault of the run
                self.after_end[report.agent] = report.failure

    def reject(self, topic: str, reason: str, detail: str) -> None:
        count = self.book.count_rejection(reason)
        if count <= 3 or count % 100 == 0:
            self.get_logger().warning(f'rejected a message on {topic} ({reason}, {count} so far): {detail}')

    @property
    def rejected(self) -> dict[str, int]:
        return self.book.rejected

    def final_reports_in(self) -> bool:
        return self.book.final_reports_in()

    # -- watching peers: agents and recorders (the books say when one is lost) ------------------

    def on_agent_liveliness(self, agent: int, info) -> None:
        self.book.note_liveliness(
            agent,
            alive_count=info.alive_count,
            not_alive_count_change=info.not_alive_count_change,
            # After a failure's final Step, an agent that dies is lost (no final report to wait for).
            finished=self.finished and self.failure_info is None,
            now=time.monotonic(),
        )

    def _on_recorder_liveliness(self, info) -> None:
        self.recorders.note_liveliness(
            alive_count=info.alive_count,
            not_alive_count_change=info.not_alive_count_change,
            now=time.monotonic(),
        )

    def _on_recorder(self, msg: String) -> None:
        """A recorder's heartbeat: the latest step it has written (lock-step flow control)."""
        if (refusal := self.recorders.accept_heartbeat(msg.data)) is not None:
            self.reject(RECORDER_TOPIC, 'field', refusal)
            return
        self.world.after_status()

    def _check_lost(self, now: float) -> None:
        """Stop the run once the recorder or an agent is lost (the books say when that is)."""
        started, where = self.step is not None, self.where()
        error = self.recorders.lost_error(now, started=started, where=where) or self.book.lost_error(
            now, started=started, where=where
        )
        if error is not None:
            raise error

    @property
    def reached_time(self) -> float:
        """The run's time now (the world's)."""
        return self.world.reached_time

    def retick(self, period: float) -> None:
        """The keeper's tick every `period` s from now on (a wall-clock simulator samples finer)."""
        self.destroy_timer(self._timer)
        self._timer = self.create_timer(period, self._tick)

    def where(self) -> str:
        return (
            'during discovery'
            if self.step is None
            else f'at t={self.reached_time!r} (step {self.step.index})'
        )

    # -- progress and results -------------------------------------------------------------------

    def _say(self, line: str) -> None:
        """A line on stdout, where `formation run` shows the progress lines."""
        with contextlib.suppress(OSError):  # nobody reads any more (the orchestrator died)
            print(line, flush=True)

    def print_progress(self) -> None:
        events = sum(len(book.trigger_times) for book in self.agents.values())
        try:
            print(
                f'progress t={self.reached_time:.6f} horizon={self.horizon:g} '
                f'events={events} steps={self.steps} '
                f'wall={self.marks.since_start(time.monotonic()):.1f}s',
                flush=True,
            )
        except OSError:  # nobody reads any more (the orchestrator died): carry on without progress
            self.progress_period = 0.0

    def mark(self, name: str) -> None:
        """Note the time the run reached `name` (extra.timestamps)."""
        self.marks.mark(name, time.monotonic())

    def delivery_publishers(self, *, with_steps: bool) -> list:
        """The writers whose readers must acknowledge everything before the node goes: the tools'
        topics and, `with_steps`, the Steps."""
        return [self.step_pub, *self.tool_publishers] if with_steps else list(self.tool_publishers)


def watch_intruders(node: TimeKeeperNode) -> tuple:
    """Strangers and duplicates in the graph (a `GraphWatch`, looked at every GRAPH_LOOK_PERIOD by
    the timer returned), and the keeper's own freezes (a `FreezeWatch`, ticked by its tick): issue
    28; (the graph watch, the freeze watch, the timer)."""
    return (
        GraphWatch(watched_topics(node)),
        FreezeWatch(period=TICK_PERIOD),
        node.create_timer(GRAPH_LOOK_PERIOD, lambda: look_at_graph(node)),
    )


def watched_topics(node: TimeKeeperNode) -> list:
    """The topics whose writers `node` watches (`intruders.GraphWatch`): the protocol's, and the
    world's (the simulator's plant and sensing, or the robots')."""
    keeper = node.get_fully_qualified_name()
    world = (
        simulator_watched(node.scenario)
        if node.world.serves_sensing
        else robot_watched(node.scenario, keeper=keeper)
    )
    return protocol_watched(node.scenario, keeper=keeper) + world


def look_at_graph(node: TimeKeeperNode, *, everything: bool = False) -> None:
    """A look at the writers of the next slice of watched topics (at most TOPICS_PER_LOOK, within
    LOOK_BUDGET s; `everything`: all of them, up to LOOK_ALL_MOST); each stranger or duplicate
    found is logged once, and one that changes the run raises (ForeignWriterError: the run stops,
    naming it); on the wall clock, so do agents that took more information than was sent."""
    if node.finished:
        return
    watch = node.graph_watch
    everything = everything and len(watch.watched) <= LOOK_ALL_MOST
    until = time.monotonic() + LOOK_BUDGET
    for _ in range(len(watch.watched) if everything else TOPICS_PER_LOOK):
        if not everything and time.monotonic() > until:
            break  # a graph of thousands of endpoints answers slower: the rest at the next look
        (watched,) = watch.due(1)
        _look_at(node, watched)
    if (error := watch.error()) is not None:
        raise error
    if node.realtime and node.step is not None:  # lock-step: RunBook.settled counts them exactly
        statuses = (book.status for book in node.agents.values())
        if (excess := information_excess(statuses, slack=2 * len(node.scenario.edges))) is not None:
            raise foreign_information_error(*excess, watch)


def graph_writers(node, watched) -> list[Writer]:
    """The writers of `watched.topic` in `node`'s ROS graph now (a service's request or reply
    topic looked up as is: `watched.mangled`)."""
    return [
        Writer(node=f'{i.node_namespace.rstrip("/")}/{i.node_name}', gid=bytes(i.endpoint_gid).hex())
        for i in node.get_publishers_info_by_topic(watched.topic, no_mangle=watched.mangled)
    ]


def _look_at(node: TimeKeeperNode, watched) -> None:
    """The writers of `watched.topic` in the graph now, noted by the node's watch (each new
    intrusion logged)."""
    writers = graph_writers(node, watched)
    for intrusion in node.graph_watch.note(watched, writers, now=time.monotonic()):
        node.get_logger().warning(intrusion.text())


def blamed(node: TimeKeeperNode, error: BaseException) -> BaseException:
    """`error` with its cause named first (issue 28): the keeper's own freeze (a KeeperFrozenError),
    else the strangers in the graph, every watched topic looked at once more (up to LOOK_ALL_MOST):
    a stranger the slices had not reached yet is named too (a second server of agent 2's sensing
    that answered at step 41 was not, and the failure named only the answer's missing tag)."""
    error = node.freeze.blame(error, time.monotonic(), who=node.get_name().removeprefix('formation_'))
    if not isinstance(error, KeeperFrozenError):
        with contextlib.suppress(Exception):  # a graph no longer there names nobody more
            for watched in list(node.graph_watch.watched)[:LOOK_ALL_MOST]:
                _look_at(node, watched)
    if node.graph_watch.found and not isinstance(error, ForeignWriterError) and error.args:
        error.args = (node.graph_watch.blame(str(error)), *error.args[1:])
    return error


def agent_readers(node: TimeKeeperNode, *, on_status, on_report) -> tuple:
    """The keeper's readers of the agents' Statuses (to `on_status`) and reports (to `on_report`):
    what comes without the run's valid tag is refused first (`tag_refused`)."""
    return (
        node.create_subscription(
            Float64MultiArray,
            STATUS_TOPIC,
            lambda msg: _tagged(node, STATUS_TOPIC, msg, on_status),
            READER_QOS,
        ),
        node.create_subscription(
            String, REPORT_TOPIC, lambda msg: _tagged(node, REPORT_TOPIC, msg, on_report), READER_QOS
        ),
    )


def _tagged(node: TimeKeeperNode, topic: str, msg, then) -> None:
    """`then(msg)` unless `msg` lacks the run's valid tag (a Status array, a report string)."""
    if not tag_refused(node, topic, msg, check_array if topic == STATUS_TOPIC else check_string):
        then(msg)


def tag_refused(node: TimeKeeperNode, topic: str, msg, check) -> bool:
    """Whether `msg` lacks the run's valid tag for `topic` (`codec.tag_refused`, `check`:
    codec.check_array or check_string): refused and counted by the keeper."""
    return refused_tag(node.verifier, topic, msg, node.reject, check=check)


def _checked_parameters(
    node: TimeKeeperNode, world_class: type[World], scenario: Scenario | None
) -> tuple[dict, Scenario]:
    """Every parameter of `node` read and every rule checked before anything is set up: one
    ParameterError names every problem (the command exits 2, nothing started, the node
    destroyed); else (the values, the scenario)."""
    specs = [
        spec for spec in world_class.PARAMETERS if not (spec.name == 'scenario' and scenario is not None)
    ]
    values, problems = read_parameters(node, specs)
    if values.get('key_file'):
        try:
            read_key(values['key_file'])
        except KeyFileError as error:
            problems.append(str(error))
    if scenario is None and 'scenario' in values:
        try:
            scenario = load_scenario(values['scenario'])
        except ScenarioError as error:
            problems.append(f"parameter 'scenario' (string): {error}")
    if scenario is not None:
        if scenario.dimension > 3:
            problems.append(
                f'distributed runs carry commands in geometry_msgs: p <= 3, got p = {scenario.dimension}'
            )
        problems += world_class.problems(values, scenario)
    if problems:
        name = node.get_fully_qualified_name()
        node.destroy_node()  # nothing of it outlives the refusal
        raise ParameterError(name, problems)
    return values, scenario


def graph_of(node) -> dict:
    """Publishers, subscriptions, services and clients of every node in the graph `node` sees
    (graph.json).

    Taken at the final Step, while every agent is still there (and, for a run that stops
    early, when it stops), not at step 0: 1000 agents' graph takes seconds to walk.  A node that
    leaves between the listing and the look at its endpoints (an agent stopped by a signal as the
    run stops) is not in the graph any more: left out (before, the error aborted the end of the
    run, and the robot of a killed agent got no zero command from the coordinator)."""
    graph = {}
    for name, namespace in node.get_node_names_and_namespaces():
        try:
            endpoints = {
                what: sorted(topic for topic, _ in look(name, namespace))
                for what, look in (
                    ('publishers', node.get_publisher_names_and_types_by_node),
                    ('subscriptions', node.get_subscriber_names_and_types_by_node),
                    ('services', node.get_service_names_and_types_by_node),
                    ('clients', node.get_client_names_and_types_by_node),
                )
            }
        except NodeNameNonExistentError:  # it left meanwhile
            continue
        graph[f'{namespace.rstrip("/")}/{name}'] = endpoints
    return graph


def discovery_gaps(node: TimeKeeperNode) -> list[str]:
    """What discovery of `node`'s run still waits for (empty: step 0 can go)."""
    n, extra = len(node.agents), node.extra_subscribers
    gaps = []

    def count(what: str, have: int, want: int) -> None:
        if have < want:
            gaps.append(f'{what} {have}/{want}')

    count(f'{STEP_TOPIC} readers', node.step_pub.get_subscription_count(), n + extra + node.step_listeners)
    for pub in node.tool_publishers:
        count(f'{pub.topic_name} readers', pub.get_subscription_count(), extra)
    count(f'{STATUS_TOPIC} writers', node.status_sub.get_publisher_count(), n)
    count(f'{REPORT_TOPIC} writers', node.report_sub.get_publisher_count(), n)
    count(f'{RECORDER_TOPIC} writers (recorders)', node.recorder_sub.get_publisher_count(), extra)
    unmatched = [i for i, sub in node.agent_writers.items() if sub.get_publisher_count() < 1]
    expired = [i for i, book in node.agents.items() if book.lost is not None]
    for what, agents in (
        (f'agents whose {node.world.watched_writer} writer is not matched', unmatched),
        ('agents whose liveliness lease expired', expired),
        ('agents not ready (their own endpoints unmatched)', node.book.not_ready()),
    ):
        if agents:
            gaps.append(f'{what}: {ids_text(agents)}')
    return gaps + node.world.gaps()


def run_extra(node: TimeKeeperNode, reached: float) -> dict:
    """summary.json's `extra` common to every coordinator: clock, steps, failure, messages."""
    return {
        'clock': node.clock_mode,
        'steps': node.steps,
        'discovery_wall_time': node.marks.discovery_wall_time,
        'timestamps': node.marks.timestamps(offset=time.time() - time.monotonic()),
        'reached_time': reached,
        'failure': node.failure_info,
        **node.world.extra(),
        **node.graph_watch.extra(),
        **(
            {'after_end': {str(i): why for i, why in sorted(node.after_end.items())}}
            if node.after_end
            else {}
        ),
        **message_counts(node),
        **safety_summary(node),
    }


def safety_summary(node: TimeKeeperNode) -> dict:
    """summary.json's `extra.safety` as the engine writes it (docs/SAFETY.md), from the agents'
    latest reports (an agent without one counts no intervention); {} without the layer."""
    safety = node.scenario.safety
    if safety is None:
        return {}
    reports = {i: book.report for i, book in node.agents.items()}
    counts = {i: 0 if r is None else r.safety_interventions or 0 for i, r in reports.items()}
    last = {i: None if r is None else r.safety_last_intervention for i, r in reports.items()}
    return {'safety': safety_extra(safety, interventions=counts, last_interventions=last)}


def message_counts(node: TimeKeeperNode) -> dict:
    """Messages rejected, faults injected, reports missing, and what was published per topic."""
    return {**node.book.message_counts(), 'published': node.book.published(node.published)}
