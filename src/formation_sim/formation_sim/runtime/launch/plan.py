"""The launch plan of a run: its ROS domain and environment, the inputs it writes, the processes it starts.

A backend decides who keeps time and what the world is (README, "Running on robots"):

- `exact`: time kept by the simulator (`sim_node`, lock-step or wall clock); the world is its
  exact world, which the agents sense through its sensing service; no extra process;
- a robot kind (`holonomic`, `unicycle`): time kept by the coordinator (`coordinator`, wall
  clock); the world is one simulated robot of that kind per agent (`robot_node`), whose poses the
  agents sense; the robots are the extra processes;
- `external`: time kept by the coordinator; the world is whatever publishes the robots' poses
  (which the agents sense) and takes their commands; no extra process.

What each kind of backend decides (its time keeper, files, mode, clock) is one table,
`backends.BackendKind`, picked by the backend's name (`LaunchPlan.kind`).

Every plan also starts one process per agent (or per `agents_per_process` agents) and, unless
told not to, the recorder.  `LaunchPlan.write_inputs` writes what every process reads into the run
folder (the scenario and one parameter file per kind of node, the only place they are built), so a
run can be started again by hand, on several machines (README, "Agents on separate machines"; the
external setup): `formation params` writes them without starting anything, and
`ProcessSpec.command` is the command line that starts each process by hand.
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib.util
import math
import os
import random
import shlex
import shutil
import socket
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, fields
from pathlib import Path

import yaml

from formation_agent.core.kinds import Geometry, default_min_separation, robot_kind
from formation_agent.core.kinds.shape import declared
from formation_agent.core.limits import Limits as KindLimits
from formation_msgs_py.middleware import (
    DOMAIN_ID_MAX,
    domain_id_ok,
    domain_ports,
    participant0_ports,
    use_our_fastdds_profile,
)
from formation_msgs_py.tags import KEY_FILE, new_key, write_key
from formation_msgs_py.topics import AGENT_NODE, ROBOT_NODE, WORLD_FRAME, robot_command_topic
from formation_sim.model.scenario import Scenario, dump_scenario
from formation_sim.runtime.contract import (
    TRAJECTORY_TOPICS,
    agent_parameters,
    formation_topics,
    robot_run_topics,
)
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.backends import BackendKind, backend_kind
from formation_sim.sim.errors import RobotError
from formation_sim.sim.robots import ROBOT_MODELS, Limits

DISCOVERY_MODES = (
    'simple',
    'server',
)  # Fast DDS simple discovery (every participant meets every other) or a discovery server
DISCOVERY_SERVER_PROGRAM = (
    'fast-discovery-server'  # in the ros-fastrtps wheel (bin/), or on PATH (a ROS install)
)
POSE_TYPES = ('odom', 'pose')
DOMAIN_RANGE = (100, DOMAIN_ID_MAX)  # ids a run picks from when not given one
MANY_PROCESSES = 30  # beyond this, shared-memory transport segments cost more than they bring
ONE_PROCESS_PER_AGENT_UP_TO = 24  # agents_per_process='auto': one process each up to this many agents ...
AUTO_AGENT_PROCESSES = 6  # ... beyond, the team in at most this many processes (BENCHMARKS.md, "Large teams")
# Simulated robots sharing a process (and its executor, its DDS participant) by default
# (BENCHMARKS.md, "CPU of a robot run").
ROBOTS_PER_PROCESS = 8
SCENARIO_FILE = 'scenario.yaml'
AGENTS_FILE = 'agents.params.yaml'
RECORDER_FILE = 'recorder.params.yaml'
ROBOTS_FILE = 'robots.params.yaml'
BAG_DIR = 'bag'
LOG_DIR = 'logs'
INJECT_KEYS = ('loss', 'delay_ms', 'jitter_ms', 'seed')
DOMAIN_RETRY = 0.1  # [s] how often reserve_domain(wait=...) looks again
AGENT_MODULE = 'formation_agent.ros.main'  # `python -m` it: the formation_agent command
RECORDER_DRAIN_QUIET = 0.1  # [s] the run's recorder closes its bag once nothing came for this long
# The console script of each node module (setup.py of formation_agent and formation_sim).
COMMANDS = {
    AGENT_MODULE: 'formation_agent',
    'formation_sim.runtime.nodes.sim_node': 'formation_sim',
    'formation_sim.runtime.nodes.coordinator': 'formation_coordinator',
    'formation_sim.runtime.nodes.recorder': 'formation_recorder',
    'formation_sim.runtime.nodes.robot_node': 'formation_robot',
}


@dataclass(frozen=True, kw_only=True)
class RobotOptions:
    """The robots of a robot backend, and what the agents on them are told (their parameters).

    Limits apply twice, as on real robots: the agent saturates its commands (and counts it, the
    theorems assume no saturation) and the base clips what it is sent.  A unicycle's scenario
    position is its control point, `control_point_distance` ahead of the axle.  Its shape is a
    `Geometry` of the kinds' declared shape parameters (formation_agent.core.kinds.shape): each
    robot node and agent is told the ones its kind takes.
    """

    model: str = 'unicycle'  # a robot kind (formation_agent.core.kinds; for `external`: what the robots are)
    geometry: Geometry = field(
        default_factory=Geometry
    )  # l, L, r, ...: each its declared default unless given
    max_linear_speed: float = math.inf  # [m/s]
    max_angular_speed: float = math.inf  # [rad/s]
    max_steering_angle: float = math.inf  # φ_max [rad] (car)
    max_linear_acceleration: float = math.inf  # [m/s²] (ETA-2)
    command_rate: float = 50.0  # [Hz] how often an agent re-sends its velocity command
    pose_type: str = 'odom'  # what the agents read: 'odom' (nav_msgs/Odometry) or 'pose' (PoseStamped)
    pose_timeout: float = 0.5  # [s] an older pose stops the agent safely
    world_frame: str = WORLD_FRAME
    time_warp: tuple[float, ...] = ()  # ETA-1: the agents' time warp [s_0, κ_0, ...] (); (): none
    # Simulated robots only:
    rate: float = 100.0  # [Hz]
    yaw: float | None = None  # initial heading of every robot [rad]; None: the scenario's `heading`s, else 0
    pose_noise: float = 0.0  # σ [m]
    yaw_noise: float = 0.0  # σ [rad]
    latency: float = 0.0  # [s] from a pose's measurement to its publication
    command_latency: float = 0.0  # [s] from a command's arrival to its effect
    command_timeout: float = 0.5  # [s] a robot without commands for this long stops
    seed: int = 0
    robots_per_process: int = ROBOTS_PER_PROCESS

    @property
    def odometry_is_truth(self) -> bool:
        """A simulated robot without noise and latency publishes its exact state as its odometry:
        then it publishes no `true_odom` (what a real robot publishes, odometry, and half the
        messages), and the formation is measured on `odom`, the same floats."""
        return self.pose_noise == 0.0 and self.yaw_noise == 0.0 and self.latency == 0.0

    def check(self, scenario: Scenario) -> None:
        """Raise RunError naming the first option that cannot work with `scenario`."""
        if self.model not in ROBOT_MODELS:
            raise RunError(f'robot model must be one of {ROBOT_MODELS}, got {self.model!r}')
        if self.pose_type not in POSE_TYPES:
            raise RunError(f'pose_type must be one of {POSE_TYPES}, got {self.pose_type!r}')
        try:
            Limits(
                linear=self.max_linear_speed, angular=self.max_angular_speed, steering=self.max_steering_angle
            )
        except RobotError as error:
            raise RunError(str(error)) from None
        for parameter in declared():  # l > 0 for every kind, as before; L >= 0; r > 0 where given
            value = self.geometry.values()[parameter.name]
            if value is not None and (problem := parameter.problem(value)) is not None:
                raise RunError(problem)
        positive = ('max_linear_acceleration', 'command_rate', 'pose_timeout', 'rate', 'command_timeout')
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise RunError(f'{name} must be > 0, got {getattr(self, name)!r}')
        for name in ('pose_noise', 'yaw_noise', 'latency', 'command_latency'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise RunError(f'{name} must be a finite number >= 0, got {value!r}')
        if self.yaw is not None and not math.isfinite(self.yaw):
            raise RunError(f'yaw must be finite, got {self.yaw!r}')
        if self.robots_per_process < 1:
            raise RunError(f'robots_per_process must be >= 1, got {self.robots_per_process}')
        if not self.world_frame:
            raise RunError('world_frame must not be empty')
        if problems := self.kind_problems(scenario.dimension):
            raise RunError('; '.join(problems))

    @classmethod
    def of(cls, **options) -> RobotOptions:
        """RobotOptions with the shape parameters given by name beside the other options
        (`RobotOptions.of(model='car', wheelbase=0.33, max_linear_speed=1.0)`): each declared
        shape parameter goes into `geometry` (with those of a `geometry` given)."""
        names = {parameter.name for parameter in declared()}
        shape = {name: options.pop(name) for name in [name for name in options if name in names]}
        geometry = options.pop('geometry', Geometry())
        return cls(geometry=geometry.replace(**shape), **options)

    def shape_parameters(self, node: str) -> dict[str, float]:
        """The shape parameters of `node` ('agent', 'robot', 'coordinator') its robots' kind takes
        (the coordinator: all it takes), each with its value."""
        kind = robot_kind(self.model)
        return {
            parameter.name: kind.shape_value(self.geometry, parameter.name)
            for parameter in declared(node=node)
            if node == 'coordinator' or parameter in kind.shape
        }

    @property
    def default_min_separation(self) -> float:
        """The `--min-separation` these robots take by default: D_s between control points for two
        footprints kept SEPARATION_MARGIN apart (`formation_agent.core.kinds.default_min_separation`;
        docs/ROBOTS.md, "Footprints")."""
        return default_min_separation(kind=robot_kind(self.model), geometry=self.geometry)

    def kind_problems(self, dimension: int) -> list[str]:
        """What the robots' kind says of these options (its dimensions, geometry and limits)."""
        try:
            limits = KindLimits(
                linear_speed=self.max_linear_speed,
                angular_speed=self.max_angular_speed,
                steering_angle=self.max_steering_angle,
            )
        except ValueError:
            return []  # named by the limits' own check
        return robot_kind(self.model).problems(dimension=dimension, geometry=self.geometry, limits=limits)

    def agent_parameters(self) -> dict:
        """What an agent on such a robot is told (formation_agent's robot parameters)."""
        params = {
            'sensing': 'poses',
            'pose_type': self.pose_type,
            'pose_timeout': float(self.pose_timeout),
            'robot': self.model,
            **self.shape_parameters('agent'),
            'command_rate': float(self.command_rate),
            'world_frame': self.world_frame,
        }
        for name in (
            'max_linear_speed',
            'max_angular_speed',
            'max_linear_acceleration',
            'max_steering_angle',
        ):
            if math.isfinite(getattr(self, name)):  # no limit: the agent's default (none)
                params[name] = float(getattr(self, name))
        if self.time_warp:  # docs/SPEED_SCALE.md, "A time warp"
            params['time_warp'] = [float(v) for v in self.time_warp]
        return params

    def robot_parameters(self, scenario: Scenario, agent_id: int) -> dict:
        """A simulated robot's parameters (`robot_node.SPECS`), placed at the agent's scenario position."""
        params = {
            'robot_id': int(agent_id),
            'model': self.model,
            'position': [float(v) for v in scenario.positions[scenario.index(agent_id)]],
            'yaw': self.initial_heading(scenario, agent_id),
            **self.shape_parameters('robot'),
            'rate': float(self.rate),
            'pose_noise': float(self.pose_noise),
            'yaw_noise': float(self.yaw_noise),
            'pose_latency': float(self.latency),
            'command_latency': float(self.command_latency),
            'command_timeout': float(self.command_timeout),
            'seed': int(self.seed),
            'world_frame': self.world_frame,
            'publish_truth': not self.odometry_is_truth,
        }
        for name in ('max_linear_speed', 'max_angular_speed', 'max_steering_angle'):
            if math.isfinite(getattr(self, name)):
                params[name] = float(getattr(self, name))
        return params

    def initial_heading(self, scenario: Scenario, agent_id: int) -> float:
        """A simulated robot's heading at t = 0: `yaw` if given, else the scenario's, else 0."""
        if self.yaw is not None:
            return float(self.yaw)
        if scenario.headings is not None:
            return float(scenario.headings[scenario.index(agent_id)])
        return 0.0

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True, kw_only=True)
class ProcessSpec:
    """One process of a run: its name, the arguments after `python`, and how it is expected to end."""

    # 'simulator', 'coordinator', 'recorder', 'agent_<i>', 'agents_<i>-<j>', 'robot_<i>',
    # 'robots_<i>-<j>', 'discovery_server'
    name: str
    args: tuple[str, ...]
    expected_exit: bool  # leaves by itself when the run completes (else it is stopped)
    keeper: bool = False  # the run's time keeper: its exit ends the run, its progress lines are shown
    program: str | None = None  # the program `args` go to (None: this Python)
    env: tuple[tuple[str, str], ...] = ()  # variables of this process alone, besides the run's environment

    @property
    def command(self) -> str:
        """The same process started by hand: its console script (or program) and arguments."""
        if self.program is not None:
            return shlex.join([self.program, *self.args])
        module, *rest = self.args[1:]
        return shlex.join([COMMANDS[module], *rest])


def resolve_agents_per_process(value: int | str, n: int) -> int:
    """How many agent nodes share a process: `value` itself, or for 'auto' one process per agent up
    to ONE_PROCESS_PER_AGENT_UP_TO agents (the mission's default, within localhost discovery's ~30
    processes) and beyond that the team split into at most AUTO_AGENT_PROCESSES processes: on 2 cores, 100
    to 1000 agents started and stepped fastest in 4-6 processes, where every process is one more
    participant for every other to discover and to keep the ROS graph of (1000 agents in 10
    processes took longer to discover than in 5)."""
    if value == 'auto':
        return 1 if n <= ONE_PROCESS_PER_AGENT_UP_TO else -(-n // AUTO_AGENT_PROCESSES)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise RunError(f"agents_per_process must be an integer >= 1 or 'auto', got {value!r}")
    return value


def _groups(ids: list[int], size: int) -> list[list[int]]:
    return [ids[start : start + size] for start in range(0, len(ids), size)]


def _group_name(kind: str, group: list[int]) -> str:
    return f'{kind}_{group[0]}' if len(group) == 1 else f'{kind}s_{group[0]}-{group[-1]}'


@dataclass(frozen=True, kw_only=True)
class LaunchPlan:
    """What a run writes and starts; built and checked before anything touches the disk."""

    scenario: Scenario
    backend: str
    out_dir: Path | None  # None until the run claims its folder (FormationRun.run)
    horizon: float
    clock: str  # 'lockstep' | 'realtime' (robot backends: always 'realtime')
    record: bool
    agents_per_process: int
    sample_period: float
    executor: str
    step_listeners: int
    inject: dict
    robots: RobotOptions | None
    discovery: str = 'simple'  # one of DISCOVERY_MODES
    discovery_port: int | None = None  # the discovery server's UDP port (chosen when the run starts)
    localhost_only: bool = True  # discovery and traffic stay on this machine

    @property
    def kind(self) -> BackendKind:
        """The kind of its backend (`backends`): its time keeper, files, mode, clock."""
        return backend_kind(self.backend)

    @property
    def keeper(self) -> str:
        return self.kind.keeper

    @property
    def simulated_robots(self) -> bool:
        return self.kind.simulated_robots

    def agent_groups(self) -> list[list[int]]:
        return _groups(list(self.scenario.agent_ids), self.agents_per_process)

    def process_count(self) -> int:
        robots = (
            len(_groups(list(self.scenario.agent_ids), self.robots.robots_per_process))
            if self.simulated_robots
            else 0
        )
        return len(self.agent_groups()) + 1 + int(self.record) + robots + int(self.discovery == 'server')

    # -- inputs ------------------------------------------------------------------------------------

    def recorder_topics(self) -> list[tuple[str, str]]:
        if not self.kind.on_robots:
            return formation_topics(self.scenario)
        return robot_run_topics(
            self.scenario,
            model=self.robots.model,
            simulated=self.simulated_robots,
            pose_type=self.robots.pose_type,
            truth=self.robot_trajectory == 'true_odom',
        )

    @property
    def robot_trajectory(self) -> str:
        """The robot topic the formation is measured on: a simulated robot's exact state (`true_odom`,
        or `odom` where that is exact: `RobotOptions.odometry_is_truth`); a real robot's as measured."""
        if not self.simulated_robots:
            return self.robots.pose_type
        return 'odom' if self.robots.odometry_is_truth else 'true_odom'

    def robot_pose_topics(self) -> list[str]:
        """The recorded pose topics the run reads: the agents' (`pose_type`) and the one the
        coordinator measures the formation on (`robot_trajectory`).  The time keeper starts a robot
        run only once the recorder has a message on each (its bag then covers t = 0); robots that
        publish only the other kind (an external team with odometry alone) must not hold it up."""
        read = robot_topics(self.scenario, self.robots.pose_type, self.robot_trajectory)
        return [name for name, _ in self.recorder_topics() if name in read]

    def endless_topics(self) -> list[str]:
        """The recorded topics of robots that outlive the run (external ones: their poses)."""
        poses = robot_topics(self.scenario, *TRAJECTORY_TOPICS)
        return [name for name, _ in self.recorder_topics() if name in poses]

    def counted_topics(self) -> set[str]:
        """The recorded topics whose messages the run's nodes count (summary.json extra.published):
        the topic table's counted rows, all but a robot's own (its poses, the commands it takes)."""
        from formation_msgs_py.topic_table import match_topic

        return {name for name, _ in self.recorder_topics() if match_topic(name)[0].counted}

    def write_inputs(self) -> dict[str, Path]:
        """scenario.yaml and the params files every process reads; their paths by role."""
        from formation_msgs_py.topics import agent_namespace

        out = self.out_dir
        out.mkdir(parents=True, exist_ok=True)
        paths = {'scenario': out / SCENARIO_FILE}
        dump_scenario(self.scenario, paths['scenario'])  # every float kept bit for bit
        # The run's own key, 0600, named by the parameter files (docs/HOSTILE_TRAFFIC.md, Tags).
        self.key_file.unlink(missing_ok=True)  # a folder this run may take holds no other run's key
        paths['key'] = write_key(self.key_file, new_key())
        extra = 1 if self.record else 0
        injected = {
            f'inject_{key}': (int(value) if key == 'seed' else float(value))
            for key, value in self.inject.items()
        }
        on_robots = self.robots.agent_parameters() if self.robots is not None else {}
        agents = {
            f'{agent_namespace(i)}/{AGENT_NODE}': {
                'ros__parameters': {
                    **agent_parameters(self.scenario, i, horizon=self.horizon, extra_subscribers=extra),
                    **injected,
                    **on_robots,
                    'key_file': str(self.key_file),
                }
            }
            for i in self.scenario.agent_ids
        }
        paths['agents'] = out / AGENTS_FILE
        _write_yaml(paths['agents'], agents)
        paths['keeper'] = out / self.kind.keeper_file
        _write_yaml(
            paths['keeper'],
            {self._keeper_node: {'ros__parameters': self.keeper_parameters(paths['scenario'])}},
        )
        if self.record:
            recorder = {
                '/formation_recorder': {
                    'ros__parameters': {
                        'output': str((out / BAG_DIR).resolve()),
                        'topics': [f'{name}:{msgtype}' for name, msgtype in self.recorder_topics()],
                        # Stopped last, once every writer has left and its messages were
                        # acknowledged by the recorder: they are in its readers already.
                        'drain_quiet': RECORDER_DRAIN_QUIET,
                        'key_file': str(self.key_file),  # Steps without the run's tag move no bag time
                        **({'watched_topics': self.robot_pose_topics()} if self.kind.on_robots else {}),
                        # External robots publish on after the run: their poses must not hold the drain up.
                        **({'endless_topics': self.endless_topics()} if self.kind.endless_poses else {}),
                    }
                }
            }
            paths['recorder'] = out / RECORDER_FILE
            _write_yaml(paths['recorder'], recorder)
        if self.simulated_robots:
            paths['robots'] = self.write_robot_inputs()
        return paths

    def write_robot_inputs(self) -> Path:
        """robots.params.yaml: every simulated robot's parameters, keyed by its node name."""
        from formation_msgs_py.topics import agent_namespace

        self.out_dir.mkdir(parents=True, exist_ok=True)
        robots = {
            f'{agent_namespace(i)}/{ROBOT_NODE}': {
                'ros__parameters': self.robots.robot_parameters(self.scenario, i)
            }
            for i in self.scenario.agent_ids
        }
        path = self.out_dir / ROBOTS_FILE
        _write_yaml(path, robots)
        return path

    # -- processes ---------------------------------------------------------------------------------

    def processes(self, paths: dict[str, Path]) -> list[ProcessSpec]:
        """Every process in the order it starts: discovery server, recorder, robots, time keeper, agents."""
        specs = []
        if self.discovery == 'server':
            specs.append(self.discovery_server_process())
        if self.record:
            specs.append(
                ProcessSpec(
                    name='recorder',
                    args=(
                        '-m',
                        'formation_sim.runtime.nodes.recorder',
                        '--ros-args',
                        '--params-file',
                        str(paths['recorder']),
                    ),
                    expected_exit=False,
                )
            )
        if self.simulated_robots:
            specs += self.robot_processes(paths['robots'])
        # Through a discovery server a client learns only of the endpoints it shares topics with;
        # the time keeper, which writes every node's endpoints into graph.json, must see them all.
        whole_graph = (('ROS_SUPER_CLIENT', 'TRUE'),) if self.discovery == 'server' else ()
        specs.append(
            ProcessSpec(
                name=self.keeper,
                args=self._keeper_args(paths),
                expected_exit=True,
                keeper=True,
                env=whole_graph,
            )
        )
        for group in self.agent_groups():
            args = (
                '-m',
                AGENT_MODULE,
                '--agents',
                ','.join(map(str, group)),
                '--executor',
                self.executor,
                '--ros-args',
                '--params-file',
                str(paths['agents']),
            )
            specs.append(ProcessSpec(name=_group_name('agent', group), args=args, expected_exit=True))
        return specs

    def discovery_server_process(self) -> ProcessSpec:
        """Fast DDS's discovery server: every other process of the run is its client
        (ROS_DISCOVERY_SERVER) and learns of the others from it alone, instead of every participant
        announcing itself to every other.  It listens on this machine only, unless the run's
        discovery reaches the network (then on every interface, for clients elsewhere)."""
        address = '127.0.0.1' if self.localhost_only else '0.0.0.0'  # noqa: S104 - a network run: clients elsewhere
        args = ('--server-id', '0', '--udp-address', address, '--udp-port', str(self.discovery_port))
        return ProcessSpec(
            name='discovery_server', program=discovery_server_program(), args=args, expected_exit=False
        )

    def robot_processes(self, params_file: Path) -> list[ProcessSpec]:
        """The simulated robots, `robots_per_process` to a process; they run until stopped."""
        specs = []
        for group in _groups(list(self.scenario.agent_ids), self.robots.robots_per_process):
            args = (
                '-m',
                'formation_sim.runtime.nodes.robot_node',
                '--robots',
                ','.join(map(str, group)),
                '--ros-args',
                '--params-file',
                str(params_file),
            )
            specs.append(ProcessSpec(name=_group_name('robot', group), args=args, expected_exit=False))
        return specs

    @property
    def _keeper_node(self) -> str:
        return self.kind.keeper_node

    @property
    def key_file(self) -> Path:
        """The run's key file (`formation_msgs_py.tags.KEY_FILE` in the run folder)."""
        return (self.out_dir / KEY_FILE).resolve()

    def keeper_parameters(self, scenario_file: Path) -> dict:
        """The time keeper's parameters (`sim_node.SIMULATOR_PARAMETERS`,
        `coordinator.COORDINATOR_PARAMETERS`)."""
        params = {
            'scenario': str(scenario_file.resolve()),
            'horizon': float(self.horizon),
            'out_dir': str(self.out_dir.resolve()),
            'sample_period': float(self.sample_period),
            'extra_subscribers': 1 if self.record else 0,
            'step_listeners': int(self.step_listeners),
            'executor': self.executor,
            # Discovery of a large team on a small machine takes long (300 agents here: ~1 min).
            'discovery_timeout': max(120.0, float(len(self.scenario.agent_ids))),
            'key_file': str(self.key_file),
        }
        if not self.kind.on_robots:
            params['clock_mode'] = self.clock
        else:
            params.update(
                backend=self.backend,
                robot=self.robots.model,
                **self.robots.shape_parameters('coordinator'),
                robot_trajectory=self.robot_trajectory,
                # A robot silent for as long as its agents accept a pose is lost: the run stops at once.
                pose_silence=float(self.robots.pose_timeout),
                world_frame=self.robots.world_frame,  # of its zero commands (robot_stops), as the agents'
                # A pose further from its robot's last one than the speed limit allows is refused
                # (issue 28); a simulated pose's noise is allowed on top (8 sigma of each pose).
                pose_jump_slack=0.05 + 8.0 * float(self.robots.pose_noise),
            )
            if math.isfinite(self.robots.max_linear_speed):
                params['max_linear_speed'] = float(self.robots.max_linear_speed)
        return params

    def _keeper_args(self, paths: dict[str, Path]) -> tuple[str, ...]:
        return ('-m', self.kind.keeper_module, '--ros-args', '--params-file', str(paths['keeper']))

    # -- environment -------------------------------------------------------------------------------

    def environment(self, domain_id: int, *, extra_env: dict[str, str]) -> dict[str, str]:
        """The environment of every child (`child_environment`), from this process's."""
        return child_environment(
            dict(os.environ),
            domain_id=domain_id,
            log_dir=self.out_dir / LOG_DIR / 'ros',
            localhost_only=self.localhost_only,
            # A client of the run's discovery server.
            discovery_server=f'127.0.0.1:{self.discovery_port}' if self.discovery == 'server' else None,
            udp_only=self.process_count() > MANY_PROCESSES,
            extra_env=extra_env,
        )


def robot_topics(scenario: Scenario, *kinds: str) -> set[str]:
    """Every robot's topics of these kinds: 'pose', 'odom', 'true_odom' (`contract.TRAJECTORY_TOPICS`)
    or 'command'."""
    by_kind = {**TRAJECTORY_TOPICS, 'command': robot_command_topic}
    return {by_kind[kind](i) for i in scenario.agent_ids for kind in kinds}


def child_environment(
    env: dict[str, str],
    *,
    domain_id: int,
    log_dir: Path,
    localhost_only: bool,
    discovery_server: str | None,
    udp_only: bool,
    extra_env: dict[str, str],
) -> dict[str, str]:
    """`env` (this process's environment) made a run's child's: its ROS domain, its logs in
    `log_dir`, discovery on this machine only (`localhost_only`) and through the run's
    `discovery_server` (host:port; None: none, not even a user's), UDP alone (`udp_only`: many
    processes), Fast DDS's settings, our packages; `extra_env` last."""
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_LOG_DIR'] = str(log_dir.resolve())
    env['RMW_IMPLEMENTATION'] = 'rmw_fastrtps_cpp'
    env['PYTHONUNBUFFERED'] = '1'
    if localhost_only:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    else:
        env.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)  # Jazzy's default: SUBNET
    if discovery_server is not None:
        env['ROS_DISCOVERY_SERVER'] = discovery_server
    else:
        env.pop('ROS_DISCOVERY_SERVER', None)  # a user's server is not the run's
    if udp_only:
        env['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    # numpy's OpenBLAS starts a thread per core at import, which costs every child ~0.1 s of
    # CPU while all of them start at once; no node does linear algebra worth a thread.
    env.setdefault('OPENBLAS_NUM_THREADS', '1')
    use_our_fastdds_profile(env)  # a user's own file wins
    env.update(extra_env)
    return with_our_packages(env)


def discovery_server_program() -> str:
    """The path of Fast DDS's discovery server program, or RunError saying where it was looked for.

    The ros-fastrtps wheel installs it beside this Python (bin/fast-discovery-server); it finds
    its libraries through LD_LIBRARY_PATH, which the wheels' bootstrap sets for every Python
    process and hence for the run's children.  A ROS install has it on PATH."""
    beside = Path(sys.executable).parent / DISCOVERY_SERVER_PROGRAM
    found = str(beside) if os.access(beside, os.X_OK) else shutil.which(DISCOVERY_SERVER_PROGRAM)
    if found is None:
        raise RunError(
            f'the discovery server needs {DISCOVERY_SERVER_PROGRAM} '
            '(Fast DDS, installed with the ros-fastrtps wheel): '
            f'neither {beside} nor any {DISCOVERY_SERVER_PROGRAM} on PATH'
        )
    return found


def free_udp_port(domain_id: int) -> int:
    """A UDP port free on this machine now, outside the RTPS ports of ROS domain `domain_id`
    (7400 + 250 d + [0, 250)), for the run's discovery server."""
    ports = domain_ports(domain_id)
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind(('127.0.0.1', 0))
            port = probe.getsockname()[1]
        if port not in ports:
            return port


def with_our_packages(env: dict[str, str]) -> dict[str, str]:
    """`env` whose PYTHONPATH lets a child find these packages the way this process did."""
    here = [
        str(Path(next(iter(importlib.util.find_spec(name).submodule_search_locations))).resolve().parent)
        for name in ('formation_msgs_py', 'formation_agent', 'formation_sim')
    ]
    env['PYTHONPATH'] = os.pathsep.join(
        dict.fromkeys(here + [p for p in env.get('PYTHONPATH', '').split(os.pathsep) if p])
    )
    return env


class _NoAliases(yaml.SafeDumper):
    """rcl reads no YAML aliases ('Will not support aliasing'): a list every agent shares (a time
    warp) is written out for each."""

    def ignore_aliases(self, data) -> bool:
        return True


def _write_yaml(path: Path, data: dict) -> None:
    path.write_text(yaml.dump(data, Dumper=_NoAliases, sort_keys=False), encoding='utf-8')


# -- ROS domain -----------------------------------------------------------------------------------


def _ports_free(domain_id: int) -> bool:
    for port in participant0_ports(domain_id):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(('', port))
            except OSError:
                return False
    return True


@contextlib.contextmanager
def reserve_domain(
    domain_id: int | None = None, *, lock_dir: Path | None = None, wait: float = 0.0
) -> Iterator[int]:
    """Hold a ROS domain id for the duration of the block (a lock file; the ports unused).

    With `domain_id` the caller pins the id; it is still locked against other runs.  `wait`: how
    long to go on trying while the id (or every id of the range) is held [s]; then `RunError`.
    """
    lock_dir = lock_dir or Path('/tmp/formation_domains')  # noqa: S108 - one folder for every run on the machine
    lock_dir.mkdir(parents=True, exist_ok=True)
    low, high = DOMAIN_RANGE
    if domain_id is not None:
        if not domain_id_ok(domain_id):
            raise RunError(f'domain id must lie in [0, {DOMAIN_ID_MAX}], got {domain_id}')
        candidates = [domain_id]
    else:
        candidates = list(range(low, high + 1))
        start = random.randrange(len(candidates))
        candidates = candidates[start:] + candidates[:start]
    deadline = time.monotonic() + wait
    while True:
        for candidate in candidates:
            handle = open(lock_dir / f'{candidate}.lock', 'w')  # noqa: SIM115 - held while running
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                handle.close()
                continue
            if domain_id is None and not _ports_free(candidate):
                handle.close()
                continue
            try:
                yield candidate
            finally:
                handle.close()
            return
        if time.monotonic() >= deadline:
            break
        time.sleep(DOMAIN_RETRY)
    waited = f' (waited {wait:g} s)' if wait > 0.0 else ''
    if domain_id is not None:
        raise RunError(f'ROS domain {domain_id} is held by another formation run{waited}')
    raise RunError(f'no free ROS domain in {low}-{high}{waited}')
