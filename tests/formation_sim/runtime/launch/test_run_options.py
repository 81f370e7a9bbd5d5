"""RunOptions: how FormationRun runs a scenario, completed and checked in one place."""

from __future__ import annotations

import dataclasses

import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.plan import RobotOptions
from formation_sim.runtime.launch.run_options import RunOptions


def test_check_completes_the_options_for_the_scenario():
    square = load_scenario('robots_square')
    exact = RunOptions().check(square)
    assert exact.horizon == square.horizon and exact.clock == 'lockstep' and exact.robots is None
    robots = RunOptions(backend='unicycle', horizon=7).check(square)
    assert robots.horizon == 7.0 and isinstance(robots.horizon, float) and robots.clock == 'realtime'
    assert robots.robots == RobotOptions(model='unicycle')
    assert RunOptions(agents_per_process='auto').check(square).agents_per_process == 1


def test_the_options_are_frozen_and_check_returns_new_ones():
    options = RunOptions(inject={'delay_ms': 3.0})
    checked = options.check(load_scenario('paper_single'))
    assert checked is not options and options.horizon is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        checked.horizon = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ('fields', 'complaint'),
    [
        ({'horizon': float('nan')}, 'horizon must be a finite number > 0, got nan'),
        ({'domain_id': 233}, 'domain id must lie in [0, 232], got 233'),
        ({'timeout': -1.0}, 'timeout must be a finite number of seconds > 0, got -1.0'),
        ({'backend': 'tank'}, 'backend must be one of'),
        (
            {'clock': 'sundial'},
            "clock must be 'lockstep' (sim time, exact) or 'realtime' (wall clock), got 'sundial'",
        ),
        (
            {'backend': 'unicycle', 'clock': 'lockstep'},
            "robots run on the wall clock: backend 'unicycle' needs clock=realtime, got 'lockstep'",
        ),
        ({'robots': RobotOptions(model='unicycle')}, 'robots are options of the robot backends'),
        ({'backend': 'external'}, "backend 'external' needs robots=RobotOptions(model=...)"),
        ({'executor': 'threads'}, 'executor must be one of'),
        ({'inject': {'loss': 0.5}}, 'inject: loss needs the wall clock'),
        ({'inject': {'drop': 1.0}}, "inject: unknown keys ['drop']"),
        ({'step_listeners': -1}, 'step_listeners must be >= 0, got -1'),
        ({'discovery': 'mdns'}, 'discovery must be one of'),
    ],
)
def test_each_broken_option_is_named_with_its_value(fields, complaint):
    with pytest.raises(RunError) as caught:
        RunOptions(**fields).check(load_scenario('robots_square'))
    assert complaint in str(caught.value)


def test_formation_run_takes_options_and_fields_over_them_and_refuses_unknown_names(tmp_path):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        'paper_single', out_dir=tmp_path / 'run', options=RunOptions(horizon=3.0, record=False), horizon=2.0
    )
    assert run.options.horizon == 2.0 and run.options.record is False and run.plan.horizon == 2.0
    with pytest.raises(TypeError, match='horizn'):
        FormationRun('paper_single', out_dir=tmp_path / 'run', horizn=2.0)
    assert not (tmp_path / 'run').exists()  # nothing on disk before run()
