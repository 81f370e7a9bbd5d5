"""`formation run` refuses bad requests before it starts any process."""

from __future__ import annotations

import math
from typing import ClassVar

import pytest

from formation_sim.cli import main
from formation_sim.runtime.errors import RunError

BAD_RUN_ARGUMENTS = [
    # (arguments, what the refusal says): each refused while parsing, before anything starts
    (
        ['--domain-id', '300'],
        'argument --domain-id: must be an integer in [0, 232] (a ROS_DOMAIN_ID), got 300',
    ),
    (
        ['--domain-id', '999'],
        'argument --domain-id: must be an integer in [0, 232] (a ROS_DOMAIN_ID), got 999',
    ),
    (
        ['--agents-per-process', '0'],
        "argument --agents-per-process: must be an integer >= 1 or 'auto', got 0",
    ),
    (['--horizon', '-1'], 'argument --horizon: must be a finite number > 0, got -1.0'),
    (['--horizon', 'nan'], 'argument --horizon: must be a finite number > 0, got nan'),
    (['--sample-dt', '-1'], 'argument --sample-dt: must be a finite number >= 0, got -1.0'),
    (['--timeout', '-5'], 'argument --timeout: must be a finite number > 0, got -5.0'),
    (['--timeout', 'soon'], "argument --timeout: must be a finite number > 0, got 'soon'"),
    (['--sample-dt', '1e-9'], 'the sample spacing 1e-09 s asks for 1e+10 samples'),
    (['--speed-scale', '0'], "argument --speed-scale: must be a finite number > 0 or 'auto', got 0.0"),
    (['--speed-scale', 'inf'], "argument --speed-scale: must be a finite number > 0 or 'auto', got inf"),
    (['--speed-scale', '1e-9'], 'gains.speed_scale: must lie in [1e-06, 1e+06]'),
    (['--threshold-floor', '-0.1'], 'argument --threshold-floor: must be a finite number >= 0, got -0.1'),
    (['--min-separation', '-0.1'], 'argument --min-separation: must be a finite number >= 0, got -0.1'),
    (
        ['--min-separation', '100'],
        'argument --min-separation: safety.sensing_radius: must exceed the guard radius',
    ),
]


@pytest.mark.parametrize(
    ('arguments', 'complaint'), BAD_RUN_ARGUMENTS, ids=[' '.join(case[0]) for case in BAD_RUN_ARGUMENTS]
)
def test_bad_run_requests_are_refused_with_the_rule_broken(
    tmp_path, capsys, monkeypatch, arguments, complaint
):
    import subprocess

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    earlier = _earlier_run(tmp_path / 'run')
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'run'), '--quiet', *arguments]) == 2
    err = capsys.readouterr().err
    assert complaint in err and 'Traceback' not in err
    assert _listing(tmp_path / 'run') == earlier  # nothing started, nothing on disk changed


def _earlier_run(folder):
    """What `formation simulate` leaves in `folder`; returns its listing with every file's bytes."""
    assert (
        main(['simulate', 'paper_single', '--horizon', '0.2', '--out', str(folder), '--quiet', '--no-plot'])
        == 0
    )
    return _listing(folder)


def _listing(folder):
    return {
        path.relative_to(folder).as_posix(): path.read_bytes() if path.is_file() else None
        for path in sorted(folder.rglob('*'))
    }


@pytest.mark.parametrize('force', [False, True], ids=['plain', 'force'])
def test_the_api_refuses_a_bad_request_before_touching_the_earlier_run(tmp_path, monkeypatch, force):
    import subprocess

    from formation_sim.runtime.launch.orchestrate import FormationRun

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    earlier = _earlier_run(tmp_path / 'run')
    for options, complaint in [
        ({'domain_id': 999}, 'domain id must lie in [0, 232], got 999'),
        ({'timeout': -5.0}, 'timeout must be a finite number of seconds > 0, got -5.0'),
        (
            {'sample_period': -1.0},
            'the sample spacing must be a finite number >= 0 (0: samples at events only), got -1.0',
        ),
        ({'horizon': 5e-324}, 'horizon must be a finite number > 0, got 5e-324'),
    ]:
        with pytest.raises(RunError) as caught:
            FormationRun('paper_single', out_dir=tmp_path / 'run', force=force, **options)
        assert complaint in str(caught.value)
    assert _listing(tmp_path / 'run') == earlier


def test_a_folder_holding_a_run_is_refused_and_kept(tmp_path, capsys, monkeypatch):
    import subprocess

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    earlier = _earlier_run(tmp_path / 'run')
    for extra in ([], ['--no-record']):
        assert (
            main(['run', 'paper_double', '--horizon', '1', '--out', str(tmp_path / 'run'), '--quiet', *extra])
            == 2
        )
        err = capsys.readouterr().err
        assert f'{tmp_path / "run"} already holds an earlier run (summary.json, trajectory/)' in err
        assert 'add --force to replace the earlier run' in err
    assert _listing(tmp_path / 'run') == earlier


def test_an_existing_bag_is_never_overwritten(tmp_path, capsys):
    (tmp_path / 'run' / 'bag').mkdir(parents=True)
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'run'), '--quiet']) == 2
    assert f'{tmp_path / "run"} already holds an earlier run (bag/)' in capsys.readouterr().err


def test_an_unknown_scenario_is_refused(tmp_path, capsys):
    assert main(['run', 'no_such_scenario', '--out', str(tmp_path / 'run')]) == 2
    assert 'no such scenario file and not a built-in scenario' in capsys.readouterr().err


# -- an invalid scenario starts nothing ------------------------------------------------------------

PAPER_SINGLE = """\
name: {name}
dynamics: single
communication_radius: 4.0
horizon: 10.0
agents:
  1: {{position: [2.0, 4.0]}}
  2: {{position: [3.5, 7.0]}}
  3: {{position: [{x3}, {y3}]}}
edges:
  - {{i: 1, j: 2, d: [0.0, -2.0]}}
  - {{i: 1, j: 3, d: [-2.0, 0.0]}}
  - {{i: 2, j: 3, d: [{d23}]}}
gains: {{alpha: 10.0, beta: 1.0}}
"""

INVALID = [
    # (label, edits, rule named, fragment of the message)
    (
        'initial condition violated',
        {'x3': 4.3, 'y3': 5.5, 'd23': '-2.0, 2.0'},
        '[initial] edge (2, 3)',
        '(initial)',
    ),
    (
        'infeasible formation',
        {'x3': 4.5, 'y3': 5.5, 'd23': '-2.0, 2.5'},
        '[feasible] formation',
        'Assumption 1',
    ),
]


def _write(tmp_path, label, edits):
    path = tmp_path / f'{label.replace(" ", "_")}.yaml'
    path.write_text(PAPER_SINGLE.format(name=label.replace(' ', '_'), **edits))
    return path


class _NoProcesses:
    """Stands in for subprocess.Popen: any attempt to start a process fails the test."""

    started: ClassVar[list] = []

    def __init__(self, args, *rest, **options):
        _NoProcesses.started.append(args)
        raise AssertionError(f'a process was started for an invalid scenario: {args}')


@pytest.mark.parametrize(('label', 'edits', 'rule', 'fragment'), INVALID, ids=[case[0] for case in INVALID])
def test_formation_run_api_refuses_an_invalid_scenario_before_anything_starts(
    tmp_path, monkeypatch, label, edits, rule, fragment
):
    import subprocess

    from formation_sim.model.validate import ValidationError
    from formation_sim.runtime.launch.orchestrate import FormationRun

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    _NoProcesses.started = []
    out = tmp_path / 'run'
    with pytest.raises(ValidationError) as caught:
        FormationRun(_write(tmp_path, label, edits), out_dir=out, progress=False).run()
    assert rule in str(caught.value) and fragment in str(caught.value)
    assert _NoProcesses.started == []
    assert not out.exists(), 'no output folder, hence no bag and no logs'


@pytest.mark.parametrize(('label', 'edits', 'rule', 'fragment'), INVALID, ids=[case[0] for case in INVALID])
def test_formation_run_command_refuses_an_invalid_scenario(
    tmp_path, capsys, monkeypatch, label, edits, rule, fragment
):
    import subprocess

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    _NoProcesses.started = []
    out = tmp_path / 'run'
    assert main(['run', str(_write(tmp_path, label, edits)), '--out', str(out)]) == 2
    err = capsys.readouterr().err
    assert "breaks the theorems' hypotheses; nothing was run" in err
    assert rule in err and fragment in err
    assert _NoProcesses.started == [] and not out.exists()


def test_formation_run_process_on_an_invalid_scenario_exits_non_zero_and_leaves_nothing(tmp_path):
    import subprocess
    import sys

    out = tmp_path / 'run'
    path = _write(tmp_path, *INVALID[0][:2])
    done = subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', 'run', str(path), '--out', str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert '[initial] edge (2, 3)' in done.stderr
    assert not out.exists()


def test_fault_injection_requests_are_checked_before_anything_starts(tmp_path):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    with pytest.raises(RunError, match='loss needs the wall clock'):
        FormationRun('paper_single', out_dir=tmp_path / 'a', inject={'loss': 0.1})
    with pytest.raises(RunError, match=r"unknown keys \['drop'\]"):
        FormationRun('paper_single', out_dir=tmp_path / 'b', inject={'drop': 0.1}, clock='realtime')
    with pytest.raises(RunError, match='loss is a probability in \\[0, 1\\], got 2'):
        FormationRun('paper_single', out_dir=tmp_path / 'c', inject={'loss': 2}, clock='realtime')
    with pytest.raises(RunError, match='delay_ms must be a finite number >= 0, got -1'):
        FormationRun('paper_single', out_dir=tmp_path / 'd', inject={'delay_ms': -1})
    assert not any(tmp_path.iterdir())


def test_discovery_is_limited_to_this_machine_unless_asked(tmp_path, monkeypatch):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    local = FormationRun('paper_single', out_dir=tmp_path / 'a')._environment(70, 4)
    assert local['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST' and local['ROS_DOMAIN_ID'] == '70'
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # as .ci/run sets it
    network = FormationRun('paper_single', out_dir=tmp_path / 'b', localhost_only=False)._environment(70, 4)
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in network  # Jazzy's default: SUBNET
    pinned = FormationRun(
        'paper_single', out_dir=tmp_path / 'c', extra_env={'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}
    )
    assert pinned._environment(70, 4)['FASTDDS_BUILTIN_TRANSPORTS'] == 'UDPv4'


def test_network_flag_reaches_the_run(tmp_path, monkeypatch):
    from formation_sim.runtime.launch import orchestrate

    seen = {}

    class Recorded(orchestrate.FormationRun):
        def run(self):
            seen['localhost_only'] = self.options.localhost_only
            raise RunError('stopped by the test')

    monkeypatch.setattr(orchestrate, 'FormationRun', Recorded)
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'a'), '--network', '--quiet']) == 2
    assert seen == {'localhost_only': False}
    assert main(['run', 'paper_single', '--out', str(tmp_path / 'b'), '--quiet']) == 2
    assert seen == {'localhost_only': True}


# -- a real run: --force replaces an earlier run completely; the largest ids validate accepts run ----


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_force_replaces_an_earlier_run_and_the_largest_agent_ids_run(
    tmp_path, capsys, paper_scenario_dict, monkeypatch
):
    import json

    import yaml

    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.engine import simulate

    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    out = tmp_path / 'run'
    assert main(['simulate', 'paper_double', '--horizon', '0.2', '--out', str(out), '--quiet']) == 0
    (out / 'analysis').mkdir()
    (out / 'analysis' / 'analysis.md').write_text('of the earlier run')
    # Section 5's single-integrator team with ids 0, 7 and 2^31 - 1 (the largest id topics,
    # messages and parameters carry), as validate accepts it.
    ids = {1: 0, 2: 7, 3: 2**31 - 1}
    data = paper_scenario_dict()
    data['name'] = 'extreme_ids'
    data['agents'] = {ids[k]: entry for k, entry in data['agents'].items()}
    for edge in data['edges']:
        edge['i'], edge['j'] = ids[edge['i']], ids[edge['j']]
    path = tmp_path / 'extreme_ids.yaml'
    path.write_text(yaml.safe_dump(data))
    assert main(['validate', str(path)]) == 0
    capsys.readouterr()

    code = main(
        [
            'run',
            str(path),
            '--horizon',
            '0.3',
            '--out',
            str(out),
            '--force',
            '--domain-id',
            '64',
            '--quiet',
            '--timeout',
            '300',
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err[-3000:]
    assert captured.out.strip() == str(out)
    assert not (out / 'analysis').exists()  # nothing of the earlier run is left beside this one
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['scenario'] == 'extreme_ids' and summary['dynamics'] == 'single'
    assert (out / 'bag' / 'metadata.yaml').is_file()
    reference = simulate(load_scenario(path), horizon=0.3)
    assert summary['trigger_times'] == {str(agent): times for agent, times in reference.trigger_times.items()}
    assert sorted(summary['trigger_times']) == ['0', '2147483647', '7']


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (
            ['--backend', 'external'],
            '--backend external needs --robot holonomic|unicycle|car (what the robots are)',
        ),
        (
            ['--backend', 'unicycle', '--robot', 'holonomic'],
            "backend 'unicycle' simulates unicycle robots, but robots.model is 'holonomic'",
        ),
        (
            ['--backend', 'unicycle', '--control-point-distance', '0'],
            'argument --control-point-distance: must be a finite number > 0, got 0.0',
        ),
        (
            ['--backend', 'unicycle', '--pose-noise', '-1'],
            'argument --pose-noise: must be a finite number >= 0, got -1.0',
        ),
    ],
)
def test_bad_robot_runs_are_refused_before_anything_starts(tmp_path, capsys, arguments, complaint):
    assert main(['run', 'robots_square', '--out', str(tmp_path / 'run'), '--quiet', *arguments]) == 2
    assert complaint in capsys.readouterr().err
    assert not (tmp_path / 'run').exists()


# -- robot limits: a team whose exact run asks for more than the robots can do is refused ----------

TURTLEBOT3_LIMITS = ['--max-speed', '0.22', '--max-angular-speed', '2.84']


def _default_layer(scenario):
    """`scenario` with the safety layer a Burger team runs by default: footprints r = 0.105 m kept
    5 cm apart, D_s = 0.26 + 2 l between control points (l = 0.1 m; docs/ROBOTS.md)."""
    from formation_agent.core.safety import SafetyConfig

    return scenario.replace(safety=SafetyConfig(min_separation=(2 * 0.105 + 0.05) + 0.1 + 0.1))


def test_a_robot_run_beyond_the_limits_is_refused_naming_the_limit_the_value_and_the_remedy(
    tmp_path, capsys, monkeypatch
):
    import subprocess

    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.largest_command import measured_command

    monkeypatch.setattr(subprocess, 'Popen', _NoProcesses)
    out = tmp_path / 'run'
    assert (
        main(['run', 'robots_lab', '--backend', 'unicycle', *TURTLEBOT3_LIMITS, '--out', str(out), '--quiet'])
        == 2
    )
    err = capsys.readouterr().err
    # the exact run at κ = 1, with the layer robots run by default (Burgers: origins 0.26 m apart)
    asked = measured_command(_default_layer(load_scenario('robots_lab'))).max_speed
    assert f'asks for {asked:.4g} m/s beyond --max-speed 0.22 m/s' in err
    assert f'{asked / 0.1:.4g} rad/s beyond --max-angular-speed 2.84 rad/s' in err
    assert '--speed-scale auto' in err and '--allow-saturation' in err
    assert not out.exists()  # nothing started, nothing written


def test_allow_saturation_turns_the_refusal_into_a_warning_and_a_team_within_the_limits_runs(
    tmp_path, capsys, monkeypatch
):
    from formation_sim.runtime.launch import orchestrate

    started = []

    class Recorded(orchestrate.FormationRun):
        def run(self):
            started.append(self.scenario.name)
            raise RunError('stopped by the test')

    monkeypatch.setattr(orchestrate, 'FormationRun', Recorded)
    arguments = ['--backend', 'unicycle', *TURTLEBOT3_LIMITS, '--quiet']
    assert main(['run', 'robots_lab', *arguments, '--allow-saturation', '--out', str(tmp_path / 'a')]) == 2
    err = capsys.readouterr().err
    assert (
        started == ['robots_lab']
        and 'warning: the exact run of robots_lab' in err
        and 'running anyway' in err
    )
    # robots_square starts within 1.5 cm of its corners: its exact run asks for 0.10 m/s, no warning
    assert main(['run', 'robots_square', *arguments, '--out', str(tmp_path / 'b')]) == 2
    err = capsys.readouterr().err
    assert started == ['robots_lab', 'robots_square'] and 'beyond' not in err
    # the exact backend has no robots, hence no limits to check
    assert main(['run', 'robots_lab', *TURTLEBOT3_LIMITS, '--quiet', '--out', str(tmp_path / 'c')]) == 2
    assert started[-1] == 'robots_lab'


def test_speed_scale_auto_runs_the_chosen_kappa_and_records_it_in_the_summary(tmp_path, capsys, monkeypatch):
    from formation_sim.runtime.launch import orchestrate

    seen = {}

    class Recorded(orchestrate.FormationRun):
        def run(self):
            seen.update(kappa=self.scenario.gains.speed_scale, extra=self.options.summary_extra)
            seen.update(warp=self.options.robots.time_warp)
            raise RunError('stopped by the test')

    monkeypatch.setattr(orchestrate, 'FormationRun', Recorded)
    # ETA-2 on robots: the constant κ
    arguments = ['run', 'robots_lab_double', '--backend', 'holonomic', '--max-speed', '0.5']
    arguments += ['--max-acceleration', '1', '--speed-scale', 'auto', '--quiet']
    assert main([*arguments, '--out', str(tmp_path / 'a')]) == 2  # the test's stop, after the check passed
    err = capsys.readouterr().err
    assert 'beyond' not in err and '--speed-scale auto: κ = ' in err
    assert seen['extra']['speed_scale']['value'] == seen['kappa'] < 0.5 and seen['warp'] == ()
    assert seen['extra']['speed_scale']['source'] == 'observed'
    assert seen['extra']['safety'] == {'layer': 'off', 'source': 'double, dimension 2'}  # ETA-1's layer
    # ETA-1 on robots: the observed time warp (issue 27), the agents at κ = 1 in the paper's time
    arguments = ['run', 'robots_lab', '--backend', 'unicycle', *TURTLEBOT3_LIMITS, '--speed-scale', 'auto']
    assert main([*arguments, '--quiet', '--out', str(tmp_path / 'b')]) == 2
    err = capsys.readouterr().err
    assert '--speed-scale auto: a time warp, κ(t) in ' in err and 'beyond' not in err
    assert seen['kappa'] == 1.0 and seen['extra']['speed_scale']['kind'] == 'time_warp'
    assert seen['extra']['safety']['source'] == 'unicycle footprints (r = 0.105 m)'  # on by default
    assert "the safety layer keeps the robots' origins 0.26 m apart" in err
    assert seen['warp'] == tuple(
        seen['extra']['speed_scale']['observed'][key][k]
        for k in range(len(seen['extra']['speed_scale']['observed']['rates']))
        for key in ('paper_starts', 'rates')
    )


def test_holonomic_robots_are_not_held_to_a_turn_rate(tmp_path, capsys, monkeypatch):
    from formation_sim.runtime.launch import orchestrate

    started = []

    class Recorded(orchestrate.FormationRun):
        def run(self):
            started.append(self.scenario.gains.speed_scale)
            raise RunError('stopped by the test')

    monkeypatch.setattr(orchestrate, 'FormationRun', Recorded)
    # κ = 0.15 keeps robots_lab's speed within 0.22 m/s; its ||u||/l (0.1 m) would exceed 0.5 rad/s
    arguments = [
        'run',
        'robots_lab',
        '--max-speed',
        '0.22',
        '--max-angular-speed',
        '0.5',
        '--speed-scale',
        '0.15',
        '--quiet',
    ]
    assert main([*arguments, '--backend', 'holonomic', '--out', str(tmp_path / 'a')]) == 2
    assert started == [0.15] and 'beyond' not in capsys.readouterr().err
    assert main([*arguments, '--backend', 'unicycle', '--out', str(tmp_path / 'b')]) == 2
    assert started == [0.15] and 'beyond --max-angular-speed 0.5 rad/s' in capsys.readouterr().err


@pytest.mark.parametrize(
    ('robot', 'backend', 'turn_limited'),
    [
        (None, 'holonomic', False),
        ('holonomic', 'external', False),
        (None, 'unicycle', True),
        (None, 'car', True),
        ('car', 'holonomic', True),  # the robots are cars: the old string test took them for holonomic
        (None, 'exact', True),  # no robots named (simulate, validate): taken to be steered, as before
        (None, None, True),
    ],
)
def test_the_turn_rate_limits_the_speed_only_of_robots_their_kind_steers(robot, backend, turn_limited):
    import argparse

    from formation_sim.commands.limits import robot_limits

    args = argparse.Namespace(robot=robot, backend=backend, max_speed=None, max_angular_speed=2.84)
    limits = robot_limits(args)
    assert limits.max_angular_speed == (2.84 if turn_limited else math.inf)
    assert limits.control_point_distance == 0.1  # not given: l's declared default


def test_speed_scale_warp_hands_the_observed_warp_to_the_robots_agents(tmp_path, capsys, monkeypatch):
    import yaml

    from formation_sim.model.scenario import load_scenario
    from formation_sim.model.speed_choice import RobotLimits
    from formation_sim.runtime.launch import orchestrate
    from formation_sim.runtime.launch import plan as launch
    from formation_sim.sim.largest_command import choose_time_warp

    seen = {}

    class Recorded(orchestrate.FormationRun):
        def run(self):
            seen.update(kappa=self.scenario.gains.speed_scale, extra=self.options.summary_extra)
            seen.update(robots=self.options.robots)
            raise RunError('stopped by the test')

    monkeypatch.setattr(orchestrate, 'FormationRun', Recorded)
    arguments = [
        'run',
        'robots_lab',
        *TURTLEBOT3_LIMITS,
        '--speed-scale',
        'warp',
        '--horizon',
        '30',
        '--quiet',
    ]
    assert main([*arguments, '--backend', 'unicycle', '--out', str(tmp_path / 'a')]) == 2  # the test's stop
    err = capsys.readouterr().err
    assert '--speed-scale warp: a time warp, κ(t) in ' in err and 'beyond' not in err
    warp = choose_time_warp(
        _default_layer(load_scenario('robots_lab')).replace(horizon=30.0),
        limits=RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1),
    ).warp
    assert seen['kappa'] == 1.0 and seen['extra']['speed_scale']['kind'] == 'time_warp'
    assert seen['robots'].time_warp == tuple(warp.to_parameter())
    parameters = seen['robots'].agent_parameters()
    assert parameters['time_warp'] == warp.to_parameter()
    # every agent's params file holds the list itself: rcl reads no YAML alias
    path = tmp_path / 'agents.params.yaml'
    launch._write_yaml(path, {f'/agent_{i}/formation_agent': {'ros__parameters': parameters} for i in (1, 2)})
    assert '&' not in path.read_text() and '*' not in path.read_text()
    assert yaml.safe_load(path.read_text())['/agent_2/formation_agent']['ros__parameters']['time_warp'] == (
        warp.to_parameter()
    )
    # the lock-step simulator takes no warp, nor ETA-2: refused before anything starts
    assert main([*arguments, '--out', str(tmp_path / 'b')]) == 2
    assert '--speed-scale warp: robot backends only so far' in capsys.readouterr().err
    double = [
        'run',
        'robots_lab_double',
        '--max-speed',
        '0.5',
        '--speed-scale',
        'warp',
        '--backend',
        'holonomic',
    ]
    assert main([*double, '--out', str(tmp_path / 'c'), '--quiet']) == 2
    assert '--speed-scale warp: time_warp: ETA-1 only' in capsys.readouterr().err
    assert not any((tmp_path / name).exists() for name in 'abc')
