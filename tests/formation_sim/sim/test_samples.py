"""Sample stores: streamed trajectories equal the in-memory record exactly, are plain .npy files,
are never left cut short under their final name, and the summary's edge maxima are the norms'."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from formation_sim.model.generate import random_scenario
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.errors import EngineError, TrajectoryError
from formation_sim.sim.samples import (
    INCOMPLETE_DIR,
    TRAJECTORY_DIR,
    EdgeLengths,
    edge_maxima,
    header_shape,
    load_trajectory,
    write_trajectory,
)
from formation_sim.sim.summary import build_summary, load_record, write_summary


def _norm_maxima(scenario, positions):
    """Per edge, the largest np.linalg.norm of x_i - x_j over the rows: the summary's formula before
    streaming."""
    index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
    return np.array(
        [
            np.linalg.norm(positions[:, index[e.i]] - positions[:, index[e.j]], axis=1).max()
            for e in scenario.edges
        ]
    )


@pytest.mark.parametrize(
    ('dynamics', 'dimension', 'horizon'),
    [('single', 2, 2.0), ('double', 2, 0.2), ('single', 3, 1.0), ('double', 1, 0.2)],
    ids=['single-2d', 'double-2d', 'single-3d', 'double-1d'],
)
def test_a_streamed_run_equals_the_in_memory_run_bit_for_bit(tmp_path, dynamics, dimension, horizon):
    scenario = random_scenario(n=12, seed=3, dynamics=dynamics, dimension=dimension)
    memory = simulate(scenario, horizon=horizon)
    streamed = simulate(scenario, horizon=horizon, trajectory_dir=tmp_path)
    assert streamed.trigger_times == memory.trigger_times and memory.total_events > 12
    assert streamed.samples.path == tmp_path / TRAJECTORY_DIR and not (tmp_path / INCOMPLETE_DIR).exists()
    assert isinstance(streamed.sample_positions, np.memmap)  # read back lazily, not held in memory
    assert np.array_equal(streamed.sample_times, memory.sample_times)
    assert np.array_equal(streamed.sample_positions, memory.sample_positions)
    if dynamics == 'double':
        assert np.array_equal(streamed.sample_velocities, memory.sample_velocities)
    else:
        assert streamed.sample_velocities is None
    first, second = build_summary(memory), build_summary(streamed)
    first.pop('wall_time'), second.pop('wall_time')
    assert first == second


def test_the_trajectory_is_plain_npy_files_that_numpy_reads_alone(tmp_path):
    scenario = load_scenario('paper_double')
    record = simulate(scenario, horizon=1.0, trajectory_dir=tmp_path)
    folder = tmp_path / TRAJECTORY_DIR
    assert sorted(path.name for path in folder.iterdir()) == [
        'agent_ids.npy',
        'positions.npy',
        'times.npy',
        'velocities.npy',
    ]
    times = np.load(folder / 'times.npy')
    positions = np.load(folder / 'positions.npy', mmap_mode='r')
    assert np.load(folder / 'agent_ids.npy').tolist() == [1, 2, 3]
    assert positions.shape == (len(times), 3, 2) == np.load(folder / 'velocities.npy').shape
    assert positions.dtype == np.dtype('<f8') and positions.offset % 64 == 0  # aligned data after the header
    assert times[0] == 0.0 and times[-1] == 1.0 and np.all(np.diff(times) > 0)
    assert np.array_equal(positions[0], scenario.positions) and np.array_equal(
        positions[-1], record.sample_positions[-1]
    )


def test_write_summary_of_an_in_memory_record_writes_a_trajectory_that_reads_back_exactly(
    tmp_path, paper_single_record
):
    write_summary(paper_single_record, tmp_path)
    rebuilt = load_record(tmp_path, paper_single_record.scenario)
    assert rebuilt.samples.path == tmp_path / TRAJECTORY_DIR
    for name in ('sample_times', 'sample_positions'):
        assert np.array_equal(getattr(rebuilt, name), getattr(paper_single_record, name))
    assert rebuilt.trigger_times == paper_single_record.trigger_times
    write_summary(paper_single_record, tmp_path)  # again into the same folder: replaced, not mixed
    assert sorted(path.name for path in tmp_path.iterdir()) == ['summary.json', TRAJECTORY_DIR]


def test_a_run_that_fails_leaves_its_samples_named_incomplete_and_readers_refuse_them(tmp_path):
    scenario = load_scenario('paper_single')
    with pytest.raises(EngineError, match='rounding, not the dynamics'):
        simulate(scenario, horizon=200.0, trajectory_dir=tmp_path)  # stops at t ≈ 34.4
    assert not (tmp_path / TRAJECTORY_DIR).exists()
    assert header_shape(tmp_path / INCOMPLETE_DIR / 'positions.npy') == (0, 3, 2)  # numpy reads it as empty
    with pytest.raises(
        TrajectoryError, match=f'{INCOMPLETE_DIR}: the run stopped before its trajectory was complete'
    ):
        load_trajectory(tmp_path)


@pytest.mark.timeout(120)
def test_a_run_killed_mid_way_leaves_no_trajectory_under_the_final_name(tmp_path):
    """SIGKILL while the samples stream: what is on disk is `trajectory.incomplete/`, never a cut
    `trajectory/`."""
    marker = tmp_path / 'midway'
    code = textwrap.dedent(f"""
        import pathlib, time
        from formation_sim.model.generate import random_scenario
        from formation_sim.sim.engine import simulate
        events = 0
        def hold(t, world, due):
            global events
            events += 1
            if events == 300:
                pathlib.Path({str(marker)!r}).write_text('at 300 events')
                time.sleep(600)
        simulate(random_scenario(n=30, seed=2), horizon=5.0, sample_dt=0.001,
                 trajectory_dir={str(tmp_path)!r}, on_event=hold)
    """)
    process = subprocess.Popen([sys.executable, '-c', code])
    try:
        deadline = time.monotonic() + 100
        while not marker.exists():
            assert process.poll() is None and time.monotonic() < deadline, 'the run never got half way'
            time.sleep(0.05)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.kill()
        process.wait()
    assert not (tmp_path / TRAJECTORY_DIR).exists()
    partial = tmp_path / INCOMPLETE_DIR / 'positions.npy'
    assert header_shape(partial) == (0, 30, 2)
    assert np.load(partial).shape == (0, 30, 2)  # a plain reader sees nothing, never a wrong array
    with pytest.raises(TrajectoryError, match='incomplete'):
        load_trajectory(tmp_path)


def test_a_trajectory_cut_short_afterwards_is_refused_naming_the_file(tmp_path):
    simulate(load_scenario('paper_single'), horizon=1.0, trajectory_dir=tmp_path)
    positions = tmp_path / TRAJECTORY_DIR / 'positions.npy'
    with positions.open('r+b') as handle:
        handle.truncate(positions.stat().st_size - 100)
    with pytest.raises(TrajectoryError, match=f'{positions}: cannot be read as a trajectory array'):
        load_trajectory(tmp_path)
    (tmp_path / TRAJECTORY_DIR / 'times.npy').unlink()
    with pytest.raises(TrajectoryError, match=f'{tmp_path / TRAJECTORY_DIR / "times.npy"}: missing'):
        load_trajectory(tmp_path)


def test_a_run_written_before_the_trajectory_folder_is_still_read(tmp_path, paper_single_record):
    record = paper_single_record
    # The layout formation simulate wrote before (np.savez_compressed, trajectory.npz).
    np.savez_compressed(
        tmp_path / 'trajectory.npz',
        agent_ids=np.array(record.scenario.agent_ids),
        times=record.sample_times,
        positions=record.sample_positions,
    )
    samples = load_trajectory(tmp_path)
    assert samples.path is None and samples.velocities is None
    assert np.array_equal(samples.times, record.sample_times) and np.array_equal(
        samples.positions, record.sample_positions
    )
    assert load_trajectory(tmp_path / 'nothing here') is None


@pytest.mark.parametrize('dimension', [1, 2, 3, 9])
def test_edge_maxima_are_the_norms_maxima_in_memory_and_on_disk(tmp_path, dimension):
    # 9 components: numpy's norm sums them pairwise, not left to right, and so must the summary.
    scenario = random_scenario(n=15, seed=dimension, dimension=dimension)
    record = simulate(scenario, horizon=0.5)
    expected = _norm_maxima(scenario, record.sample_positions)
    assert np.array_equal(edge_maxima(scenario, record.samples), expected)
    on_disk = write_trajectory(record.samples, tmp_path, agent_ids=scenario.agent_ids)
    assert np.array_equal(edge_maxima(scenario, on_disk), expected)
    tiny_blocks = [positions for positions, _ in on_disk.blocks(values=2 * scenario.n * dimension + 1)]
    assert len(tiny_blocks) == -(-len(record.sample_times) // 2)  # two rows a block, read from the file
    assert np.array_equal(np.concatenate(tiny_blocks), record.sample_positions)


@pytest.mark.parametrize('name', ['paper_single', 'random'])
def test_without_event_samples_the_edge_maxima_still_cover_every_trigger(name):
    # Single integrators: an edge's length is convex between its agents' triggers, so its maximum
    # is at t = 0, the horizon or one of those triggers: the lean record must find the maximum of
    # the record that samples every event, and more than its own grid shows.
    scenario = load_scenario('paper_single') if name == 'paper_single' else random_scenario(n=40, seed=5)
    full = simulate(scenario, horizon=3.0, sample_dt=None)  # every event time, no grid
    lean = simulate(scenario, horizon=3.0, sample_dt=0.25, sample_events=False)
    exact = _norm_maxima(scenario, full.sample_positions)
    grid_only = _norm_maxima(scenario, lean.sample_positions)
    found = edge_maxima(scenario, lean.samples)
    assert np.allclose(found, exact, rtol=4e-16, atol=0.0)  # the same up to the rounding of the states
    assert np.any(found > grid_only)  # the grid alone misses maxima
    assert lean.extra['samples'] == 'grid' and full.extra['samples'] == 'events'
    summary = build_summary(lean)
    assert [edge['max_length'] for edge in summary['edges']] == found.tolist()


def test_edge_lengths_of_some_agents_touch_only_their_edges():
    scenario = load_scenario('paper_single')  # edges (1, 2), (1, 3), (2, 3)
    lengths = EdgeLengths(scenario)
    assert lengths.edges_of([0]).tolist() == [0, 1] and lengths.edges_of([2]).tolist() == [1, 2]
    edges = lengths.edges_of([1])
    x = scenario.positions
    lengths.add_edges(edges, x[lengths.heads[edges]], x[lengths.tails[edges]])
    expected = [np.linalg.norm(x[0] - x[1]), 0.0, np.linalg.norm(x[1] - x[2])]
    assert lengths.maxima.tolist() == expected


def test_a_summary_with_non_finite_values_is_written_as_strict_json_naming_each(tmp_path):
    """Issue 28: `formation run` died writing summary.json ('Out of range float values are not JSON
    compliant: nan') after NaN poses; every such value is null now, and named with what it was."""
    import json

    from formation_sim.sim.summary import RunSummary, write_summary_file

    run = dict(scenario='s', dynamics='single', mode='distributed', horizon=1.0, n_agents=1, dimension=2)
    summary = RunSummary(
        **run,
        delta=4.0,
        wall_time=0.5,
        extra={'failure': None},
        trigger_times={'1': [0.0]},
        event_counts={'1': 1},
        total_events=1,
        min_inter_event_time={'1': None},
        messages_sent=0,
        sensing_calls=0,
        edges=[{'max_length': 2.0}, {'max_length': np.float64('inf')}],
        max_edge_length=float('nan'),
        final_formation_error=0.0,
        final_positions={'1': (1.0, -np.inf)},
        final_velocities=None,
        theorem_constants={},
        xi_check={},
    )
    path = write_summary_file(summary, tmp_path / 'summary.json')
    text = path.read_text()
    data = json.loads(text, parse_constant=lambda name: pytest.fail(f'{name} in summary.json'))
    assert data['max_edge_length'] is None and data['edges'][1]['max_length'] is None
    assert data['edges'][0]['max_length'] == 2.0 and data['final_positions'] == {'1': [1.0, None]}
    assert data['extra'] == {
        'failure': None,
        'non_finite': {
            'max_edge_length': 'nan',
            'edges[1].max_length': 'inf',
            'final_positions.1[1]': '-inf',
        },
    }
    # A finite summary is written as it is, with no such entry.
    clean = RunSummary(**run, delta=1.5, wall_time=None, extra={})
    write_summary_file(clean, tmp_path / 'clean.json')
    assert json.loads((tmp_path / 'clean.json').read_text()) == clean.to_dict()
    assert clean.to_dict()['delta'] == 1.5 and 'non_finite' not in clean.extra
