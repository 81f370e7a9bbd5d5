"""What a robot run costs in CPU, per kind of process: now and at the code before (issue 19).

    .venv/bin/python benchmarks/cpu.py [--horizon 30] [--repeats 1] [--baseline REV]
        [--profile DIR] [--out DIR]

Runs `formation run robots_square --backend unicycle` (4 agents, 4 simulated robots, the
coordinator, the recorder) as a process of its own, with the working tree's packages and with
those of a baseline revision (`--baseline`, BASELINE_REV by default; `startup.Baseline`, first on
the path of the command and of every process it starts), alternating.  A watcher samples utime +
stime (/proc/<pid>/stat) of every process under the command every SAMPLE_PERIOD s, by kind (its
command line), and reports each kind's CPU as a fraction of one core:

- `stepping`: over the run's steady state, from STEADY_AFTER s after step 0 to STEADY_BEFORE s
  before the final Step (the Unix times of both in summary.json's extra.timestamps), what a
  robot's computer pays while the team moves;
- `life`: over each process's whole life (imports, discovery, the end included), per second of
  the command's wall time; its CPU seconds are also split into the phases before step 0 (imports,
  discovery), from step 0 to the final Step, and after it (the end), per kind.

Both codes' modules are compiled before the runs (`compileall`), as an installed package's are.
Per agent and per simulated robot: the kind's total divided by the number of agents or robots
(robots may share a process).  Then each kind's threads over the stepping window
(/proc/<pid>/task: the main thread 'python', where the executor runs every callback, and Fast
DDS's 'dds.*' threads).

`--profile DIR` runs every child under cProfile (a sitecustomize on PYTHONPATH; the main thread's
CPU time, `time.thread_time`, where the executor runs every callback; written when the process
exits) and prints each kind's top functions by own time.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from startup import Baseline, command  # noqa: E402 - after the sys.path entry above

BASELINE_REV = 'da90a99'  # main when issue 19's CPU work began
SCENARIO = 'robots_square'
SAMPLE_PERIOD = 0.25
STEADY_AFTER = 3.0
STEADY_BEFORE = 1.0
TICKS = os.sysconf('SC_CLK_TCK')

KINDS = (  # (marker in the command line, kind)
    ('formation_agent.ros.main', 'agents'),
    ('formation_sim.runtime.nodes.robot_node', 'robots'),
    ('formation_sim.runtime.nodes.coordinator', 'coordinator'),
    ('formation_sim.runtime.nodes.recorder', 'recorder'),
)

_PROFILE_HOOK = """
import atexit, cProfile, os, sys, time
_folder = os.environ.get('FORMATION_CPU_PROFILE')
_kind = next((k for m, k in {kinds!r} if any(m in a for a in sys.argv + getattr(sys, 'orig_argv', []))), None)
if _folder and _kind:
    _profile = cProfile.Profile(time.thread_time)  # CPU of the main thread (the callbacks), not wall time
    _profile.enable()
    _path = os.path.join(_folder, f'{{_kind}}-{{os.getpid()}}.prof')
    atexit.register(lambda: (_profile.disable(), _profile.dump_stats(_path)))
"""


class CpuWatch(threading.Thread):
    """utime + stime of every descendant process, by kind, every SAMPLE_PERIOD s."""

    def __init__(self, root_pid: int) -> None:
        super().__init__(daemon=True)
        self.root = root_pid
        self.samples: dict[int, list[tuple[float, float]]] = {}  # pid -> [(unix time, cpu seconds)]
        self.kinds: dict[int, str] = {}
        # Per thread: (pid, tid) -> [(unix time, cpu seconds)], and its (kind, thread name).
        self.thread_samples: dict[tuple[int, int], list[tuple[float, float]]] = {}
        self.thread_names: dict[tuple[int, int], tuple[str, str]] = {}
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.is_set():
            now = time.time()
            for pid, (kind, cpu) in _descendants(self.root).items():
                self.kinds[pid] = kind
                self.samples.setdefault(pid, []).append((now, cpu))
                for tid, (name, thread_cpu) in _threads(pid).items():
                    self.thread_names[pid, tid] = (kind, name)
                    self.thread_samples.setdefault((pid, tid), []).append((now, thread_cpu))
            self._halt.wait(SAMPLE_PERIOD)

    def stop(self) -> None:
        self._halt.set()
        self.join()

    def cpu_between(self, start: float, end: float) -> dict[str, float]:
        """CPU seconds each kind used between two Unix times (linear between samples)."""
        used: dict[str, float] = {}
        for pid, series in self.samples.items():
            used[self.kinds[pid]] = used.get(self.kinds[pid], 0.0) + _at(series, end) - _at(series, start)
        return used

    def thread_cpu_between(self, start: float, end: float) -> dict[str, float]:
        """CPU seconds between two Unix times by kind and thread ('agents python', 'robots dds.shm')."""
        used: dict[str, float] = {}
        for key, series in self.thread_samples.items():
            label = ' '.join(self.thread_names[key])
            used[label] = used.get(label, 0.0) + _at(series, end) - _at(series, start)
        return used

    def cpu_life(self) -> dict[str, float]:
        used: dict[str, float] = {}
        for pid, series in self.samples.items():
            used[self.kinds[pid]] = used.get(self.kinds[pid], 0.0) + series[-1][1]
        return used


def _at(series: list[tuple[float, float]], when: float) -> float:
    if when <= series[0][0]:
        return series[0][1] if when >= series[0][0] - SAMPLE_PERIOD else 0.0
    for (t0, c0), (t1, c1) in zip(series, series[1:]):
        if t0 <= when <= t1:
            return c0 + (c1 - c0) * (when - t0) / (t1 - t0)
    return series[-1][1]


def _threads(pid: int) -> dict[int, tuple[str, float]]:
    """Each thread of `pid`: its name (Fast DDS's port numbers cut: 'dds.shm.7411' -> 'dds.shm')
    and its utime + stime."""
    found = {}
    try:
        tasks = list(Path(f'/proc/{pid}/task').iterdir())
    except OSError:
        return found
    for task in tasks:
        try:
            stat = (task / 'stat').read_text()
        except OSError:
            continue
        name = re.sub(r'\.\d+$', '', stat[stat.index('(') + 1 : stat.rindex(')')])
        fields = stat.rsplit(')', 1)[1].split()
        found[int(task.name)] = (name, (int(fields[11]) + int(fields[12])) / TICKS)
    return found


def _descendants(root: int) -> dict[int, tuple[str, float]]:
    parents, found = {}, {}
    stats = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            fields = stat.rsplit(')', 1)[1].split()
            parents[int(entry.name)] = int(fields[1])
            stats[int(entry.name)] = (entry, (int(fields[11]) + int(fields[12])) / TICKS)
        except (OSError, ValueError, IndexError):
            continue
    for pid, (entry, cpu) in stats.items():
        ancestor, ours = pid, False
        for _ in range(8):
            ancestor = parents.get(ancestor, 0)
            if ancestor == root:
                ours = True
                break
            if ancestor <= 1:
                break
        if not ours:
            continue
        try:
            line = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
        except OSError:
            continue
        kind = next((kind for marker, kind in KINDS if marker in line), None)
        if kind is not None:
            found[pid] = (kind, cpu)
    return found


def measure(
    *, baseline: Baseline | None, out: Path, horizon: float, domain_id: int, profile: Path | None
) -> dict:
    """One run: each kind's CPU as a fraction of one core, stepping and over its life."""
    run_dir = out / 'run'
    argv = [
        *command(baseline),
        'run',
        SCENARIO,
        '--backend',
        'unicycle',
        '--horizon',
        repr(horizon),
        '--out',
        str(run_dir),
        '--force',
        '--domain-id',
        str(domain_id),
        '--no-plot',
    ]
    env = dict(os.environ)
    if profile is not None:
        hook = Path(tempfile.mkdtemp(prefix='bench_cpu_hook_'))
        (hook / 'sitecustomize.py').write_text(_PROFILE_HOOK.format(kinds=KINDS))
        profile.mkdir(parents=True, exist_ok=True)
        env.update(
            FORMATION_CPU_PROFILE=str(profile),
            PYTHONPATH=os.pathsep.join(filter(None, [str(hook), env.get('PYTHONPATH')])),
        )
    began = time.time()
    process = subprocess.Popen(
        argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    watch = CpuWatch(process.pid)
    watch.start()
    try:
        _, stderr = process.communicate(timeout=horizon + 300.0)
    finally:
        watch.stop()
    ended = time.time()
    row: dict = {
        'code': 'now' if baseline is None else f'before ({baseline.rev})',
        'exit_status': process.returncode,
        'message': (stderr.strip().splitlines() or [''])[-1][:300],
        'wall_s': ended - began,
        'processes': {kind: sum(1 for k in watch.kinds.values() if k == kind) for _, kind in KINDS},
    }
    life = watch.cpu_life()
    row['life'] = {kind: life.get(kind, 0.0) / row['wall_s'] for _, kind in KINDS}
    summary = run_dir / 'summary.json'
    if summary.is_file():
        extra = json.loads(summary.read_text())['extra']
        marks = extra.get('timestamps', {})  # the time keeper's Unix times
        if 'step0' not in marks:  # older code: its timeline, counted from about the command's start
            marks = {name: began + at for name, at in extra.get('timeline', {}).items()}
        if 'step0' in marks and 'final_step' in marks:
            step0, final = marks['step0'], marks['final_step']
            start, end = step0 + STEADY_AFTER, final - STEADY_BEFORE
            used = watch.cpu_between(start, end)
            row['stepping_window_s'] = end - start
            row['stepping'] = {kind: used.get(kind, 0.0) / (end - start) for _, kind in KINDS}
            threads = watch.thread_cpu_between(start, end)
            row['stepping_threads'] = {label: cpu / (end - start) for label, cpu in sorted(threads.items())}
            row['phases_s'] = _phases(watch, began - SAMPLE_PERIOD, step0, final)
    return row


def _phases(watch: CpuWatch, before: float, step0: float, final: float) -> dict[str, dict[str, float]]:
    """CPU seconds of each kind before step 0, from step 0 to the final Step, and after it."""
    first, run, life = watch.cpu_between(before, step0), watch.cpu_between(step0, final), watch.cpu_life()
    return {
        kind: {
            'start': first.get(kind, 0.0),
            'run': run.get(kind, 0.0),
            'end': life.get(kind, 0.0) - first.get(kind, 0.0) - run.get(kind, 0.0),
        }
        for _, kind in KINDS
    }


def phase_table(rows: list[dict]) -> str:
    """CPU seconds per kind (all its processes) before step 0, stepping and after the final Step
    (medians over the runs of a code)."""
    lines = ['| code | kind | start [s] | run [s] | end [s] |', '|---|---|---|---|---|']
    for code in dict.fromkeys(r['code'] for r in rows):
        done = [r['phases_s'] for r in rows if r['code'] == code and r.get('phases_s')]
        for kind in dict.fromkeys(kind for _, kind in KINDS):
            if done:
                cells = [
                    statistics.median(run[kind][phase] for run in done) for phase in ('start', 'run', 'end')
                ]
                lines.append(f'| {code} | {kind} | ' + ' | '.join(f'{c:.2f}' for c in cells) + ' |')
    return '\n'.join(lines)


def per_unit(row: dict, key: str, n: int) -> dict:
    """Fractions of a core: per agent, per robot, the coordinator, the recorder, and the total."""
    shares = row.get(key)
    if not shares:
        return {}
    return {
        'agent': shares['agents'] / n,
        'robot': shares['robots'] / n,
        'coordinator': shares['coordinator'],
        'recorder': shares['recorder'],
        'total': sum(shares.values()),
    }


def table(rows: list[dict], n: int) -> str:
    lines = [
        '| code | window | per agent | per simulated robot | coordinator | recorder | total | processes |',
        '|---|---|---|---|---|---|---|---|',
    ]
    for code in dict.fromkeys(r['code'] for r in rows):
        done = [r for r in rows if r['code'] == code and r['exit_status'] == 0]
        for key in ('stepping', 'life'):
            units = [per_unit(r, key, n) for r in done if r.get(key)]
            if not units:
                continue
            median = {name: statistics.median(u[name] for u in units) for name in units[0]}
            processes = ', '.join(f'{k} {v}' for k, v in done[0]['processes'].items())
            lines.append(
                f'| {code} | {key} | {median["agent"]:.1%} | {median["robot"]:.1%} | '
                f'{median["coordinator"]:.1%} | {median["recorder"]:.1%} | {median["total"]:.1%} | '
                f'{processes} |'
            )
    return '\n'.join(lines)


def thread_table(rows: list[dict]) -> str:
    """Each kind's threads in the stepping window (medians over the runs of a code): where the CPU
    goes, the executor's thread ('python': every callback) against Fast DDS's ('dds.*')."""
    codes = list(dict.fromkeys(r['code'] for r in rows))
    shares = {
        code: [r['stepping_threads'] for r in rows if r['code'] == code and r.get('stepping_threads')]
        for code in codes
    }
    labels = sorted({label for runs in shares.values() for run in runs for label in run})
    lines = ['| process kind, thread | ' + ' | '.join(codes) + ' |', '|---|' + '---|' * len(codes)]
    for label in labels:
        cells = [
            f'{statistics.median(run.get(label, 0.0) for run in shares[code]):.1%}' if shares[code] else '-'
            for code in codes
        ]
        if any(cell not in ('0.0%', '-') for cell in cells):
            lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def print_profiles(folder: Path, *, top: int) -> None:
    for kind in dict.fromkeys(kind for _, kind in KINDS):
        files = sorted(str(p) for p in folder.glob(f'{kind}-*.prof'))
        if not files:
            continue
        stats = pstats.Stats(*files, stream=sys.stdout)
        print(f'\n===== {kind} ({len(files)} processes): by own time')
        stats.sort_stats('tottime').print_stats(top)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--horizon', type=float, default=30.0)
    parser.add_argument('--repeats', type=int, default=1)
    parser.add_argument(
        '--domain-id', type=int, default=180, help='ROS_DOMAIN_ID of the first run (then +1 per run)'
    )
    parser.add_argument(
        '--out', type=Path, default=None, help='where the runs go (default: a temporary folder)'
    )
    parser.add_argument('--only', choices=('now', 'before'), default=None, help='one code only')
    parser.add_argument(
        '--profile', type=Path, default=None, help='cProfile every child into this folder (now only)'
    )
    parser.add_argument('--top', type=int, default=25)
    parser.add_argument(
        '--baseline', default=BASELINE_REV, help=f'the code before: a git revision (default {BASELINE_REV})'
    )
    options = parser.parse_args()
    from formation_sim.model.scenario import load_scenario

    n = len(load_scenario(SCENARIO).agent_ids)
    out = options.out or Path(tempfile.mkdtemp(prefix='bench_cpu_'))
    codes = ['now'] if options.profile else [c for c in ('before', 'now') if options.only in (None, c)]
    baseline = Baseline(options.baseline) if 'before' in codes else None
    # Both codes' modules compiled ahead, as an installed package's are (pip compiles them): an
    # environment with PYTHONDONTWRITEBYTECODE would have every process compile them again.
    for tree in [ROOT, *([Path(baseline.root)] if baseline is not None else [])]:
        subprocess.run([sys.executable, '-m', 'compileall', '-q', str(tree / 'src')], check=True)
    rows, domain = [], options.domain_id
    try:
        for k in range(options.repeats):
            for code in codes:
                print(f'{code} ({k + 1}/{options.repeats}) ...', file=sys.stderr, flush=True)
                row = measure(
                    baseline=baseline if code == 'before' else None,
                    out=out / f'{code}-{k}',
                    horizon=options.horizon,
                    domain_id=domain,
                    profile=options.profile,
                )
                domain += 1
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    finally:
        if baseline is not None:
            baseline.close()
    print(
        f'robots_square, unicycle backend, horizon {options.horizon:g} s, {n} agents; fractions of one core'
    )
    print(table(rows, n))
    print('\nBy thread, stepping (all processes of a kind together):')
    print(thread_table(rows))
    print('\nCPU seconds by phase (all processes of a kind): before step 0, stepping, after the final Step:')
    print(phase_table(rows))
    (out / 'cpu.json').write_text(json.dumps(rows, indent=1))
    if options.profile:
        print_profiles(options.profile, top=options.top)
    return 0 if all(r['exit_status'] == 0 for r in rows) else 1


if __name__ == '__main__':
    sys.exit(main())
