"""`formation measure`: a scenario started from where the robots are, read from their poses."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
import yaml

from formation_sim.cli import main
from formation_sim.model.scenario import load_scenario, scenario_to_dict

DOMAIN_ID = 92  # the silent-robot test on SILENT_DOMAIN_ID: pytest-xdist may run the two side by side
SILENT_DOMAIN_ID = 94
L = 0.1  # the control point ahead of the axle [m]

# Where each robot of robots_lab stands (its axle) and faces: set down by hand, nowhere near the file's.
AXLES = {1: (0.31, -0.12, 0.4), 2: (1.22, 0.05, 2.0), 3: (1.07, 1.18, -2.5), 4: (-0.08, 0.93, -1.0)}


@pytest.fixture
def robots():
    """`robots(domain=..., silent=())`: robots 1-4 publishing their odometry (`AXLES`) at 20 Hz on
    ROS domain `domain` until the test ends; `silent` ids publish nothing."""
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor

    from formation_msgs_py.qos import ROBOT_POSE_QOS
    from formation_msgs_py.topics import robot_odom_topic
    from formation_sim.sim.robots import quaternion_from_yaw

    running = []

    def start(*, domain: int, silent=()):
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node('fake_robots', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        publishers = {
            i: node.create_publisher(Odometry, robot_odom_topic(i), ROBOT_POSE_QOS)
            for i in AXLES
            if i not in silent
        }

        def publish():
            for i, publisher in publishers.items():
                x, y, theta = AXLES[i]
                msg = Odometry()
                msg.header.frame_id = 'world'
                msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
                msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = quaternion_from_yaw(theta)[2:]
                publisher.publish(msg)

        node.create_timer(0.05, publish)
        thread = threading.Thread(target=executor.spin, daemon=True)
        thread.start()
        running.append((context, node, executor, thread))

    yield start
    for context, node, executor, thread in running:
        executor.shutdown()
        thread.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.ros
def test_a_team_set_down_by_hand_gets_its_measured_control_points_and_headings(robots, tmp_path, capsys):
    robots(domain=DOMAIN_ID)
    out = tmp_path / 'measured.yaml'
    assert (
        main(
            ['measure', 'robots_lab', '--robot', 'unicycle', '--domain-id', str(DOMAIN_ID), '--out', str(out)]
        )
        == 0
    )
    measured, original = load_scenario(out), load_scenario('robots_lab')
    for k, i in enumerate(measured.agent_ids):
        x, y, theta = AXLES[i]
        assert np.allclose(
            measured.positions[k], [x + L * math.cos(theta), y + L * math.sin(theta)], rtol=0, atol=1e-12
        )
        assert measured.headings[k] == pytest.approx(theta, abs=1e-12)
    # Everything else is the file's: edges, gains, Δ, horizon.
    kept = {key: value for key, value in scenario_to_dict(original).items() if key not in ('agents', 'name')}
    assert {
        key: value for key, value in scenario_to_dict(measured).items() if key not in ('agents', 'name')
    } == kept
    assert 'robot 3: at ' in capsys.readouterr().out


@pytest.mark.ros
def test_positions_may_be_missing_and_a_silent_robot_is_named(robots, tmp_path, capsys):
    data = scenario_to_dict(load_scenario('robots_lab'))
    data['agents'] = {i: {} for i in data['agents']}  # no positions, no headings
    team = tmp_path / 'team.yaml'
    team.write_text(yaml.safe_dump(data))
    robots(domain=SILENT_DOMAIN_ID, silent=(3,))
    out = tmp_path / 'measured.yaml'
    assert (
        main(
            [
                'measure',
                str(team),
                '--robot',
                'unicycle',
                '--domain-id',
                str(SILENT_DOMAIN_ID),
                '--timeout',
                '2',
                '--out',
                str(out),
            ]
        )
        == 1
    )
    assert 'no pose within 2 s from robots 3 (topics /agent_<i>/robot/odom' in capsys.readouterr().err
    assert not out.exists()


def test_a_scenario_without_positions_points_at_formation_measure(tmp_path):
    from formation_sim.model.errors import ScenarioError

    data = scenario_to_dict(load_scenario('robots_lab'))
    data['agents'] = {i: {} for i in data['agents']}
    team = tmp_path / 'team.yaml'
    team.write_text(yaml.safe_dump(data))
    with pytest.raises(
        ScenarioError,
        match=r'agents\.1: position missing \(robots set down by hand: `formation measure` writes',
    ):
        load_scenario(team)


def test_an_existing_file_is_never_overwritten_and_bad_input_is_refused(tmp_path, capsys):
    out = tmp_path / 'measured.yaml'
    out.write_text('mine')
    assert main(['measure', 'robots_lab', '--robot', 'unicycle', '--out', str(out)]) == 2
    assert 'exists; choose a new file' in capsys.readouterr().err and out.read_text() == 'mine'
    assert (
        main(
            [
                'measure',
                'paper_double',
                '--robot',
                'holonomic',
                '--pose-type',
                'pose',
                '--out',
                str(tmp_path / 'd.yaml'),
            ]
        )
        == 2
    )
    assert 'double integrators start with a velocity: read it from odometry' in capsys.readouterr().err
    assert (
        main(
            [
                'measure',
                'robots_lab',
                '--robot',
                'unicycle',
                '--control-point-distance',
                '0',
                '--out',
                str(tmp_path / 'e.yaml'),
            ]
        )
        == 2
    )


def test_the_measured_start_replaces_positions_and_headings_only():
    from formation_sim.commands.measure import complete

    data = {
        'agents': {1: {'position': [0.0, 0.0], 'heading': 1.0}, 2: {}},
        'edges': [{'i': 1, 'j': 2, 'd': [1.0, 0.0]}],
        'gains': {'alpha': 1.0},
    }
    done = complete(data, {1: ([0.5, 0.25], 0.5, None), 2: ([1.5, 0.0], -0.5, [0.1, 0.0])})
    assert done['agents'] == {
        1: {'position': [0.5, 0.25], 'heading': 0.5},
        2: {'position': [1.5, 0.0], 'heading': -0.5, 'velocity': [0.1, 0.0]},
    }
    assert done['edges'] == data['edges'] and data['agents'][2] == {}  # the input is left as it was
