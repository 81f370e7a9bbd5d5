"""`formation run` from the outside: time to first result and large teams, now and at a baseline.

Each measurement runs the `formation` command as a process of its own and times it from its start
to its exit (what a user waits for), either with the working tree's packages or with those of an
earlier git revision (the baseline), materialised by `engine_baseline.materialise` and put first
on the path of the command and of every process it starts (they inherit its PYTHONPATH, and the
baseline's own `fastdds_profile.xml` comes with it).  The run's summary.json gives the stepping
wall time (t = 0 to the horizon, measured by the simulator) and, for code that writes them, the
phases (extra.timeline); the peak resident memory of every process under the command is sampled
from /proc (`distributed._MemoryWatch`, descendants included).

Used by run.py's sections `startup` and `large`: python benchmarks/run.py --only startup large
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from cases import build_scenario  # noqa: E402 - benchmarks/ put on sys.path first
from engine_baseline import PACKAGES, materialise  # noqa: E402 - benchmarks/ put on sys.path first

from formation_sim.runtime.launch.plan import resolve_agents_per_process  # noqa: E402 - after the path is set up

# The code before the start-up work of issue 14 (main when it began).
BASELINE_REV = 'f87c698'

# Runs the command with REV's packages first on the path (sys.argv[1]: their folder); the
# editable installs of the working tree must not fill in what REV lacks.
_BASELINE_COMMAND = f"""
import sys
root = sys.argv.pop(1)
sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, '__module__', '').startswith('__editable__')]
sys.path[:0] = [root + '/src/' + package for package in {PACKAGES!r}]
from formation_sim.cli import main
import formation_sim
assert formation_sim.__file__.startswith(root), formation_sim.__file__
sys.exit(main(sys.argv[1:]))
"""


class Baseline:
    """REV's three packages in a temporary folder, while in use."""

    def __init__(self, rev: str = BASELINE_REV) -> None:
        self.rev = rev
        self._folder = tempfile.TemporaryDirectory(prefix='bench_startup_baseline_')
        materialise(rev, Path(self._folder.name))
        self.root = self._folder.name

    def close(self) -> None:
        self._folder.cleanup()


def command(baseline: Baseline | None) -> list[str]:
    if baseline is None:
        return [sys.executable, '-m', 'formation_sim.cli']
    return [sys.executable, '-c', _BASELINE_COMMAND, baseline.root]


def formation_run(
    scenario,
    *,
    out: Path,
    horizon: float,
    domain_id: int,
    baseline: Baseline | None = None,
    extra: tuple[str, ...] = (),
    timeout: float = 3600.0,
) -> dict:
    """One `formation run` of `scenario` (written to a YAML file) into `out`: the measurements."""
    from distributed import _MemoryWatch

    from formation_sim.model.scenario import dump_scenario

    out.mkdir(parents=True, exist_ok=True)
    path = out / f'{scenario.name}.yaml'
    dump_scenario(scenario, path)
    run_dir = out / 'run'
    argv = [
        *command(baseline),
        'run',
        str(path),
        '--horizon',
        repr(horizon),
        '--out',
        str(run_dir),
        '--force',
        '--domain-id',
        str(domain_id),
        *extra,
    ]
    watch = _MemoryWatch(descendants=True)
    watch.start()
    started = time.monotonic()
    try:
        done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    finally:
        memory = watch.stop()
    row: dict = {
        'code': 'now' if baseline is None else f'before ({baseline.rev})',
        'n': len(scenario.agent_ids),
        'horizon': horizon,
        'options': list(extra),
        'exit_status': done.returncode,
        'total_wall_s': time.monotonic() - started,
        'message': (done.stderr.strip().splitlines() or [''])[-1][:300],
        'memory_mib': {
            role: {'processes': len(peaks), 'sum': sum(peaks) / 1024, 'max': max(peaks) / 1024}
            for role, peaks in memory.items()
        },
    }
    summary_path = run_dir / 'summary.json'
    if not summary_path.is_file():
        return row
    summary = json.loads(summary_path.read_text())
    extra_ = summary['extra']
    row.update(
        events=summary['total_events'],
        steps=extra_['steps'],
        stepping_s=summary['wall_time'],
        discovery_s=extra_.get('discovery_wall_time'),
        trigger_times=summary['trigger_times'],
        timeline=extra_.get('timeline'),
        phases=extra_.get('phases'),
    )
    row['outside_stepping_s'] = row['total_wall_s'] - row['stepping_s']
    return row


def equal_to_engine(row: dict, scenario, horizon: float) -> dict:
    """Whether the run's triggering times are the in-process engine's, float for float."""
    from formation_sim.sim.engine import simulate

    reference = simulate(scenario, horizon=horizon, sample_dt=None)
    got = row.pop('trigger_times', None)
    if got is None:
        return {'equal': None}
    worst, same = 0.0, True
    for agent, times in reference.trigger_times.items():
        mine = got[str(agent)]
        if len(mine) != len(times):
            same = False
            continue
        worst = max([worst, *(abs(a - b) for a, b in zip(mine, times))])
    return {'equal': same and worst == 0.0, 'engine_events': reference.total_events, 'max_difference': worst}


def time_to_first_result(cases: list[dict], *, repeats: int, runs: Path, domains, progress) -> list[dict]:
    """`formation run` of each case, now and at the baseline, `repeats` times each, alternating."""
    baseline = Baseline()
    rows = []
    try:
        for case in cases:
            scenario = build_scenario(case)
            for k in range(repeats):
                for code in (baseline, None):
                    name = 'now' if code is None else 'before'
                    progress(f'startup {scenario.name} T={case["horizon"]} {name} ({k + 1}/{repeats})')
                    row = formation_run(
                        scenario,
                        out=runs / f'startup-{scenario.name}-{name}-{k}',
                        horizon=case['horizon'],
                        domain_id=next(domains),
                        baseline=code,
                        extra=tuple(case.get('extra', ())),
                    )
                    row.pop('trigger_times', None)
                    row['case'] = case['label']
                    rows.append(row)
    finally:
        baseline.close()
    return rows


def summarise(rows: list[dict]) -> list[dict]:
    """Medians per case and code; ratios now / before."""
    table = []
    for case in dict.fromkeys(r['case'] for r in rows):
        medians = {}
        for code in dict.fromkeys(r['code'] for r in rows if r['case'] == case):
            done = [r for r in rows if r['case'] == case and r['code'] == code and r['exit_status'] == 0]
            if not done:
                continue
            medians[code] = entry = {'case': case, 'code': code, 'runs': len(done)}
            for key in ('total_wall_s', 'stepping_s', 'outside_stepping_s', 'discovery_s'):
                entry[key] = statistics.median(r[key] for r in done)
            entry['outside_over_stepping'] = statistics.median(
                r['outside_stepping_s'] / r['stepping_s'] for r in done
            )
            phases = [r['phases'] for r in done if r.get('phases')]
            if phases:
                entry['phases'] = {
                    key: statistics.median(p[key] for p in phases if key in p) for key in phases[0]
                }
                marks = [r['timeline'] for r in done]
                entry['timeline'] = {
                    key: statistics.median(m[key] for m in marks if key in m) for key in marks[0]
                }
        now = medians.get('now')
        before = next((v for k, v in medians.items() if k != 'now'), None)
        if now and before:
            now['total_now_over_before'] = now['total_wall_s'] / before['total_wall_s']
            now['outside_now_over_before'] = now['outside_stepping_s'] / before['outside_stepping_s']
        table += list(medians.values())
    return table


def large_teams(cases: list[dict], *, runs: Path, domains, progress, timeout: float) -> list[dict]:
    """Random teams of 100 to 1000 agents, packed, without bag or figure: simple discovery and the
    discovery server now, and the baseline where the case says so; one run each, one at a time."""
    baseline = None
    rows = []
    try:
        for case in cases:
            scenario = build_scenario(case)
            for variant in case['variants']:
                code = None
                if variant == 'before':
                    baseline = baseline or Baseline()
                    code = baseline
                extra = [
                    '--no-record',
                    '--no-plot',
                    '--agents-per-process',
                    str(case['per_process']),
                    '--timeout',
                    repr(timeout),
                ]
                if variant == 'server':
                    extra.append('--discovery-server')
                progress(
                    f'large n={len(scenario.agent_ids)} T={case["horizon"]} {variant} '
                    f'({case["per_process"]} per process)'
                )
                row = formation_run(
                    scenario,
                    out=runs / f'large-{len(scenario.agent_ids)}-{variant}',
                    horizon=case['horizon'],
                    domain_id=next(domains),
                    baseline=code,
                    extra=tuple(extra),
                    timeout=timeout + 300.0,
                )
                row.update(equal_to_engine(row, scenario, case['horizon']))
                n = len(scenario.agent_ids)
                per_process = resolve_agents_per_process(case['per_process'], n)
                row.update(
                    case=case['label'],
                    variant=variant,
                    per_process=per_process,
                    processes=-(-n // per_process),
                )
                rows.append(row)
    finally:
        if baseline is not None:
            baseline.close()
    return rows
