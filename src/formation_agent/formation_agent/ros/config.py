"""The agent node's parameters: one table (`AGENT_PARAMETERS`, `GAIN_PARAMETERS`), read into an `AgentConfig`.

`formation_agent --help` prints the table (`agent_help`); `ros2 param describe` shows the same
descriptions and ranges.  `read_config` checks every parameter, and the rules between them, and
raises one `ParameterError` naming every problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from formation_agent.core.commander import Limits
from formation_agent.core.errors import RuleError, SafetyError, WarpError
from formation_agent.core.eta import SCALE_GAINS
from formation_agent.core.kinds import KindNames, robot_kind
from formation_agent.core.kinds.shape import Geometry, declared
from formation_agent.core.safety import (
    DEFAULT_GAMMA,
    DEFAULT_MAX_SPEED,
    DEFAULT_SENSING_RADIUS,
    DEFAULT_TURN,
    SafetyConfig,
)
from formation_agent.core.speed_scale import SPEED_SCALE_LIMITS
from formation_agent.core.time_warp import TimeWarp
from formation_agent.core.trigger import DEFAULT_RULE, rule_factory
from formation_agent.ros.errors import ParameterError
from formation_agent.ros.kind_parameters import SpecTable, limit_spec, shape_specs
from formation_agent.ros.parameters import (
    DOUBLE,
    DOUBLE_ARRAY,
    INTEGER,
    INTEGER_ARRAY,
    STRING,
    ParameterSpec,
    parameter_help,
    read_parameters,
)
from formation_msgs_py.errors import KeyFileError
from formation_msgs_py.tags import read_key
from formation_msgs_py.topics import (
    WORLD_FRAME,
    agent_namespace,
    robot_command_topic,
    robot_odom_topic,
    robot_pose_topic,
)
from formation_msgs_py.types import MAX_AGENT_ID

SENSING_SOURCES = ('service', 'poses')
POSE_TYPES = ('pose', 'odom')
ROBOTS = KindNames(before=('none',))  # 'none' and every registered robot kind, read at each use
LIMIT_PARAMETERS = ('max_linear_speed', 'max_angular_speed', 'max_linear_acceleration', 'max_steering_angle')


def _spec(name, kind, description, **options) -> ParameterSpec:
    return ParameterSpec(name=name, type=kind, description=description, **options)


_FORMATION = (
    # The formation (written per agent by `formation run`, from the scenario).
    _spec(
        'agent_id',
        INTEGER,
        "this agent's id i; the node runs in namespace /agent_<i>",
        low=0,
        high=MAX_AGENT_ID,
    ),
    _spec(
        'algorithm',
        STRING,
        'eta1 (single integrators, Theorem 1) or eta2 (double integrators, Theorem 2)',
        choices=('eta1', 'eta2'),
    ),
    _spec(
        'dimension',
        INTEGER,
        'dimension p of positions (commands travel as geometry_msgs: 1 to 3)',
        low=1,
        high=3,
    ),
    _spec('neighbour_ids', INTEGER_ARRAY, 'ids j of the neighbours in the graph', low=0, high=MAX_AGENT_ID),
    _spec(
        'neighbour_offsets',
        DOUBLE_ARRAY,
        'desired d_ij = x_i - x_j per neighbour, p values each, in neighbour_ids order [m]',
    ),
    _spec('delta', DOUBLE, 'communication radius Δ [m]', low=0.0, low_open=True),
    _spec(
        'horizon', DOUBLE, 'end of the run t_end [s]; no trigger is planned after it', low=0.0, low_open=True
    ),
    _spec(
        'speed_scale',
        DOUBLE,
        "speed scale κ (docs/SPEED_SCALE.md): the paper's run in the time s = κt, every "
        'triggering time divided by κ, commands times κ (eta2: gains κ²k1, κk2, κk3); 1: the paper',
        default=SCALE_GAINS['speed_scale'],
        low=SPEED_SCALE_LIMITS[0],
        high=SPEED_SCALE_LIMITS[1],
    ),
    _spec(
        'time_warp',
        DOUBLE_ARRAY,
        "eta1 on robots: a time warp [s_0, κ_0, s_1, κ_1, ...] (docs/SPEED_SCALE.md, 'A time warp'): "
        "the paper's run at s(t), ds/dt = κ_m from s_m on, commands κ(t) u_i; speed_scale must be 1; "
        '[]: none',
        default=[],
    ),
    _spec(
        'threshold_floor',
        DOUBLE,
        "threshold floor c0 of c0 + α e^{-κβt}, in the units of the paper's e_i / E_i "
        '(docs/SPEED_SCALE.md); 0: the paper',
        default=SCALE_GAINS['threshold_floor'],
        low=0.0,
    ),
    _spec(
        'trigger_rule',
        STRING,
        'the triggering rule, the family of thresholds θ(t; c0, α, β) the error is held below '
        '(formation_agent.core.trigger): a registered name or an import path package.module:Class; '
        f'{DEFAULT_RULE}: c0 + α e^{{-κβt}}, the paper',
        default=DEFAULT_RULE,
    ),
    # The safety layer (docs/SAFETY.md): the scenario's safety: keys, written by `formation run`.
    _spec(
        'min_separation',
        DOUBLE,
        'safety layer (docs/SAFETY.md, eta1, planar): D, the least distance kept between two robots [m]; '
        '0: the layer off',
        default=0.0,
        low=0.0,
    ),
    _spec(
        'sensing_radius',
        DOUBLE,
        'safety layer: R, the range within which the agent senses the other robots [m]',
        default=DEFAULT_SENSING_RADIUS,
        low=0.0,
        low_open=True,
    ),
    _spec(
        'safety_gamma',
        DOUBLE,
        'safety layer: γ, how fast a barrier may shrink, dh/dt >= -γ h [1/s]',
        default=DEFAULT_GAMMA,
        low=0.0,
        low_open=True,
    ),
    _spec(
        'safety_max_speed',
        DOUBLE,
        'safety layer: v̄, the bound of every applied command [m/s]',
        default=DEFAULT_MAX_SPEED,
        low=0.0,
        low_open=True,
    ),
    _spec(
        'safety_turn',
        DOUBLE,
        "safety layer: λ, the tie-break's turn to the right, atan(λ)",
        default=DEFAULT_TURN,
        low=0.0,
    ),
    _spec(
        'other_robot_ids',
        INTEGER_ARRAY,
        "safety layer with sensing: poses — ids of the team's other robots (not itself, not a "
        'neighbour), whose pose topics the agent reads to see those within sensing_radius',
        default=[],
        low=0,
        high=MAX_AGENT_ID,
    ),
)


_ROBOT = (
    # Robots (README, "Running on robots").
    _spec(
        'sensing',
        STRING,
        "where the agent senses: 'service' (the simulator's /agent_<i>/sense) or "
        "'poses' (its own and its neighbours' pose topics)",
        default='service',
        choices=SENSING_SOURCES,
    ),
    _spec(
        'pose_type',
        STRING,
        "sensing: poses — 'pose' (geometry_msgs/PoseStamped, motion capture) or "
        "'odom' (nav_msgs/Odometry; ETA-2 velocities from its twist)",
        default='pose',
        choices=POSE_TYPES,
    ),
    _spec(
        'pose_topic',
        STRING,
        "sensing: poses — topic of robot {id}'s poses, e.g. /vrpn/cf{id}/pose "
        "('': /agent_{id}/robot/pose or /agent_{id}/robot/odom, by pose_type)",
        default='',
    ),
    _spec(
        'pose_timeout',
        DOUBLE,
        'sensing: poses — a pose older than this at a trigger (or on the '
        'command timer, for its own robot) stops the agent [s]',
        default=0.5,
        low=0.0,
        low_open=True,
    ),
    _spec('world_frame', STRING, 'frame_id of every pose and of holonomic commands', default=WORLD_FRAME),
    _spec(
        'robot',
        STRING,
        "command output: 'none' (cmd_vel/cmd_accel to the simulator's plant) or a robot kind: "
        + ', '.join(f"'{name}' ({robot_kind(name).summary})" for name in ROBOTS[1:]),
        default='none',
        choices=ROBOTS,
    ),
    _spec(
        'command_topic',
        STRING,
        "robot: the robot's velocity command topic ('': /agent_<i>/robot/cmd_vel)",
        default='',
    ),
)
_DRIVE = (
    limit_spec('max_linear_speed', 'robot: speed limit [m/s] (inf: none); clips are counted and reported'),
    limit_spec('max_angular_speed', 'robot: unicycle — turn rate limit [rad/s] (inf: none)'),
    limit_spec(
        'max_steering_angle',
        'robot: car — steering limit φ_max [rad], in (0, π/2): |ω| <= |v| tan φ_max / L '
        '(inf: none, for the other kinds)',
    ),
    limit_spec(
        'max_linear_acceleration',
        'robot: ETA-2 — acceleration limit of the velocity reference [m/s²] (inf: none)',
    ),
    _spec(
        'command_rate',
        DOUBLE,
        'robot: rate at which the velocity command is recomputed and republished [Hz]',
        default=50.0,
        low=0.0,
        low_open=True,
    ),
    # Runs and tests.
    _spec(
        'extra_subscribers',
        INTEGER,
        'listeners besides the protocol peers (a recorder) that must match before step 0',
        default=0,
        low=0,
    ),
    _spec(
        'inject_loss',
        DOUBLE,
        'test facility: drop probability of arriving triggering information (wall clock)',
        default=0.0,
        low=0.0,
        high=1.0,
    ),
    _spec(
        'inject_delay_ms',
        DOUBLE,
        'test facility: delay of arriving triggering information [ms]',
        default=0.0,
        low=0.0,
    ),
    _spec(
        'inject_jitter_ms',
        DOUBLE,
        'test facility: extra uniform delay in [0, jitter] [ms]',
        default=0.0,
        low=0.0,
    ),
    _spec('inject_seed', INTEGER, 'test facility: seed of the injected faults', default=0, low=0),
    _spec(
        'key_file',
        STRING,
        "the run's key (docs/HOSTILE_TRAFFIC.md, Tags): the agent tags what it sends and refuses Steps "
        "and information without a valid tag; '' (default): no tags (an agent started by hand)",
        default='',
    ),
)


def _agent_parameters() -> tuple[ParameterSpec, ...]:
    """Built at each use: a kind registered later brings its shape parameters."""
    return (*_FORMATION, *_ROBOT, *shape_specs('agent'), *_DRIVE)


AGENT_PARAMETERS = SpecTable(_agent_parameters)
"""The agent's parameters (`formation_agent --help`; docs/PARAMETERS.md), its robot's shape
parameters generated from the kinds registered at each use."""

GAIN_PARAMETERS = {
    'eta1': (
        _spec('alpha', DOUBLE, 'eta1: threshold gain α of (triggersingle)', low=0.0, low_open=True),
        _spec(
            'beta', DOUBLE, 'eta1: threshold decay rate β of (triggersingle) [1/s]', low=0.0, low_open=True
        ),
    ),
    'eta2': (
        _spec('alpha_d', DOUBLE, 'eta2: threshold gain α_d of (triggerdouble)', low=0.0, low_open=True),
        _spec(
            'beta_d',
            DOUBLE,
            'eta2: threshold decay rate β_d of (triggerdouble) [1/s]',
            low=0.0,
            low_open=True,
        ),
        _spec('k1', DOUBLE, 'eta2: position gain k1 of (uxdouble)', low=0.0, low_open=True),
        _spec('k2', DOUBLE, 'eta2: velocity gain k2 of (uxdouble)', low=0.0, low_open=True),
        _spec('k3', DOUBLE, 'eta2: damping k3 of (uxdouble) [1/s]', low=0.0, low_open=True),
    ),
}


@dataclass(frozen=True, kw_only=True)
class AgentConfig:
    agent_id: int
    algorithm: str
    dimension: int
    neighbour_ids: tuple[int, ...]
    neighbours: dict[int, tuple[float, ...]]  # j -> d_ij
    delta: float
    horizon: float
    gains: dict[str, float]
    sensing: str
    pose_type: str
    pose_topic: str
    pose_timeout: float
    world_frame: str
    robot: str
    command_topic: str
    geometry: Geometry  # the robot's shape parameters (formation_agent.core.kinds.shape)
    limits: Limits
    command_rate: float
    extra_subscribers: int
    inject_loss: float
    inject_delay_ms: float
    inject_jitter_ms: float
    inject_seed: int
    time_warp: TimeWarp | None = None
    trigger_rule: str = DEFAULT_RULE  # the threshold's family (formation_agent.core.trigger)
    safety: SafetyConfig | None = None  # the safety layer (min_separation > 0), docs/SAFETY.md
    other_robot_ids: tuple[int, ...] = ()  # the safety layer on robots: the others' pose topics
    key: bytes | None = field(default=None, repr=False)  # the run's key (key_file), never printed

    @property
    def double(self) -> bool:
        return self.algorithm == 'eta2'

    @property
    def wall_clock_only(self) -> bool:
        """Poses and robots live on the wall clock: lock-step sim time cannot drive them."""
        return self.sensing == 'poses' or self.robot != 'none'

    def robot_pose_topic(self, robot: int) -> str:
        if self.pose_topic:
            return self.pose_topic.replace('{id}', str(robot))
        return robot_pose_topic(robot) if self.pose_type == 'pose' else robot_odom_topic(robot)

    @property
    def robot_command_topic(self) -> str:
        return self.command_topic or robot_command_topic(self.agent_id)

    @property
    def control_point_offset(self) -> tuple[float, float, float]:
        """Where the control point sits in the robot's body frame (by its kind; none: the origin)."""
        return (
            (0.0, 0.0, 0.0) if self.robot == 'none' else robot_kind(self.robot).control_offset(self.geometry)
        )


def read_config(node) -> AgentConfig:
    """Every parameter of `node`, checked; one ParameterError names every problem."""
    values, problems = read_parameters(node, AGENT_PARAMETERS)
    algorithm = values.get('algorithm')
    if algorithm is not None:
        gains, gain_problems = read_parameters(node, GAIN_PARAMETERS[algorithm])
        problems += gain_problems
    problems += _rules(node, values)
    if problems:
        raise ParameterError(node.get_fully_qualified_name(), problems)
    p = values['dimension']
    ids = tuple(int(j) for j in values['neighbour_ids'])
    offsets = [float(v) for v in values['neighbour_offsets']]
    return AgentConfig(
        agent_id=values['agent_id'],
        algorithm=algorithm,
        dimension=p,
        neighbour_ids=ids,
        neighbours={j: tuple(offsets[k * p : (k + 1) * p]) for k, j in enumerate(ids)},
        delta=values['delta'],
        horizon=values['horizon'],
        gains={name: float(value) for name, value in gains.items()}
        | {name: float(values[name]) for name in SCALE_GAINS},  # κ and c0, for make_agent and the commands
        limits=Limits(
            linear_speed=values['max_linear_speed'],
            angular_speed=values['max_angular_speed'],
            linear_acceleration=values['max_linear_acceleration'],
            steering_angle=values['max_steering_angle'],
        ),
        time_warp=TimeWarp.from_parameter(values['time_warp']) if values['time_warp'] else None,
        safety=_safety(values) if values['min_separation'] > 0.0 else None,
        other_robot_ids=tuple(int(j) for j in values['other_robot_ids']),
        geometry=_geometry(values),
        key=read_key(values['key_file']) if values['key_file'] else None,
        **{
            name: values[name]
            for name in (
                'sensing',
                'pose_type',
                'pose_topic',
                'pose_timeout',
                'world_frame',
                'robot',
                'command_topic',
                'command_rate',
                'extra_subscribers',
                'inject_loss',
                'inject_delay_ms',
                'inject_jitter_ms',
                'inject_seed',
                'trigger_rule',
            )
        },
    )


def _rules(node, values: dict) -> list[str]:
    """The rules between parameters (each checked only when its parameters are good)."""
    problems = []

    def have(*names: str) -> bool:
        return all(name in values for name in names)

    if have('dimension', 'neighbour_ids', 'neighbour_offsets'):
        p, ids, offsets = values['dimension'], list(values['neighbour_ids']), values['neighbour_offsets']
        if len(offsets) != p * len(ids):
            problems.append(
                f'neighbour_offsets must hold dimension * len(neighbour_ids) = {p} * {len(ids)} values '
                f'(d_ij per neighbour), got {len(offsets)}'
            )
        if len(set(ids)) != len(ids):
            problems.append(f'neighbour_ids repeat an id: {ids}')
    if have('agent_id', 'neighbour_ids') and values['agent_id'] in values['neighbour_ids']:
        problems.append(f'neighbour_ids hold the agent itself ({values["agent_id"]})')
    if have('horizon') and not math.isfinite(values['horizon']):
        problems.append(f'horizon must be a finite number > 0, got {values["horizon"]!r}')
    if have('agent_id') and node.get_namespace() != (expected := agent_namespace(values['agent_id'])):
        # Its relative names (sense, cmd_vel, trigger_info/to_<j>) must resolve under it.
        problems.append(
            f'agent {values["agent_id"]} must run in namespace {expected}, not {node.get_namespace()} '
            f'(e.g. --ros-args -r __ns:={expected}, or formation_agent --agents {values["agent_id"]})'
        )
    if have('time_warp') and values['time_warp']:
        problems += _warp_problems(values)
    if have('trigger_rule'):
        try:
            rule_factory(values['trigger_rule'])
        except RuleError as error:
            problems.append(str(error))
    if have('min_separation', *SAFETY_PARAMETERS.values()) and values['min_separation'] > 0.0:
        problems += _safety_problems(values)
    if have('key_file') and values['key_file']:
        try:
            read_key(values['key_file'])
        except KeyFileError as error:
            problems.append(str(error))
    if have('world_frame') and not values['world_frame']:
        problems.append("world_frame must name a frame, got ''")
    if have('pose_topic') and values['pose_topic'] and '{id}' not in values['pose_topic']:
        problems.append(f"pose_topic must hold '{{id}}' (one topic per robot), got {values['pose_topic']!r}")
    robot = values.get('robot')
    if robot == 'none' and have('command_topic', *LIMIT_PARAMETERS):
        given = [name for name in (*LIMIT_PARAMETERS, 'command_topic') if values[name] not in (math.inf, '')]
        if given:
            problems.append(
                f"{', '.join(given)} apply to a robot's command adapter (robot: one of {tuple(ROBOTS[1:])}); "
                "with robot: none the simulator's plant takes the exact commands"
            )
    if robot not in (None, 'none') and have('sensing') and values['sensing'] != 'poses':
        problems.append(
            f"robot: {robot} needs sensing: poses (the simulator's sensing service reports its own simulated "
            'world, which does not take robot commands)'
        )
    if robot not in (None, 'none') and have(*(parameter.name for parameter in declared(node='agent'))):
        problems += [f'robot: {robot}: {problem}' for problem in _kind_problems(robot, values)]
    return problems


SAFETY_PARAMETERS = {
    'min_separation': 'min_separation',
    'sensing_radius': 'sensing_radius',
    'gamma': 'safety_gamma',
    'max_speed': 'safety_max_speed',
    'turn': 'safety_turn',
}
"""The safety layer's keys (`SafetyConfig`) -> the agent's parameters."""


def _safety(values: dict) -> SafetyConfig:
    return SafetyConfig(**{key: values[name] for key, name in SAFETY_PARAMETERS.items()})


def _safety_problems(values: dict) -> list[str]:
    """The safety layer on: its own rules (`SafetyConfig`), eta1 in the plane, sensing from the
    simulator's service (which reports the other robots within R); a time warp is fine (every
    robot follows the same one, so the layer holds in the paper's time)."""
    problems = []
    try:
        _safety(values)
    except SafetyError as error:
        problems.append(str(error))
    if values.get('algorithm') == 'eta2':
        problems.append('min_separation: the safety layer runs with eta1 only, got algorithm eta2')
    if values.get('dimension', 2) != 2:
        problems.append(f'min_separation: the safety layer is planar, got dimension {values["dimension"]}')
    others = list(values.get('other_robot_ids', []))
    mine = {values.get('agent_id'), *values.get('neighbour_ids', [])}
    if len(set(others)) != len(others) or mine & set(others):
        problems.append(
            f'other_robot_ids must name each other robot once, not the agent or a neighbour, got {others}'
        )
    return problems


def _warp_problems(values: dict) -> list[str]:
    """A time warp: a good one (its rule time_warp), on ETA-1, at speed scale 1, on a robot."""
    try:
        TimeWarp.from_parameter(values['time_warp'])
    except WarpError as error:
        return [str(error)]
    problems = []
    if values.get('algorithm') == 'eta2':
        problems.append('time_warp: eta1 only (eta2 stays on a constant speed_scale: docs/SPEED_SCALE.md)')
    if values.get('speed_scale', 1.0) != 1.0:
        problems.append(
            f'time_warp: replaces speed_scale, which must then be 1, got {values["speed_scale"]!r}'
        )
    if values.get('robot') == 'none':
        problems.append(
            'time_warp: applies to robots (wall clock) only so far; a lock-step run takes none (robot: none)'
        )
    return problems


def _kind_problems(robot: str, values: dict) -> list[str]:
    """What the robot's kind says of the parameters known (formation_agent.core.kinds)."""
    kind = robot_kind(robot)
    geometry = _geometry(values)
    problems = kind.placement_problems(dimension=values.get('dimension'), geometry=geometry)
    if all(name in values for name in LIMIT_PARAMETERS):
        limits = Limits(
            linear_speed=values['max_linear_speed'],
            angular_speed=values['max_angular_speed'],
            linear_acceleration=values['max_linear_acceleration'],
            steering_angle=values['max_steering_angle'],
        )
        problems += kind.drive_problems(geometry=geometry, limits=limits)
    return problems


def _geometry(values: dict) -> Geometry:
    """The robot's shape from the agent's shape parameters read (those not read: their defaults)."""
    return Geometry(**{p.name: values[p.name] for p in declared(node='agent') if p.name in values})


def agent_help() -> str:
    """The parameter table `formation_agent --help` prints."""
    return parameter_help((*AGENT_PARAMETERS, *GAIN_PARAMETERS['eta1'], *GAIN_PARAMETERS['eta2']))
