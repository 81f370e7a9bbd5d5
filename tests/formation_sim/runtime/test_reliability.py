"""Faults a robot team meets: bad messages, dead processes, signals, lossy links, shared networks.

Real processes in private ROS domains 60-79 (each test its own). Every run starts 2-5 processes;
the tests share the distributed tests' xdist group, so one run at a time on its worker.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from formation_msgs_py.exit_codes import ExitCode
from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group('formation_distributed')]

ROOT = Path(__file__).resolve().parents[3]
GENTLE = ROOT / 'benchmarks' / 'gentle_square.yaml'
TOLERANCE = 1e-9


# -- helpers ----------------------------------------------------------------------------------


def _assert_same_events(summary: dict, reference) -> None:
    for agent, times in reference.trigger_times.items():
        got = summary['trigger_times'][str(agent)]
        assert len(got) == len(times), (
            f'agent {agent}: {len(got)} events distributed, {len(times)} in process'
        )
        assert max(abs(a - b) for a, b in zip(got, times)) <= TOLERANCE, f'agent {agent}'
    assert summary['total_events'] == reference.total_events
    assert summary['messages_sent'] == reference.messages_sent


def _in_background(run):
    results: list = []
    worker = threading.Thread(target=lambda: results.append(run.run()), daemon=True)
    worker.start()
    return worker, results


def _processes_mentioning(text: str) -> list[int]:
    """Live (not zombie) processes whose command line contains `text`."""
    found = []
    for proc in Path('/proc').iterdir():
        if not proc.name.isdigit() or int(proc.name) == os.getpid():
            continue
        try:
            cmdline = (proc / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
            state = (proc / 'stat').read_text().rsplit(')', 1)[1].split()[0]
        except OSError:
            continue
        if text in cmdline and state != 'Z':
            found.append(int(proc.name))
    return found


def _wait_until_gone(text: str, limit: float = 30.0) -> list[int]:
    deadline = time.monotonic() + limit
    while (left := _processes_mentioning(text)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return left


@dataclass
class _Outsider:
    """A node outside a run, writing on agent 2's triggering-information topic to agent 1."""

    publisher: object
    executor: object
    node: object
    worker: threading.Thread
    results: list
    steps: list[int]  # the indices of the Steps it heard


@contextlib.contextmanager
def _outsider_with_run(name: str, domain_id: int, run):
    """Start `run` (made with step_listeners=1) in the background beside an outside node.

    A node that joins a running domain can take seconds to be discovered, longer than a short
    run: step 0 waits for the node's Step reader, which is made only once agent 1 and the
    recorder read the node's topic. The run is over when the block ends.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.codec import decode_step
    from formation_msgs_py.qos import PROTOCOL_QOS, READER_QOS
    from formation_msgs_py.topics import STEP_TOPIC, trigger_info_topic

    assert run.options.step_listeners == 1
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node(name, context=context)
    try:
        publisher = node.create_publisher(Float64MultiArray, trigger_info_topic(2, 1), PROTOCOL_QOS)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        worker, results = _in_background(run)
        deadline = time.monotonic() + 120.0
        while publisher.get_subscription_count() < 2 and worker.is_alive() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.02)
        steps: list[int] = []
        # Keep-all, as every reader of the protocol: a keep-last 32 history lost Steps 0-4 while
        # this busy test process did not take them for a moment.
        node.create_subscription(
            Float64MultiArray, STEP_TOPIC, lambda msg: steps.append(decode_step(msg).index), READER_QOS
        )
        yield _Outsider(
            publisher=publisher, executor=executor, node=node, worker=worker, results=results, steps=steps
        )
        worker.join()
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.fixture
def ros_env(tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_LOG_DIR', str(tmp_path / 'ros_log'))


# -- bad messages -------------------------------------------------------------------------------


@pytest.mark.timeout(300)
def test_bad_messages_mid_run_are_rejected_counted_and_change_nothing(tmp_path, ros_env):
    """Malformed and implausible triggering information on agent 1's topic from agent 2, injected
    while the lock-step run goes on (through a 2 ms injected delay): the run still equals the
    in-process engine, and summary.json counts each rejection under its reason."""
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.codec import encode_trigger_info, tag_array
    from formation_msgs_py.tags import KEY_FILE, Signer, read_key
    from formation_msgs_py.topics import trigger_info_topic
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.runtime.launch.orchestrate import FormationRun

    domain_id = 70
    scenario = load_scenario('paper_single')
    horizon = 2.0
    reference = simulate(scenario, horizon=horizon)
    # Inject once every agent has received agent 2's second trigger (all steps before a step
    # are settled when it is published): a stamp of 0 is then going backwards for sure.
    events = sorted({t for times in reference.trigger_times.values() for t in times})
    inject_at = events.index(reference.trigger_times[2][1]) + 1
    assert inject_at < len(events) - 10

    def raw(values):
        return Float64MultiArray(data=[float(v) for v in values])

    def info(**fields):
        values = {
            'sender': 2,
            'receiver': 1,
            'stamp': 0.0,
            'control': (0.5, -0.5),
            'rel_position': (1.0, 2.0),
        }
        return encode_trigger_info(TriggerInfo(**{**values, **fields}))

    bad = [
        (raw([2, 1, 2, 1, 1.0, 2, 0.5, -0.5, 1.0, 2.0]), 'version'),
        (raw([1, 1, 2, 1, 1.0, 2, 0.5, -0.5, 1.0]), 'length'),
        (raw([1, 1, 2, 1, 1.0, 2, math.nan, -0.5, 1.0, 2.0]), 'non_finite'),
        (info(sender=3, stamp=1.0), 'sender'),
        (info(stamp=0.0), 'time_backwards'),
    ]

    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=domain_id,
        progress=False,
        timeout=240.0,
        inject={'delay_ms': 2.0},
        step_listeners=1,
    )
    injected = False
    with _outsider_with_run('bad_message_injector', domain_id, run) as outsider:
        while outsider.worker.is_alive():
            outsider.executor.spin_once(timeout_sec=0.05)
            if not injected and outsider.steps and max(outsider.steps) >= inject_at:
                # An insider: it holds the run's key (a node of the run gone bad), so its messages
                # pass the tag and meet the layout and plausibility checks (docs/HOSTILE_TRAFFIC.md).
                signer = Signer(read_key(run.out_dir / KEY_FILE), writer='injector')
                for msg, _ in bad:
                    outsider.publisher.publish(tag_array(msg, signer, trigger_info_topic(2, 1)))
                injected = True
    seen, results = outsider.steps, outsider.results
    (result,) = results
    assert injected, f'the run ended before step {inject_at}'
    assert min(seen) == 0, 'the injector missed Steps: step 0 did not wait for it'
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    _assert_same_events(summary, reference)
    expected = {reason: 1 for _, reason in bad}
    assert summary['extra']['rejected_messages'] == {
        'total': len(bad),
        'by_reason': expected,
        'by_agent': {'1': expected},
        'simulator': {},
    }
    assert summary['extra']['failure'] is None
    # Every message that reached an agent's topic went through the injected delay.
    assert summary['extra']['injected_faults']['delayed'] == summary['messages_sent'] + len(bad)
    assert summary['extra']['injected_faults']['dropped'] == 0
    log = (result.out_dir / 'logs' / 'agent_1.log').read_text()
    assert f'rejected a message on {trigger_info_topic(2, 1)} (sender, 1 so far)' in log
    assert 'information from agent 3 on the topic of agent 2' in log


@pytest.mark.timeout(300)
def test_forged_plausible_messages_without_the_runs_tag_change_nothing_and_are_counted_foreign(
    tmp_path, ros_env
):
    """Issue 28 item 2.  An outsider without the run's key sends mid-run a well-formed, plausible
    TriggerInfo from agent 2 to agent 1 (stamped at the latest Step's time: the layout and
    plausibility checks take it), the same under another run's key, a Step that is the run's
    next one, marked final (agents stop on any final Step they take), and a call of agent 2's
    sensing service.  Each is refused by its tag before the algorithm sees it: the lock-step run
    equals the in-process engine bit for bit, and summary.json counts them as foreign."""
    from rcl_interfaces.srv import SetParameters
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.codec import decode_step, encode_step, encode_trigger_info, tag_array
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, Step
    from formation_msgs_py.qos import PROTOCOL_QOS, READER_QOS
    from formation_msgs_py.tags import Signer, new_key
    from formation_msgs_py.topics import STEP_TOPIC, sense_service, trigger_info_topic
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.runtime.launch.orchestrate import FormationRun

    domain_id = 73
    scenario = load_scenario('paper_single')
    horizon = 2.0
    reference = simulate(scenario, horizon=horizon)
    events = sorted({t for times in reference.trigger_times.values() for t in times})
    inject_at = len(events) // 2
    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=domain_id,
        progress=False,
        timeout=240.0,
        step_listeners=1,
    )
    injected = False
    with _outsider_with_run('forger', domain_id, run) as outsider:
        steps: list[Step] = []
        outsider.node.create_subscription(
            Float64MultiArray, STEP_TOPIC, lambda msg: steps.append(decode_step(msg)), READER_QOS
        )
        step_writer = outsider.node.create_publisher(Float64MultiArray, STEP_TOPIC, PROTOCOL_QOS)
        sense = outsider.node.create_client(SetParameters, sense_service(2))
        while outsider.worker.is_alive():
            outsider.executor.spin_once(timeout_sec=0.05)
            agents_hear_it = step_writer.get_subscription_count() >= len(scenario.agent_ids)
            agents_hear_it = agents_hear_it and sense.service_is_ready()
            if not injected and agents_hear_it and steps and steps[-1].index >= inject_at:
                last = steps[-1]
                info = encode_trigger_info(
                    TriggerInfo(
                        sender=2, receiver=1, stamp=last.time, control=(3.0, -3.0), rel_position=(1.0, 2.0)
                    )
                )
                outsider.publisher.publish(info)  # untagged
                other_run = Signer(new_key(), writer='agent_2')
                outsider.publisher.publish(tag_array(info, other_run, trigger_info_topic(2, 1)))  # forged
                final = Step(
                    index=last.index + 1, time=last.time, flags=STEP_FLAG_FINAL, epoch=last.epoch, due=()
                )
                step_writer.publish(encode_step(final))  # untagged
                answer = sense.call_async(
                    SetParameters.Request()
                )  # untagged, as `ros2 service call` sends it
                injected = True
    (result,) = outsider.results
    assert injected, f'the run ended before step {inject_at}'
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    for agent, times in reference.trigger_times.items():  # bit for bit: JSON floats round-trip
        assert summary['trigger_times'][str(agent)] == list(times), f'agent {agent}'
    assert summary['total_events'] == reference.total_events
    assert summary['messages_sent'] == reference.messages_sent
    n = len(scenario.agent_ids)
    rejected = summary['extra']['rejected_messages']
    assert rejected['by_reason'] == {'untagged': 2 + n, 'forged': 1}, rejected
    assert rejected['by_agent']['1'] == {'untagged': 2, 'forged': 1}
    assert all(rejected['by_agent'][str(i)] == {'untagged': 1} for i in scenario.agent_ids if i != 1)
    assert rejected['simulator'] == {'untagged': 1}  # the sensing call
    assert summary['extra']['foreign_sensing_calls'] == {'2': 1}
    assert answer.done() and not answer.result().results[0].successful
    assert summary['extra']['foreign_messages'] == n + 3
    assert summary['extra']['failure'] is None
    log = (result.out_dir / 'logs' / 'agent_1.log').read_text()
    assert "a message without the run's tag" in log and 'that is not the run key' in log


def test_a_second_server_of_an_agents_sensing_service_stops_the_run_and_is_named(tmp_path, ros_env):
    """Issue 28: a stranger serving /agent_2/sense with a plausible state.  Agent 2's client may
    take its answer for the world's: the simulator's graph watch names the second server and
    stops the run (an agent that took such an answer refuses it for its tag and stops too), so
    the run cannot end done."""
    from rcl_interfaces.srv import SetParameters

    from formation_msgs_py.codec import encode_sensed_state
    from formation_msgs_py.topics import sense_service
    from formation_msgs_py.types import SensedState
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario('paper_single')
    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=2.0,
        domain_id=83,
        progress=False,
        timeout=240.0,
        step_listeners=1,
    )
    lie = SensedState(agent=2, stamp=0.0, rel_positions=dict.fromkeys(scenario.neighbours(2), (0.0, 0.0)))
    with _outsider_with_run('rogue_server', 83, run) as outsider:
        outsider.node.create_service(
            SetParameters, sense_service(2), lambda request, response: encode_sensed_state(lie)
        )
        while outsider.worker.is_alive():
            outsider.executor.spin_once(timeout_sec=0.05)
    (result,) = outsider.results
    assert not result.ok
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    print(failure['message'])
    # Whichever comes first: the graph watch (foreign_writer), or agent 2 stopping on the answer
    # without the simulator's tag (agent_failed); the server named either way.
    assert failure['kind'] in ('foreign_writer', 'agent_failed'), failure
    assert 'a node outside the run, /rogue_server (writer gid ' in failure['message'], failure
    assert 'writes answers of /agent_2/sense (rr/agent_2/senseReply)' in failure['message'], failure


@pytest.mark.timeout(300)
def test_a_flood_of_junk_on_a_triggering_information_topic_does_not_starve_the_protocol(tmp_path, ros_env):
    """Thousands of malformed messages per second, with the protocol's own QoS, on the topic that
    carries agent 2's information to agent 1, from step 0 to the end of a lock-step run. Before
    agents' readers kept all they received, the junk pushed agent 2's real information out of
    agent 1's 32-deep history and the run stalled at step 0 (2 runs of 2 at 4000/s here)."""
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.topics import trigger_info_topic
    from formation_sim.runtime.launch.orchestrate import FormationRun

    domain_id = 60
    scenario = load_scenario('paper_single')
    horizon = 10.0
    reference = simulate(scenario, horizon=horizon)
    rate = 4000.0  # junk messages per second
    junk = Float64MultiArray(data=[2.0, 1, 2, 1, 1.0, 2, 0.5, -0.5, 1.0, 2.0])  # layout version 2

    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=domain_id,
        progress=False,
        timeout=240.0,
        step_listeners=1,
    )
    sent, began, first_step = 0, None, None
    with _outsider_with_run(
        'junk_flooder', domain_id, run
    ) as outsider:  # the flood is on from the first step
        while outsider.worker.is_alive():
            outsider.executor.spin_once(timeout_sec=0.0)
            if began is None and outsider.steps:
                began, first_step = time.monotonic(), max(outsider.steps)
            if began is not None:
                for _ in range(int((time.monotonic() - began) * rate) - sent):
                    outsider.publisher.publish(junk)
                    sent += 1
            time.sleep(0.001)
    results = outsider.results
    (result,) = results
    assert first_step is not None and first_step <= 1, f'the flood began at step {first_step}'
    assert result.ok, result.message
    summary = json.loads(result.summary.read_text())
    _assert_same_events(summary, reference)
    rejected = summary['extra']['rejected_messages']
    # The junk reached agent 1 while the run went on, and only there; it carries no tag of the run's
    # key, so it is refused for that before its layout is read (docs/HOSTILE_TRAFFIC.md, Tags).
    assert rejected['by_agent'] == {'1': {'untagged': rejected['total']}}
    assert rejected['total'] >= 500, f'{rejected["total"]} junk messages rejected of {sent} sent'
    # The recorder records every writer of the topic: the junk is in the bag, said to be foreign.
    recording = summary['extra']['recording']
    assert recording['complete'] and set(recording['foreign']) == {trigger_info_topic(2, 1)}
    assert recording['foreign'][trigger_info_topic(2, 1)] >= rejected['total']
    assert 'messages from publishers outside the run' in result.message and '/junk_flooder' in result.message


# -- node faults --------------------------------------------------------------------------------


@pytest.mark.timeout(300)
def test_an_agent_killed_mid_run_is_reported_and_the_bag_holds_every_message_until_then(
    tmp_path, ros_env, bag_trigger_stamps, stepping_run, long_run_scenario, shm_files
):
    from formation_sim.runtime.launch.fastdds_shm import held_files
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario(long_run_scenario)
    run = FormationRun(scenario, out_dir=tmp_path / 'run', domain_id=71, progress=False, timeout=240.0)
    stepping = stepping_run(run)
    time.sleep(0.5)  # well into the run
    victim = next(child for child in run._children if child.name == 'agent_2')
    held = shm_files(held_files(victim.pid))
    os.kill(victim.pid, signal.SIGKILL)
    result = stepping.result(timeout=120.0)
    assert result.exit_status == ExitCode.LOST == 3
    assert held.paths and not held.left(), held.left()
    assert f'agent_2 (pid {victim.pid}) killed by SIGKILL' in result.message
    assert 'agent 2 lost at t=' in result.message and 'no sign of life' in result.message
    assert not _wait_until_gone(str(result.out_dir))

    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure == result.failure
    assert failure['kind'] == 'agent_lost' and failure['agents'] == [2]
    assert failure['detected_by'] == 'simulator, orchestrator'
    assert failure['process']['name'] == 'agent_2' and failure['process']['returncode'] == -signal.SIGKILL
    t_fail = failure['time']
    assert 0.0 < t_fail == summary['extra']['reached_time'] < scenario.horizon

    # Up to the failure, the run is the engine's: every trigger that completed, at its time.
    reference = simulate(scenario, horizon=t_fail)
    for agent, times in reference.trigger_times.items():
        got = summary['trigger_times'][str(agent)]
        assert got == times[: len(got)] and len(got) >= len([t for t in times if t < t_fail]), (
            f'agent {agent}'
        )

    # The bag was finalised and holds every triggering-information message sent before the
    # failing step, each exactly once and in order — but for what the killed agent had not yet
    # handed to the recorder: lock-step keeps the recorder within RECORDER_LAG steps, and a
    # process killed hard delivers nothing more, so its messages of those last steps may be gone.
    from formation_sim.runtime.nodes.sim_node import RECORDER_LAG

    assert result.bag is not None and not result.bag_recovered
    counts, stamps = bag_trigger_stamps(result.bag)
    steps = sorted({t for times in reference.trigger_times.values() for t in times if t < t_fail})
    in_flight = set(steps[-(RECORDER_LAG + 1) :])
    for i in scenario.agent_ids:
        for j in scenario.neighbours(i):
            before = [t for t in reference.trigger_times[i] if t < t_fail]
            sent = [t for t in stamps[(i, j)] if t < t_fail]
            assert stamps[(i, j)] == sorted(set(stamps[(i, j)])) and all(
                t <= t_fail for t in stamps[(i, j)]
            ), f'edge {i}->{j}'
            if i == 2:  # the victim: a prefix, missing at most its last steps
                assert sent == before[: len(sent)] and set(before[len(sent) :]) <= in_flight, f'edge {i}->{j}'
            else:
                assert sent == before, f'edge {i}->{j}'
    assert counts['/formation/sensing_log'] >= sum(
        len([t for t in ts if t < t_fail]) for ts in reference.trigger_times.values()
    )


@pytest.mark.timeout(300)
def test_a_recorder_killed_mid_run_stops_the_run_and_its_bag_is_recovered(
    tmp_path, ros_env, stepping_run, long_run_scenario
):
    from formation_sim.bag.io import read_bag
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        long_run_scenario, out_dir=tmp_path / 'run', domain_id=72, progress=False, timeout=240.0
    )
    stepping = stepping_run(run)
    time.sleep(1.5)  # past at least two of the recorder's 0.5 s flushes
    recorder = next(child for child in run._children if child.name == 'recorder')
    os.kill(recorder.pid, signal.SIGKILL)
    result = stepping.result(timeout=120.0)
    assert result.exit_status == ExitCode.LOST
    assert f'recorder (pid {recorder.pid}) killed by SIGKILL' in result.message
    assert result.message.count(f'recorder (pid {recorder.pid})') == 1, result.message  # said once
    assert 'its bag was recovered' in result.message
    assert result.bag_recovered and result.bag is not None
    assert not _wait_until_gone(str(result.out_dir))
    messages = list(read_bag(result.bag))
    assert {m.topic for m in messages} >= {
        '/formation/step',
        '/agent_1/trigger_info/to_2',
        '/formation/status',
    }
    assert all(a.timestamp_ns <= b.timestamp_ns for a, b in zip(messages, messages[1:]))
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'process_lost' and failure['process']['name'] == 'recorder'
    assert summary['total_events'] > 0


BYSTANDER = """
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
node = rclpy.create_node('bystander')
node.create_publisher(String, '/bystander', 10)
node.create_subscription(String, '/bystander', lambda msg: None, 10)
print('ready', flush=True)
sys.stdin.read()  # until the test closes it
rclpy.shutdown()
"""


@pytest.mark.timeout(300)
def test_children_killed_hard_leave_none_of_their_shared_memory_files_and_no_other_is_touched(
    tmp_path, ros_env, stepping_run, long_run_scenario, shm_files
):
    """Every child of a recorded run killed with SIGKILL at once: each segment and port its
    children held goes whole (file, semaphore, lock file), including the machine-wide ports 70xx
    outside the domain's range; a live participant of another domain and a dead port of nobody
    in the run keep theirs."""
    from formation_sim.runtime.launch.fastdds_shm import SHM_DIR, held_files
    from formation_sim.runtime.launch.orchestrate import FormationRun

    def family(path: str) -> set[Path]:
        name = Path(path).name.removeprefix('sem.').removesuffix('_mutex').removesuffix('_el')
        return {SHM_DIR / name, SHM_DIR / f'sem.{name}_mutex', SHM_DIR / f'{name}_el'}

    stranger = [
        SHM_DIR / f'fastrtps_port{65380 + os.getpid() % 5}',
        SHM_DIR / f'fastrtps_port{65380 + os.getpid() % 5}_el',
    ]
    bystander = subprocess.Popen(
        [sys.executable, '-c', BYSTANDER],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, 'ROS_DOMAIN_ID': '68'},
        start_new_session=True,
    )
    try:
        for path in stranger:
            path.touch()
        assert bystander.stdout.readline().strip() == 'ready'
        bystanders = held_files(bystander.pid)
        assert bystanders, 'the bystander holds no Fast DDS file'
        run = FormationRun(
            long_run_scenario, out_dir=tmp_path / 'run', domain_id=65, progress=False, timeout=240.0
        )
        stepping = stepping_run(run)
        time.sleep(0.5)
        children = list(run._children)
        held = set().union(*(held_files(child.pid) for child in children))
        family_files = shm_files(str(path) for path in set().union(*(family(path) for path in held)))
        for child in children:
            os.kill(child.pid, signal.SIGKILL)
        result = stepping.result(timeout=120.0)
        assert result.exit_status == ExitCode.LOST, result.message
        assert all(child.process.returncode == -signal.SIGKILL for child in run._children)
        ports = {Path(path).name for path in held if 'fastrtps_port' in path}
        assert any(
            not 7400 + 250 * 65 <= int(name.split('port')[1].split('_')[0]) < 7400 + 250 * 66
            for name in ports
        ), ports
        assert any(path.endswith('_el') for path in held), 'no lock file noted'
        left = family_files.left()
        assert not left, f'left in /dev/shm: {left}'
        assert all(Path(path).exists() for path in bystanders), 'a live participant lost its files'
        assert all(path.exists() for path in stranger), 'a dead port of nobody in the run was removed'
        segments = {path for path in held if Path(path).name.startswith('fastrtps_') and 'port' not in path}
        assert segments and set(run.removed_shm_files) >= segments  # segment names are never reused
    finally:
        bystander.stdin.close()
        try:
            bystander.wait(timeout=30.0)
        except subprocess.TimeoutExpired:
            bystander.kill()
        for path in stranger:
            path.unlink(missing_ok=True)


@pytest.mark.timeout(300)
def test_a_frozen_recorder_stops_the_run_and_the_bag_is_checked_against_what_was_published(
    tmp_path, ros_env, stepping_run, long_run_scenario, bag_trigger_stamps
):
    """SIGSTOP on the recorder mid-run: it acknowledges nothing more, and every keep-last writer
    of the run would overwrite what it has not acknowledged. The simulator sees its heartbeat
    writer's liveliness lapse and stops the run (exit 3); once the recorder runs again (the
    orchestrator sends SIGCONT with SIGINT) it closes its bag, and summary.json says, per topic,
    what the run published and the bag lacks."""
    from formation_sim.runtime.launch.orchestrate import FormationRun

    run = FormationRun(
        long_run_scenario, out_dir=tmp_path / 'run', domain_id=61, progress=False, timeout=240.0
    )
    stepping = stepping_run(run)
    recorder = next(child for child in run._children if child.name == 'recorder')
    os.kill(recorder.pid, signal.SIGSTOP)
    try:
        result = stepping.result(timeout=120.0)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(recorder.pid, signal.SIGCONT)
    assert result.exit_status == ExitCode.LOST, result.message
    assert 'the recorder lost at t=' in result.message and 'no sign of life for 1.0 s' in result.message
    summary = json.loads(result.summary.read_text())
    failure = summary['extra']['failure']
    assert failure['kind'] == 'recorder_lost' and failure['detected_by'] == 'simulator'
    assert 0.0 < failure['time'] == summary['extra']['reached_time'] < 600.0
    assert result.bag is not None and not result.bag_recovered  # closed by the recorder itself
    assert not _wait_until_gone(str(result.out_dir))

    # What the bag holds is what the run published less what summary.json says is missing.
    published, recording = summary['extra']['published'], summary['extra']['recording']
    counts, _ = bag_trigger_stamps(result.bag)
    for topic, n in published.items():
        if topic != '/formation/status':  # the bag also holds the agents' discovery announcements
            assert counts.get(topic, 0) == n - recording['missing'].get(topic, 0), topic
    assert recording['complete'] == (not recording['missing'])
    assert ('the bag misses' in result.message) == bool(recording['missing']), result.message
    if recording['missing']:
        worst = max(recording['missing'], key=recording['missing'].get)
        assert (
            f'{worst} {published[worst] - recording["missing"][worst]} of {published[worst]}'
            in result.message
        )


@pytest.mark.timeout(300)
def test_a_simulator_killed_hard_still_leaves_a_summary_of_what_is_known(
    tmp_path, ros_env, stepping_run, long_run_scenario
):
    """SIGKILL leaves the simulator no time to write summary.json: the orchestrator writes it,
    with the failure, the last sim time and step of the simulator's progress, every process's
    exit, and the run as far as the (finalised) bag holds it, which is the engine's run so far."""
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario(long_run_scenario)
    run = FormationRun(scenario, out_dir=tmp_path / 'run', domain_id=63, progress=False, timeout=240.0)
    stepping = stepping_run(run)
    time.sleep(1.5)  # past a progress line or two
    simulator = next(child for child in run._children if child.name == 'simulator')
    os.kill(simulator.pid, signal.SIGKILL)
    result = stepping.result(timeout=120.0)
    assert result.exit_status == ExitCode.LOST
    assert result.message.startswith(f'simulator (pid {simulator.pid}) killed by SIGKILL; see ')
    assert result.summary is not None and result.bag is not None and not result.bag_recovered
    assert not _wait_until_gone(str(result.out_dir))

    summary = json.loads(result.summary.read_text())
    extra = summary['extra']
    failure = extra['failure']
    assert failure == result.failure
    assert failure['kind'] == 'process_lost' and failure['detected_by'] == 'orchestrator'
    assert failure['process']['name'] == 'simulator' and failure['process']['returncode'] == -signal.SIGKILL
    assert extra['processes']['simulator'] == 'killed by SIGKILL'
    assert 'bag' in extra['summary_source']
    # The last progress line came before the kill; the bag holds the run up to the kill: the
    # failure is at the latest of the two (issue 28), at least where the bag's samples reach.
    assert isinstance(failure['step'], int) and failure['step'] > 0
    assert 0.0 < extra['reached_time'] <= failure['time'] < scenario.horizon
    assert "the bag's last Step" in failure['time_from']
    # The bag may hold the triggers of the step in progress (sent, not yet sampled): one more step.
    last = max(t for times in summary['trigger_times'].values() for t in times)
    reference = simulate(scenario, horizon=last + 1.0)
    for agent, times in reference.trigger_times.items():
        got = summary['trigger_times'][str(agent)]
        assert got == times[: len(got)], f'agent {agent}'
        assert len(got) >= len([t for t in times if t < extra['reached_time']]), f'agent {agent}'


@pytest.mark.timeout(300)
def test_a_full_disk_is_named_and_leaves_no_corrupt_or_stray_file(
    tmp_path, ros_env, small_disk, long_run_scenario
):
    """`formation run` into a 2 MB tmpfs: the bag fills it. The recorder names the error and
    leaves; the run stops; what cannot be written (the recovered bag, summary.json) is named and
    absent rather than empty or cut short, and no temporary file is left."""
    out = small_disk(2) / 'run'
    done = subprocess.run(
        [
            sys.executable,
            '-m',
            'formation_sim.cli',
            'run',
            long_run_scenario,
            '--horizon',
            '20',
            '--out',
            str(out),
            '--domain-id',
            '64',
            '--no-plot',
        ],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert done.returncode in (1, 3), done.stderr
    assert 'Traceback' not in done.stderr, done.stderr
    assert 'No space left on device' in done.stderr
    assert not _wait_until_gone(str(out)), 'orphan processes'
    files = [path for path in out.rglob('*') if path.is_file() and 'logs' not in path.relative_to(out).parts]
    assert not [path.name for path in files if path.name.endswith(('.tmp', '.recovering'))], files
    for path in files:
        assert path.stat().st_size > 0, f'{path} is empty'
        if path.suffix in ('.json', '.yaml'):
            (json.loads if path.suffix == '.json' else __import__('yaml').safe_load)(
                path.read_text()
            )  # complete
    if (out / 'summary.json').exists():
        assert 'extra' in json.loads((out / 'summary.json').read_text())
    else:
        assert 'summary.json could not be written: [Errno 28] No space left on device' in done.stderr
    bag = out / 'bag'
    if not (bag / 'metadata.yaml').exists():  # not recovered: the damage is named
        assert (
            'its bag could not be recovered' in done.stderr
            and 'free space, then recover it again' in done.stderr
        )
        assert sorted(path.name for path in bag.iterdir()) == ['bag_0.mcap']


def _start_cli_run(scenario: Path, out: Path, domain_id: int, *extra: str) -> subprocess.Popen:
    process = subprocess.Popen(
        [
            sys.executable,
            '-m',
            'formation_sim.cli',
            'run',
            str(scenario),
            '--out',
            str(out),
            '--domain-id',
            str(domain_id),
            '--no-plot',
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    log = out / 'logs' / 'simulator.log'
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline:
        if log.is_file() and 'progress t=' in log.read_text():
            return process
        assert process.poll() is None, process.communicate()
        time.sleep(0.1)
    process.kill()
    raise AssertionError('the run never started stepping')


@pytest.mark.timeout(300)
def test_ctrl_c_on_formation_run_stops_every_process_and_finalises_the_bag(
    tmp_path, ros_env, long_run_scenario
):
    from formation_sim.bag.io import read_bag

    out = tmp_path / 'run'
    process = _start_cli_run(long_run_scenario, out, 73)
    process.send_signal(signal.SIGINT)  # what a terminal's Ctrl-C sends (children have their own sessions)
    _, err = process.communicate(timeout=120.0)
    assert process.returncode == 130, err
    assert 'interrupted' in err
    assert not _wait_until_gone(str(out)), 'orphan processes'
    assert (out / 'bag' / 'metadata.yaml').is_file()
    assert sum(1 for _ in read_bag(out / 'bag')) > 0
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['extra']['failure']['kind'] == 'interrupted' and summary['total_events'] > 0


@pytest.mark.timeout(300)
def test_formation_run_killed_hard_takes_its_children_with_it(tmp_path, ros_env, long_run_scenario):
    """SIGKILL cannot be caught: the kernel's parent-death signal stops the children instead."""
    from formation_sim.bag.io import read_bag

    out = tmp_path / 'run'
    process = _start_cli_run(long_run_scenario, out, 74)
    process.kill()
    process.communicate(timeout=60.0)
    assert not _wait_until_gone(str(out)), 'orphan processes'
    assert (out / 'bag' / 'metadata.yaml').is_file()  # the recorder got SIGTERM and closed its bag
    assert sum(1 for _ in read_bag(out / 'bag')) > 0
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['extra']['failure']['kind'] == 'interrupted'


# -- communication faults (wall clock) ----------------------------------------------------------


@pytest.mark.timeout(300)
def test_injected_loss_and_delay_happen_and_are_counted(tmp_path, ros_env):
    """A test facility, not a result (the experiment's numbers are in the README). On the wall
    clock the outcome may vary: a run either reaches the horizon or stops with the reason."""
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario(GENTLE)
    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=3.0,
        domain_id=75,
        progress=False,
        timeout=240.0,
        record=False,
        agents_per_process=4,
        clock='realtime',
        inject={'loss': 0.1, 'delay_ms': 5.0, 'jitter_ms': 5.0, 'seed': 1},
    )
    result = run.run()
    summary = json.loads(result.summary.read_text())
    if not result.ok:  # an honest failure, named: not a crash
        assert summary['extra']['failure']['kind'] in ('connectivity_lost', 'agent_failed'), result.message
    injected = summary['extra']['injected_faults']
    assert injected['dropped'] > 0 and injected['delayed'] > 0
    assert injected['dropped'] + injected['delayed'] <= summary['messages_sent']  # each arrival once
    assert set(injected['by_agent']) <= {str(i) for i in scenario.agent_ids}
    assert sum(entry['dropped'] for entry in injected['by_agent'].values()) == injected['dropped']
    assert summary['extra']['rejected_messages']['total'] == 0  # delays keep each edge in order
    assert summary['extra']['reports_missing'] == []
    params = (result.out_dir / 'agents.params.yaml').read_text()
    assert 'inject_loss: 0.1' in params and 'inject_delay_ms: 5.0' in params and 'inject_seed: 1' in params


# -- isolation ----------------------------------------------------------------------------------


@pytest.mark.timeout(300)
def test_two_runs_side_by_side_on_different_domains_do_not_see_each_other(tmp_path, ros_env):
    from formation_sim.runtime.launch.orchestrate import FormationRun

    scenario = load_scenario('paper_single')
    reference = simulate(scenario, horizon=1.0)
    runs = [
        FormationRun(
            scenario,
            out_dir=tmp_path / f'run{domain_id}',
            horizon=1.0,
            domain_id=domain_id,
            progress=False,
            timeout=240.0,
            record=False,
            agents_per_process=3,
        )
        for domain_id in (76, 77)
    ]
    started = [_in_background(run) for run in runs]
    for worker, _ in started:
        worker.join(timeout=240.0)
    own = {'/formation_simulator', *(f'/agent_{i}/formation_agent' for i in scenario.agent_ids)}
    for (_, (result,)), domain_id in zip(started, (76, 77)):
        assert result.ok, result.message
        assert result.domain_id == domain_id
        graph = json.loads((result.out_dir / 'graph.json').read_text())
        assert set(graph) == own, f'domain {domain_id} sees {sorted(graph)}'
        _assert_same_events(json.loads(result.summary.read_text()), reference)


# -- several hosts ------------------------------------------------------------------------------

SUBNET = '10.231.0'  # private addresses, only on links inside the namespaces made here


class _Hosts:
    """Network namespaces acting as hosts, joined by a bridge in a namespace of its own.

    Nothing is added to the machine's own network stack: every link is created inside the
    namespaces, and deleting them (`close`) removes everything.
    """

    def __init__(self, tag: str, names: list[str]) -> None:
        self.tag = tag
        self.created: list[str] = []
        self.switch = f'{tag}sw'
        self.namespaces = {name: f'{tag}{name}' for name in names}

    def _ip(self, *args: str) -> None:
        done = subprocess.run(['ip', *args], capture_output=True, text=True, check=False, timeout=30)
        if done.returncode != 0:
            raise OSError(f'ip {" ".join(args)}: {done.stderr.strip()}')

    def open(self) -> None:
        self._ip('netns', 'add', self.switch)
        self.created.append(self.switch)
        self._ip('-n', self.switch, 'link', 'add', 'br0', 'type', 'bridge')
        self._ip('-n', self.switch, 'link', 'set', 'br0', 'up')
        for k, namespace in enumerate(self.namespaces.values(), start=1):
            self._ip('netns', 'add', namespace)
            self.created.append(namespace)
            self._ip(
                'link',
                'add',
                'name',
                'eth0',
                'netns',
                namespace,
                'type',
                'veth',
                'peer',
                'name',
                f'port{k}',
                'netns',
                self.switch,
            )
            self._ip('-n', self.switch, 'link', 'set', f'port{k}', 'master', 'br0', 'up')
            self._ip('-n', namespace, 'addr', 'add', f'{SUBNET}.{k}/24', 'dev', 'eth0')
            self._ip('-n', namespace, 'link', 'set', 'eth0', 'up')
            self._ip('-n', namespace, 'link', 'set', 'lo', 'up')
            # DDS discovery multicasts to 239.255.0.1: route it onto the link.
            self._ip('-n', namespace, 'route', 'add', '224.0.0.0/4', 'dev', 'eth0')

    def close(self) -> None:
        for namespace in reversed(self.created):
            subprocess.run(['ip', 'netns', 'del', namespace], capture_output=True, check=False, timeout=30)
        self.created.clear()


@pytest.fixture
def hosts():
    import shutil

    if os.geteuid() != 0:
        pytest.skip('network namespaces need root (CI runs as root)')
    if shutil.which('ip') is None:
        pytest.skip('iproute2 is not installed (apt-get install -y iproute2)')
    made = _Hosts(f'fm{os.getpid() % 100000}', ['h0', 'h1', 'h2', 'h3'])
    try:
        made.open()
    except OSError as error:
        made.close()
        if 'Operation not permitted' in str(error) or 'Permission denied' in str(error):
            pytest.skip(f'network namespaces are not permitted here: {error}')
        raise
    try:
        yield made
    finally:
        made.close()


@pytest.mark.timeout(300)
def test_agents_on_separate_hosts_discover_each_other_over_udp_and_match_the_engine(
    tmp_path, ros_env, hosts, bag_trigger_stamps
):
    """Simulator and recorder on one host, each agent on its own; DDS over UDPv4 only (no shared
    memory), discovery by multicast on the hosts' subnet."""
    from formation_sim.runtime.launch.orchestrate import FormationRun

    place = {'simulator': 'h0', 'recorder': 'h0', 'agent_1': 'h1', 'agent_2': 'h2', 'agent_3': 'h3'}
    scenario = load_scenario('paper_single')
    horizon = 2.0
    reference = simulate(scenario, horizon=horizon)
    run = FormationRun(
        scenario,
        out_dir=tmp_path / 'run',
        horizon=horizon,
        domain_id=78,
        progress=False,
        timeout=240.0,
        localhost_only=False,
        extra_env={'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'},
        launch_prefix=lambda name: ['ip', 'netns', 'exec', hosts.namespaces[place[name]]],
    )
    worker, results = _in_background(run)
    # Which network stack each child lives on, read while they discover each other over UDP
    # (seconds; stepping to t = 2 then takes well under a second): once all five are started and
    # each has left this process's stack (`ip netns exec` enters its namespace, then runs python).
    own = os.readlink('/proc/self/ns/net')
    stacks: dict[str, str] = {}
    deadline = time.monotonic() + 60.0
    while (len(stacks) < len(place) or own in stacks.values()) and time.monotonic() < deadline:
        stacks = {child.name: os.readlink(f'/proc/{child.pid}/ns/net') for child in list(run._children)}
        time.sleep(0.02)
    worker.join(timeout=240.0)
    (result,) = results
    assert result.ok, result.message
    assert os.readlink('/proc/self/ns/net') not in stacks.values()
    assert stacks['recorder'] == stacks['simulator']
    assert len({stacks[name] for name in ('simulator', 'agent_1', 'agent_2', 'agent_3')}) == 4
    summary = json.loads(result.summary.read_text())
    _assert_same_events(summary, reference)
    counts, _ = bag_trigger_stamps(result.bag)
    assert counts['/agent_1/trigger_info/to_2'] == len(reference.trigger_times[1])
