"""The nodes' robot parameters, generated from one declaration each: the tables agree."""

from __future__ import annotations

import math

import pytest

from formation_agent.core.kinds.shape import declared, shape_parameter
from formation_agent.ros.kind_parameters import LIMITS, SpecTable, limit_spec, shape_spec, shape_specs


def _tables() -> dict:
    from formation_agent.ros.config import AGENT_PARAMETERS
    from formation_sim.runtime.nodes.coordinator import COORDINATOR_PARAMETERS
    from formation_sim.runtime.nodes.robot_node import SPECS

    return {'agent': AGENT_PARAMETERS, 'coordinator': COORDINATOR_PARAMETERS, 'robot': SPECS}


def _key(spec):
    """Everything of a spec but its description: what a node accepts and assumes."""
    return (spec.type, spec.default, spec.low, spec.high, spec.low_open, spec.high_open, spec.choices)


def test_every_node_declares_each_shape_parameter_it_takes_as_its_kind_does():
    """The finding of issue 29: l defaulted to 0.0 (>= 0) in the agent, 0.1 (>= 0) in the coordinator
    and 0.1 (> 0) in the robot node.  Now one declaration: 0.1, > 0 and finite, in all three."""
    tables = _tables()
    for parameter in declared():
        specs = [
            next(spec for spec in tables[node] if spec.name == parameter.name) for node in parameter.nodes
        ]
        assert len({_key(spec) for spec in specs}) <= 1, parameter.name
        assert len({spec.description for spec in specs}) <= 1, parameter.name
        for node, table in tables.items():
            assert (parameter.name in {spec.name for spec in table}) == (node in parameter.nodes)
    l_spec = next(spec for spec in tables['coordinator'] if spec.name == 'control_point_distance')
    assert (l_spec.default, l_spec.constraint_text()) == (0.1, '> 0, finite')
    assert l_spec.problem(0.0) == 'must be > 0, finite, got 0.0'
    assert l_spec.problem(math.inf) == 'must be > 0, finite, got inf'


def test_a_shape_spec_carries_the_declaration_and_the_kinds_that_take_it():
    wheelbase = shape_spec(shape_parameter('wheelbase'))
    assert (wheelbase.default, wheelbase.constraint_text(), wheelbase.problem(0.0)) == (
        0.0,
        '>= 0, finite',
        None,
    )
    assert wheelbase.description == 'car: the wheelbase L from the rear axle to the steered front axle [m]'
    # A default that is each kind's own is 0 in a node, "the kind's own".
    footprint = shape_spec(shape_parameter('footprint_radius'))
    assert (footprint.default, footprint.constraint_text()) == (0.0, '>= 0, finite')
    assert footprint.description.endswith("(0: the kind's own)")
    assert footprint.description.startswith('holonomic, unicycle, car: radius r of its footprint')
    assert [spec.name for spec in shape_specs('coordinator')] == ['control_point_distance']


def test_a_limit_is_declared_once_for_every_node_that_takes_it():
    tables = _tables()
    for name in LIMITS:
        specs = [spec for table in tables.values() for spec in table if spec.name == name]
        assert specs and len({_key(spec) for spec in specs}) == 1, name
        assert _key(specs[0]) == _key(limit_spec(name, 'x'))
        assert (specs[0].default, specs[0].constraint_text()) == (math.inf, '> 0')
    with pytest.raises(ValueError, match=r"limit must be one of \('max_linear_speed', .*got 'max_jerk'"):
        limit_spec('max_jerk', 'jerk limit [m/s³]')


def test_a_spec_table_is_built_at_each_use():
    built = []

    def build():
        built.append(1)
        return tuple(shape_specs('robot'))

    table = SpecTable(build)
    assert [spec.name for spec in table] == ['control_point_distance', 'wheelbase']
    assert len(table) == 2 and table[0].name == 'control_point_distance' and len(built) == 3
