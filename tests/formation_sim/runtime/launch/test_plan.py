"""The launch plan of each backend: what a run writes and starts, and the options it refuses
before anything touches the disk (no process is started here)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from formation_agent.core.kinds import Geometry
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.orchestrate import FormationRun
from formation_sim.runtime.launch.plan import RobotOptions

TURTLEBOT3 = RobotOptions(
    model='unicycle',
    geometry=Geometry(control_point_distance=0.1),
    max_linear_speed=0.22,
    max_angular_speed=2.84,
)


def _plan(tmp_path, backend, robots=None, **options):
    return FormationRun(
        'robots_square', out_dir=tmp_path / 'run', backend=backend, robots=robots, **options
    ).plan


def test_the_exact_backend_is_the_simulator_and_its_agents(tmp_path):
    plan = _plan(tmp_path, 'exact')
    specs = plan.processes(plan.write_inputs())
    assert [spec.name for spec in specs] == [
        'recorder',
        'simulator',
        'agent_1',
        'agent_2',
        'agent_3',
        'agent_4',
    ]
    assert [spec.name for spec in specs if spec.keeper] == ['simulator'] and plan.clock == 'lockstep'
    simulator = yaml.safe_load((tmp_path / 'run' / 'simulator.params.yaml').read_text())[
        '/formation_simulator'
    ]['ros__parameters']
    assert specs[1].args[-2:] == ('--params-file', str(tmp_path / 'run' / 'simulator.params.yaml'))
    assert simulator['clock_mode'] == 'lockstep' and simulator['scenario'] == str(
        (tmp_path / 'run' / 'scenario.yaml').resolve()
    )
    assert (
        specs[1].command
        == f'formation_sim --ros-args --params-file {tmp_path / "run" / "simulator.params.yaml"}'
    )
    agents = yaml.safe_load((tmp_path / 'run' / 'agents.params.yaml').read_text())
    assert 'sensing' not in agents['/agent_1/formation_agent']['ros__parameters']  # the simulator's service
    assert not (tmp_path / 'run' / 'robots.params.yaml').exists()


def test_auto_packing_keeps_one_process_per_agent_for_small_teams_and_few_processes_for_large_ones(tmp_path):
    from formation_sim.model.generate import random_scenario
    from formation_sim.runtime.launch.plan import AUTO_AGENT_PROCESSES, ONE_PROCESS_PER_AGENT_UP_TO

    small = FormationRun('paper_single', out_dir=tmp_path / 'small', agents_per_process='auto').plan
    assert small.agent_groups() == [[1], [2], [3]]
    edge = random_scenario(n=ONE_PROCESS_PER_AGENT_UP_TO, seed=3)
    assert (
        FormationRun(edge, out_dir=tmp_path / 'edge', agents_per_process='auto').plan.agents_per_process == 1
    )
    large = FormationRun(
        random_scenario(n=ONE_PROCESS_PER_AGENT_UP_TO + 1, seed=3),
        out_dir=tmp_path / 'large',
        agents_per_process='auto',
    ).plan
    groups = large.agent_groups()
    assert 1 < len(groups) <= AUTO_AGENT_PROCESSES and sorted(i for group in groups for i in group) == list(
        large.scenario.agent_ids
    )
    assert max(map(len, groups)) == -(-(ONE_PROCESS_PER_AGENT_UP_TO + 1) // AUTO_AGENT_PROCESSES)
    for bad in (0, 'many', 2.5, True):
        with pytest.raises(
            RunError, match=f"agents_per_process must be an integer >= 1 or 'auto', got {bad!r}"
        ):
            FormationRun('paper_single', out_dir=tmp_path / 'bad', agents_per_process=bad)
    assert not (tmp_path / 'bad').exists()


def test_a_discovery_server_starts_first_and_every_other_child_is_its_client(tmp_path, monkeypatch):
    import dataclasses
    import os

    monkeypatch.setenv('ROS_DISCOVERY_SERVER', '10.0.0.9:11811')  # a user's own server is not the run's
    simple = _plan(tmp_path / 'simple', 'exact')
    assert 'ROS_DISCOVERY_SERVER' not in simple.environment(150, extra_env={})
    plan = dataclasses.replace(_plan(tmp_path / 'server', 'exact', discovery='server'), discovery_port=40123)
    specs = plan.processes(plan.write_inputs())
    assert [spec.name for spec in specs][:3] == ['discovery_server', 'recorder', 'simulator']
    # The simulator writes every node's endpoints into graph.json: it must learn of them all.
    assert [spec.name for spec in specs if dict(spec.env).get('ROS_SUPER_CLIENT') == 'TRUE'] == ['simulator']
    server = specs[0]
    assert os.access(server.program, os.X_OK) and server.program.endswith('fast-discovery-server')
    assert (
        server.args == ('--server-id', '0', '--udp-address', '127.0.0.1', '--udp-port', '40123')
        and not server.expected_exit
    )
    assert plan.environment(150, extra_env={})['ROS_DISCOVERY_SERVER'] == '127.0.0.1:40123'
    assert plan.process_count() == simple.process_count() + 1
    across = dataclasses.replace(
        _plan(tmp_path / 'across', 'exact', discovery='server', localhost_only=False), discovery_port=40123
    )
    assert across.discovery_server_process().args[3] == '0.0.0.0'  # noqa: S104 - clients on other machines reach it


def test_a_discovery_server_that_is_not_installed_is_refused_before_anything_exists(tmp_path, monkeypatch):
    from formation_sim.runtime.launch import plan as launch

    monkeypatch.setattr(launch, 'DISCOVERY_SERVER_PROGRAM', 'no-such-discovery-server')
    with pytest.raises(
        RunError,
        match='the discovery server needs no-such-discovery-server .*neither .*/no-such-discovery-server nor',
    ):
        _plan(tmp_path, 'exact', discovery='server')
    with pytest.raises(RunError, match="discovery must be one of \\('simple', 'server'\\), got 'multicast'"):
        _plan(tmp_path, 'exact', discovery='multicast')
    assert not (tmp_path / 'run').exists()


def test_a_unicycle_run_places_each_robot_by_its_control_point_and_tells_its_agent(tmp_path):
    plan = _plan(
        tmp_path,
        'unicycle',
        RobotOptions(**{**TURTLEBOT3.to_dict(), 'yaw': math.pi / 2, 'robots_per_process': 2}),
    )
    paths = plan.write_inputs()
    specs = plan.processes(paths)
    assert [spec.name for spec in specs] == [
        'recorder',
        'robots_1-2',
        'robots_3-4',
        'coordinator',
        'agent_1',
        'agent_2',
        'agent_3',
        'agent_4',
    ]
    assert plan.clock == 'realtime'
    assert 'formation_sim.runtime.nodes.coordinator' in next(spec for spec in specs if spec.keeper).args
    coordinator = yaml.safe_load(paths['keeper'].read_text())['/formation_coordinator']['ros__parameters']
    assert coordinator['robot'] == 'unicycle' and coordinator['backend'] == 'unicycle'
    assert (
        coordinator['robot_trajectory'] == 'odom'
    )  # simulated without noise or latency: its odometry is exact
    robots = yaml.safe_load(paths['robots'].read_text())
    scenario = load_scenario('robots_square')
    for agent in scenario.agent_ids:
        params = robots[f'/agent_{agent}/simulated_robot']['ros__parameters']
        assert (
            params['model'] == 'unicycle'
            and params['max_linear_speed'] == 0.22
            and params['max_angular_speed'] == 2.84
        )
        # The robot node puts its axle l behind `position` along `yaw`: here the scenario point itself.
        assert (
            params['position'] == scenario.positions[scenario.index(agent)].tolist()
            and params['yaw'] == math.pi / 2
        )
        assert params['publish_truth'] is False  # its odometry is the truth: no second copy
    agents = yaml.safe_load(paths['agents'].read_text())['/agent_3/formation_agent']['ros__parameters']
    assert {
        key: agents[key]
        for key in (
            'sensing',
            'pose_type',
            'robot',
            'control_point_distance',
            'max_linear_speed',
            'max_angular_speed',
            'world_frame',
        )
    } == {
        'sensing': 'poses',
        'pose_type': 'odom',
        'robot': 'unicycle',
        'control_point_distance': 0.1,
        'max_linear_speed': 0.22,
        'max_angular_speed': 2.84,
        'world_frame': 'world',
    }
    assert 'max_linear_acceleration' not in agents  # no limit given: the agent's default (none)
    recorder = yaml.safe_load(paths['recorder'].read_text())['/formation_recorder']['ros__parameters']
    assert (
        'clock_topic' not in recorder
    )  # the Step topic: bag time is the run's time, as on the exact backend
    recorded = {spec.split(':')[0] for spec in recorder['topics']}
    assert {'/agent_2/robot/cmd_vel', '/agent_2/robot/odom', '/formation/robots'} <= recorded
    assert '/agent_2/robot/pose' not in recorded  # the agents read odometry
    assert '/agent_2/robot/true_odom' not in recorded  # not published: odom is exact
    assert recorder['watched_topics'] == [f'/agent_{i}/robot/odom' for i in scenario.agent_ids]


@pytest.mark.parametrize(
    ('noise', 'pose_type'),
    [({'pose_noise': 0.005}, 'odom'), ({'yaw_noise': 0.01}, 'odom'), ({'latency': 0.02}, 'pose')],
)
def test_simulated_robots_whose_odometry_is_not_exact_publish_their_truth_and_the_formation_is_measured_on_it(
    tmp_path, noise, pose_type
):
    plan = _plan(
        tmp_path, 'unicycle', RobotOptions(**{**TURTLEBOT3.to_dict(), **noise, 'pose_type': pose_type})
    )
    paths = plan.write_inputs()
    assert (
        yaml.safe_load(paths['keeper'].read_text())['/formation_coordinator']['ros__parameters'][
            'robot_trajectory'
        ]
        == 'true_odom'
    )
    robots = yaml.safe_load(paths['robots'].read_text())
    assert all(params['ros__parameters']['publish_truth'] is True for params in robots.values())
    recorder = yaml.safe_load(paths['recorder'].read_text())['/formation_recorder']['ros__parameters']
    recorded = {spec.split(':')[0] for spec in recorder['topics']}
    sensed = '/agent_2/robot/pose' if pose_type == 'pose' else '/agent_2/robot/odom'
    assert {'/agent_2/robot/true_odom', sensed} <= recorded  # the truth, and what the agents read
    assert (
        recorder['watched_topics'] == [t for t in recorder['watched_topics'] if t.startswith('/agent_')]
        and len(recorder['watched_topics']) == 8
    )


def test_an_external_run_starts_no_robot_and_measures_the_formation_on_what_the_agents_read(tmp_path):
    plan = _plan(tmp_path, 'external', RobotOptions(model='holonomic', pose_type='pose'))
    specs = plan.processes(plan.write_inputs())
    assert [spec.name for spec in specs] == [
        'recorder',
        'coordinator',
        'agent_1',
        'agent_2',
        'agent_3',
        'agent_4',
    ]
    coordinator = yaml.safe_load((tmp_path / 'run' / 'coordinator.params.yaml').read_text())[
        '/formation_coordinator'
    ]['ros__parameters']
    assert coordinator['robot_trajectory'] == 'pose' and coordinator['backend'] == 'external'
    recorder = yaml.safe_load((tmp_path / 'run' / 'recorder.params.yaml').read_text())['/formation_recorder'][
        'ros__parameters'
    ]
    assert '/agent_1/robot/cmd_vel:geometry_msgs/msg/TwistStamped' in recorder['topics']


@pytest.mark.parametrize('pose_type', ['odom', 'pose'])
def test_the_recorder_waits_only_for_the_poses_the_agents_read(tmp_path, pose_type):
    """An external team that publishes only odometry (or only PoseStamped) starts: the recorder
    records both kinds, whichever the robots have, but step 0 waits only for the kind the agents
    read (before, an odometry-only team never started: a DiscoveryError after 120 s)."""
    other = {'odom': 'pose', 'pose': 'odom'}[pose_type]
    for backend, robots in (
        ('external', RobotOptions(model='unicycle', pose_type=pose_type)),
        ('unicycle', RobotOptions(model='unicycle', pose_type=pose_type)),
    ):
        folder = tmp_path / f'{backend}_{pose_type}'
        plan = _plan(folder, backend, robots)
        plan.write_inputs()
        recorder = yaml.safe_load((folder / 'run' / 'recorder.params.yaml').read_text())[
            '/formation_recorder'
        ]['ros__parameters']
        coordinator = yaml.safe_load((folder / 'run' / 'coordinator.params.yaml').read_text())[
            '/formation_coordinator'
        ]['ros__parameters']
        # What the agents read, and what the coordinator measures the formation on.
        read = {f'/agent_1/robot/{pose_type}', f'/agent_1/robot/{coordinator["robot_trajectory"]}'}
        assert sorted(
            topic for topic in recorder['watched_topics'] if topic.startswith('/agent_1/')
        ) == sorted(read)
        recorded = {entry.split(':')[0] for entry in recorder['topics']}
        if backend == 'external':  # both kinds recorded, whichever the robots have
            assert (
                f'/agent_1/robot/{other}' in recorded
                and f'/agent_1/robot/{other}' not in recorder['watched_topics']
            )
        assert coordinator['pose_silence'] == robots.pose_timeout
        assert coordinator['world_frame'] == robots.world_frame  # its zero commands' frame


@pytest.mark.parametrize(
    ('options', 'complaint'),
    [
        (dict(backend='external'), "backend 'external' needs robots=RobotOptions(model=...)"),
        (
            dict(backend='unicycle', robots=RobotOptions(model='holonomic')),
            "backend 'unicycle' simulates unicycle robots, but robots.model is 'holonomic'",
        ),
        (
            dict(backend='holonomic', clock='lockstep'),
            "robots run on the wall clock: backend 'holonomic' needs clock=realtime, got 'lockstep'",
        ),
        (dict(backend='exact', robots=TURTLEBOT3), 'robots are options of the robot backends'),
        (
            dict(backend='mujoco'),
            "backend must be one of ('exact', 'holonomic', 'unicycle', 'car', 'external'), got 'mujoco'",
        ),
        (
            dict(backend='unicycle', robots=RobotOptions(max_linear_speed=0.0)),
            'the linear speed limit must be > 0 (inf: none), got 0.0',
        ),
        (
            dict(backend='unicycle', robots=RobotOptions(pose_noise=-0.1)),
            'pose_noise must be a finite number >= 0, got -0.1',
        ),
        (
            dict(backend='unicycle', robots=RobotOptions(geometry=Geometry(control_point_distance=0.0))),
            'control_point_distance l must be a finite number > 0 [m], got 0.0',
        ),
        (
            dict(backend='unicycle', robots=RobotOptions(pose_type='tf')),
            "pose_type must be one of ('odom', 'pose'), got 'tf'",
        ),
    ],
)
def test_bad_robot_options_are_refused_before_anything_exists(tmp_path, options, complaint):
    with pytest.raises(RunError) as caught:
        FormationRun('robots_square', out_dir=tmp_path / 'run', **options)
    assert complaint in str(caught.value)
    assert not (tmp_path / 'run').exists()


def test_unicycles_need_a_planar_scenario(tmp_path, paper_scenario_dict):
    data = paper_scenario_dict()
    for agent in data['agents'].values():
        agent['position'] = [*agent['position'], 0.0]
    for edge in data['edges']:
        edge['d'] = [*edge['d'], 0.0]
    path = tmp_path / 'space.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(RunError, match='a unicycle moves in the plane: dimension p must be 2, got 3'):
        FormationRun(path, out_dir=tmp_path / 'run', backend='unicycle')
    assert FormationRun(path, out_dir=tmp_path / 'run', backend='holonomic').plan.robots.model == 'holonomic'


def test_robot_options_reach_the_simulated_robots(tmp_path):
    noisy = RobotOptions(model='holonomic', pose_noise=0.005, latency=0.02, seed=3)
    params = noisy.robot_parameters(load_scenario('robots_square'), 2)
    assert {key: params[key] for key in ('pose_noise', 'pose_latency', 'seed', 'rate')} == {
        'pose_noise': 0.005,
        'pose_latency': 0.02,
        'seed': 3,
        'rate': 100.0,
    }
    assert np.array_equal(params['position'], [1.015, -0.0075])


def test_simulated_robots_start_at_the_scenarios_headings_unless_one_is_given(tmp_path):
    lab = load_scenario('robots_lab')
    options = RobotOptions(**{**TURTLEBOT3.to_dict(), 'yaw': None})
    assert [options.initial_heading(lab, agent) for agent in lab.agent_ids] == lab.headings.tolist()
    assert options.initial_heading(load_scenario('robots_square'), 1) == 0.0  # none in the scenario
    given = RobotOptions(**{**TURTLEBOT3.to_dict(), 'yaw': 0.5})
    assert {given.initial_heading(lab, agent) for agent in lab.agent_ids} == {0.5}  # --initial-heading wins
    assert options.robot_parameters(lab, 3)['yaw'] == -0.155


def test_a_childs_environment_is_the_runs_whatever_this_process_had(tmp_path):
    from formation_msgs_py.middleware import FASTDDS_PROFILE
    from formation_sim.runtime.launch.plan import child_environment

    mine = {
        'ROS_DOMAIN_ID': '7',
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
        'ROS_DISCOVERY_SERVER': '10.0.0.9:11811',  # a user's own server is not the run's
        'OPENBLAS_NUM_THREADS': '4',  # the user's choice stays
        'HOME': '/home/someone',
    }
    where = dict(domain_id=150, log_dir=tmp_path / 'logs' / 'ros', udp_only=False, extra_env={})
    env = child_environment(dict(mine), localhost_only=True, discovery_server=None, **where)
    assert env['ROS_DOMAIN_ID'] == '150' and env['ROS_LOG_DIR'] == str((tmp_path / 'logs' / 'ros').resolve())
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST' and 'ROS_DISCOVERY_SERVER' not in env
    assert env['OPENBLAS_NUM_THREADS'] == '4' and env['HOME'] == '/home/someone'
    assert env['RMW_IMPLEMENTATION'] == 'rmw_fastrtps_cpp' and 'FASTDDS_BUILTIN_TRANSPORTS' not in env
    assert env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(FASTDDS_PROFILE)
    wide = child_environment(
        dict(mine), localhost_only=False, discovery_server='127.0.0.1:40123', **{**where, 'udp_only': True}
    )
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in wide  # Jazzy's default: the subnet
    assert wide['ROS_DISCOVERY_SERVER'] == '127.0.0.1:40123' and wide['FASTDDS_BUILTIN_TRANSPORTS'] == 'UDPv4'
    extra = child_environment(
        dict(mine),
        localhost_only=True,
        discovery_server=None,
        **{**where, 'extra_env': {'ROS_DOMAIN_ID': '9', 'FOO': 'bar'}},
    )
    assert extra['ROS_DOMAIN_ID'] == '9' and extra['FOO'] == 'bar'  # the caller's own word is last


def test_a_robots_topics_by_kind():
    from formation_sim.runtime.launch.plan import robot_topics

    scenario = load_scenario('robots_square')
    assert robot_topics(scenario, 'pose', 'command') == {
        f'/agent_{i}/robot/{name}' for i in scenario.agent_ids for name in ('pose', 'cmd_vel')
    }
    assert robot_topics(scenario, 'odom', 'odom') == {f'/agent_{i}/robot/odom' for i in scenario.agent_ids}


def test_simulated_robots_run_on_after_a_lost_agent_until_their_command_timeout_stops_them(tmp_path):
    import dataclasses
    from types import SimpleNamespace

    from formation_sim.runtime.launch.orchestrate import robots_after

    agent, robot = SimpleNamespace(name='agent_2'), SimpleNamespace(name='robot_2')
    robots = dataclasses.replace(TURTLEBOT3, command_timeout=0.75)
    unicycles = _plan(tmp_path / 'u', 'unicycle', robots=robots)
    assert robots_after(unicycles, agent) == 0.75 + 0.3  # its robot stops on its own, in the bag
    assert robots_after(unicycles, robot) == robots_after(unicycles, None) == 0.0
    assert robots_after(_plan(tmp_path / 'x', 'external', robots=robots), agent) == 0.0  # not ours


def test_every_node_of_a_run_is_its_own_and_a_signal_asks_the_run_to_stop():
    import signal

    from formation_agent.ros.process import SignalFlag
    from formation_sim.runtime.launch.orchestrate import own_nodes, signals_trapped

    assert own_nodes(load_scenario('paper_single')) == {
        '/formation_simulator',
        '/formation_coordinator',
        '/formation_recorder',
        *(f'/agent_{i}/{node}' for i in (1, 2, 3) for node in ('formation_agent', 'simulated_robot')),
    }
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig, handler in before.items():
        flag = SignalFlag()
        with signals_trapped(flag):
            signal.getsignal(sig)(sig, None)  # what the interpreter calls on the signal
            assert flag.is_set()
        assert signal.getsignal(sig) is handler


def test_robot_options_take_the_shape_parameters_and_give_the_default_separation():
    from formation_sim.cli import build_parser
    from formation_sim.commands.common import plan_options

    burgers = RobotOptions(model='unicycle')
    assert burgers.geometry == Geometry(control_point_distance=0.1)  # the declared default
    assert math.isclose(burgers.default_min_separation, 2 * 0.105 + 0.05 + 2 * 0.1, rel_tol=1e-15)
    waffles = RobotOptions.of(model='unicycle', footprint_radius=0.22, max_linear_speed=0.26)
    assert (waffles.geometry.footprint_radius, waffles.max_linear_speed) == (0.22, 0.26)
    assert math.isclose(waffles.default_min_separation, 2 * 0.22 + 0.05 + 2 * 0.1, rel_tol=1e-15)
    # The command line's flags are the declared parameters; a car's files hold its L.
    args = build_parser().parse_args(
        ['run', 'robots_square', '--backend', 'car', '--wheelbase', '0.33', '--footprint-radius', '0.3']
    )
    cars = plan_options(args)['robots']
    assert cars.geometry == Geometry(control_point_distance=0.1, wheelbase=0.33, footprint_radius=0.3)
    scenario = load_scenario('robots_square')
    assert {k: cars.agent_parameters()[k] for k in ('control_point_distance', 'wheelbase')} == {
        'control_point_distance': 0.1,
        'wheelbase': 0.33,
    }
    assert cars.robot_parameters(scenario, 1)['wheelbase'] == 0.33
    assert 'wheelbase' not in RobotOptions(model='unicycle').agent_parameters()  # not a unicycle's
    with pytest.raises(RunError, match=r'footprint_radius r must be a finite number > 0 \[m\], got 0.0'):
        RobotOptions(model='unicycle', geometry=Geometry(footprint_radius=0.0)).check(scenario)
