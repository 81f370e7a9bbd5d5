"""formation_sim.analysis.analyze and formation_sim.analysis.figures: runs rebuilt from bags, metrics, checks,
figures."""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import numpy as np
import pytest

from formation_sim.analysis.checks import run_series, theorem_checks, theory_bounds
from formation_sim.analysis.errors import AnalysisError
from formation_sim.analysis.load import load_bag_run, locate
from formation_sim.analysis.report import bag_summary, diff_summaries
from formation_sim.model import theory
from formation_sim.model.scenario import dump_scenario, load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.summary import build_summary, write_summary


def _events(record) -> list[float]:
    return sorted({t for times in record.trigger_times.values() for t in times})


# ------------------------------------------------------------------------------ rebuilding


def test_a_bag_gives_back_the_run_exactly(paper_single_record, write_run_bag, tmp_path):
    record = paper_single_record
    bag = write_run_bag(record, tmp_path / 'bag', scenario_topic=True)
    run = load_bag_run(bag)
    assert run.scenario_source == 'bag topic /formation/scenario'
    assert run.record.scenario == record.scenario.replace(
        horizon=record.horizon
    )  # as the simulator publishes it
    assert run.horizon == record.horizon and run.stop is None
    assert run.record.trigger_times == record.trigger_times  # floats equal, not close
    assert np.array_equal(run.record.sample_times, record.sample_times)
    assert np.array_equal(run.record.sample_positions, record.sample_positions)
    assert run.record.horizon == record.horizon
    assert run.record.messages_sent == record.messages_sent
    assert run.record.sensing_calls == record.total_events
    assert [check for check in run.checks if not check.ok] == []
    # Every metric of summary.json but what differs by construction (mode, wall time, details).
    expected = build_summary(record)
    got = bag_summary(run.record)
    for key in set(expected) - {'mode', 'wall_time', 'extra'}:
        assert got[key] == expected[key], key


def test_double_integrator_bags_keep_the_velocities(write_run_bag, tmp_path):
    record = simulate(load_scenario('paper_double'), horizon=0.3)
    run = load_bag_run(write_run_bag(record, tmp_path / 'bag', scenario_topic=True))
    assert np.array_equal(run.record.sample_velocities, record.sample_velocities)
    assert run.record.trigger_times == record.trigger_times
    assert bag_summary(run.record)['final_velocities'] == build_summary(record)['final_velocities']


def test_the_scenario_comes_from_the_run_folder_or_the_caller(paper_single_record, write_run_bag, tmp_path):
    record = paper_single_record
    bag = write_run_bag(record, tmp_path / 'run' / 'bag')
    with pytest.raises(AnalysisError, match=r'no /formation/scenario topic .* --scenario'):
        load_bag_run(bag)
    assert load_bag_run(bag, scenario='paper_single').scenario_source == '--scenario paper_single'
    dump_scenario(record.scenario, tmp_path / 'run' / 'scenario.yaml')
    location = locate(tmp_path / 'run')
    assert location.bag == bag and location.run_dir == tmp_path / 'run'
    run = load_bag_run(location.bag, run_dir=location.run_dir)
    assert run.scenario_source.startswith('run folder file')
    assert run.record.scenario == record.scenario


def test_a_scenario_that_is_not_the_bags_run_is_refused(paper_single_record, write_run_bag, tmp_path):
    bag = write_run_bag(paper_single_record, tmp_path / 'bag')
    with pytest.raises(AnalysisError, match="lack velocities; the scenario is 'double'"):
        load_bag_run(bag, scenario='paper_double')
    moved = paper_single_record.scenario.replace(
        positions=paper_single_record.scenario.positions + [[0.0, 0.0], [0.0, 0.0], [0.5, 0.0]]
    )
    with pytest.raises(AnalysisError, match=r'agent 3 starts at \[4.5, 5.5\] in the bag but at \[5.0, 5.5\]'):
        load_bag_run(bag, scenario=moved)


def test_a_lost_message_is_reported_not_hidden(paper_single_record, write_run_bag, tmp_path):
    record = paper_single_record
    second = record.trigger_times[1][1]
    bag = write_run_bag(record, tmp_path / 'bag', scenario_topic=True, drop={(1, 2, 1)})
    run = load_bag_run(bag)
    failed = {check.name: check.detail for check in run.checks if not check.ok}
    assert set(failed) == {'one TriggerInfo per neighbour per trigger'}
    assert f'1 @ {second!r} -> [2]' in failed['one TriggerInfo per neighbour per trigger']
    assert run.record.trigger_times == record.trigger_times  # the message to agent 3 still shows the trigger
    assert run.record.messages_sent == record.messages_sent - 1


def test_a_trigger_whose_messages_are_all_lost_is_caught_by_the_sensing_log(
    paper_single_record, write_run_bag, tmp_path
):
    record = paper_single_record
    bag = write_run_bag(record, tmp_path / 'bag', scenario_topic=True, drop={(1, 2, 1), (1, 3, 1)})
    run = load_bag_run(bag)
    failed = {check.name: check.detail for check in run.checks if not check.ok}
    assert failed['sensing log = triggers'] == 'agents [1] sensed at other times than they triggered'
    assert len(run.record.trigger_times[1]) == len(record.trigger_times[1]) - 1


def test_locate_refuses_what_is_not_a_run(tmp_path):
    with pytest.raises(AnalysisError, match='no such file or folder'):
        locate(tmp_path / 'missing')
    with pytest.raises(AnalysisError, match='neither a bag'):
        locate(tmp_path)


# ---------------------------------------------------------------------------- summary diff


def test_every_differing_key_is_listed_with_both_values(paper_single_record):
    from_bag = bag_summary(paper_single_record)
    from_file = copy.deepcopy(from_bag)
    from_file['wall_time'] = 1.25  # a bag has no wall time: not a difference
    from_file['extra']['discovery_wall_time'] = 0.5  # runtime detail the bag lacks: not a difference
    shifted = from_file['trigger_times']['2'][3] + 1e-15
    from_file['trigger_times']['2'][3] = shifted
    from_file['trigger_times']['3'].pop()
    from_file['messages_sent'] += 1
    from_file['edges'][1]['max_length'] = 9.0
    differences, skipped = diff_summaries(from_bag, from_file)
    found = {d.key: (d.bag, d.summary) for d in differences}
    assert found == {
        'trigger_times.2[3]': (from_bag['trigger_times']['2'][3], shifted),
        'trigger_times.3 (length)': (
            len(from_bag['trigger_times']['3']),
            len(from_bag['trigger_times']['3']) - 1,
        ),
        'messages_sent': (from_bag['messages_sent'], from_bag['messages_sent'] + 1),
        'edges[1].max_length': (from_bag['edges'][1]['max_length'], 9.0),
    }
    assert set(skipped) == {'wall_time', 'extra.discovery_wall_time'}
    assert diff_summaries(from_bag, copy.deepcopy(from_bag)) == ([], ['wall_time'])


def test_a_key_the_bag_recomputes_is_compared_even_in_extra():
    differences, _ = diff_summaries({'extra': {'failure': None}}, {'extra': {'failure': {'kind': 'stall'}}})
    assert [d.key for d in differences] == ['extra.failure']
    differences, _ = diff_summaries({'ready': True}, {'ready': 1})
    assert [d.key for d in differences] == ['ready']  # True == 1 in Python, not in JSON


# --------------------------------------------------------------------------- series, theory


def test_series_at_t0_match_the_papers_formulas(paper_single_record):
    record = paper_single_record
    scenario = record.scenario
    series = run_series(record)
    x = scenario.positions
    index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
    nu = 0.0
    for column, edge in enumerate(scenario.edges):
        rel = x[index[edge.i]] - x[index[edge.j]]
        error = math.dist(rel, edge.d)
        assert series.edge_lengths[0, column] == pytest.approx(math.hypot(*rel), rel=1e-15)
        assert series.edge_errors[0, column] == pytest.approx(error, rel=1e-15)
        nu += error**2 / (scenario.delta - math.hypot(*edge.d) - error)  # ν_ij, each edge once
    assert series.tension[0] == pytest.approx(nu, rel=1e-12)
    # V = ½ Σ ||y_i - ȳ||², with y_i = x_i - τ_i for a τ of the formation: τ = (0,0), d_21, d_31.
    tau = np.array([[0.0, 0.0], [0.0, 2.0], [2.0, 0.0]])
    y = x - tau
    assert series.lyapunov[0] == pytest.approx(0.5 * float(np.sum((y - y.mean(axis=0)) ** 2)), rel=1e-12)


@pytest.mark.parametrize('dynamics', ['single', 'double'])
def test_series_takes_each_samples_own_float_across_chunks(dynamics, monkeypatch):
    # run_series evaluates ν and V on (K, n, p) blocks; every sample must still get the float of
    # its own 1-D sums (written out here), across a block boundary (a 3-sample block on 8 samples).
    from formation_sim.analysis import checks
    from formation_sim.model.generate import random_scenario

    monkeypatch.setattr(checks, 'SERIES_CHUNK', 3)
    scenario = random_scenario(n=17, seed=3, dimension=3, dynamics=dynamics, slack=0.3)
    record = simulate(scenario, horizon=0.05)
    series = run_series(record)
    heads, tails, d = scenario.edge_indices()
    capacity = scenario.delta - np.linalg.norm(d, axis=1)
    tau = theory.formation_feasibility(scenario).tau
    x, q = record.sample_positions, record.sample_velocities
    assert len(record.sample_times) >= 8
    for k in range(len(record.sample_times)):
        l = np.linalg.norm(x[k][heads] - x[k][tails] - d, axis=1)
        nu = float(np.sum(l * l / (capacity - l)))
        y = x[k] - tau
        dy = y - y.mean(axis=0)
        if dynamics == 'single':
            assert series.tension[k] == nu
            assert series.lyapunov[k] == 0.5 * float(np.sum(dy * dy))
            continue
        P, qk = scenario.gains.P, q[k]
        dq = qk - qk.mean(axis=0)
        assert series.tension[k] == scenario.gains.k1 * nu + 0.5 * float(np.sum(qk * qk))
        assert series.lyapunov[k] == 0.5 * float(
            P[0, 0] * np.sum(dy * dy) + 2.0 * P[0, 1] * np.sum(dy * dq) + P[1, 1] * np.sum(dq * dq)
        )


def test_theorem_1_guarantees_hold_on_the_paper_run(paper_single_record):
    record = paper_single_record
    series = run_series(record)
    checks = theorem_checks(record, series, theory_bounds(record.scenario))
    assert [check for check in checks if not check.ok] == []
    assert len(checks) == 6  # connectivity, (kij), (knu), (kV), (lengthysV), (xi)
    assert np.all(series.edge_lengths < record.scenario.delta)


def test_theorem_2_on_the_paper_example_gives_connectivity_but_no_decay_bound():
    # docs/THEOREM2.md: β_d = 1 is not below the corrected (2-k4)/λmax(P) = 0.186, so the proof
    # bounds ν_d and the edges (part (i)) but gives no k_V, decay bound or ξ.
    record = simulate(load_scenario('paper_double'), horizon=0.5)
    series = run_series(record)
    bounds = theory_bounds(record.scenario)
    assert bounds.k_V is None and bounds.error_gain is None and bounds.xi is None
    assert 'no decay bound' in bounds.note
    checks = theorem_checks(record, series, bounds)
    assert [check.name for check in checks] == [
        'connectivity: ||x_i - x_j|| < Δ',
        'edge lengths <= k_ij + ||d_ij|| (kij)',
        'tension <= k_nu (knu)',
    ]
    assert all(check.ok for check in checks)
    assert bounds.printed_k_V is not None  # the printed chain, drawn for comparison


def test_theorem_checks_catch_a_violation(paper_single_record):
    record = paper_single_record
    series = run_series(record)
    bounds = theory_bounds(record.scenario)
    grown = dataclasses.replace(
        series, formation_error=series.formation_error * 100.0, edge_lengths=series.edge_lengths * 2.0
    )
    failed = {check.name: check.detail for check in theorem_checks(record, grown, bounds) if not check.ok}
    assert 'formation error < 2 sqrt(k_V) e^{-beta t}' in failed
    assert failed['connectivity: ||x_i - x_j|| < Δ'].startswith('max edge length 6.7082039')  # 2 ||(1.5, 3)||
    tight = dataclasses.replace(bounds, xi=dict.fromkeys(bounds.xi, 1.0))
    failed = {check.name: check.detail for check in theorem_checks(record, series, tight) if not check.ok}
    assert failed['inter-event times >= xi_i (xi)'].startswith('agent 1: ')


def test_double_integrator_bounds_use_the_corrected_chain():
    # β_d below (2-k4)/λmax(P) = 0.186: the corrected chain holds and bounds the error by
    # 2 sqrt(k^d_V / λmin(P)) e^{-β_d t} (yiyj, corrected).
    base = load_scenario('paper_double')
    scenario = base.replace(gains=dataclasses.replace(base.gains, beta_d=0.1))
    bounds = theory_bounds(scenario)
    chain = theory.theorem_constants(scenario).corrected_chain
    assert chain.holds and bounds.theorem == 2 and bounds.rate == 0.1
    assert bounds.error_gain == pytest.approx(
        2.0 * math.sqrt(chain.k_V / np.linalg.eigvalsh(scenario.gains.P).min()), rel=1e-12
    )


# ------------------------------------------------------------------------------------ figures


def test_the_paper_figure_draws_exactly_the_recorded_events_and_paths(paper_single_record):
    from formation_sim.analysis.figures import paper_figure, pyplot

    record = paper_single_record
    fig, trajectories, raster = paper_figure(record)
    try:
        assert len(raster.ticks.get_segments()) == record.total_events
        for agent in record.scenario.agent_ids:
            assert raster.drawn_times(agent) == record.trigger_times[agent]
        x = record.sample_positions
        assert np.array_equal(
            trajectories.rows, np.arange(len(record.sample_times))
        )  # a small run: every sample
        paths, starts = trajectories.paths.get_segments(), trajectories.starts.get_offsets()
        for k, _agent in enumerate(record.scenario.agent_ids):
            assert np.array_equal(paths[k], x[:, k]) and np.array_equal(
                paths[k][0], record.scenario.positions[k]
            )
            assert np.array_equal(starts[k], record.scenario.positions[k])
        index = {agent: k for k, agent in enumerate(record.scenario.agent_ids)}
        edges = trajectories.formation.get_segments()
        assert len(edges) == len(record.scenario.edges)
        for segment, edge in zip(edges, record.scenario.edges):
            assert np.array_equal(segment, x[-1, [index[edge.i], index[edge.j]]])
        assert [handle.get_label() for handle in fig.axes[0].get_legend().legend_handles] == [
            'agent 1',
            'agent 2',
            'agent 3',
        ]
    finally:
        pyplot().close(fig)


def test_a_long_run_of_a_large_team_is_drawn_through_evenly_spaced_samples():
    from formation_sim.analysis.figures import FIGURE_POINTS, figure_rows

    times = np.concatenate(
        [np.linspace(0.0, 1e-6, 50_000), np.linspace(1e-6, 2.0, 20_000)[1:]]
    )  # a burst, then calm
    assert np.array_equal(figure_rows(times, agents=3), np.arange(len(times)))  # few points: all of them
    rows = figure_rows(times, agents=1000)
    assert rows[0] == 0 and rows[-1] == len(times) - 1 and np.all(np.diff(rows) > 0)
    assert len(rows) * 1000 <= FIGURE_POINTS
    gaps = np.diff(times[rows])
    assert gaps.max() < 2.5 * 2.0 / (
        FIGURE_POINTS // 1000
    )  # evenly spread in time, not crowded into the burst


def test_analysis_panels_hold_the_series_and_bounds(paper_single_record):
    from formation_sim.analysis.figures import (
        plot_energy,
        plot_formation_error,
        plot_inter_event_times,
        pyplot,
    )

    record = paper_single_record
    series = run_series(record)
    bounds = theory_bounds(record.scenario)
    plt = pyplot()
    fig, (ax_error, ax_gaps, ax_nu, ax_v) = plt.subplots(1, 4)
    try:
        error = plot_formation_error(ax_error, series, bounds)
        t = error.lines['bound'].get_xdata()
        assert np.all(series.formation_error < error.lines['bound'].get_ydata())  # Theorem 1 (ii)
        assert np.allclose(
            error.lines['envelope'].get_ydata(),
            series.formation_error[0] * np.exp(-record.scenario.gains.beta * t),
        )
        gaps = plot_inter_event_times(ax_gaps, record, bounds.xi)
        histogram_total = sum(
            patch.get_path().vertices[:, 1].max() > 0 for patch in ax_gaps.patches
        )  # one outline per agent
        assert histogram_total == len(record.scenario.agent_ids)
        assert sum(g.size for g in gaps.gaps.values()) == record.total_events - len(record.scenario.agent_ids)
        assert {agent: line.get_xdata()[0] for agent, line in gaps.xi_lines.items()} == bounds.xi
        energy = plot_energy(ax_nu, ax_v, record, series, bounds)
        assert np.array_equal(energy.lines['tension'].get_ydata(), series.tension)
        assert np.all(series.lyapunov < energy.lines['k_V'].get_ydata())  # (kV)
    finally:
        plt.close(fig)


def test_the_animation_has_the_frames_asked_for(paper_single_record, tmp_path):
    from PIL import Image

    from formation_sim.analysis.figures import animate, frame_indices

    record = paper_single_record
    chosen = frame_indices(record.sample_times, frames=7)
    assert chosen[0] == 0 and chosen[-1] == len(record.sample_times) - 1
    assert np.all(np.diff(chosen) >= 0)
    targets = np.linspace(0.0, record.sample_times[-1], 7)
    assert np.all(record.sample_times[chosen] <= targets)
    seen = []
    path = animate(
        record, tmp_path / 'run.gif', frames=7, progress=lambda done, total: seen.append((done, total))
    )
    with Image.open(path) as image:
        assert image.n_frames == 7
        assert min(image.size) >= 500  # readable: 7 in at 80 dpi
    assert seen[-1] == (7, 7)


def test_the_edge_length_margins_show_the_room_the_theorem_guarantees(paper_single_record):
    # On a log scale of Δ - length, the guaranteed room Δ - (k_ij + ||d_ij||) lies below the
    # measured room at every sample (Theorem 1 (i)): the dotted lines are visible, not on Δ.
    from formation_sim.analysis.checks import run_series, theory_bounds
    from formation_sim.analysis.figures import plot_edge_lengths, pyplot

    record = paper_single_record
    series, bounds = run_series(record), theory_bounds(record.scenario)
    plt = pyplot()
    fig, (ax, margin_ax) = plt.subplots(2, 1)
    try:
        plot = plot_edge_lengths(ax, record, series, bounds, margin_ax=margin_ax)
        assert margin_ax.get_yscale() == 'log'
        for column, edge in enumerate(record.scenario.edges):
            room = plot.lines[f'room {edge.i}-{edge.j}'].get_ydata()
            assert np.array_equal(room, record.scenario.delta - series.edge_lengths[:, column])
            guaranteed = plot.lines[f'bound {edge.i}-{edge.j}'].get_ydata()[0]
            assert guaranteed == pytest.approx(
                record.scenario.delta - bounds.edge_bounds[edge.pair], rel=1e-15
            )
            assert 0.0 < guaranteed < room.min()
    finally:
        plt.close(fig)


# ---------------------------------------------------------------------------------- command


def _distributed_like(record):
    """The record as the simulator node would report it (mode and the extras a bag holds)."""
    extra = {
        'clock': 'lockstep',
        'steps': len(_events(record)),
        'reached_time': record.horizon,
        'failure': None,
    }
    return dataclasses.replace(record, mode='distributed', extra=extra)


def test_analyze_command_reports_agreement_and_each_difference(paper_single_record, write_run_bag, tmp_path):
    from formation_sim.cli import main

    record = _distributed_like(paper_single_record)
    run_dir = tmp_path / 'run'
    write_run_bag(record, run_dir / 'bag', scenario_topic=True)
    summary = write_summary(record, run_dir)
    assert main(['analyze', str(run_dir), '--no-animation', '--quiet']) == 0
    report = json.loads((run_dir / 'analysis' / 'analysis.json').read_text())
    assert report['summary_json']['equal'] is True
    assert report['summary']['trigger_times'] == {str(a): t for a, t in record.trigger_times.items()}
    for name in (
        'formation.png',
        'edge_lengths.png',
        'formation_error.png',
        'inter_event_times.png',
        'energy.png',
    ):
        assert (run_dir / 'analysis' / name).stat().st_size > 1000

    data = json.loads(summary.read_text())
    data['messages_sent'] += 2
    summary.write_text(json.dumps(data))
    assert main(['analyze', str(run_dir), '--no-figures', '--quiet', '--out', str(tmp_path / 'second')]) == 1
    markdown = (tmp_path / 'second' / 'analysis.md').read_text()
    assert f'| `messages_sent` | {record.messages_sent} | {record.messages_sent + 2} |' in markdown
    assert 'differs from the bag in 1 value(s)' in markdown


def test_analyze_command_exit_2_names_what_is_missing(tmp_path, capsys):
    from formation_sim.cli import main

    (tmp_path / 'empty').mkdir()
    assert main(['analyze', str(tmp_path / 'empty')]) == 2
    assert 'neither a bag' in capsys.readouterr().err


def _damage(bag, how):
    """The bag folder as a damaged recording leaves it; returns the path to give the command."""
    mcap = next(bag.glob('*.mcap'))
    if how == 'recorder killed (no metadata.yaml)':
        (bag / 'metadata.yaml').unlink()
        return bag, 'no metadata.yaml (it holds'
    if how == 'random bytes named .mcap':
        (bag / 'metadata.yaml').unlink()
        mcap.write_bytes(bytes(range(256)) * 8)
        return mcap, 'no metadata.yaml (it holds'
    if how == 'random bytes beside metadata.yaml':
        mcap.write_bytes(bytes(range(256)) * 8)
        return (
            bag,
            'its MCAP file is not an MCAP file (its first bytes are not the MCAP magic; the reader said '
            "'File magic is invalid.')",
        )
    data = mcap.read_bytes()  # cut short beside its metadata.yaml
    mcap.write_bytes(data[: len(data) // 2])
    return bag, 'its MCAP file is cut short or its end is damaged'


DAMAGE = [
    'recorder killed (no metadata.yaml)',
    'random bytes named .mcap',
    'random bytes beside metadata.yaml',
    'cut short',
]


@pytest.mark.parametrize('command', ['analyze', 'compare'])
@pytest.mark.parametrize('how', DAMAGE)
def test_a_damaged_bag_is_refused_with_exit_2_and_what_to_do(
    paper_single_record, write_run_bag, tmp_path, capsys, command, how
):
    from formation_sim.cli import main

    bag = write_run_bag(paper_single_record, tmp_path / 'run' / 'bag')
    target, fragment = _damage(bag, how)
    arguments = [str(target)] if command == 'analyze' else [str(target), str(target)]
    assert main([command, *arguments, '--quiet']) == 2
    err = capsys.readouterr().err
    assert fragment in err and 'Traceback' not in err
    if 'no metadata.yaml' in fragment:
        assert f'`formation recover {bag}` rebuilds it' in err
    else:  # issue 28: what is wrong in words, and the way out
        assert f'`formation recover {bag}` keeps every intact chunk' in err
    assert not (tmp_path / 'run' / 'analysis').exists()


@pytest.mark.parametrize(
    ('arguments', 'complaint'),
    [
        (['--fps', '0'], 'argument --fps: must be an integer in [1, 100], got 0'),
        (['--fps', '12.5'], "argument --fps: must be an integer in [1, 100], got '12.5'"),
        (['--frames', '0'], 'argument --frames: must be an integer >= 1, got 0'),
    ],
)
def test_analyze_arguments_are_checked_before_the_analysis(tmp_path, capsys, arguments, complaint):
    from formation_sim.cli import main

    assert (
        main(['analyze', str(tmp_path / 'nothing_here'), *arguments]) == 2
    )  # refused before the run is even looked for
    assert complaint in capsys.readouterr().err


def test_a_report_never_overwrites_a_run(paper_single_record, write_run_bag, tmp_path, capsys):
    from formation_sim.cli import main

    write_run_bag(paper_single_record, tmp_path / 'a' / 'bag')
    other = tmp_path / 'other'
    write_summary(paper_single_record, other)
    before = sorted(p.name for p in other.iterdir())
    assert main(['analyze', str(tmp_path / 'a'), '--out', str(other), '--quiet']) == 2
    assert (
        'holds a run (summary.json or bag/) whose files the report would overwrite' in capsys.readouterr().err
    )
    assert sorted(p.name for p in other.iterdir()) == before


# ------------------------------------------------------------------------------------- ROS


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_analysing_a_distributed_bag_reproduces_what_the_run_reported(distributed_single_run):
    run = distributed_single_run
    location = locate(run.out_dir)
    rebuilt = load_bag_run(location.bag, run_dir=location.run_dir)
    assert [check for check in rebuilt.checks if not check.ok] == []
    summary = run.summary
    assert {str(a): t for a, t in rebuilt.record.trigger_times.items()} == summary['trigger_times']  # exactly
    final = rebuilt.record.sample_positions[-1]
    for k, agent in enumerate(rebuilt.record.scenario.agent_ids):
        assert final[k].tolist() == summary['final_positions'][str(agent)]
    differences, skipped = diff_summaries(bag_summary(rebuilt.record), summary)
    assert differences == []
    assert 'wall_time' in skipped
    # and the same events as the in-process engine
    assert rebuilt.record.total_events == run.reference.total_events


def test_a_wall_clock_trigger_at_the_horizon_is_explained(paper_single_record, tmp_path):
    from formation_sim.analysis.load import BagRun
    from formation_sim.analysis.report import build_report

    reported = dataclasses.replace(paper_single_record, extra={'clock': 'realtime'})
    summary = tmp_path / 'summary.json'
    summary.write_text(json.dumps(bag_summary(reported)))
    times = {agent: list(t) for agent, t in reported.trigger_times.items()}
    times[2].append(reported.horizon)  # sensed at the horizon; its command came after the end
    recorded = dataclasses.replace(reported, trigger_times=times)
    run = BagRun(bag=tmp_path / 'bag', record=recorded, scenario_source='test', topics={}, counts={})
    report = build_report(run, series=run_series(recorded), bounds=None, summary_path=summary)
    assert {d['key'] for d in report['summary_json']['differences']} == {
        'trigger_times.2 (length)',
        'event_counts.2',
        'total_events',
    }
    (note,) = report['summary_json']['notes']
    assert note.startswith('agents [2] triggered at the horizon t = 1.0 (wall clock)')


def test_the_analysis_api_says_what_it_takes(paper_single_record, write_run_bag, tmp_path):
    from formation_sim.analysis import diff_summaries, load_bag_run, run_series

    bag_run = load_bag_run(write_run_bag(paper_single_record, tmp_path / 'bag', scenario_topic=True))
    with pytest.raises(
        TypeError,
        match=r'run_series takes a RunRecord \(a BagRun holds it: pass bag_run.record\), got BagRun',
    ):
        run_series(bag_run)
    with pytest.raises(TypeError, match='from_bag is NoneType'):
        diff_summaries(None, {})
    with pytest.raises(TypeError, match='from_file is list'):
        diff_summaries({}, [])


# ------------------------------------------------------------------------------ runs stopped early


def test_a_run_stopped_early_and_consistent_with_its_bag_passes_with_the_stop_named(
    paper_single_record, write_run_bag, tmp_path, capsys
):
    """A run asked for t = 10 that stopped at t = 1 (SIGINT): its bag ends with the final Step the
    simulator sends at the stop, and its summary.json states the horizon asked and the failure."""
    from formation_sim.cli import main

    stopped = _distributed_like(paper_single_record)
    run_dir = tmp_path / 'run'
    write_run_bag(stopped, run_dir / 'bag', scenario_topic=True, asked_horizon=10.0)
    failure = {
        'kind': 'interrupted',
        'message': 'stopped by a signal (SIGINT/SIGTERM)',
        'agents': [],
        'time': 1.0,
        'step': 123,
    }
    reported = dataclasses.replace(
        stopped,
        horizon=10.0,
        extra={'clock': 'lockstep', 'steps': 122, 'reached_time': 1.0, 'failure': failure},
    )
    write_summary(reported, run_dir)

    assert main(['analyze', str(run_dir), '--no-figures']) == 0
    err = capsys.readouterr().err
    stop = (
        'the run stopped early at t = 1 (step 123), before its horizon 10: interrupted: stopped by a signal '
        '(SIGINT/SIGTERM) (summary.json)'
    )
    assert stop in err and 'summary.json equals the bag' in err
    report = json.loads((run_dir / 'analysis' / 'analysis.json').read_text())
    assert report['run']['stopped'] == {
        'time': 1.0,
        'step': 123,
        'horizon': 10.0,
        'final_step': True,
        'reason': 'interrupted: stopped by a signal (SIGINT/SIGTERM)',
    }
    assert report['summary_json']['equal'] and all(check['ok'] for check in report['bag_checks'])
    assert (
        '**The run stopped early**: at t = 1 (step 123), before its horizon 10'
        in (run_dir / 'analysis' / 'analysis.md').read_text()
    )

    # A summary that does not end where the bag does is still a finding.
    data = json.loads((run_dir / 'summary.json').read_text())
    data['extra']['reached_time'] = 1.5
    (run_dir / 'summary.json').write_text(json.dumps(data))
    assert main(['analyze', str(run_dir), '--no-figures', '--quiet', '--out', str(tmp_path / 'second')]) == 1
    assert '| `extra.reached_time` | 1.0 | 1.5 |' in (tmp_path / 'second' / 'analysis.md').read_text()


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_an_interrupted_distributed_run_agrees_with_its_bag(
    tmp_path, monkeypatch, wait_for_stepping, long_run_scenario, capsys
):
    """SIGINT mid-run: the simulator sends a final Step at the instant it stopped and the samples up
    to it, counts the triggers whose command was on its way, and every process flushes what it
    published before the recorder closes the bag; then summary.json (messages_sent included) is
    exactly what the bag gives back."""
    import threading

    from formation_sim.cli import main
    from formation_sim.runtime.launch.orchestrate import FormationRun

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))
    run = FormationRun(
        long_run_scenario, out_dir=tmp_path / 'run', domain_id=69, progress=False, timeout=240.0
    )
    results = []
    worker = threading.Thread(target=lambda: results.append(run.run()), daemon=True)
    worker.start()
    wait_for_stepping(run)
    run.interrupt()
    worker.join(timeout=120.0)
    (result,) = results
    assert result.exit_status == 130 and result.message == 'interrupted'
    summary = json.loads(result.summary.read_text())
    assert summary['extra']['recording']['complete'], summary['extra']['recording']

    assert main(['analyze', str(result.out_dir), '--no-figures']) == 0, (
        result.out_dir / 'analysis' / 'analysis.md'
    ).read_text()
    err = capsys.readouterr().err
    reached = summary['extra']['reached_time']
    assert (
        f'the run stopped early at t = {reached:.6g}' in err
        and 'before its horizon 600: interrupted: ' in err
    )
    report = json.loads((result.out_dir / 'analysis' / 'analysis.json').read_text())
    assert report['summary_json']['equal'], report['summary_json']['differences']
    assert report['summary']['messages_sent'] == summary['messages_sent']
    assert report['run']['stopped']['time'] == reached < 600.0


def test_any_bytes_on_any_topic_of_a_bag_are_read_or_named_as_damaged():
    """Issue 28, property-based: a bag's message of any bytes on any topic `formation analyze`
    reads is taken, or refused with an error `_read` turns into a named problem of the bag; no
    other exception escapes (it would be a traceback)."""
    import struct

    from hypothesis import given, settings
    from hypothesis import strategies as st

    from formation_msgs_py.errors import MessageError
    from formation_sim.analysis.load import _Collected, _dispatch

    topics = [
        ('/agent_1/trigger_info/to_2', 'std_msgs/msg/Float64MultiArray'),
        ('/formation/state', 'std_msgs/msg/Float64MultiArray'),
        ('/formation/step', 'std_msgs/msg/Float64MultiArray'),
        ('/formation/status', 'std_msgs/msg/Float64MultiArray'),
        ('/formation/sensing_log', 'std_msgs/msg/String'),
        ('/formation/scenario', 'std_msgs/msg/String'),
        ('/formation/robots', 'std_msgs/msg/String'),
        ('/formation/agent_report', 'std_msgs/msg/String'),
        ('/agent_1/robot/odom', 'nav_msgs/msg/Odometry'),
        ('/agent_2/robot/cmd_vel', 'geometry_msgs/msg/Twist'),
    ]
    doubles = st.lists(
        st.one_of(st.floats(), st.sampled_from([math.nan, math.inf, 1e300, 1.0, 2.0, 3.0])), max_size=16
    )
    payloads = st.one_of(
        st.binary(max_size=96),
        doubles.map(
            lambda values: b'\x00\x01\x00\x00' + struct.pack(f'<II{len(values)}d', 0, len(values), *values)
        ),
    )

    @settings(max_examples=600, deadline=None)
    @given(st.sampled_from(topics), payloads)
    def feed(topic, rawdata):
        escaped = None
        try:
            _dispatch(_Collected(), topic[0], topic[1], rawdata, stamp_ns=0)
        except Exception as error:  # noqa: BLE001 - whatever escapes is what the test looks at
            escaped = error
        # MessageError, and what _read names as a message that does not decode.
        assert (
            escaped is None
            or type(escaped).__module__.startswith('rosbags')
            or isinstance(escaped, (MessageError, struct.error, IndexError, ValueError))
        ), repr(escaped)

    feed()


def test_analyze_never_writes_into_a_runs_bag_folder(paper_single_record, write_run_bag, tmp_path, capsys):
    """Issue 28: `formation analyze RUN --out RUN/bag` wrote its report into the bag's folder."""
    from formation_sim.cli import main

    bag = write_run_bag(paper_single_record, tmp_path / 'run' / 'bag')
    before = sorted(p.name for p in bag.iterdir())
    for out in (bag, bag / 'report'):
        assert main(['analyze', str(tmp_path / 'run'), '--out', str(out), '--quiet']) == 2
        assert 'the bag folder' in capsys.readouterr().err
    assert sorted(p.name for p in bag.iterdir()) == before


@pytest.mark.parametrize(
    ('realtime', 'last', 'extra', 'ok'),
    [
        (True, 0.0, 1, True),  # the wall clock: each agent's zero command as it leaves
        (True, 0.0, 0, True),  # an agent that left without its zero command
        (True, 0.3, 1, False),  # one command more, not a stop
        (True, 0.0, 2, False),
        (False, 0.0, 1, False),  # lock-step: no command outside a trigger
    ],
)
def test_one_command_per_trigger_counts_the_wall_clocks_final_zero_command(realtime, last, extra, ok):
    """Issue 28: a clean --real-time run exited 0 and `formation analyze` of it 1 ('one command per
    trigger', commands {1: 19, ...} for 18 triggers): on the wall clock every agent sends its
    plant a zero command as it leaves (PlantOutput.stop), which the check now expects."""
    from geometry_msgs.msg import Twist
    from rclpy.serialization import serialize_message

    from formation_sim.analysis.load import _Collected, _dispatch, _message_checks

    scenario = load_scenario('paper_single')
    trigger_times = {agent: [0.0, 0.5, 1.0] for agent in scenario.agent_ids}
    got = _Collected()
    for agent in scenario.agent_ids:
        for k in range(3 + extra):
            command = Twist()
            command.linear.x = last if k == 2 + extra else 0.1
            _dispatch(got, f'/agent_{agent}/cmd_vel', 'geometry_msgs/msg/Twist', serialize_message(command))
    (check,) = [
        c
        for c in _message_checks(got, scenario, trigger_times, stopped=False, horizon=1.0, realtime=realtime)
        if c.name == 'one command per trigger'
    ]
    assert check.ok == ok, check.detail
