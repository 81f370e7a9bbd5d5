"""Distributed runs (real processes, private ROS domains 110-119) against the in-process engine."""

from __future__ import annotations

import json
import math
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.runtime.launch.plan import LOG_DIR
from formation_sim.sim.engine import simulate

# Each run starts 4-5 ROS processes: one run at a time on this suite's worker.
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]

TOLERANCE = 1e-9


def _run(scenario, tmp_path: Path, *, domain_id: int, horizon: float, **options):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=domain_id,
        progress=False,
        timeout=240.0,
        **options,
    )
    return run.run()


def _assert_same_events(summary: dict, reference) -> None:
    for agent, times in reference.trigger_times.items():
        got = summary['trigger_times'][str(agent)]
        assert len(got) == len(times), (
            f'agent {agent}: {len(got)} events distributed, {len(times)} in process'
        )
        worst = max(abs(a - b) for a, b in zip(got, times))
        assert worst <= TOLERANCE, f'agent {agent}: triggering times differ by up to {worst}'
    assert summary['total_events'] == reference.total_events
    assert summary['messages_sent'] == reference.messages_sent
    assert summary['sensing_calls'] == reference.total_events


def _assert_agents_isolated(graph: dict, scenario) -> None:
    """No agent subscribes to ground truth or state, or uses another agent's sensing."""
    for i in scenario.agent_ids:
        node = graph[f'/agent_{i}/formation_agent']
        allowed = {'/formation/step'} | {f'/agent_{j}/trigger_info/to_{i}' for j in scenario.neighbours(i)}
        assert set(node['subscriptions']) == allowed, f'agent {i} subscribes to {node["subscriptions"]}'
        assert node['clients'] == [f'/agent_{i}/sense'], f'agent {i} has clients {node["clients"]}'
        for forbidden in ('/formation/state', '/formation/ground_truth', '/formation/sensing_log', '/clock'):
            assert forbidden not in node['subscriptions']


@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    ('name', 'horizon', 'domain_id'), [('paper_single', 10.0, 110), ('paper_double', 8.0, 111)]
)
def test_lockstep_run_reproduces_the_in_process_engine(
    tmp_path, name, horizon, domain_id, bag_trigger_stamps
):
    scenario = load_scenario(name)
    reference = simulate(scenario, horizon=horizon)
    result = _run(scenario, tmp_path, domain_id=domain_id, horizon=horizon)
    assert result.ok, result.message
    assert result.domain_id == domain_id
    summary = json.loads(result.summary.read_text())
    assert summary['mode'] == 'distributed'
    _assert_same_events(summary, reference)
    # summary.json through its type (issue 29): read and written again, the same bytes.
    from formation_sim.sim.summary import RunSummary

    typed = RunSummary.read(result.summary)
    assert typed.to_dict() == summary and typed.started and typed.failure is None
    assert typed.write(tmp_path / 'again.json').read_bytes() == result.summary.read_bytes()

    # The bag: every topic of the run, one TriggerInfo per trigger and neighbour, stamped with
    # the sender's triggering times.
    from formation_sim.runtime.contract import formation_topics

    counts, stamps = bag_trigger_stamps(result.bag)
    assert set(counts) == {topic for topic, _ in formation_topics(scenario)}
    for i in scenario.agent_ids:
        for j in scenario.neighbours(i):
            sent = stamps[(i, j)]
            assert len(sent) == len(reference.trigger_times[i]), f'edge {i}->{j}'
            assert max(abs(a - b) for a, b in zip(sent, reference.trigger_times[i])) <= TOLERANCE
    assert counts['/formation/sensing_log'] == reference.total_events
    command = 'cmd_accel' if scenario.dynamics == 'double' else 'cmd_vel'
    for i in scenario.agent_ids:
        assert counts[f'/agent_{i}/{command}'] == len(reference.trigger_times[i])

    _assert_agents_isolated(json.loads((result.out_dir / 'graph.json').read_text()), scenario)
    _assert_children_left_cleanly(result)
    _assert_timeline(summary, result)


def _assert_children_left_cleanly(result) -> None:
    """Every child exited 0 by itself, or left the run with 0 before its ROS teardown hung in C code
    (rclpy's destroy_node, cut short: `ChildExit.left_with`); one that did not is named with its
    log's end (its stacks, if it was stuck: `Supervisor.ask_for_stacks`)."""
    unclean = [child for child in result.children if child.returncode != 0 and child.left_with != 0]
    tails = [
        f'{child}:\n' + '\n'.join(_log_lines(result.out_dir / LOG_DIR / f'{child.name}.log')[-60:])
        for child in unclean
    ]
    assert not unclean, '\n\n'.join(tails)


def _log_lines(path: Path) -> list[str]:
    return path.read_text(errors='replace').splitlines() if path.exists() else [f'(no log at {path})']


def _assert_timeline(summary: dict, result) -> None:
    """Where the run's time went: every mark in the order the run reaches them, and the phases
    adding up to them; stepping is the simulator's own stepping time."""
    timeline, phases = summary['extra']['timeline'], summary['extra']['phases']
    order = [
        'run',
        'spawned',
        'node_created',
        'node_up',
        'agents_ready',
        'step0',
        'final_step',
        'final_reports',
        'delivered',
        'keeper_exited',
        'stopped',
        'checked',
    ]
    assert [mark for mark in timeline if mark in order] == order, timeline
    assert timeline['agents_announced'] <= timeline['agents_ready']
    assert all(timeline[a] <= timeline[b] for a, b in zip(order, order[1:])), timeline
    assert phases['start'] == timeline['step0']
    assert phases['stepping'] == pytest.approx(summary['wall_time'], abs=1e-6)
    assert phases['start'] + phases['stepping'] + phases['end'] == pytest.approx(timeline['checked'])
    assert timeline['checked'] < result.wall_time


@pytest.mark.timeout(300)
def test_agents_packed_in_one_process_give_the_same_run(tmp_path):
    # Also the fallback executor (rclpy's SingleThreadedExecutor) in every process.
    scenario = load_scenario('paper_single')
    horizon = 3.0
    reference = simulate(scenario, horizon=horizon)
    result = _run(
        scenario,
        tmp_path,
        domain_id=112,
        horizon=horizon,
        agents_per_process=3,
        record=False,
        executor='single',
    )
    assert result.ok, result.message
    assert result.bag is None
    assert [child.name for child in result.children] == ['simulator', 'agents_1-3']
    _assert_same_events(json.loads(result.summary.read_text()), reference)


@pytest.mark.timeout(300)
def test_a_run_discovering_through_a_discovery_server_equals_the_engine(tmp_path):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario('paper_single')
    horizon = 3.0
    reference = simulate(scenario, horizon=horizon)
    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=118,
        progress=False,
        timeout=240.0,
        discovery='server',
    )
    result = run.run()
    assert result.ok, result.message
    assert [child.name for child in result.children] == [
        'discovery_server',
        'recorder',
        'simulator',
        'agent_1',
        'agent_2',
        'agent_3',
    ]
    _assert_same_events(json.loads(result.summary.read_text()), reference)
    # Every child was a client of the run's server, which served on that port.
    port = run.plan.discovery_port
    assert run._supervisor.env['ROS_DISCOVERY_SERVER'] == f'127.0.0.1:{port}'
    assert (
        f'Server Addresses:   UDPv4:[127.0.0.1]:{port}'
        in (result.out_dir / 'logs' / 'discovery_server.log').read_text()
    )
    # The ROS graph is whole all the same (every node saw every other through the server).
    graph = json.loads((result.out_dir / 'graph.json').read_text())
    assert set(graph) == {
        '/formation_simulator',
        '/formation_recorder',
        *(f'/agent_{i}/formation_agent' for i in scenario.agent_ids),
    }
    _assert_agents_isolated(graph, scenario)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie is dead but not yet reaped by its parent.
    try:
        return Path(f'/proc/{pid}/stat').read_text().split()[2] != 'Z'
    except OSError:
        return False


@pytest.mark.timeout(300)
def test_interrupt_stops_every_child_and_leaves_a_readable_bag(tmp_path, stepping_run, long_run_scenario):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        long_run_scenario, out_dir=tmp_path / 'run', domain_id=113, progress=False, timeout=240.0
    )
    stepping = stepping_run(run)
    run.interrupt()
    result = stepping.result(timeout=60.0)
    assert result.exit_status == 130 and result.message == 'interrupted'
    assert result.bag is not None  # the recorder was stopped by SIGINT and closed its bag
    assert not [child for child in result.children if _alive(child.pid)]
    # The simulator wrote what happened up to the interruption.
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'interrupted' and result.failure == failure
    assert 0.0 < summary['extra']['reached_time'] == failure['time'] < run.options.horizon
    assert summary['total_events'] > 0


@pytest.mark.timeout(300)
def test_a_dead_agent_ends_the_run_and_its_peers(tmp_path, stepping_run, long_run_scenario, shm_files):
    import signal

    from formation_sim.runtime.launch.fastdds_shm import held_files
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        long_run_scenario,
        out_dir=tmp_path / 'run',
        domain_id=114,
        progress=False,
        record=False,
        timeout=240.0,
    )
    stepping = stepping_run(run)
    victim = next(child for child in run._children if child.name == 'agent_2')
    leftovers = shm_files(held_files(victim.pid))
    os.kill(victim.pid, signal.SIGKILL)
    result = stepping.result(timeout=60.0)
    # What the victim could not remove, the orchestrator did (unless another process still uses it).
    assert not leftovers.left()
    assert result.exit_status == 3
    assert f'agent_2 (pid {victim.pid}) killed by SIGKILL' in result.message
    assert 'agent 2 lost at t=' in result.message
    assert not [child for child in result.children if _alive(child.pid)]


GENTLE = """\
name: gentle_single
dynamics: single
communication_radius: 4.0
horizon: 4.0
agents:
  1: {position: [0.0, 0.0]}
  2: {position: [0.3, -2.2]}
  3: {position: [-2.1, 0.2]}
edges:
  - {i: 1, j: 2, d: [0.0, 2.0]}
  - {i: 1, j: 3, d: [2.0, 0.0]}
  - {i: 2, j: 3, d: [2.0, -2.0]}
gains: {alpha: 0.5, beta: 0.3}
"""


@pytest.mark.timeout(300)
def test_wall_clock_run_triggers_on_agents_own_timers_and_keeps_the_formation(tmp_path):
    """Wall clock: events depend on delays, but each agent triggers in order and the run completes."""
    path = tmp_path / 'gentle.yaml'
    path.write_text(GENTLE)
    scenario = load_scenario(path)
    result = _run(path, tmp_path, domain_id=115, horizon=scenario.horizon, record=False, clock='realtime')
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    assert summary['extra']['clock'] == 'realtime'
    for agent in scenario.agent_ids:
        times = summary['trigger_times'][str(agent)]
        assert times and 0.0 <= times[0] < scenario.horizon
        assert all(a < b for a, b in zip(times, times[1:])), f'agent {agent}: {times}'
    assert set(summary['extra']['lateness']) == {str(agent) for agent in scenario.agent_ids}
    # Delays of milliseconds do not break this formation: connectivity is kept and the error shrinks.
    assert summary['max_edge_length'] < scenario.delta
    initial_error = max(
        float(
            np.linalg.norm(
                scenario.positions[scenario.index(e.i)] - scenario.positions[scenario.index(e.j)] - e.d
            )
        )
        for e in scenario.edges
    )
    assert summary['final_formation_error'] < initial_error


# Run the rest of the command line with SIGINT and SIGTERM blocked.
_DEAF_EXEC = (
    'import os, signal, sys; signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM}); '
    'os.execv(sys.argv[1], sys.argv[1:])'
)


@pytest.mark.timeout(300)
def test_children_killed_hard_leave_no_shared_memory_files(
    tmp_path, stepping_run, long_run_scenario, shm_files
):
    from formation_sim.runtime.launch.fastdds_shm import held_files
    from formation_sim.runtime.launch.orchestrate import FormationRun

    # No grace period: every child still alive right after SIGINT is killed by SIGTERM or SIGKILL.
    # The simulator blocks SIGINT and SIGTERM (a mask exec keeps): it neither stops nor ends the
    # run, so SIGKILL is what ends it, however late the stop comes on a loaded machine (its agents
    # may have left by then, on SIGINT).
    run = FormationRun(
        long_run_scenario,
        out_dir=tmp_path / 'run',
        domain_id=117,
        progress=False,
        record=False,
        timeout=240.0,
        stop_timeouts=(0.0, 0.0),
        launch_prefix=lambda name: [sys.executable, '-c', _DEAF_EXEC] if name == 'simulator' else [],
    )
    stepping = stepping_run(run)
    held = shm_files(set().union(*(held_files(child.pid) for child in run._children)))
    run.interrupt()
    result = stepping.result(timeout=60.0)
    assert result.exit_status == 130
    killed = [
        child for child in run._children if child.process.returncode in (-signal.SIGTERM, -signal.SIGKILL)
    ]
    assert 'simulator' in [child.name for child in killed], [c.process.returncode for c in run._children]
    files = set().union(*(child.shm_files for child in killed))
    assert files, 'the killed children mapped no Fast DDS shared-memory file'
    assert not held.left()
    assert not [child for child in result.children if _alive(child.pid)]


@pytest.mark.timeout(300)
def test_lockstep_run_takes_same_instant_rounds_and_stops_where_the_engine_stops(tmp_path):
    # paper_single to t = 200: the engine stops where the threshold reaches the rounding of the
    # states (after an instant with a second round of triggers); the distributed run must take the
    # same rounds and stop at the same event with the same message.
    from formation_sim.sim.errors import EngineError

    scenario = load_scenario('paper_single')
    with pytest.raises(EngineError) as stop:
        simulate(scenario, horizon=200.0, sample_dt=None)
    result = _run(scenario, tmp_path, domain_id=116, horizon=200.0, record=False)
    assert not result.ok
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['message'] == str(stop.value)
    reference = simulate(scenario, horizon=math.nextafter(failure['time'], 0.0), sample_dt=None)
    _assert_same_events(summary, reference)
    instants = [t for times in reference.trigger_times.values() for t in times if t > 0.0]
    assert len(instants) > len(set(instants)), 'no second round at one instant before the stop'
