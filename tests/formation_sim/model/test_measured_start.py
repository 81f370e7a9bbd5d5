"""The check of the robots' measured start against the initial condition (initial), before step 0
(formation_sim.model.measured_start; the coordinator refuses a run that breaks it)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from formation_sim.model.measured_start import check_measured_start
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.robots import pose_sample


def _moved(scenario, agent: int, position) -> np.ndarray:
    x = np.array(scenario.positions, dtype=float)
    x[scenario.agent_ids.index(agent)] = position
    return x


def _pose(x: float, y: float, yaw: float):
    """A geometry_msgs/PoseStamped as pose_sample reads it (header stamp, position, orientation)."""
    return SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=0, nanosec=0)),
        pose=SimpleNamespace(
            position=SimpleNamespace(x=x, y=y, z=0.0),
            orientation=SimpleNamespace(x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0)),
        ),
    )


def test_robots_where_the_scenario_puts_them_start():
    scenario = load_scenario('robots_square')
    start = check_measured_start(scenario, scenario.positions)
    assert start.ok and not start.breaches
    assert np.all(start.distances == 0.0) and start.largest[1] == 0.0


def test_a_robot_moved_far_off_breaks_its_edges_with_the_numbers():
    scenario = load_scenario('robots_square')  # Δ = 2, ||d_ij|| = 1: Δ - ||d_ij|| = 1 on every edge
    x = _moved(scenario, 1, (-1.5, 0.0))
    start = check_measured_start(scenario, x)
    assert not start.ok
    assert [(b.i, b.j) for b in start.breaches] == [(1, 2), (4, 1)]
    by_edge = {(b.i, b.j): b for b in start.breaches}
    x1, x2, x4 = x[0], x[1], x[3]
    assert by_edge[1, 2].error == np.linalg.norm(x1 - x2 - np.array([-1.0, 0.0]))  # 1.515...
    assert by_edge[4, 1].error == np.linalg.norm(x4 - x1 - np.array([0.0, 1.0]))
    assert all(b.capacity == 2.0 - 1.0 for b in start.breaches)
    message = start.message()
    assert message.startswith(
        'edge (1,2): the measured ‖x_1 − x_2 − d_12‖ = 1.52 m is not below Δ − ‖d_12‖ = 1 m (initial '
        'condition of Theorem 1)'
    )
    assert 'edge (4,1): the measured ‖x_4 − x_1 − d_41‖ = 1.49 m' in message
    assert message.endswith(': the run does not start')
    assert start.largest == (1, 1.5)
    assert start.to_dict()['agents']['1'] == {'position': [-1.5, 0.0], 'distance': 1.5}


def test_the_numbers_are_printed_apart_when_they_round_alike():
    scenario = load_scenario('robots_square')
    # Edge (1,2) just past its bound: 1.0000001 must not read "1 is not below 1".
    x = _moved(scenario, 2, (-1e-7, 0.0))  # x_1 - x_2 - d_12 = (1 + 1e-7, 0)
    (breach,) = check_measured_start(scenario, x).breaches
    assert (breach.i, breach.j) == (1, 2) and breach.error > breach.capacity
    assert '= 1.0000001 m is not below Δ − ‖d_12‖ = 1 m' in breach.message()


def test_a_double_integrator_run_names_theorem_2():
    scenario = load_scenario('paper_double')
    far = np.array(scenario.positions[0]) + 10.0 * scenario.delta
    start = check_measured_start(scenario, _moved(scenario, scenario.agent_ids[0], far))
    assert start.breaches and all('(initial condition of Theorem 2)' in b.message() for b in start.breaches)


def test_a_unicycle_is_checked_at_its_control_point_not_its_axle():
    """Robot 1's axle at (-0.95, 0) meets (initial) on its edges (1,2) and (4,1) (0.965 and 0.935 < 1);
    its control point l = 0.1 m ahead does or does not, by its heading."""
    scenario = load_scenario('robots_square')

    def measured(yaw: float):
        point = pose_sample(
            _pose(-0.95, 0.0, yaw), model='unicycle', dimension=2, control_point_distance=0.1, epoch=0.0
        ).position
        return point, check_measured_start(scenario, _moved(scenario, 1, point))

    axle = check_measured_start(scenario, _moved(scenario, 1, (-0.95, 0.0)))
    assert axle.ok
    point, facing_away = measured(math.pi)  # heading -x: the control point 0.1 m further out
    assert np.allclose(point, (-1.05, 0.0), atol=1e-12)
    x = _moved(scenario, 1, point)
    assert [(b.i, b.j) for b in facing_away.breaches] == [(1, 2), (4, 1)]
    assert facing_away.breaches[0].error == np.linalg.norm(x[0] - x[1] - np.array([-1.0, 0.0]))  # 1.065
    assert facing_away.breaches[1].error == np.linalg.norm(x[3] - x[0] - np.array([0.0, 1.0]))  # 1.035
    point, facing_in = measured(0.0)  # heading +x: 0.1 m closer
    assert np.allclose(point, (-0.85, 0.0), atol=1e-12) and facing_in.ok
