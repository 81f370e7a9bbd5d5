"""The coordinator node: opens a run of agent nodes, watches it, ends it, and writes what it saw.

It holds no world.  On robots (`formation run --backend <robot kind> | external`) the
robots are the world: agents sense poses and command velocities themselves (README, "Running on
robots"), and the coordinator only keeps the run's time and books (`run_book.RunBook`):

- **opens the run** once every agent is connected (discovery, docs/MESSAGES.md): Step 0 at
  t = 0 in wall-clock mode, carrying the epoch every agent times its triggers from; but first it
  checks where the robots are (`formation_sim.model.measured_start`): measured control points
  that break the initial condition (initial) on an edge refuse the run before any Step or command;
- **watches** every agent's Status and reports, and its sign of life: the DDS liveliness of its
  triggering-information writer (the one to its first neighbour, on which it also reads the
  agent's triggering times); and the robots' poses, stopping the run at the first edge that
  reaches Δ (`robot_trajectory` topic: a simulated robot's noise-free `true_odom`, else the
  measured `odom` or `pose`);
- **ends the run** at the horizon with the final Step, or on a fault (an agent lost, an edge at
  Δ, a protocol violation; SIGINT/SIGTERM) with a final Step that sends the agents home;
- **writes summary.json** (`formation_sim.sim.summary`, mode `robots`) from what it saw: the
  triggering times from the agents' messages, the formation from the poses sampled every
  `sample_period` and at every event (`formation_sim.sim.robots.trajectory_samples`, as
  `formation analyze` samples the bag), and `extra`: the run's failure, rejected messages,
  lateness and the commands the agents' limits saturated.

Opening, watching and ending the run is `time_keeper.TimeKeeperNode`'s life cycle, which the
simulator of the `exact` backend (`sim_node.FormationSimulatorNode`) shares, holding the exact
world (`sim_node.SimulatorWorld`); this module adds the robots' world, `RobotWorld` (a
`world.World`; `keeper_main.main`, shared by both time keepers, ends the run through `run_end`:
final reports, delivery, the agents stopped early, summary.json and graph.json).  Exit status:
0 done, 1 failed, 3 an agent or the recorder lost, 4 the robots' measured start breaks the initial
condition (no Step 0, no command), 5 an operator stopped the run (the emergency stop
`/formation/stop`: `operator_stop`), 130 interrupted.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from typing import NoReturn

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, String

from formation_agent.core.kinds import Geometry, KindNames, robot_kind
from formation_agent.core.kinds.shape import declared
from formation_agent.ros.kind_parameters import SpecTable, limit_spec, shape_specs
from formation_agent.ros.parameters import DOUBLE, STRING, ParameterSpec
from formation_agent.ros.process import exit_process
from formation_msgs_py.cdr import odometry_fields, pose_stamped_fields
from formation_msgs_py.codec import check_array, decode_trigger_info, encode_step
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME, Step
from formation_msgs_py.qos import READER_QOS, SIMULATOR_QOS
from formation_msgs_py.topics import COORDINATOR_NODE, ROBOTS_TOPIC, WORLD_FRAME, trigger_info_topic
from formation_sim.model.measured_start import MeasuredStart, check_measured_start
from formation_sim.model.scenario import Scenario
from formation_sim.runtime.contract import COORDINATOR_FILE, TRAJECTORY_TOPICS
from formation_sim.runtime.errors import AgentFailedError, InitialConditionError
from formation_sim.runtime.nodes import keeper_main
from formation_sim.runtime.nodes.robot_poses import RobotPoses, pose_rules
from formation_sim.runtime.nodes.robot_stops import RobotStops
from formation_sim.runtime.nodes.run_book import ids_text
from formation_sim.runtime.nodes.time_keeper import (
    TIME_KEEPER_PARAMETERS,
    TimeKeeperNode,
    graph_of,
    run_extra,
    tag_refused,
)
from formation_sim.sim.record import RunRecord
from formation_sim.sim.robots import POSES_AFTER_END, ROBOT_MODELS, sample_times, trajectory_samples
from formation_sim.sim.samples import Samples

TRAJECTORY_SOURCES = tuple(TRAJECTORY_TOPICS)  # which robot topic the formation is measured on

# Poses are read as the recorder reads them, reliable and keeping all, so that summary.json and
# `formation analyze` sample the same poses; volatile and without a liveliness lease, so that
# any reliable pose writer matches (robots' drivers keep ROS's defaults).
POSE_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


_HEAD = (
    *TIME_KEEPER_PARAMETERS,
    ParameterSpec(
        name='robot',
        type=STRING,
        default='holonomic',
        choices=ROBOT_MODELS,
        description='what the robots are',
    ),
)
_TAIL = (
    ParameterSpec(
        name='robot_trajectory',
        type=STRING,
        default='true_odom',
        choices=TRAJECTORY_SOURCES,
        description=(
            "the topic the formation is measured on: a simulated robot's noise-free true_odom, or the odom "
            'or pose the agents read'
        ),
    ),
    ParameterSpec(
        name='pose_silence',
        type=DOUBLE,
        default=0.5,
        low=0.0,
        low_open=True,
        high=math.inf,
        high_open=True,
        description=(
            "a robot whose poses on robot_trajectory stop for this long while the other robots' still come "
            "is lost: the run stops at once [s] (formation run: the agents' pose_timeout)"
        ),
    ),
    ParameterSpec(
        name='pose_ahead_tolerance',
        type=DOUBLE,
        default=0.1,
        low=0.0,
        high=math.inf,
        high_open=True,
        description=(
            "a pose stamped further ahead of this node's clock is refused and counted, never sampled [s] "
            '(the agents: their pose_timeout)'
        ),
    ),
    limit_spec(
        'max_linear_speed',
        "the robots' speed limit [m/s] (inf: none): a pose further from its robot's last one than it "
        'allows between their stamps (plus pose_jump_slack) is refused and counted',
    ),
    ParameterSpec(
        name='pose_jump_slack',
        type=DOUBLE,
        default=0.05,
        low=0.0,
        high=math.inf,
        high_open=True,
        description='the distance a pose may be off the speed limit on top (its noise) [m]',
    ),
    ParameterSpec(
        name='world_frame',
        type=STRING,
        default=WORLD_FRAME,
        description="frame_id of the zero commands it sends holonomic robots (the agents' world_frame)",
    ),
    ParameterSpec(
        name='backend',
        type=STRING,
        default='external',
        choices=KindNames(after=('external',)),
        description='the backend, as /formation/robots tells the tools (simulated robots, or external ones)',
    ),
)


def _coordinator_parameters() -> tuple[ParameterSpec, ...]:
    """Built at each use: a kind registered later brings its shape parameters."""
    return (*_HEAD, *shape_specs('coordinator'), *_TAIL)


COORDINATOR_PARAMETERS = SpecTable(_coordinator_parameters)
"""The coordinator's parameters (`formation_coordinator --help`; docs/PARAMETERS.md)."""


def _geometry(values: dict) -> Geometry:
    """The robots' shape from the coordinator's shape parameters."""
    return Geometry(**{p.name: values[p.name] for p in declared(node='coordinator')})


def robots_description(values: dict) -> dict:
    """What /formation/robots tells the tools (and summary.json's `extra.robots`), from the
    coordinator's parameters `values`: the backend, the robots' kind and control point, the topic
    the formation is measured on, and the rules its poses are refused by."""
    model = values['robot']
    return {
        'version': 1,
        'backend': values['backend'],
        'model': model,
        # Where the scenario's point sits ahead of the robot's origin, by its kind (a holonomic robot: 0).
        'control_point_distance': robot_kind(model).control_offset(_geometry(values))[0],
        'trajectory': values['robot_trajectory'],
        'sample_period': values['sample_period'],
        'pose_silence': values['pose_silence'],  # poses silent this long at the end are not sampled past it
        **pose_rules(values),  # the poses refused (formation analyze refuses them too)
    }


def _tag_refused_info(node: TimeKeeperNode, msg, agent: int) -> bool:
    """Whether agent `agent`'s triggering information lacks the run's valid tag (refused, counted)."""
    return tag_refused(node, trigger_info_topic(agent, min(node.agents[agent].neighbours)), msg, check_array)


class RobotWorld:
    """The robots of a run (a `world.World`): their poses, the agents' triggering times, the
    formation sampled from them, the robots' zero commands."""

    PARAMETERS: Sequence[ParameterSpec] = COORDINATOR_PARAMETERS
    COMMAND = 'formation_coordinator'
    PARAMS_FILE = COORDINATOR_FILE
    NODE_NAME = COORDINATOR_NODE
    DESCRIPTION = (
        'The time keeper of a robot run (formation run --backend <robot kind>|external): opens the run '
        'on the wall clock once every agent and robot is connected, watches it, stops it at the horizon '
        'or on a fault, and writes summary.json and graph.json into out_dir.'
    )
    serves_sensing = False  # the coordinator serves no sensing: it learns triggers from the agents
    batched_spin = True  # many poses: 0.1 s of events per look at its stop signals (issue 19)
    watched_writer = 'triggering-information'  # the writer whose liveliness is an agent's sign of life

    @staticmethod
    def problems(values: dict, scenario: Scenario) -> list[str]:
        """The rules between the world's parameters and the scenario (robots)."""
        problems = []
        model = values.get('robot')
        if model is not None and all(p.name in values for p in declared(node='coordinator')):
            geometry = _geometry(values)
            problems += robot_kind(model).placement_problems(dimension=scenario.dimension, geometry=geometry)
        if 'sample_period' in values and not values['sample_period'] > 0.0:
            problems.append(
                "parameter 'sample_period' (double) must be > 0 on robots (the poses are sampled on its "
                f'grid), got {values["sample_period"]!r}'
            )
        return problems

    @staticmethod
    def clock_mode_of(values: dict) -> str:
        return 'realtime'  # robots run on the wall clock

    def __init__(self, keeper: TimeKeeperNode) -> None:
        """The robots of `keeper`'s run: which topic shows each where it is, and what its scenario
        position is."""
        self.keeper = keeper
        values = keeper.parameter_values
        self.trajectory_source = values['robot_trajectory']
        self.robots = robots_description(values)  # what /formation/robots tells the tools
        self._robots_pub = keeper.create_publisher(String, ROBOTS_TOPIC, SIMULATOR_QOS)
        keeper.tool_publishers.append(self._robots_pub)
        topic = TRAJECTORY_TOPICS[self.trajectory_source]
        kind, self._pose_fields = (
            (PoseStamped, pose_stamped_fields)
            if self.trajectory_source == 'pose'
            else (Odometry, odometry_fields)
        )
        self.poses = RobotPoses.of_coordinator(keeper.scenario, keeper.parameter_values)
        # Raw: the poses' fields read from their bytes (formation_msgs_py.cdr), not through rclpy's
        # Python messages, which were most of the coordinator's CPU (400 Odometry a second for 4
        # robots); the same floats as `formation analyze` reads from the bag (sim.robots.sample_from_fields).
        self._pose_subs = {
            i: keeper.create_subscription(
                kind, topic(i), lambda data, agent=i: self._on_pose(data, agent), POSE_READER_QOS, raw=True
            )
            for i in keeper.scenario.agent_ids
        }
        self._info_stamps: dict[int, set[float]] = {i: set() for i in keeper.scenario.agent_ids}
        self._horizon_timer = None
        self.robot_stops = RobotStops(
            keeper,
            model=values['robot'],
            robots=keeper.scenario.agent_ids,
            dimension=keeper.scenario.dimension,
            world_frame=keeper.parameter_values['world_frame'],
        )
        self.measured_start: MeasuredStart | None = None

    def watch_agents(self) -> dict:
        """Each agent's triggering information to its first neighbour: its triggering times (one
        message per trigger and neighbour, stamped with the trigger's time) and its sign of life."""
        keeper = self.keeper
        return {
            i: keeper.create_subscription(
                Float64MultiArray,
                trigger_info_topic(i, min(book.neighbours)),
                lambda msg, agent=i: self._on_tagged_info(msg, agent),
                READER_QOS,
                event_callbacks=SubscriptionEventCallbacks(
                    liveliness=lambda info, agent=i: keeper.on_agent_liveliness(agent, info)
                ),
            )
            for i, book in keeper.agents.items()
        }

    def gaps(self) -> list[str]:
        topic = f'robot/{self.trajectory_source}'
        # The coordinator reads reliable, as the recorder does, so that both see every pose.
        missing = [i for i, sub in self._pose_subs.items() if sub.get_publisher_count() < 1]
        if missing:
            return [
                f'robots whose {topic} writer is not matched (not running, or a best-effort writer): '
                f'{ids_text(missing)}'
            ]
        # The first sample (t = 0) needs each robot's pose from before it.
        silent = self.poses.unheard()
        if silent:
            return [f'robots whose first {topic} message has not arrived: {ids_text(silent)}']
        # The recorder too, or its bag would lack a robot's pose before t = 0 (it matched late).
        beats, recorders = self.keeper.recorders.silent, self.keeper.extra_subscribers
        if len(beats) < recorders:
            return [f'a heartbeat from each recorder ({len(beats)} of {recorders})']
        unheard = sorted({name for topics in beats.values() for name in topics})
        return (
            [f'robot topics the recorder has had no message on yet: {", ".join(unheard)}'] if unheard else []
        )

    def check_start(self) -> str:
        """Before step 0: where the robots are (each one's latest pose, its control point) must meet
        the initial condition (initial) on every edge, or the run does not start: nothing was sent."""
        keeper = self.keeper
        latest = self.poses.start_positions(epoch=keeper.epoch)
        self.measured_start = start = check_measured_start(keeper.scenario, latest)
        if not start.ok:
            first = start.breaches[0]
            breaches = [breach.to_dict() for breach in start.breaches]
            raise InitialConditionError(start.message(), agents=[first.i, first.j], breaches=breaches)
        agent, largest = start.largest
        return f'measured start within {largest:.3g} m of the scenario (agent {agent}); '

    def extra(self) -> dict:
        extra = {} if self.measured_start is None else {'measured_start': self.measured_start.to_dict()}
        return {**extra, **self.robot_stops.extra()}

    def stop_robots(self, *, why: str) -> list[int]:
        """An operator's emergency stop: every robot its zero command now; the robots."""
        return self.robot_stops.stop_all(why=why)

    def stop_unreported_robots(self) -> None:
        self.robot_stops.stop(self.keeper.book.unreported(), why='no final report from their agents')

    def begin(self) -> None:
        """t = 0: the robots' run starts on the wall clock (Step 0 carries its epoch)."""
        keeper = self.keeper
        keeper.publish(self._robots_pub, String(data=json.dumps(self.robots, separators=(',', ':'))))
        keeper.epoch = time.time()
        keeper.step = Step(index=0, time=0.0, flags=STEP_FLAG_REALTIME, epoch=keeper.epoch)
        keeper.publish(keeper.step_pub, encode_step(keeper.step))
        # Each robot was heard (discovery waited for its first pose).
        self.poses.begin(epoch=keeper.epoch, now=time.monotonic())
        # The final Step at the horizon on the dot, not at the next tick: an agent whose last
        # trigger is due just before it must not wait for the run's end.
        self._horizon_timer = keeper.create_timer(
            max(keeper.horizon - (time.time() - keeper.epoch), 1e-3), self._at_horizon
        )

    def _at_horizon(self) -> None:
        self._horizon_timer.cancel()
        if not self.keeper.finished:
            self.tick()
            if not self.keeper.finished:  # the timer fired a hair early: the horizon is now
                self._end_at_horizon()

    def tick(self) -> None:
        t = self.reached_time
        self._check_robots()
        if (latest := self.poses.latest_positions()) is not None:
            self.keeper.book.check_connectivity(t, latest)
        if t >= self.keeper.horizon:
            self._end_at_horizon()

    def _check_robots(self, *, fraction: float = 1.0) -> None:
        """Stop the run at once when a robot's poses stopped (RobotLostError, exit status 3)."""
        silent = self.poses.watch.silent(time.monotonic(), fraction=fraction)
        if silent:
            raise self.poses.watch.error(
                silent, now=time.monotonic(), where=self.keeper.where(), topics=self._pose_topics(silent)
            )

    def _pose_topics(self, robots: list[int]) -> str:
        return ', '.join(TRAJECTORY_TOPICS[self.trajectory_source](i) for i in robots)

    def agent_failed(self, agent: int, failure: str) -> None:
        """An agent stopped on an error: the run stops at once.  The first cause is a robot whose
        poses stopped, if one has been silent for half the silence already (the agent's stale
        pose followed from it), else the agent's error."""
        self._check_robots(fraction=0.5)
        raise AgentFailedError(
            f'agent {agent} stopped {self.keeper.where()}: {failure}; the run stops', agents=[agent]
        )

    def _end_at_horizon(self) -> None:
        keeper = self.keeper
        keeper.marks.finish(time.monotonic())
        keeper.step = Step(
            index=1, time=keeper.horizon, flags=STEP_FLAG_FINAL | STEP_FLAG_REALTIME, epoch=keeper.epoch
        )
        keeper.publish(keeper.step_pub, encode_step(keeper.step))  # first: the robots stop now
        keeper.finished = True
        keeper.reached = keeper.horizon
        # The graph now: the agents are still there (they leave after their final reports).
        keeper.graph = graph_of(self.keeper)

    @property
    def reached_time(self) -> float:
        """Run time now: wall time since the epoch, never past the horizon (frozen once finished)."""
        if self.keeper.step is None:
            return 0.0
        if self.keeper.finished:
            return self.keeper.horizon if self.keeper.reached is None else self.keeper.reached
        return min(self.keeper.horizon, max(0.0, time.time() - self.keeper.epoch))

    def after_final_step(self, executor) -> None:
        """Before the summary: the poses up to the horizon (each robot's first one past it), and
        the zero commands sent from here acknowledged (`robot_stops`), both within POSES_AFTER_END."""
        keeper = self.keeper
        deadline = time.monotonic() + POSES_AFTER_END
        end = self.reached_time
        # Not for a robot whose poses stopped (lost, or on their way to it): it sends no more.
        failure = keeper.failure_info or {}
        lost = failure['agents'] if failure.get('kind') == 'robot_lost' else []
        waiting = self.poses.expected(lost=lost, now=time.monotonic())
        stops = self.robot_stops
        while time.monotonic() < deadline and (self.poses.behind(waiting, end) or stops.unacknowledged()):
            executor.spin_once(timeout_sec=0.02)
        stops.note_unacknowledged(within=POSES_AFTER_END)

    def flush(self) -> None:
        """The robots' world publishes nothing that could wait."""

    def after_status(self) -> None:
        """The wall clock needs nothing."""

    def record(self) -> RunRecord:
        """The run as the coordinator saw it (triggers from the agents' messages, formation from the
        poses)."""
        keeper = self.keeper
        end = self.reached_time
        trigger_times = {
            i: sorted(t for t in book.trigger_times if t <= end) for i, book in keeper.agents.items()
        }
        times = sample_times(end, keeper.sample_period, [t for ts in trigger_times.values() for t in ts])
        tracks = self.poses.tracks(end, source=self.trajectory_source)
        positions, velocities = trajectory_samples(tracks, keeper.scenario.agent_ids, times)
        return RunRecord(
            scenario=keeper.scenario,
            horizon=keeper.horizon,
            mode='robots',
            trigger_times=trigger_times,
            samples=Samples(
                times=times, positions=positions, velocities=velocities if keeper.double else None
            ),
            messages_sent=sum(keeper.book.information_sent(i) for i in keeper.agents),
            sensing_calls=sum(map(len, trigger_times.values())),
            wall_time=keeper.marks.since_start(keeper.marks.finished_at or time.monotonic()),
            extra={
                **run_extra(self.keeper, end),
                **keeper.book.lateness(trigger_times),
                'robots': self.robots,
                'saturation': keeper.book.saturation(),
            },
        )

    def _on_tagged_info(self, msg: Float64MultiArray, agent: int) -> None:
        """Agent `agent`'s triggering information, unless it lacks the run's valid tag."""
        if not _tag_refused_info(self.keeper, msg, agent):
            self._on_info(msg, agent)

    def _on_info(self, msg: Float64MultiArray, agent: int) -> None:
        try:
            info = decode_trigger_info(msg)
        except MessageError as error:
            self.keeper.reject(
                trigger_info_topic(agent, min(self.keeper.agents[agent].neighbours)), error.reason, str(error)
            )
            return
        if info.sender != agent:
            self.keeper.reject(
                trigger_info_topic(agent, info.receiver),
                'sender',
                f'information from agent {info.sender} on the topic of agent {agent}',
            )
            return
        stamps = self._info_stamps[agent]
        if info.stamp not in stamps:  # a copy replayed after a rematch (transient local) is no new trigger
            stamps.add(info.stamp)
            self.keeper.agents[agent].trigger_times.append(info.stamp)

    def _on_pose(self, data: bytes, agent: int) -> None:
        try:
            fields = self._pose_fields(data)
        except MessageError as error:
            self.keeper.reject(self._pose_subs[agent].topic_name, error.reason, str(error))
            return
        if (refusal := self.poses.refusal(agent, fields, wall=time.time())) is not None:  # the agents' rules
            self.keeper.reject(self._pose_subs[agent].topic_name, *refusal)
        else:  # before t = 0 (no epoch yet): kept, the last few, for the first sample
            self.poses.note(
                agent,
                fields,
                epoch=None if self.keeper.step is None else self.keeper.epoch,
                now=time.monotonic(),
            )


class FormationCoordinatorNode(TimeKeeperNode):
    """The coordinator: a time keeper holding the robots (`RobotWorld`, its `world`)."""

    def __init__(
        self,
        *,
        scenario: Scenario | None = None,
        parameter_overrides: list[Parameter] | None = None,
        context=None,
    ) -> None:
        super().__init__(
            world_class=RobotWorld,
            scenario=scenario,
            parameter_overrides=parameter_overrides,
            context=context,
        )


def main(args: Sequence[str] | None = None) -> int:
    """The coordinator until its run ends (`keeper_main.main`); its exit status."""
    return keeper_main.main(args, world_class=RobotWorld)


def entry_point() -> NoReturn:
    """The `formation_coordinator` console script: `main()`, then `exit_process` (a plain entry point's
    `sys.exit(main())` would run the interpreter's finalization and C++ static destructors after
    rclpy's shutdown)."""
    exit_process(main())


if __name__ == '__main__':
    entry_point()
