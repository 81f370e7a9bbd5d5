"""The agent node's parameters: what it needs is checked up front, with the rule broken named."""

from __future__ import annotations

import os

import pytest

pytestmark = pytest.mark.ros

DOMAIN_ID = 116

GOOD = {
    'agent_id': 1,
    'algorithm': 'eta1',
    'dimension': 2,
    'neighbour_ids': [2, 3],
    'neighbour_offsets': [0.0, -2.0, -2.0, 0.0],
    'delta': 4.0,
    'horizon': 10.0,
    'alpha': 10.0,
    'beta': 1.0,
}


@pytest.fixture(scope='module')
def ros(tmp_path_factory):
    import rclpy

    os.environ.setdefault('ROS_LOG_DIR', str(tmp_path_factory.mktemp('ros_log')))
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)


def make_node(ros, **changes):
    from rclpy.parameter import Parameter

    from formation_agent.node import FormationAgentNode

    values = {**GOOD, **changes}
    overrides = [Parameter(name, value=value) for name, value in values.items() if value is not None]
    node = FormationAgentNode(namespace='agent_1', context=ros, parameter_overrides=overrides, start_parameter_services=False)
    node.destroy_node()
    return node


def test_good_parameters_give_the_agent_its_neighbours(ros):
    node = make_node(ros)
    assert node.neighbours == {2: (0.0, -2.0), 3: (-2.0, 0.0)}
    assert node.gains == {'alpha': 10.0, 'beta': 1.0}


@pytest.mark.parametrize(
    ('changes', 'complaint'),
    [
        ({'delta': None}, "parameter 'delta' (DOUBLE) is required"),
        ({'beta': None}, "parameter 'beta' (DOUBLE) is required"),
        ({'algorithm': 'eta3'}, "algorithm must be one of ['eta1', 'eta2'], got 'eta3'"),
        ({'dimension': 4}, 'dimension must be 1, 2 or 3 (commands travel as geometry_msgs), got 4'),
        ({'neighbour_offsets': [0.0, -2.0, -2.0]}, 'neighbour_offsets must hold dimension * len(neighbour_ids) = 2 * 2 values'),
        ({'neighbour_ids': [2, 2]}, 'neighbour_ids repeat an id: [2, 2]'),
        ({'horizon': float('inf')}, 'horizon must be a finite number > 0, got inf'),
        ({'algorithm': 'eta2'}, "parameter 'alpha_d' (DOUBLE) is required"),
        ({'agent_id': 7}, 'agent 7 must run in namespace /agent_7'),
    ],
)
def test_bad_parameters_are_rejected_with_the_rule_broken(ros, changes, complaint):
    from formation_agent.node import AgentNodeError

    with pytest.raises(AgentNodeError) as error:
        make_node(ros, **changes)
    assert complaint in str(error.value)
    assert '/agent_1/formation_agent' in str(error.value)
