"""Robot faults measured from the outside: how fast every robot gets its zero command, how far the
robots move after the fault, how `formation run` ends, and whether `formation analyze` agrees.

Each row is one `formation run robots_square` (its own process, as a user starts it) on simulated
robots (`--backend unicycle`) or on `--backend external` driving a `formation robots` fleet.  An
observer node in this process reads every robot's velocity command (`/agent_<i>/robot/cmd_vel`)
and noise-free pose (`/agent_<i>/robot/true_odom`).  Once the run has driven the robots for
`--after` seconds, one fault is injected into one process, found by its command line:

- `robot_kill`: SIGKILL to robot 2's process;
- `robot_stop`: SIGSTOP to robot 2's process, SIGCONT 2 s later;
- `agent_kill`: SIGKILL to agent 2's process;
- `ctrl_c`: SIGINT to `formation run` (what Ctrl-C does);
- `pose_cut`: robot 2's pose feed stops while the robot lives on: SIGSTOP to its process and
  never SIGCONT until the run is over (a frozen driver; a motion-capture outage looks the same
  to the run).

Columns: the time from the fault to the last robot's last zero command (a robot whose agent was
killed gets its zero from the coordinator, `formation_sim.runtime.nodes.robot_stops`), the largest
distance a robot's control point... (its pose) travelled after the fault, the exit status and the message of
`formation run`, the time it took to exit after the fault, and whether `formation analyze` found
the bag to agree with summary.json.  A `robot_stop` row also says what the frozen robot did once
resumed (`resumed`): how far its first pose after SIGCONT lies from its last before the freeze,
how far it moved after that, the non-zero commands it was sent after SIGCONT, and the timeout
stops its log names (`resumed_by`: `formation run` had already ended, resuming and stopping it).

    python benchmarks/robot_faults.py --domain-id 33 [--faults robot_kill ctrl_c] \
        [--backends unicycle external]

Run it under the machine's ROS lock (`flock /tmp/ros-tests.lock ...`): it starts 10-20 processes a row.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

FAULTS = ('robot_kill', 'robot_stop', 'agent_kill', 'ctrl_c', 'pose_cut')
BACKENDS = ('unicycle', 'external')
ROBOTS = (1, 2, 3, 4)
VICTIM = 2


class Observer:
    """Every robot's commands and true poses, with their arrival times (monotonic)."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('robot_fault_observer', context=self.context)
        self.commands: dict[int, list[tuple[float, bool]]] = {i: [] for i in ROBOTS}  # (arrival, zero)
        # (arrival, x, y) per source: the noise-free true_odom, else the odometry (a noise-free
        # simulated robot publishes no true_odom: its odometry is exact)
        self.sources: dict[str, dict[int, list[tuple[float, float, float]]]] = {
            'true_odom': {i: [] for i in ROBOTS},
            'odom': {i: [] for i in ROBOTS},
        }
        for i in ROBOTS:
            self.node.create_subscription(
                Twist, f'/agent_{i}/robot/cmd_vel', lambda m, i=i: self._command(i, m), 100
            )
            for source in self.sources:
                self.node.create_subscription(
                    Odometry, f'/agent_{i}/robot/{source}', lambda m, i=i, s=source: self._pose(s, i, m), 100
                )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def _command(self, i: int, msg) -> None:
        self.commands[i].append((time.monotonic(), msg.linear.x == 0.0 and msg.angular.z == 0.0))

    def _pose(self, source: str, i: int, msg) -> None:
        p = msg.pose.pose.position
        self.sources[source][i].append((time.monotonic(), p.x, p.y))

    @property
    def poses(self) -> dict[int, list[tuple[float, float, float]]]:
        truth = self.sources['true_odom']
        return truth if any(truth.values()) else self.sources['odom']

    def driving(self) -> bool:
        return all(any(not zero for _, zero in self.commands[i]) for i in ROBOTS)

    def close(self) -> None:
        import rclpy

        self._stop.set()
        self._thread.join()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def last_zero_after(self, fault: float) -> tuple[float, list[int]]:
        """Seconds from the fault to the last robot's zero command (the first of the zeros that
        end its command stream); the robots whose stream does not end with a zero after the fault."""
        last, moving = 0.0, []
        for i in ROBOTS:
            after = [(at, zero) for at, zero in self.commands[i] if at >= fault]
            if not after or not after[-1][1]:
                moving.append(i)
                continue
            k = max((n for n, (_, zero) in enumerate(after) if not zero), default=-1)
            last = max(last, after[k + 1][0] - fault)
        return last, moving

    def largest_motion_after(self, fault: float) -> float:
        largest = 0.0
        poses = self.poses
        for i in ROBOTS:
            before = [(x, y) for at, x, y in poses[i] if at <= fault]
            if not before:
                continue
            x0, y0 = before[-1]
            largest = max([largest, *(math.hypot(x - x0, y - y0) for at, x, y in poses[i] if at > fault)])
        return largest

    def on_resume(self, robot: int, *, fault: float, resumed: float, logs: Path, by_run: bool) -> dict:
        """What a robot frozen at `fault` did once resumed: how far its first pose after SIGCONT
        is from its last before the freeze, how far it moved after that first pose, the non-zero
        commands it was sent after SIGCONT (unknown when `formation run` resumed it: `by_run`), and
        its own log's timeout stops."""
        poses = self.poses[robot]
        before = [(x, y) for at, x, y in poses if at <= fault]
        after = [(x, y) for at, x, y in poses if at > resumed]
        stops = []
        for log in logs.glob(f'robot*_{robot}*.log'):
            stops += [
                line.split(': ', 1)[-1]
                for line in log.read_text(errors='replace').splitlines()
                if 'stopping' in line
            ]
        return {
            'jump': math.hypot(after[0][0] - before[-1][0], after[0][1] - before[-1][1])
            if before and after
            else None,
            'moved_after': max(
                (math.hypot(x - after[0][0], y - after[0][1]) for x, y in after), default=None
            ),
            'poses_after': len(after),
            'nonzero_commands_after': (
                None if by_run else sum(1 for at, zero in self.commands[robot] if at > resumed and not zero)
            ),
            'timeout_stops': stops,
        }


def _pids(*words: str) -> list[int]:
    """Processes whose command line holds every one of `words`."""
    found = []
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            args = (entry / 'cmdline').read_bytes().decode(errors='replace').split('\0')
        except OSError:
            continue
        # A path or a module: within an argument; anything else (an id): an argument of its own.
        if all(
            any(word == arg or (('/' in word or '.' in word) and word in arg) for arg in args)
            for word in words
        ):
            found.append(int(entry.name))
    return found


def _one(pid_words: tuple[str, ...]) -> int:
    pids = _pids(*pid_words)
    if len(pids) != 1:
        raise RuntimeError(f'expected one process with {pid_words} in its command line, found {pids}')
    return pids[0]


def measure(backend: str, fault: str, *, domain_id: int, folder: Path, horizon: float, after: float) -> dict:
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_LOG_DIR': str(folder / 'ros_log')}
    formation = [sys.executable, '-m', 'formation_sim.cli']
    out, fleet_out = folder / f'{backend}_{fault}', folder / f'{backend}_{fault}_fleet'
    fleet = None
    if backend == 'external':
        fleet = subprocess.Popen(
            [
                *formation,
                'robots',
                'robots_square',
                '--model',
                'unicycle',
                '--domain-id',
                str(domain_id),
                '--out',
                str(fleet_out),
                '--robots-per-process',
                '1',
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
    observer = Observer(domain_id)
    run_args = [
        'run',
        'robots_square',
        '--backend',
        backend,
        '--horizon',
        str(horizon),
        '--out',
        str(out),
        '--domain-id',
        str(domain_id),
        '--no-plot',
    ]
    if backend == 'external':
        run_args += ['--robot', 'unicycle']
    else:  # a fault hits one robot: each its own process
        run_args += ['--robots-per-process', '1']
    run = subprocess.Popen(
        [*formation, *run_args],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    row = {'backend': backend, 'fault': fault}
    try:
        limit = time.monotonic() + 120.0
        while not observer.driving() and run.poll() is None and time.monotonic() < limit:
            time.sleep(0.05)
        if not observer.driving():
            raise RuntimeError(f'the robots never drove ({run.poll()=})')
        time.sleep(after)
        robot_params = str((fleet_out if backend == 'external' else out) / 'robots.params.yaml')
        fault_at = time.monotonic()
        if fault in ('robot_kill', 'robot_stop', 'pose_cut'):
            victim = _one(('formation_sim.runtime.nodes.robot_node', '--robots', robot_params, str(VICTIM)))
            os.kill(victim, {'robot_kill': signal.SIGKILL}.get(fault, signal.SIGSTOP))
            if fault == 'robot_stop':
                time.sleep(2.0)
                resumed_at = time.monotonic()
                try:
                    os.kill(victim, signal.SIGCONT)
                except ProcessLookupError:  # formation run ended first: it resumed and stopped it
                    row['resumed_by'] = 'formation run (SIGCONT with SIGINT at its end)'
                    resumed_at = fault_at + 0.05  # any pose of the frozen robot after this came after
        elif fault == 'agent_kill':
            os.kill(
                _one(('formation_agent.ros.main', '--agents', str(out / 'agents.params.yaml'), str(VICTIM))),
                signal.SIGKILL,
            )
        elif fault == 'ctrl_c':
            os.killpg(run.pid, signal.SIGINT)
        _, err = run.communicate(timeout=120)
        exited = time.monotonic() - fault_at
        if fault == 'pose_cut':
            with contextlib.suppress(ProcessLookupError):  # formation run stopped it (SIGINT with SIGCONT)
                os.kill(victim, signal.SIGCONT)
        time.sleep(0.5)  # the last commands and poses on their way
        last_zero, moving = observer.last_zero_after(fault_at)
        lines = [line for line in err.splitlines() if line.startswith('[formation run]')]
        row.update(
            last_zero=last_zero,
            still_moving=moving,
            motion=observer.largest_motion_after(fault_at),
            status=run.returncode,
            message=lines[-1].split(': ', 1)[-1] if lines else err.strip()[-200:],
            exited=exited,
        )
        analyze = subprocess.run(
            [*formation, 'analyze', str(out), '--no-figures', '--quiet'],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        report = out / 'analysis' / 'analysis.json'
        if report.is_file():
            analysis = json.loads(report.read_text())
            differences = [d['key'] for d in (analysis.get('summary_json') or {}).get('differences', [])]
            failing = [
                c['name']
                for c in analysis['bag_checks'] + analysis['theorem_checks']
                if not c['ok'] and c.get('binding', True)
            ]
        else:
            differences, failing = None, analyze.stderr.strip()[-300:]
        row.update(analyze=analyze.returncode, differences=differences, failing_checks=failing)
        if fault == 'robot_stop':
            logs = (fleet_out if backend == 'external' else out) / 'logs'
            row['resumed'] = observer.on_resume(
                VICTIM, fault=fault_at, resumed=resumed_at, logs=logs, by_run='resumed_by' in row
            )
    finally:
        for process in (run, fleet):
            if process is not None and process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
                process.wait(timeout=30)
        observer.close()
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--domain-id', type=int, required=True)
    parser.add_argument('--faults', nargs='+', choices=FAULTS, default=list(FAULTS))
    parser.add_argument('--backends', nargs='+', choices=BACKENDS, default=list(BACKENDS))
    parser.add_argument('--horizon', type=float, default=20.0)
    parser.add_argument('--after', type=float, default=3.0, help='seconds of driving before the fault')
    parser.add_argument('--json', type=Path, help='append the rows to this JSON lines file')
    parser.add_argument('--keep', type=Path, help='keep the run folders here (default: a temporary folder)')
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='robot_faults_') as temporary:
        folder = args.keep or temporary
        for backend in args.backends:
            for fault in args.faults:
                row = measure(
                    backend,
                    fault,
                    domain_id=args.domain_id,
                    folder=Path(folder),
                    horizon=args.horizon,
                    after=args.after,
                )
                print(json.dumps(row), flush=True)
                if args.json:
                    with args.json.open('a') as handle:
                        handle.write(json.dumps(row) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
