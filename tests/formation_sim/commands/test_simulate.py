"""`formation simulate`: the figure of each controller (the continuous one has no event raster)."""

from __future__ import annotations

import json
import re

import matplotlib.image
import numpy as np
import pytest
from matplotlib.collections import LineCollection, PathCollection

from formation_sim.analysis.plots import FIGURE_FILE, run_figure
from formation_sim.cli import main
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.baselines import simulate_continuous
from formation_sim.sim.engine import simulate
from formation_sim.sim.samples import load_trajectory


@pytest.fixture(scope='module')
def scenario():
    return load_scenario('paper_single')


def test_continuous_figure_has_no_raster_and_says_why(scenario):
    fig = run_figure(simulate_continuous(scenario, horizon=0.5))
    assert len(fig.axes) == 1
    assert 'no triggering events' in fig.get_suptitle()
    (ax,) = fig.axes
    assert not ax.get_title().startswith('(a)')  # a lone panel is not labelled
    paths, formation = (
        c for c in ax.collections if isinstance(c, LineCollection)
    )  # trajectories, final edges
    (starts,) = (c for c in ax.collections if isinstance(c, PathCollection))  # start circles
    assert len(paths.get_segments()) == len(starts.get_offsets()) == scenario.n
    assert len(formation.get_segments()) == len(scenario.edges)


def test_event_triggered_figure_draws_one_tick_per_trigger(scenario):
    record = simulate(scenario, horizon=0.5)
    fig = run_figure(record)
    assert len(fig.axes) == 2
    raster = fig.axes[1]
    ticks = sum(len(c.get_segments()) for c in raster.collections if isinstance(c, LineCollection))
    assert ticks == record.total_events > 0
    assert f'({record.total_events} events)' in raster.get_title()
    assert 'no triggering events' not in fig.get_suptitle()


@pytest.mark.parametrize(('flags', 'panels'), [([], 2), (['--continuous'], 1)], ids=['events', 'continuous'])
def test_simulate_writes_the_figure_with_the_panels_of_its_controller(tmp_path, capsys, flags, panels):
    out = tmp_path / 'run'
    assert main(['simulate', 'paper_single', '--horizon', '0.5', '--out', str(out), '--quiet', *flags]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    height, width = matplotlib.image.imread(out / FIGURE_FILE).shape[:2]
    # 7 in wide at 110 dpi; 9 in high with the raster below, 5.6 in without it.
    assert (width, height) == (770, 990 if panels == 2 else 616)


# -- run folders: nothing is replaced unless asked, every argument checked first -------------------


def _listing(folder):
    return {
        path.relative_to(folder).as_posix(): path.read_bytes() if path.is_file() else None
        for path in sorted(folder.rglob('*'))
    }


def test_an_earlier_run_is_refused_then_replaced_with_force_leaving_nothing_stale(tmp_path, capsys):
    out = tmp_path / 'run'
    assert main(['simulate', 'paper_single', '--horizon', '0.3', '--out', str(out), '--quiet']) == 0
    (out / 'analysis').mkdir()
    (out / 'analysis' / 'analysis.md').write_text('of the earlier run')
    earlier = _listing(out)
    capsys.readouterr()
    assert (
        main(['simulate', 'paper_double', '--horizon', '0.3', '--out', str(out), '--quiet', '--no-plot']) == 2
    )
    err = capsys.readouterr().err
    assert (
        f'{out} already holds an earlier run (analysis/, formation.png, summary.json, trajectory/); '
        'nothing was changed' in err
    )
    assert _listing(out) == earlier
    assert (
        main(
            [
                'simulate',
                'paper_double',
                '--horizon',
                '0.3',
                '--out',
                str(out),
                '--quiet',
                '--no-plot',
                '--force',
            ]
        )
        == 0
    )
    assert sorted(p.name for p in out.iterdir()) == [
        'summary.json',
        'trajectory',
    ]  # no old figure, no old analysis
    assert '"dynamics": "double"' in (out / 'summary.json').read_text()


def test_without_out_every_run_gets_a_new_folder_under_runs(
    tmp_path, capsys, monkeypatch, paper_scenario_dict
):
    import yaml

    monkeypatch.chdir(tmp_path)
    data = paper_scenario_dict()
    data['name'] = '../../escaped'
    (tmp_path / 'escaping.yaml').write_text(yaml.safe_dump(data))
    folders = []
    for _ in range(2):
        assert main(['simulate', 'escaping.yaml', '--horizon', '0.1', '--quiet', '--no-plot']) == 0
        folders.append(capsys.readouterr().out.strip())
    assert folders[0] != folders[1]
    for folder in folders:
        assert re.fullmatch(r'runs/escaped-simulate-\d{8}-\d{6}(-\d+)?', folder), folder
        assert (tmp_path / folder / 'summary.json').is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['escaping.yaml', 'runs']
    assert not (tmp_path.parent / 'escaped').exists() and not (tmp_path.parent.parent / 'escaped').exists()


BAD_SIMULATE_ARGUMENTS = [
    (['--sample-dt', '-1'], 'argument --sample-dt: must be a finite number >= 0, got -1.0'),
    (
        ['--sample-dt', '1e-9'],
        'argument --sample-dt: the sample spacing 1e-09 s asks for 1e+10 samples of 6 numbers',
    ),
    (['--sample-dt', '0', '--continuous'], 'argument --sample-dt: must be > 0 with --continuous'),
    (['--horizon', 'inf'], 'argument --horizon: must be a finite number > 0, got inf'),
    (['--horizon', '0'], 'argument --horizon: must be a finite number > 0, got 0.0'),
    (['--period', '-1'], 'argument --period: must be a finite number > 0, got -1.0'),
    (['--tolerance', '0'], 'argument --tolerance: must be a finite number > 0, got 0.0'),
    (['--period', '0.1', '--continuous'], 'argument --continuous: not allowed with argument --period'),
    (
        ['--samples', 'all'],
        "argument --samples: invalid choice: 'all' (choose from 'auto', 'events', 'grid', 'none')",
    ),
    (
        ['--samples', 'none', '--sample-dt', '0.1'],
        'argument --sample-dt: --samples none keeps no grid (only t = 0 and the horizon), got '
        '--sample-dt 0.1',
    ),
    (
        ['--samples', 'grid', '--sample-dt', '0'],
        'argument --sample-dt: --samples grid needs a grid spacing > 0 (t = 0 and the horizon alone: '
        '--samples none)',
    ),
    (
        ['--samples', 'events', '--continuous'],
        'argument --samples: the continuous controller has no events; its trajectory is the grid '
        '(--sample-dt), got events',
    ),
]


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    BAD_SIMULATE_ARGUMENTS,
    ids=[' '.join(case[0]) for case in BAD_SIMULATE_ARGUMENTS],
)
def test_bad_arguments_exit_2_and_touch_nothing(tmp_path, capsys, arguments, complaint):
    out = tmp_path / 'run'
    assert (
        main(['simulate', 'paper_single', '--horizon', '0.2', '--out', str(out), '--quiet', '--no-plot']) == 0
    )
    earlier = _listing(out)
    capsys.readouterr()
    for target in (out, tmp_path / 'new'):
        assert main(['simulate', 'paper_single', '--out', str(target), '--force', *arguments]) == 2
        err = capsys.readouterr().err
        assert complaint in err and 'Traceback' not in err
    assert _listing(out) == earlier and not (tmp_path / 'new').exists()


def test_simulate_refuses_an_initial_slack_double_precision_cannot_resolve(tmp_path, capsys, tight_edge):
    # Issue 10's "initial slack of 1e-12": formerly a CrossingError traceback. Now validate refuses
    # it, naming the edge, the slack and the floor, before anything is written.
    from formation_sim.model.scenario import dump_scenario

    path = tmp_path / 'tight.yaml'
    dump_scenario(tight_edge('paper_single', 1e-12), path)
    out = tmp_path / 'run'
    assert main(['simulate', str(path), '--horizon', '1e-6', '--out', str(out)]) == 2
    captured = capsys.readouterr()
    text = captured.out + captured.err
    assert '[precision] edge (2, 3): initial slack' in text and 'is below 0.00106827' in text
    assert 'Traceback' not in text and not out.exists()


# -- what the trajectory keeps ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('policy', 'times'),
    [
        ('events', None),  # every event time and the grid: the record of the Python API
        ('grid', [0.0, 0.25, 0.5, 0.75, 1.0]),
        ('none', [0.0, 1.0]),
    ],
)
def test_each_sample_policy_keeps_what_it_says_and_the_same_run(tmp_path, capsys, policy, times):
    scenario = load_scenario('paper_single')
    reference = simulate(scenario, horizon=1.0, sample_dt=0.25)  # in memory, every event time sampled
    out = tmp_path / policy
    grid = [] if policy == 'none' else ['--sample-dt', '0.25']
    assert (
        main(
            [
                'simulate',
                'paper_single',
                '--horizon',
                '1',
                '--out',
                str(out),
                '--samples',
                policy,
                *grid,
                '--no-plot',
            ]
        )
        == 0
    )
    assert f'samples: {policy}, ' in capsys.readouterr().err
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['extra']['samples'] == policy
    assert {
        int(a): t for a, t in summary['trigger_times'].items()
    } == reference.trigger_times  # sampling never moves an event
    samples = load_trajectory(out)
    if times is None:
        assert np.array_equal(samples.times, reference.sample_times) and np.array_equal(
            samples.positions, reference.sample_positions
        )
    else:
        assert samples.times.tolist() == times
        rows = np.searchsorted(reference.sample_times, times)
        assert np.array_equal(samples.positions, reference.sample_positions[rows])
    # The connectivity check covers every trigger whatever is kept (single integrators: exact).
    for edge, expected in zip(summary['edges'], reference_edges(reference)):
        assert edge['max_length'] == pytest.approx(expected, rel=4e-16, abs=0.0)


def reference_edges(record):
    index = {agent: k for k, agent in enumerate(record.scenario.agent_ids)}
    x = record.sample_positions
    return [
        float(np.linalg.norm(x[:, index[e.i]] - x[:, index[e.j]], axis=1).max())
        for e in record.scenario.edges
    ]


def test_auto_keeps_event_samples_for_small_teams_only(tmp_path, capsys, monkeypatch):
    import formation_sim.commands.simulate as command

    assert (
        main(['simulate', 'paper_single', '--horizon', '0.5', '--out', str(tmp_path / 'small'), '--no-plot'])
        == 0
    )
    assert 'samples: events (auto)' in capsys.readouterr().err
    monkeypatch.setattr(command, 'AUTO_EVENTS_MAX_AGENTS', 2)  # three agents count as a large team now
    assert (
        main(['simulate', 'paper_single', '--horizon', '0.5', '--out', str(tmp_path / 'large'), '--no-plot'])
        == 0
    )
    assert 'samples: grid (auto), 51 states' in capsys.readouterr().err
    assert json.loads((tmp_path / 'large' / 'summary.json').read_text())['extra']['samples'] == 'grid'


def test_a_run_that_fails_leaves_no_folder_and_no_samples(tmp_path, capsys):
    out = tmp_path / 'run'
    assert (
        main(['simulate', 'paper_single', '--horizon', '200', '--out', str(out), '--no-plot']) == 1
    )  # stops at t ≈ 34.4
    err = capsys.readouterr().err
    assert 'rounding, not the dynamics, decides the events' in err and 'Traceback' not in err
    assert not out.exists()  # the samples streamed so far went with it


def test_speed_scale_auto_chooses_kappa_from_the_limits_and_records_it(tmp_path, capsys):
    import json
    import math

    from formation_sim.model.scenario import load_scenario
    from formation_sim.sim.largest_command import measured_command

    out = tmp_path / 'lab'
    assert (
        main(
            [
                'simulate',
                'robots_lab',
                '--speed-scale',
                'auto',
                '--max-speed',
                '0.22',
                '--max-angular-speed',
                '2.84',
                '--horizon',
                '20',
                '--out',
                str(out),
                '--quiet',
                '--no-plot',
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    summary = json.loads((out / 'summary.json').read_text())
    chosen = summary['extra']['speed_scale']
    assert (
        chosen['source'] == 'observed' and 'speed 0.22 m/s' in chosen['binding'] and chosen['margin'] == 1.25
    )
    kappa = chosen['value']
    assert f'--speed-scale auto: κ = {kappa:.4g} (observed' in err
    # the engine at that κ (scale's implementation) asks for exactly the limit over the margin
    scaled = measured_command(load_scenario('robots_lab').with_scale(speed_scale=kappa), horizon=20.0)
    assert math.isclose(scaled.max_speed * 1.25, 0.22, rel_tol=1e-9)
    # without limits there is nothing to choose from
    assert (
        main(['simulate', 'robots_lab', '--speed-scale', 'auto', '--out', str(tmp_path / 'none'), '--quiet'])
        == 2
    )
    assert (
        '--speed-scale auto: a speed scale from the limits needs at least one of --max-speed'
        in capsys.readouterr().err
    )
    assert not (tmp_path / 'none').exists()
    assert (
        main(['simulate', 'robots_lab', '--speed-scale', 'fast', '--out', str(tmp_path / 'bad'), '--quiet'])
        == 2
    )
    assert (
        "argument --speed-scale: must be a finite number > 0 or 'auto', got 'fast'" in capsys.readouterr().err
    )


def test_a_warped_run_whose_robots_jam_at_the_default_turn_runs_every_agent_at_the_next(
    tmp_path, capsys, monkeypatch
):
    """Issue 27: the stress sweep's team 19 jams at λ = 1.5 (docs/SAFETY.md, "Ties"): `simulate
    --speed-scale warp` says so, runs at λ = 2, and records it; the run is the engine's at λ = 2 under
    the same warp, event for event.  The jam cap is lowered to 500 per agent to keep the test short."""
    import dataclasses

    from formation_agent.core.time_warp import TimeWarp
    from formation_sim.model.scenario import dump_scenario
    from formation_sim.sim import largest_command, safety_cases

    monkeypatch.setattr(largest_command, 'JAM_EVENTS_PER_AGENT', 500)
    team = safety_cases.random_team(19)
    dump_scenario(team, tmp_path / 'team19.yaml')
    out = tmp_path / 'run'
    arguments = ['simulate', str(tmp_path / 'team19.yaml'), '--speed-scale', 'warp', '--max-speed', '1']
    assert main([*arguments, '--out', str(out), '--quiet', '--no-plot']) == 0
    err = capsys.readouterr().err
    assert "the safety layer's tie-break turn λ = 2 for every agent: the robots jam at λ = 1.5 (" in err
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['extra']['safety']['turn'] == 2.0
    chosen = summary['extra']['speed_scale']['tie_break_turn']
    assert chosen['turn'] == 2.0 and [jam['turn'] for jam in chosen['jams']] == [1.5]
    assert chosen['jams'][0]['events'] > 500 * team.n
    observed = summary['extra']['speed_scale']['observed']
    warp = TimeWarp(paper_starts=tuple(observed['paper_starts']), rates=tuple(observed['rates']))
    turned = team.replace(safety=dataclasses.replace(team.safety, turn=2.0))
    record = simulate(turned, sample_dt=None, time_warp=warp)
    assert summary['trigger_times'] == {str(k): v for k, v in record.trigger_times.items()}


def test_speed_scale_warp_runs_the_observed_warp_and_records_it(tmp_path, capsys):
    import json

    from formation_agent.core.time_warp import TimeWarp
    from formation_sim.model.scenario import load_scenario
    from formation_sim.model.speed_choice import RobotLimits
    from formation_sim.sim.largest_command import choose_time_warp

    limits = ['--max-speed', '0.22', '--max-angular-speed', '2.84']
    out = tmp_path / 'warp'
    arguments = ['simulate', 'robots_lab', '--speed-scale', 'warp', *limits, '--horizon', '20']
    assert main([*arguments, '--out', str(out), '--quiet', '--no-plot']) == 0
    err = capsys.readouterr().err
    summary = json.loads((out / 'summary.json').read_text())
    chosen = summary['extra']['speed_scale']
    assert chosen['kind'] == 'time_warp' and chosen['source'] == 'observed' and chosen['margin'] == 1.25
    assert chosen['cap'] == 1.0 and chosen['limits']['max_speed'] == 0.22
    warp = TimeWarp(
        paper_starts=tuple(chosen['observed']['paper_starts']), rates=tuple(chosen['observed']['rates'])
    )
    assert summary['extra']['time_warp']['rates'] == list(warp.rates)
    assert (
        f'--speed-scale warp: a time warp, κ(t) in {warp.pieces} pieces from {warp.rates[0]:.4g} to 1' in err
    )
    # the choice is the library's for the same limits, and the run is the engine's under it
    choice = choose_time_warp(
        load_scenario('robots_lab').replace(horizon=20.0),
        limits=RobotLimits(max_speed=0.22, max_angular_speed=2.84, control_point_distance=0.1),
    )
    assert choice.warp == warp
    record = simulate(load_scenario('robots_lab'), horizon=20.0, sample_dt=None, time_warp=warp)
    assert summary['trigger_times'] == {str(k): v for k, v in record.trigger_times.items()}
    # what applies no warp is refused before anything starts
    for extra, words in (
        (['--period', '0.1'], '--speed-scale warp: the event-triggered engine only'),
        ([], '--speed-scale warp: time_warp: ETA-1 only'),
    ):
        scenario = 'paper_double' if not extra else 'robots_lab'
        bad = tmp_path / 'bad'
        assert main(['simulate', scenario, '--speed-scale', 'warp', *limits, *extra, '--out', str(bad)]) == 2
        assert words in capsys.readouterr().err
        assert not bad.exists()
