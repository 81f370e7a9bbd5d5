"""Shape parameters: declared once, in a kind; a Geometry of the declared names."""

from __future__ import annotations

import copy
import math

import pytest

from formation_agent.core.kinds import KindError, RobotKind, register, robot_kind, unregister
from formation_agent.core.kinds.shape import (
    Geometry,
    ShapeError,
    ShapeParameter,
    declared,
    owners,
    shape_parameter,
)


def test_the_built_in_kinds_declare_footprint_l_and_l_once_each():
    assert [p.name for p in declared()] == ['footprint_radius', 'control_point_distance', 'wheelbase']
    assert owners('control_point_distance') == ('unicycle', 'car')  # the car takes the unicycle's l
    assert owners('footprint_radius') == ('holonomic', 'unicycle', 'car')
    assert owners('wheelbase') == ('car',)
    # Which node takes which: the coordinator places control points (l) only; no node takes r yet.
    assert [p.name for p in declared(node='agent')] == ['control_point_distance', 'wheelbase']
    assert [p.name for p in declared(node='robot')] == ['control_point_distance', 'wheelbase']
    assert [p.name for p in declared(node='coordinator')] == ['control_point_distance']


@pytest.mark.parametrize(
    ('name', 'value', 'problem'),
    [
        ('control_point_distance', 0.0, 'control_point_distance l must be a finite number > 0 [m], got 0.0'),
        (
            'control_point_distance',
            math.inf,
            'control_point_distance l must be a finite number > 0 [m], got inf',
        ),
        ('control_point_distance', 0.1, None),
        ('wheelbase', 0.0, None),  # 0: not given (a car refuses it: test_car)
        ('wheelbase', -0.33, 'wheelbase L must be a finite number >= 0 [m], got -0.33'),
        ('wheelbase', math.nan, 'wheelbase L must be a finite number >= 0 [m], got nan'),
        ('footprint_radius', 0.0, 'footprint_radius r must be a finite number > 0 [m], got 0.0'),
    ],
)
def test_each_parameter_names_its_rule_and_the_value_that_breaks_it(name, value, problem):
    assert shape_parameter(name).problem(value) == problem


def test_a_geometry_holds_the_declared_defaults_unless_given():
    default = Geometry()
    assert (default.control_point_distance, default.wheelbase, default.footprint_radius) == (0.1, 0.0, None)
    given = Geometry(control_point_distance=0.33, wheelbase=0.33)
    assert given.given() == {'control_point_distance': 0.33, 'wheelbase': 0.33}
    assert given.values() == {'footprint_radius': None, 'control_point_distance': 0.33, 'wheelbase': 0.33}
    assert given.replace(wheelbase=0.5).wheelbase == 0.5 and given.wheelbase == 0.33
    # Equal when every value is, a default given or not; hashable; copied (and pickled) whole.
    assert Geometry(control_point_distance=0.1) == default and hash(
        Geometry(control_point_distance=0.1)
    ) == hash(default)
    assert given != default
    assert copy.deepcopy(given) == given
    assert repr(given) == 'Geometry(control_point_distance=0.33, wheelbase=0.33)'
    with pytest.raises(AttributeError, match='immutable'):
        given.wheelbase = 1.0


def test_a_geometry_of_an_undeclared_name_is_refused_naming_the_declared_ones():
    with pytest.raises(
        ShapeError, match=r"shape parameter must be one of \('footprint_radius', .*got 'track'"
    ):
        Geometry(track=0.2)
    with pytest.raises(AttributeError, match="Geometry has no shape parameter 'track'"):
        _ = Geometry().track


def test_a_parameter_declared_twice_differently_is_refused_and_a_kind_without_its_own_footprint_too():
    other_l = ShapeParameter(name='control_point_distance', symbol='l', help='elsewhere [m]', default=0.2)

    class Skid(RobotKind):
        name = 'skid'
        shape = (*RobotKind.shape, other_l)
        footprint_radius = 0.3

    with pytest.raises(
        ShapeError, match="shape parameter 'control_point_distance' is declared once: kind 'skid'"
    ):
        register(Skid())
    assert 'skid' not in owners('control_point_distance') + owners('footprint_radius')  # nothing of it
    with pytest.raises(
        ValueError,
        match=r'a robot kind sets its own footprint_radius r \(a finite number > 0 \[m\]\): skid has 0.0',
    ):
        register(type('Bare', (Skid,), {'shape': RobotKind.shape, 'footprint_radius': 0.0})())
    with pytest.raises(KindError, match="got 'skid'"):
        robot_kind('skid')
    unregister('skid')  # a kind never registered: nothing to forget


def test_a_parameter_rule_and_name_are_checked_where_it_is_declared():
    with pytest.raises(ShapeError, match="got 'hull width' with nodes"):
        ShapeParameter(name='hull width', symbol='w', help='[m]', default=0.3)
    with pytest.raises(ShapeError, match=r"nodes among \('agent', 'coordinator', 'robot'\)"):
        ShapeParameter(name='hull', symbol='w', help='[m]', default=0.3, nodes=('simulator',))
    assert ShapeParameter(name='hull_width', symbol='w', help='[m]', default=0.3).flag == '--hull-width'
