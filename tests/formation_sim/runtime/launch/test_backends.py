"""Tests of formation_sim.runtime.launch.backends: the kinds of backend, picked by name, agree with
the time keepers' worlds on the node side (which the launch side may not import) and with the
plan that starts them."""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path

import pytest

from formation_msgs_py.middleware import LIVELINESS_LEASE, LOST_GRACE
from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch import backends
from formation_sim.runtime.launch.backends import BACKENDS, EXACT, EXTERNAL, SIMULATED, backend_kind
from formation_sim.sim.robots import ROBOT_MODELS

WORLDS = {'exact': 'SimulatorWorld', 'simulated': 'RobotWorld', 'external': 'RobotWorld'}


def test_each_name_picks_its_kind_and_an_unknown_one_is_refused_by_name():
    assert backend_kind('exact') is EXACT and backend_kind('external') is EXTERNAL
    kinds = [name for name in BACKENDS if name not in ('exact', 'external')]
    assert kinds == list(ROBOT_MODELS) and kinds  # every robot kind: simulated robots of it
    assert all(backend_kind(name) is SIMULATED for name in kinds)
    for bad in ('Exact', 'simulated', ''):
        with pytest.raises(RunError, match=rf"^backend must be one of \(.*'external'\), got {bad!r}$"):
            backend_kind(bad)


@pytest.mark.parametrize('kind', [EXACT, SIMULATED, EXTERNAL], ids=lambda kind: kind.name)
def test_each_kind_names_the_keeper_whose_world_says_the_same(kind):
    """The keeper module's world class (node side) has the kind's parameter file, node name, mode
    and clock: what the launch side writes is what the node reads."""
    module = importlib.import_module(kind.keeper_module)
    world = getattr(module, WORLDS[kind.name])
    assert kind.keeper_file == world.PARAMS_FILE and kind.keeper_node == f'/{world.NODE_NAME}'
    # summary.json's mode: the world that serves sensing is the exact one (run_end.write_unstarted)
    assert kind.mode == ('distributed' if world.serves_sensing else 'robots')
    assert kind.on_robots == (not world.serves_sensing)
    if kind.on_robots:  # the coordinator's clock is the wall clock, whatever it is given
        assert kind.clocks == (world.clock_mode_of({}),) == (kind.default_clock,)
    else:  # the simulator's clock is its parameter: its choices and default
        (clock,) = [spec for spec in world.PARAMETERS if spec.name == 'clock_mode']
        assert kind.clocks == tuple(clock.choices) and kind.default_clock == clock.default
        assert world.clock_mode_of({'clock_mode': 'realtime'}) == 'realtime'


def test_the_keeper_gets_its_time_to_see_a_killed_agent_only_where_it_must_wait_for_the_lease():
    """Lock-step: the simulator notices a dead agent by its liveliness lease (and grace), so the
    orchestrator waits longer than that; on robots it stops the run at once (a robot would drive on)."""
    assert EXACT.agent_killed_detection == backends.LOST_DETECTION > LIVELINESS_LEASE + LOST_GRACE
    assert SIMULATED.agent_killed_detection == EXTERNAL.agent_killed_detection == 0.0
    assert SIMULATED.agent_failed_detection == backends.AGENT_REPORT_DETECTION > 0.0


@pytest.mark.parametrize('backend', ['exact', 'unicycle', 'external'])
def test_the_plan_starts_and_writes_the_keeper_of_its_backends_kind(tmp_path: Path, backend):
    from formation_sim.runtime.launch.orchestrate import FormationRun
    from formation_sim.runtime.launch.plan import RobotOptions

    robots = None if backend == 'exact' else RobotOptions(model='unicycle')
    scenario = 'paper_single' if backend == 'exact' else 'robots_square'
    run = FormationRun(load_scenario(scenario), out_dir=tmp_path / 'run', backend=backend, robots=robots)
    plan = run.plan
    kind = backend_kind(backend)
    assert plan.kind is kind and plan.keeper == kind.keeper
    assert plan.simulated_robots == kind.simulated_robots == (backend == 'unicycle')
    assert run.options.clock == kind.default_clock
    plan = dataclasses.replace(plan, out_dir=tmp_path / 'run')  # as the run sets it once it claimed it
    paths = plan.write_inputs()
    assert paths['keeper'] == tmp_path / 'run' / kind.keeper_file
    (keeper,) = [spec for spec in plan.processes(paths) if spec.name == kind.keeper]
    assert keeper.args[:2] == ('-m', kind.keeper_module)
