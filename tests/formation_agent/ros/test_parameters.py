"""formation_agent.ros.parameters: descriptors, one error for every bad parameter, the help table."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.ros

DOMAIN_ID = 95  # nodes are created, never discovered: the domain only keeps runs apart


def _specs():
    from formation_agent.ros.parameters import DOUBLE, DOUBLE_ARRAY, INTEGER, STRING, ParameterSpec

    return (
        ParameterSpec(name='agent_id', type=INTEGER, description="this agent's id", low=0, high=2**31 - 1),
        ParameterSpec(
            name='delta', type=DOUBLE, description='communication radius Δ [m]', low=0.0, low_open=True
        ),
        ParameterSpec(
            name='loss', type=DOUBLE, description='drop probability', default=0.0, low=0.0, high=1.0
        ),
        ParameterSpec(
            name='offsets',
            type=DOUBLE_ARRAY,
            description='d_ij per neighbour',
            default=[0.0],
            low=-10.0,
            high=10.0,
        ),
        ParameterSpec(
            name='robot',
            type=STRING,
            description='command adapter',
            default='none',
            choices=('none', 'unicycle'),
        ),
    )


def _node(ros, **values):
    import rclpy
    from rclpy.parameter import Parameter

    overrides = [Parameter(name, value=value) for name, value in values.items()]
    return rclpy.create_node('probe', context=ros, parameter_overrides=overrides)


def test_good_parameters_are_read_with_their_defaults(ros):
    from formation_agent.ros.parameters import declare_parameters

    node = _node(ros, agent_id=3, delta=4.0)
    try:
        values = declare_parameters(node, _specs())
    finally:
        node.destroy_node()
    assert values == {
        'agent_id': 3,
        'delta': 4.0,
        'loss': 0.0,
        'offsets': pytest.approx([0.0]),
        'robot': 'none',
    }


def test_every_problem_is_named_in_one_error(ros):
    from formation_agent.ros.errors import ParameterError
    from formation_agent.ros.parameters import declare_parameters

    node = _node(ros, delta=0.0, loss=1.5, offsets=[1.0, 11.0], robot='tank')
    try:
        with pytest.raises(ParameterError) as caught:
            declare_parameters(node, _specs())
    finally:
        node.destroy_node()
    problems = caught.value.problems
    assert len(problems) == 5, problems
    assert problems[0] == "parameter 'agent_id' (int) is required: this agent's id"
    assert problems[1] == "parameter 'delta' (double) must be > 0, got 0.0"
    assert "parameter 'loss' (double)" in problems[2] and '1.5' in problems[2]  # rclpy's own range check
    assert problems[3] == "parameter 'offsets' (double[]) must be in [-10, 10] (every element), got 11.0"
    assert problems[4] == "parameter 'robot' (string) must be one of 'none', 'unicycle', got 'tank'"
    assert str(caught.value).startswith('/probe: ')


def test_a_value_of_the_wrong_type_is_named(ros):
    from formation_agent.ros.errors import ParameterError
    from formation_agent.ros.parameters import declare_parameters

    node = _node(ros, agent_id=1, delta='4.0')
    try:
        with pytest.raises(ParameterError, match=r"parameter 'delta' \(double\)") as caught:
            declare_parameters(node, _specs())
    finally:
        node.destroy_node()
    assert len(caught.value.problems) == 1


def test_descriptors_carry_description_type_and_range(ros):
    from rclpy.parameter import Parameter

    from formation_agent.ros.parameters import declare_parameters

    node = _node(ros, agent_id=1, delta=4.0)
    try:
        declare_parameters(node, _specs())
        agent, delta, loss, robot = node.describe_parameters(['agent_id', 'delta', 'loss', 'robot'])
    finally:
        node.destroy_node()
    assert agent.type == Parameter.Type.INTEGER.value and agent.description == "this agent's id"
    assert (agent.integer_range[0].from_value, agent.integer_range[0].to_value) == (0, 2**31 - 1)
    assert delta.additional_constraints == '> 0' and not delta.floating_point_range  # strict: words only
    assert (loss.floating_point_range[0].from_value, loss.floating_point_range[0].to_value) == (0.0, 1.0)
    assert robot.additional_constraints == "one of 'none', 'unicycle'"
    assert all(d.read_only for d in (agent, delta, loss, robot))


def test_the_help_table_lists_every_parameter():
    from formation_agent.ros.parameters import parameter_help

    text = parameter_help(_specs())
    lines = text.splitlines()
    assert len(lines) == 1 + len(_specs())
    assert lines[1].split()[:3] == ['agent_id', 'int', 'required']
    assert 'delta' in lines[2] and '> 0' in lines[2] and 'communication radius Δ [m]' in lines[2]
    assert "'none'" in lines[5] and "one of 'none', 'unicycle'" in lines[5]
