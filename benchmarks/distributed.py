"""Distributed runs (`formation_sim.runtime.launch.orchestrate.FormationRun`) measured from outside.

`measure_run` runs one scenario in lock-step and reports: events and steps per wall second while
stepping (t = 0 to the horizon), start-up time (spawn and discovery: the simulator's
`discovery_wall_time`, and everything the orchestrator spent outside stepping), the peak resident
memory of every child process (VmHWM, sampled from /proc while the run goes on), and, when the
run is recorded, the messages of every topic per event (counted in the bag).
"""

from __future__ import annotations

import json
import os
import statistics
import threading
import time
from collections import Counter
from pathlib import Path

ROLES = (
    ('formation_sim.runtime.nodes.sim_node', 'simulator'),
    ('formation_agent.ros.main', 'agents'),
    ('formation_sim.runtime.nodes.recorder', 'recorder'),
    ('fast-discovery-server', 'discovery_server'),
    ('formation_sim.cli', 'command'),
    ('from formation_sim.cli import main', 'command'),
)


def _children(*, descendants: bool = False) -> dict[int, str]:
    """Processes whose parent is this process (or, with `descendants`, any of its descendants),
    with their role."""
    me = os.getpid()
    parents, commands = {}, {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            parents[int(entry.name)] = int(stat.rsplit(')', 1)[1].split()[1])
            commands[int(entry.name)] = (
                (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
            )
        except (OSError, ValueError, IndexError):
            continue

    def ours(pid: int) -> bool:
        for _ in range(8):  # the command, its children (through a launch prefix, at most a few levels)
            pid = parents.get(pid, 0)
            if pid == me:
                return True
            if not descendants or pid <= 1:
                return False
        return False

    found = {}
    for pid, command in commands.items():
        if not ours(pid):
            continue
        role = next((role for marker, role in ROLES if marker in command), None)
        if role is not None:
            found[pid] = role
    return found


def _peak_rss_kib(pid: int) -> int | None:
    try:
        for line in Path(f'/proc/{pid}/status').read_text().splitlines():
            if line.startswith('VmHWM:'):
                return int(line.split()[1])
    except OSError:
        return None
    return None


class _MemoryWatch(threading.Thread):
    """Peak RSS per child process, sampled every `period` seconds until stopped."""

    def __init__(self, period: float = 0.2, *, descendants: bool = False) -> None:
        super().__init__(daemon=True)
        self.period = period
        self.descendants = descendants
        self.peaks: dict[int, int] = {}
        self.roles: dict[int, str] = {}
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.is_set():
            for pid, role in _children(descendants=self.descendants).items():
                peak = _peak_rss_kib(pid)
                if peak is not None:
                    self.roles[pid] = role
                    self.peaks[pid] = max(peak, self.peaks.get(pid, 0))
            self._halt.wait(self.period)

    def stop(self) -> dict[str, list[int]]:
        self._halt.set()
        self.join()
        by_role: dict[str, list[int]] = {}
        for pid, peak in self.peaks.items():
            by_role.setdefault(self.roles[pid], []).append(peak)
        return by_role


def _bag_counts(bag: Path) -> Counter:
    """Messages per topic; Status messages of discovery (step_index -1) counted apart."""
    from formation_msgs_py.codec import decode_status
    from formation_msgs_py.topics import STATUS_TOPIC
    from formation_sim.bag.io import decode, read_bag

    counts: Counter = Counter()
    for topic, msgtype, _, rawdata in read_bag(bag):
        if topic == STATUS_TOPIC and decode_status(decode(rawdata, msgtype)).step_index < 0:
            topic += ' (discovery)'
        counts[topic] += 1
    return counts


def measure_run(
    scenario,
    *,
    out_dir: Path,
    horizon: float,
    domain_id: int,
    agents_per_process: int = 1,
    record: bool = False,
    sample_period: float = 0.01,
    executor: str = 'events',
    timeout: float = 600.0,
) -> dict:
    """One lock-step run; the measurements described in the module docstring."""
    from formation_sim.runtime.launch.orchestrate import FormationRun

    watch = _MemoryWatch()
    watch.start()
    started = time.monotonic()
    try:
        result = FormationRun(
            scenario,
            out_dir=out_dir,
            horizon=horizon,
            domain_id=domain_id,
            agents_per_process=agents_per_process,
            record=record,
            sample_period=sample_period,
            executor=executor,
            progress=False,
            timeout=timeout,
        ).run()
    finally:
        memory = watch.stop()
    total = time.monotonic() - started
    row: dict = {
        'scenario': scenario.name,
        'n': len(scenario.agent_ids),
        'edges': len(scenario.edges),
        'horizon': horizon,
        'agents_per_process': agents_per_process,
        'processes': -(-len(scenario.agent_ids) // agents_per_process),
        'record': record,
        'sample_period': sample_period,
        'executor': executor,
        'ok': result.ok,
        'message': result.message,
        'total_wall_s': total,
    }
    agents_kib = memory.get('agents', [])
    row['memory'] = {
        'agent_process_peak_mib_median': statistics.median(agents_kib) / 1024 if agents_kib else None,
        'agents_total_peak_mib': sum(agents_kib) / 1024,
        'per_agent_mib': sum(agents_kib) / 1024 / len(scenario.agent_ids) if agents_kib else None,
        'simulator_peak_mib': max(memory.get('simulator', [0])) / 1024,
        'recorder_peak_mib': max(memory.get('recorder', [0])) / 1024 if 'recorder' in memory else None,
    }
    if not result.ok or result.summary is None:
        return row
    summary = json.loads(Path(result.summary).read_text())
    extra = summary['extra']
    stepping = summary['wall_time']
    events = summary['total_events']
    row.update(
        events=events,
        steps=extra['steps'],
        messages_sent=summary['messages_sent'],
        stepping_wall_s=stepping,
        events_per_s=events / stepping,
        steps_per_s=extra['steps'] / stepping,
        discovery_s=extra['discovery_wall_time'],
        outside_stepping_s=total - stepping,
    )
    if record and result.bag is not None:
        counts = _bag_counts(result.bag)
        grouped: Counter = Counter()
        for topic, count in counts.items():
            if '/trigger_info/' in topic:
                grouped['trigger_info'] += count
            elif topic.endswith(('/cmd_vel', '/cmd_accel')):
                grouped['command'] += count
            else:
                grouped[topic] += count
        row['messages_per_event'] = {key: value / events for key, value in sorted(grouped.items())}
        row['messages_per_step'] = {key: value / extra['steps'] for key, value in sorted(grouped.items())}
    return row
