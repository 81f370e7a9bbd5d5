"""formation_sim.analysis.compare and `formation compare`: two runs side by side."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from formation_sim.analysis.compare import (
    RunData,
    compare_runs,
    compare_trajectories,
    compare_triggers,
    interpolate,
    load_run,
    overlay_figures,
    within,
)
from formation_sim.analysis.errors import CompareError
from formation_sim.sim.engine import simulate
from formation_sim.sim.summary import write_summary


def _run_data(label: str, trigger_times: dict, times=None, positions=None, agent_ids=(1, 2)) -> RunData:
    return RunData(
        label=label,
        source='test',
        scenario='s',
        dynamics='single',
        mode='in_process',
        horizon=1.0,
        agent_ids=agent_ids,
        edges=[(1, 2, np.array([1.0]))],
        trigger_times=trigger_times,
        messages_sent=sum(len(t) for t in trigger_times.values()),
        sensing_calls=sum(len(t) for t in trigger_times.values()),
        times=None if times is None else np.asarray(times, dtype=float),
        positions=None if positions is None else np.asarray(positions, dtype=float),
    )


def test_triggers_are_matched_index_by_index_and_count_mismatches_named():
    a = _run_data('A', {1: [0.0, 0.25, 0.5], 2: [0.0, 0.3]})
    b = _run_data('B', {1: [0.0, 0.25, 0.5], 2: [0.0, 0.3125, 0.7, 0.9]})
    one, two = compare_triggers(a, b)
    assert (one.count_a, one.count_b, one.compared, one.max_deviation, one.first_difference) == (
        3,
        3,
        3,
        0.0,
        None,
    )
    assert (two.count_a, two.count_b, two.compared, two.first_difference) == (2, 4, 2, 1)
    assert two.max_deviation == 0.3125 - 0.3
    report = compare_runs(a, b)
    assert report['events_equal'] is False
    assert report['count_mismatches'] == ['agent 2: 2 events in A, 4 in B (compared the first 2)']
    assert report['max_trigger_deviation'] == 0.3125 - 0.3
    assert not within(report, 1.0)  # counts differ, whatever the tolerance


def test_trajectories_are_compared_on_the_union_of_sample_times():
    # A samples at 0, 0.5, 1; B at 0, 0.25, 0.75, 1; both move on straight lines, B 0.1 ahead in x.
    def line(t, shift):
        return np.stack([np.stack([t + shift, 0 * t], axis=1), np.stack([2 * t, 1 + 0 * t], axis=1)], axis=1)

    ta, tb = np.array([0.0, 0.5, 1.0]), np.array([0.0, 0.25, 0.75, 1.0])
    a = _run_data('A', {1: [0.0], 2: [0.0]}, ta, line(ta, 0.0))
    b = _run_data('B', {1: [0.0], 2: [0.0]}, tb, line(tb, 0.1))
    deviation = compare_trajectories(a, b)
    assert deviation.times.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert np.allclose(deviation.deviation, 0.1, rtol=0.0, atol=1e-15)  # linear paths: interpolation is exact
    assert deviation.per_agent[2] == 0.0
    assert np.array_equal(interpolate(ta, line(ta, 0.0), np.array([0.25]))[0], [[0.25, 0.0], [0.5, 1.0]])


def test_runs_of_different_agents_cannot_be_compared():
    a = _run_data('A', {1: [0.0], 2: [0.0]})
    b = _run_data('B', {1: [0.0], 3: [0.0]}, agent_ids=(1, 3))
    with pytest.raises(CompareError, match=r'different agents: A \[1, 2\], B \[1, 3\]'):
        compare_runs(a, b)


def test_identical_in_process_runs_agree_exactly(paper_single_record, tmp_path):
    write_summary(paper_single_record, tmp_path / 'a')
    write_summary(simulate(paper_single_record.scenario, horizon=paper_single_record.horizon), tmp_path / 'b')
    a = load_run(tmp_path / 'a', label='first')
    b = load_run(tmp_path / 'b' / 'summary.json', label='second')
    assert a.source.endswith('+ trajectory/')
    report = compare_runs(a, b)
    assert report['events_equal'] and report['max_trigger_deviation'] == 0.0
    assert report['trajectory']['max_deviation'] == 0.0
    assert within(report, 0.0)


def test_event_triggered_against_periodic_sampling(paper_single_record, tmp_path):
    period = 0.002
    periodic = simulate(paper_single_record.scenario, horizon=paper_single_record.horizon, period=period)
    write_summary(paper_single_record, tmp_path / 'eta')
    write_summary(periodic, tmp_path / 'periodic')
    a = load_run(tmp_path / 'eta', label='ETA-1')
    b = load_run(tmp_path / 'periodic', label='periodic')
    report = compare_runs(a, b)
    assert report['runs']['b']['period'] == period
    assert report['runs']['b']['messages_sent'] == periodic.messages_sent
    expected = [
        f'agent {agent}: {len(paper_single_record.trigger_times[agent])} events in A, '
        f'{len(periodic.trigger_times[agent])} in B '
        f'(compared the first {len(paper_single_record.trigger_times[agent])})'
        for agent in (1, 2, 3)
    ]
    assert report['count_mismatches'] == expected
    figures = overlay_figures(a, b, tmp_path / 'figures')
    name, events = figures['triggering times']
    assert (tmp_path / 'figures' / name).is_file()
    for agent in (1, 2, 3):  # the raster holds exactly both runs' events
        assert list(events[('a', agent)].get_positions()) == paper_single_record.trigger_times[agent]
        assert list(events[('b', agent)].get_positions()) == periodic.trigger_times[agent]
    _, lines = figures['trajectories']
    assert np.array_equal(lines[('b', 3)].get_xydata()[-1], periodic.sample_positions[-1, 2])


def test_a_summary_without_trajectory_compares_events_only(paper_single_record, tmp_path):
    write_summary(paper_single_record, tmp_path / 'a')
    shutil.rmtree(tmp_path / 'a' / 'trajectory')
    run = load_run(tmp_path / 'a', label='A')
    assert run.times is None
    report = compare_runs(run, run)
    assert report['trajectory'] is None and report['events_equal']


# ------------------------------------------------------------------------------------- ROS


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_distributed_run_against_the_in_process_engine(distributed_single_run, tmp_path, capsys):
    from formation_sim.cli import main

    run = distributed_single_run
    out = tmp_path / 'compare'
    code = main(
        [
            'compare',
            str(run.out_dir),
            str(run.reference_dir),
            '--out',
            str(out),
            '--tolerance',
            '1e-9',
            '--quiet',
        ]
    )
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / 'compare.json').read_text())
    assert report['runs']['a']['source'].startswith('bag ')  # the distributed side comes from its bag
    assert report['runs']['a']['mode'] == 'distributed' and report['runs']['b']['mode'] == 'in_process'
    assert report['events_equal'] and report['count_mismatches'] == []
    assert report['max_trigger_deviation'] < 1e-9  # ETA-1: the lock-step reproduces the engine
    assert report['trajectory']['max_deviation'] < 1e-9
    assert (
        report['runs']['a']['messages_sent']
        == report['runs']['b']['messages_sent']
        == run.reference.messages_sent
    )
    for name in ('overlay_trajectories.png', 'overlay_triggers.png', 'overlay_deviation.png'):
        assert (out / name).stat().st_size > 1000
