"""The registry of robot kinds: a kind defined once is what every consumer sees."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formation_agent.core.commander import RobotCommander
from formation_agent.core.errors import KindError, ShapeError
from formation_agent.core.kinds import (
    KIND_NAMES,
    SEPARATION_MARGIN,
    Geometry,
    KindNames,
    RobotKind,
    control_point_separation,
    default_min_separation,
    register,
    robot_kind,
    unregister,
)
from formation_agent.core.kinds.shape import ShapeParameter, declared
from formation_agent.core.limits import Limits, SaturationLog

HULL_WIDTH = ShapeParameter(
    name='hull_width',
    symbol='w',
    help='the width of its hull [m]',
    default=0.3,
    nodes=('agent', 'robot'),
    metavar='W',
)
"""The toy kind's own shape parameter: its one declaration is all it takes (docs/DESIGN.md)."""


class Sluggish(RobotKind):
    """A toy kind: a world-frame robot whose base moves at half the velocity it is sent, so its
    adapter sends 2u (and halves the speed limit); 1-D or 2-D; a shape parameter of its own."""

    name = 'sluggish'
    summary = 'world-frame TwistStamped at half speed (a toy)'
    command_type = 'geometry_msgs/msg/TwistStamped'
    world_frame_command = True
    dimensions = (1, 2)
    shape = (*RobotKind.shape, HULL_WIDTH)
    footprint_radius = 0.2

    def command(self, u, *, heading, geometry, limits, log):
        u = np.asarray(u, dtype=float)
        speed = float(np.linalg.norm(u))
        if speed > limits.linear_speed:
            log.note('linear_speed', speed, limits.linear_speed)
            u = u * (limits.linear_speed / speed)
        return tuple(float(c) for c in 2.0 * u)

    def clip(self, linear, angular, *, geometry, limits):
        return tuple(linear), float(angular), False

    def move(self, position, yaw, linear, angular, duration):
        return position + 0.5 * duration * np.array(linear), yaw + duration * angular

    def body_twist(self, linear, angular, yaw):
        world = np.zeros(3)
        world[: len(linear)] = 0.5 * np.array(linear)
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c * world[0] + s * world[1], -s * world[0] + c * world[1], world[2]]), angular


@pytest.fixture
def sluggish():
    kind = register(Sluggish())
    yield kind
    unregister(kind.name)
    assert kind.name not in KIND_NAMES
    assert HULL_WIDTH not in declared()  # its shape parameter went with it
    with pytest.raises(ShapeError, match=r"shape parameter must be one of \(.*\), got 'hull_width'"):
        Geometry(hull_width=0.3)


def test_a_kind_defined_once_is_usable_everywhere(sluggish, tmp_path):
    from formation_agent.ros.commands import command_message
    from formation_agent.ros.config import AGENT_PARAMETERS, _kind_problems
    from formation_sim.cli import build_parser
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.contract import robot_run_topics
    from formation_sim.runtime.launch.backends import BACKENDS
    from formation_sim.runtime.launch.plan import RobotOptions
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS
    from formation_sim.runtime.nodes.robot_node import SPECS as ROBOT_SPECS
    from formation_sim.sim.robots import Command, make_robot
    from formation_sim.sim.robots import Limits as BaseLimits

    # The command line: a backend, and what external robots or a fleet are.
    parser = build_parser()
    run = parser.parse_args(['run', 'robots_square', '--backend', 'sluggish'])
    assert run.backend == 'sluggish' and 'sluggish' in BACKENDS
    assert (
        parser.parse_args(['run', 'robots_square', '--backend', 'external', '--robot', 'sluggish']).robot
        == 'sluggish'
    )
    assert (
        parser.parse_args(['robots', 'robots_square', '--model', 'sluggish', '--domain-id', '41']).model
        == 'sluggish'
    )
    # The nodes' parameters: the agent's `robot`, the simulated robot's `model`, the coordinator's.
    for specs, name in (
        (AGENT_PARAMETERS, 'robot'),
        (ROBOT_SPECS, 'model'),
        (COORDINATOR_PARAMETERS, 'robot'),
        (COORDINATOR_PARAMETERS, 'backend'),
    ):
        spec = next(spec for spec in specs if spec.name == name)
        assert spec.problem('sluggish') is None and 'sluggish' in spec.constraint_text()
        assert spec.problem('tank') is not None
    assert _kind_problems('sluggish', {'control_point_distance': 0.0, 'wheelbase': 0.0, 'dimension': 3}) == [
        'a sluggish moves in 1 or 2 dimensions: dimension p must be 1 or 2, got 3'
    ]
    # The launch plan and the recorder's topics.
    scenario = load_scenario('robots_square')
    RobotOptions(model='sluggish').check(scenario)
    assert RobotOptions(model='sluggish').agent_parameters()['robot'] == 'sluggish'
    topics = dict(robot_run_topics(scenario, model='sluggish', simulated=True, pose_type='odom'))
    assert topics['/agent_1/robot/cmd_vel'] == 'geometry_msgs/msg/TwistStamped'
    # The agent's command adapter and the simulated robot both come from the kind: the robot
    # moves its control point with exactly the velocity u the agent asked for.
    _its_shape_parameter_is_everywhere(parser, scenario)
    commander = RobotCommander(drive='sluggish', dimension=2, limits=Limits(linear_speed=1.0))
    u = (0.3, -0.4)
    commander.set_control(0.0, u)
    command = commander.command(0.0)
    robot = make_robot(
        'sluggish',
        scenario_position=[1.0, 2.0],
        yaw=0.0,
        geometry=Geometry(control_point_distance=0.0),
        limits=BaseLimits(),
    )
    robot.set_command(Command(linear=command, angular=0.0))
    robot.advance(2.0)
    assert np.allclose(robot.scenario_position(), [1.6, 1.2], rtol=0, atol=1e-15)
    assert command_message(sluggish).__name__ == 'TwistStamped'


def _its_shape_parameter_is_everywhere(parser, scenario):
    """The toy kind's one declaration, HULL_WIDTH, in the command line, RobotOptions, the parameter
    files a run writes and the tables of the nodes it names (not the coordinator's)."""
    from formation_agent.ros.config import AGENT_PARAMETERS
    from formation_sim.commands.common import plan_options
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS
    from formation_sim.runtime.nodes.robot_node import SPECS as ROBOT_SPECS

    args = parser.parse_args(['run', 'robots_square', '--backend', 'sluggish', '--hull-width', '0.4'])
    robots = plan_options(args)['robots']
    assert robots.geometry.hull_width == 0.4 and Geometry().hull_width == 0.3  # given; its default
    assert robots.agent_parameters()['hull_width'] == 0.4
    assert robots.robot_parameters(scenario, 1)['hull_width'] == 0.4
    for table, present in ((AGENT_PARAMETERS, True), (ROBOT_SPECS, True), (COORDINATOR_PARAMETERS, False)):
        specs = {spec.name: spec for spec in table}
        assert ('hull_width' in specs) is present
        if present:
            spec = specs['hull_width']
            assert (spec.default, spec.constraint_text()) == (0.3, '> 0, finite')
            assert spec.description == 'sluggish: the width of its hull [m]'
            assert spec.problem(0.0) == 'must be > 0, finite, got 0.0'
    with pytest.raises(SystemExit):  # its rule, on the command line: > 0
        parser.parse_args(['run', 'robots_square', '--backend', 'sluggish', '--hull-width', '0'])


def test_kind_names_are_read_at_each_use(sluggish):
    backends = KindNames(before=('exact',), after=('external',))
    assert backends[0] == 'exact' and backends[-1] == 'external' and 'sluggish' in backends
    assert tuple(backends) == ('exact', *KIND_NAMES, 'external')
    unregister('sluggish')
    assert 'sluggish' not in backends
    register(sluggish)


def test_a_kind_is_registered_once_under_a_free_name(sluggish):
    with pytest.raises(
        KindError, match="a robot kind needs a name that is new and not one of .*got 'sluggish'"
    ):
        register(Sluggish())
    with pytest.raises(KindError, match="a robot kind needs a name .*got 'none'"):
        register(type('Plant', (Sluggish,), {'name': 'none'})())
    with pytest.raises(KindError, match=r"robot kind must be one of \('holonomic', 'unicycle'.*got 'tank'"):
        robot_kind('tank')


def test_every_built_in_kind_has_its_example_parameter_file():
    import yaml

    from formation_agent.config import (
        DIRECTORY as config,
    )  # the installed examples (python3 -m formation_agent.config)

    for name in KIND_NAMES:
        kind = robot_kind(name)
        params = yaml.safe_load((config / kind.params_file).read_text())['/**']['ros__parameters']
        assert params['robot'] == name, kind.params_file
        geometry = Geometry(
            control_point_distance=params.get('control_point_distance', 0.0),
            wheelbase=params.get('wheelbase', 0.0),
        )
        limits = Limits(
            linear_speed=params.get('max_linear_speed', math.inf),
            angular_speed=params.get('max_angular_speed', math.inf),
            steering_angle=params.get('max_steering_angle', math.inf),
        )
        assert kind.drive_problems(geometry=geometry, limits=limits) == []
        assert kind.placement_problems(dimension=None, geometry=geometry) == []


@pytest.mark.parametrize('name', ['holonomic', 'unicycle'])
def test_a_kinds_adapter_and_model_agree_where_no_limit_acts(name):
    """The command the adapter sends for u, held by the kind's model for a short time, moves the
    control point by u times that time to first order (the kinematics are exact at the instant)."""
    kind = robot_kind(name)
    geometry = Geometry(control_point_distance=0.2)
    rng = np.random.default_rng(5)
    for _ in range(20):
        u = rng.normal(size=2)
        yaw = rng.uniform(-math.pi, math.pi)
        log = SaturationLog()
        command = kind.command(u, heading=yaw, geometry=geometry, limits=Limits(), log=log)
        linear, angular = (command, 0.0) if kind.world_frame_command else ((command[0],), command[1])
        point = np.array([0.5, -0.25])
        origin = kind.origin(point, yaw, geometry)
        tau = 1e-6
        moved, turned = kind.move(origin, yaw, linear, angular, tau)
        rate = (moved + kind.world_offset(turned, geometry, 2) - point) / tau
        assert np.allclose(rate, u, atol=1e-5) and log.records == {}


def test_each_built_in_kind_carries_its_footprint():
    """Crazyflie 2.x with propellers, TurtleBot3 Burger (turtlebot3_navigation2's robot_radius), an
    F1TENTH car about its rear axle (docs/ROBOTS.md, "Footprints")."""
    footprints = {name: robot_kind(name).footprint(Geometry()) for name in ('holonomic', 'unicycle', 'car')}
    assert footprints == {'holonomic': 0.07, 'unicycle': 0.105, 'car': 0.49}
    assert robot_kind('unicycle').footprint(Geometry(footprint_radius=0.22)) == 0.22  # a Waffle, given
    # The F1TENTH body (f1tenth_gym: 0.58 m x 0.31 m, its centre lr = 0.17145 m ahead of the rear
    # axle) lies within the car's disc about its rear axle.
    front, rear, half_width = 0.17145 + 0.29, 0.29 - 0.17145, 0.155
    corners = [(x, y) for x in (front, -rear) for y in (half_width, -half_width)]
    assert max(math.hypot(x, y) for x, y in corners) <= footprints['car']


@pytest.mark.parametrize(
    ('name', 'geometry', 'reach'),
    [
        ('holonomic', Geometry(), 0.0),
        ('unicycle', Geometry(control_point_distance=0.1), 0.1),
        ('car', Geometry(control_point_distance=0.33, wheelbase=0.33), 0.33),
    ],
)
def test_control_points_kept_d_s_apart_keep_the_origins_d_apart_and_no_less_would(name, geometry, reach):
    kind, separation = robot_kind(name), 0.3
    d_s = control_point_separation(separation, kind=kind, geometry=geometry)
    assert math.isclose(d_s, separation + 2 * reach, rel_tol=0, abs_tol=1e-15)  # D + 2l (docs/SAFETY.md)
    rng = np.random.default_rng(27)
    for _ in range(2000):  # control points d_s apart, any direction, any headings
        yaw_i, yaw_j, direction = rng.uniform(-math.pi, math.pi, 3)
        point_j = d_s * np.array([math.cos(direction), math.sin(direction)])
        origin_i = kind.origin(np.zeros(2), yaw_i, geometry)
        origin_j = kind.origin(point_j, yaw_j, geometry)
        assert np.linalg.norm(origin_i - origin_j) >= separation - 1e-12
    # Back to back (control points pointing away from each other) the origins are exactly D apart.
    origin_i = kind.origin(np.zeros(2), math.pi, geometry)
    origin_j = kind.origin(np.array([d_s, 0.0]), 0.0, geometry)
    assert math.isclose(float(np.linalg.norm(origin_i - origin_j)), separation, rel_tol=0, abs_tol=1e-12)


def test_the_separation_between_two_kinds_adds_each_ones_reach():
    unicycle, holonomic = robot_kind('unicycle'), robot_kind('holonomic')
    mixed = control_point_separation(
        0.3,
        kind=unicycle,
        geometry=Geometry(control_point_distance=0.1),
        other_kind=holonomic,
        other_geometry=Geometry(),
    )
    assert math.isclose(mixed, 0.4, rel_tol=0, abs_tol=1e-15)
    with pytest.raises(KindError, match=r'origin_separation D must be a finite number >= 0 \[m\], got -0.1'):
        control_point_separation(-0.1, kind=unicycle, geometry=Geometry())


def test_the_default_separation_keeps_two_footprints_a_margin_apart():
    """--min-separation on robots by default: D_s for D = 2r + 0.05 m, between control points."""
    assert SEPARATION_MARGIN == 0.05
    cases = [
        ('holonomic', Geometry(), 2 * 0.07 + 0.05),
        ('unicycle', Geometry(), 2 * 0.105 + 0.05 + 2 * 0.1),  # TurtleBot3 Burgers at l = 0.1 m: 0.46 m
        ('unicycle', Geometry(footprint_radius=0.22), 2 * 0.22 + 0.05 + 2 * 0.1),  # Waffles: 0.69 m
        ('car', Geometry(control_point_distance=0.33, wheelbase=0.33), 2 * 0.49 + 0.05 + 2 * 0.33),
    ]
    for name, geometry, expected in cases:
        separation = default_min_separation(kind=robot_kind(name), geometry=geometry)
        assert math.isclose(separation, expected, rel_tol=1e-15), (name, separation, expected)
    assert default_min_separation(kind=robot_kind('holonomic'), geometry=Geometry(), margin=0.0) == 0.14
    with pytest.raises(KindError, match=r'margin must be a finite number >= 0 \[m\], got nan'):
        default_min_separation(kind=robot_kind('holonomic'), geometry=Geometry(), margin=math.nan)
