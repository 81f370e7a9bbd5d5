"""formation_sim.runtime.contract: what the launch side writes is what the node programs read.

The launch side (`runtime.launch`) imports no node module (tests/test_layout.py), so nothing but
these tests holds the two sides to the same names: the parameter files a launch plan writes carry
the node names and parameters the node programs declare, and an agent's parameters give back
the scenario's offsets and gains bit for bit.  No ROS context is started (the tables only).
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from formation_msgs_py.topics import AGENT_NODE, COORDINATOR_NODE, SIMULATOR_NODE, agent_namespace
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.contract import (
    COORDINATOR_FILE,
    SIMULATOR_FILE,
    TRAJECTORY_TOPICS,
    agent_parameters,
    formation_topics,
    robot_run_topics,
)


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_an_agents_parameters_give_back_what_it_knows_of_the_scenario(name: str) -> None:
    scenario = load_scenario(name)
    gains = scenario.gains
    for agent in scenario.agent_ids:
        params = agent_parameters(scenario, agent, horizon=7.5, extra_subscribers=2)
        p = params['dimension']
        offsets = params['neighbour_offsets']
        assert len(offsets) == p * len(params['neighbour_ids'])
        back = {j: offsets[k * p : (k + 1) * p] for k, j in enumerate(params['neighbour_ids'])}
        expected = scenario.neighbours(agent)
        assert set(back) == set(expected)
        for j, d in expected.items():
            assert np.array_equal(np.asarray(back[j]), d), (agent, j)  # bit for bit
        assert (params['agent_id'], params['horizon'], params['extra_subscribers']) == (agent, 7.5, 2)
        if scenario.dynamics == 'single':
            assert (params['algorithm'], params['alpha'], params['beta']) == ('eta1', gains.alpha, gains.beta)
        else:
            assert params['algorithm'] == 'eta2'
            assert [params[k] for k in ('alpha_d', 'beta_d', 'k1', 'k2', 'k3')] == [
                gains.alpha_d,
                gains.beta_d,
                gains.k1,
                gains.k2,
                gains.k3,
            ]


@pytest.mark.parametrize('name', ['paper_single', 'paper_double'])
def test_every_parameter_an_agent_gets_is_one_the_agent_declares(name: str) -> None:
    from formation_agent.ros.config import AGENT_PARAMETERS, GAIN_PARAMETERS

    scenario = load_scenario(name)
    params = agent_parameters(scenario, scenario.agent_ids[0], horizon=1.0)
    declared = {spec.name for spec in AGENT_PARAMETERS} | {
        spec.name for spec in GAIN_PARAMETERS[params['algorithm']]
    }
    assert set(params) <= declared, sorted(set(params) - declared)


def _written(tmp_path, backend: str, file: str) -> dict:
    from formation_sim.runtime.launch.orchestrate import FormationRun

    plan = FormationRun('robots_square', out_dir=tmp_path / backend, backend=backend).plan
    paths = plan.write_inputs()
    assert paths['keeper'] == tmp_path / backend / file
    return yaml.safe_load(paths['keeper'].read_text())


def test_the_keepers_parameter_file_is_the_one_its_node_reads(tmp_path) -> None:
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS, RobotWorld
    from formation_sim.runtime.nodes.sim_node import SIMULATOR_PARAMETERS, SimulatorWorld

    for backend, file, world, node_name, table in (
        ('exact', SIMULATOR_FILE, SimulatorWorld, SIMULATOR_NODE, SIMULATOR_PARAMETERS),
        ('holonomic', COORDINATOR_FILE, RobotWorld, COORDINATOR_NODE, COORDINATOR_PARAMETERS),
    ):
        assert file == world.PARAMS_FILE  # `formation params` and the node's --help name this file
        assert node_name == world.NODE_NAME and table is world.PARAMETERS  # the node the file is for
        written = _written(tmp_path, backend, file)
        assert list(written) == [f'/{node_name}'], backend
        names = set(written[f'/{node_name}']['ros__parameters'])
        declared = {spec.name for spec in table}
        assert names and names <= declared, (backend, sorted(names - declared))


def test_the_agents_file_holds_each_agents_contract_parameters(tmp_path) -> None:
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun('paper_single', out_dir=tmp_path / 'run', backend='exact', horizon=3.0)
    paths = run.plan.write_inputs()
    written = yaml.safe_load(paths['agents'].read_text())
    scenario = run.plan.scenario
    for agent in scenario.agent_ids:
        got = written[f'{agent_namespace(agent)}/{AGENT_NODE}']['ros__parameters']
        own = agent_parameters(scenario, agent, horizon=3.0, extra_subscribers=1)  # the recorder reads
        assert {key: got[key] for key in own} == own, agent


def test_a_robot_run_records_the_topic_the_formation_is_measured_on() -> None:
    scenario = load_scenario('robots_square')
    for simulated, pose_type, truth, measured in (
        (True, 'pose', None, 'true_odom'),
        (True, 'odom', False, 'odom'),
        (False, 'pose', None, 'pose'),
        (False, 'odom', None, 'odom'),
    ):
        listed = {
            topic
            for topic, _ in robot_run_topics(
                scenario, model='holonomic', simulated=simulated, pose_type=pose_type, truth=truth
            )
        }
        for agent in scenario.agent_ids:
            assert TRAJECTORY_TOPICS[measured](agent) in listed, (simulated, pose_type, agent)
            assert TRAJECTORY_TOPICS[pose_type](agent) in listed  # what the agents read
    exact = {topic for topic, _ in formation_topics(scenario)}
    assert not any('/robot/' in topic for topic in exact)  # the exact world has no robots
