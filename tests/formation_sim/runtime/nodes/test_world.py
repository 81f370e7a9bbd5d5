"""Tests of formation_sim.runtime.nodes.world: the `World` a time keeper holds.

Both worlds provide every member of the Protocol, the module's table names each member, the node
classes add no world of their own (no hook methods), and a third, toy world plugs into the one time
keeper: its rules refuse bad parameters before anything is set up, its gaps hold discovery."""

from __future__ import annotations

import inspect
import re
from typing import ClassVar

import pytest

from formation_sim.model.scenario import load_scenario

DOMAIN_ID = 93


def _members() -> set[str]:
    from formation_sim.runtime.nodes.world import World

    own = {name for name in vars(World) if not name.startswith('_')}
    return own | set(World.__annotations__)


def _worlds() -> list[type]:
    from formation_sim.runtime.nodes.coordinator import RobotWorld
    from formation_sim.runtime.nodes.sim_node import SimulatorWorld

    return [SimulatorWorld, RobotWorld]


def test_the_protocol_holds_the_hooks_a_keeper_calls() -> None:
    assert {'watch_agents', 'gaps', 'check_start', 'begin', 'tick', 'record', 'reached_time'} <= _members()
    assert len(_members()) == 24  # 8 class attributes, 2 static methods, 14 of the world made


def test_each_world_provides_every_member_of_the_protocol() -> None:
    for world in _worlds():
        missing = sorted(name for name in _members() if not hasattr(world, name))
        assert missing == [], world.__name__
        for name in ('problems', 'clock_mode_of'):  # asked before the world (or the node) exists
            assert isinstance(inspect.getattr_static(world, name), staticmethod), (world.__name__, name)


def test_the_modules_table_names_each_member_and_nothing_else() -> None:
    from formation_sim.runtime.nodes import world

    named = re.findall(r'^- (.+?): ', world.__doc__, flags=re.MULTILINE)
    listed = [m.split('(')[0] for entry in named for m in re.findall(r'`([^`]+)`', entry)]
    assert sorted(listed) == sorted(_members())


def test_the_node_classes_hold_a_world_and_fill_no_hooks() -> None:
    from formation_sim.runtime.nodes.coordinator import FormationCoordinatorNode
    from formation_sim.runtime.nodes.sim_node import FormationSimulatorNode
    from formation_sim.runtime.nodes.time_keeper import TimeKeeperNode

    for node in (FormationSimulatorNode, FormationCoordinatorNode):
        assert [name for name in vars(node) if not name.startswith('__')] == [], node.__name__
    # The keeper's only member of the Protocol's name: the run's time, which it asks its world.
    assert sorted(_members() & set(vars(TimeKeeperNode))) == ['reached_time']


class _ToyWorld:
    """A world of nothing but rules and gaps, for the keeper's side of the contract."""

    PARAMETERS: tuple = ()  # the keeper's own (set by the test: importing them needs rclpy)
    COMMAND = 'formation_toy'
    PARAMS_FILE = 'toy.params.yaml'
    DESCRIPTION = 'a toy world'
    NODE_NAME = 'formation_toy'
    serves_sensing = False
    watched_writer = 'toy'
    batched_spin = True
    made: ClassVar[list] = []  # every one made, in order

    @staticmethod
    def problems(values: dict, scenario) -> list[str]:
        horizon = values['horizon']
        return [] if horizon != 7.0 else [f"toy rule: parameter 'horizon' must not be 7, got {horizon!r}"]

    @staticmethod
    def clock_mode_of(values: dict) -> str:
        return 'realtime'

    def __init__(self, keeper) -> None:
        self.keeper = keeper
        self.watched = 0
        _ToyWorld.made.append(self)

    def watch_agents(self) -> dict:
        self.watched += 1
        return {}

    def gaps(self) -> list[str]:
        return ['the toy world is not ready']

    def extra(self) -> dict:
        return {'toy': True}

    @property
    def reached_time(self) -> float:
        return 0.25


@pytest.mark.ros
def test_a_toy_world_plugs_into_the_one_time_keeper(ros) -> None:
    from rclpy.parameter import Parameter

    from formation_agent.ros.errors import ParameterError
    from formation_sim.runtime.nodes.time_keeper import (
        TIME_KEEPER_PARAMETERS,
        TimeKeeperNode,
        discovery_gaps,
        run_extra,
    )

    _ToyWorld.PARAMETERS = TIME_KEEPER_PARAMETERS
    scenario = load_scenario('paper_single')
    _ToyWorld.made.clear()
    with pytest.raises(ParameterError, match=r"toy rule: parameter 'horizon' must not be 7, got 7\.0"):
        TimeKeeperNode(
            world_class=_ToyWorld,
            scenario=scenario,
            context=ros,
            parameter_overrides=[Parameter('horizon', value=7.0)],
        )
    assert _ToyWorld.made == []  # refused before anything was set up
    node = TimeKeeperNode(world_class=_ToyWorld, scenario=scenario, context=ros)
    try:
        (world,) = _ToyWorld.made
        assert node.world is world and world.keeper is node and world.watched == 1
        assert node.get_name() == 'formation_toy' and node.clock_mode == 'realtime'
        assert discovery_gaps(node)[-1] == 'the toy world is not ready'
        assert node.reached_time == 0.25 and run_extra(node, 0.25)['toy'] is True
    finally:
        node.destroy_node()
