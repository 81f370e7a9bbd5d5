"""Shared runs for the analysis, comparison, replay and inspection tests.

- `paper_single_record`: the in-process engine's paper_single run up to t = 1 (no ROS).
- `write_run_bag`: writes what a distributed run records (docs/MESSAGES.md) for a `RunRecord`,
  through the real codec encoders, into a bag (no ROS process: rclpy only serializes).
- `wait_for_stepping`: waits until a FormationRun's simulator reports sim time past 0.
- `bag_trigger_stamps`: reads a bag's message counts and TriggerInfo stamps per directed edge.
- `small_disk`: `small_disk(megabytes)` mounts a tmpfs of that size (a disk that fills up);
  root only, skipped otherwise, unmounted after the test.
- `distributed_single_run`: one distributed paper_single run (horizon 2, ROS domain 180 + xdist worker
  index) and the in-process run of the same scenario, shared by every test that asks for it in a session.
- `tight_edge`: a paper example whose edge (2, 3) starts with a given fraction of its capacity as slack.
"""

from __future__ import annotations

import json
import os
import re
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from formation_sim.model.scenario import load_scenario
from formation_sim.sim.engine import simulate
from formation_sim.sim.record import RunRecord

# Session fixtures run once per xdist worker: each worker needs its own domain (gw0 -> 180, ...).
DISTRIBUTED_DOMAIN = 180 + int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0').removeprefix('gw') or 0)


def _bag_trigger_stamps(bag: Path) -> tuple[dict[str, int], dict[tuple[int, int], list[float]]]:
    """Messages per topic of a bag, and the TriggerInfo stamps per (sender, receiver) edge."""
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.codec import decode_trigger_info
    from formation_sim.bag.io import read_bag

    counts: dict[str, int] = defaultdict(int)
    stamps: dict[tuple[int, int], list[float]] = defaultdict(list)
    for message in read_bag(bag):
        counts[message.topic] += 1
        if '/trigger_info/' in message.topic:
            info = decode_trigger_info(deserialize_message(message.rawdata, Float64MultiArray))
            assert message.topic == f'/agent_{info.sender}/trigger_info/to_{info.receiver}'
            stamps[(info.sender, info.receiver)].append(info.stamp)
    return counts, stamps


def _wait_for_stepping(run, limit: float = 120.0, *, ended=lambda: None) -> None:
    """Wait until the simulator reports sim time past 0 (on a loaded machine that can take a while).
    `ended()`: the run's result once it has returned (then waiting is over: say how it ended)."""
    deadline = time.monotonic() + limit

    def reached() -> float:
        found = re.search(r'\bt=([0-9.eE+-]+)', run.last_progress)
        return float(found.group(1)) if found else 0.0

    while reached() <= 0.0 and time.monotonic() < deadline and ended() is None:
        time.sleep(0.05)
    result = ended()
    how = '' if result is None else f'; it ended with status {result.exit_status}: {result.message}'
    assert reached() > 0.0, f'the run never stepped past t = 0 (last progress: {run.last_progress!r}){how}'


class _SteppingRun:
    """A FormationRun whose run() goes on in a thread of the test, already stepping past t = 0."""

    def __init__(self, run) -> None:
        self.run = run
        self._results: list = []
        self._worker = threading.Thread(target=lambda: self._results.append(run.run()), daemon=True)
        self._worker.start()
        _wait_for_stepping(run, ended=lambda: self._results[0] if self._results else None)

    def result(self, timeout: float):
        """run()'s result, once it returned within `timeout` seconds."""
        self._worker.join(timeout=timeout)
        assert not self._worker.is_alive(), f'the run did not end within {timeout} s'
        (result,) = self._results
        return result


def _tight_edge(name: str, fraction: float):
    """`name` (a built-in) with agent 3 moved along y_23 = x_2 - x_3 - d_23 so that the slack
    Δ - ||d_23|| - ||y_23(0)|| is `fraction` of the capacity Δ - ||d_23||."""
    scenario = load_scenario(name)
    edge = next(e for e in scenario.edges if e.pair == (2, 3))
    x = scenario.positions.copy()
    two, three = scenario.index(2), scenario.index(3)
    y = x[two] - x[three] - edge.d
    capacity = scenario.delta - np.linalg.norm(edge.d)
    x[three] = x[two] - edge.d - y / np.linalg.norm(y) * (1.0 - fraction) * capacity
    return scenario.replace(positions=x, name=f'{name}_slack{fraction:g}')


@pytest.fixture(scope='session')
def tight_edge():
    """`tight_edge(name, fraction) -> Scenario`: edge (2, 3) of a paper example with slack
    `fraction` of its capacity."""
    return _tight_edge


@pytest.fixture
def small_disk(tmp_path):
    """`small_disk(megabytes) -> Path`: a folder on a tmpfs that holds only that much."""
    import subprocess

    mounted: list[Path] = []

    def mount(megabytes: float) -> Path:
        if os.geteuid() != 0:
            pytest.skip('mounting a small tmpfs needs root (CI runs as root)')
        folder = tmp_path / f'disk{len(mounted)}'
        folder.mkdir()
        done = subprocess.run(
            ['mount', '-t', 'tmpfs', '-o', f'size={int(megabytes * 1024)}k', 'tmpfs', str(folder)],
            capture_output=True,
            text=True,
            check=False,
            timeout=30,
        )
        if done.returncode != 0:
            pytest.skip(f'cannot mount a tmpfs here: {done.stderr.strip()}')
        mounted.append(folder)
        return folder

    try:
        yield mount
    finally:
        for folder in reversed(mounted):
            subprocess.run(['umount', '--lazy', str(folder)], capture_output=True, check=False, timeout=30)


@pytest.fixture
def wait_for_stepping():
    """`wait_for_stepping(run)`: block until a FormationRun's simulator reports sim time past 0."""
    return _wait_for_stepping


@pytest.fixture
def stepping_run():
    """`stepping_run(run)`: start a FormationRun's run() in a thread and return once it steps;
    `.result(timeout)` joins it."""
    return _SteppingRun


def _inode(path: str) -> int | None:
    try:
        return os.stat(path).st_ino
    except FileNotFoundError:
        return None


class _ShmFiles:
    """Fast DDS files of processes about to die, by inode: `left()` are those still there as the
    same file and not in use.  A machine-wide port (fastrtps_port7000, ...) made anew meanwhile by
    another process (another test on another worker) is another file, not one the dead left."""

    def __init__(self, paths) -> None:
        self.paths = set(paths)
        self._inodes = {path: _inode(path) for path in self.paths}

    def left(self) -> list[str]:
        from formation_sim.runtime.launch.fastdds_shm import in_use

        return sorted(
            path
            for path in self.paths - in_use(self.paths)
            if self._inodes[path] is not None and _inode(path) == self._inodes[path]
        )


@pytest.fixture
def shm_files():
    """`shm_files(paths)`: note the Fast DDS files `paths` now; `.left()` after their owners died."""
    return _ShmFiles


@pytest.fixture
def bag_trigger_stamps():
    """`bag_trigger_stamps(bag) -> (messages per topic, TriggerInfo stamps per directed edge)`."""
    return _bag_trigger_stamps


@pytest.fixture(scope='session')
def paper_single_record() -> RunRecord:
    return simulate(load_scenario('paper_single'), horizon=1.0)


def _write_run_bag(
    record: RunRecord,
    path: Path,
    *,
    scenario_topic: bool = False,
    drop: set[tuple[int, int, int]] | None = None,
    asked_horizon: float | None = None,
) -> Path:
    """The bag a distributed run of `record` leaves; `drop` leaves out TriggerInfo (sender, receiver, k-th
    trigger).

    The run ends at record.horizon; `asked_horizon` (default the same) is the horizon it was run
    for, which the scenario topic carries: a later one makes the bag a run stopped early.
    """
    import yaml
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Twist
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    from formation_msgs_py.codec import encode_step, encode_trigger_info, encode_world_state
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, Step, WorldState
    from formation_msgs_py.types import TriggerInfo
    from formation_sim.bag.io import BagWriter
    from formation_sim.model.scenario import scenario_to_dict

    scenario = record.scenario
    p = scenario.dimension
    messages: list[tuple[float, int, str, str, bytes]] = []  # (time, order, topic, type, data)
    order = 0

    def add(t: float, topic: str, msgtype: str, msg) -> None:
        nonlocal order
        messages.append((t, order, topic, msgtype, serialize_message(msg)))
        order += 1

    array = 'std_msgs/msg/Float64MultiArray'
    if scenario_topic:
        asked = scenario.replace(
            horizon=record.horizon if asked_horizon is None else asked_horizon
        )  # as the simulator publishes it
        add(
            0.0,
            '/formation/scenario',
            'std_msgs/msg/String',
            String(data=yaml.safe_dump(scenario_to_dict(asked), sort_keys=False)),
        )
    events = sorted({t for times in record.trigger_times.values() for t in times})
    for index, t in enumerate(events):
        add(t, '/formation/step', array, encode_step(Step(index=index, time=t)))
    add(
        record.horizon,
        '/formation/step',
        array,
        encode_step(Step(index=len(events), time=record.horizon, flags=STEP_FLAG_FINAL)),
    )
    for agent, times in record.trigger_times.items():
        for k, t in enumerate(times):
            log = json.dumps(
                {'version': 1, 'agent': agent, 'step': events.index(t), 'time': t}, separators=(',', ':')
            )
            add(t, '/formation/sensing_log', 'std_msgs/msg/String', String(data=log))
            add(t, f'/agent_{agent}/cmd_vel', 'geometry_msgs/msg/Twist', Twist())
            for j in scenario.neighbours(agent):
                if drop and (agent, j, k) in drop:
                    continue
                info = TriggerInfo(
                    sender=agent, receiver=j, stamp=t, control=(0.0,) * p, rel_position=(0.0,) * p
                )
                add(t, f'/agent_{agent}/trigger_info/to_{j}', array, encode_trigger_info(info))
    velocities = record.sample_velocities
    for k, t in enumerate(record.sample_times):
        state = WorldState(
            time=float(t),
            agent_ids=scenario.agent_ids,
            positions=record.sample_positions[k],
            velocities=None if velocities is None else velocities[k],
        )
        add(float(t), '/formation/state', array, encode_world_state(state))
        seconds = round(float(t) * 1e9)
        add(
            float(t),
            '/clock',
            'rosgraph_msgs/msg/Clock',
            Clock(clock=Time(sec=seconds // 10**9, nanosec=seconds % 10**9)),
        )
    messages.sort(key=lambda m: (m[0], m[1]))
    with BagWriter(path) as bag:
        for _, _, topic, msgtype, _ in messages:
            bag.add_topic(topic, msgtype)
        for t, _, topic, _, data in messages:
            bag.write(topic, round(t * 1e9), data)
    return path


@pytest.fixture(scope='session')
def write_run_bag():
    """write_run_bag(record, path, *, scenario_topic=False, drop=None, asked_horizon=None) -> path."""
    return _write_run_bag


@dataclass(frozen=True)
class DistributedRun:
    out_dir: Path
    bag: Path
    summary: dict
    reference: RunRecord  # the in-process engine's run of the same scenario and horizon
    reference_dir: Path  # its summary.json and trajectory/


@pytest.fixture(scope='session')
def distributed_single_run(tmp_path_factory) -> DistributedRun:
    """paper_single, horizon 2, run once per session (per xdist worker) as ROS processes in domain
    DISTRIBUTED_DOMAIN."""
    from formation_sim.runtime.launch.orchestrate import FormationRun
    from formation_sim.sim.summary import write_summary

    scenario = load_scenario('paper_single')
    horizon = 2.0
    root = tmp_path_factory.mktemp('distributed_single')
    result = FormationRun(
        scenario,
        out_dir=root / 'run',
        horizon=horizon,
        domain_id=DISTRIBUTED_DOMAIN,
        progress=False,
        timeout=240.0,
    ).run()
    assert result.ok, result.message
    assert result.bag is not None
    reference = simulate(scenario, horizon=horizon)
    write_summary(reference, root / 'in_process')
    return DistributedRun(
        out_dir=result.out_dir,
        bag=result.bag,
        summary=json.loads(result.summary.read_text()),
        reference=reference,
        reference_dir=root / 'in_process',
    )
