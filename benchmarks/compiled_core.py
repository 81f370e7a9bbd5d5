"""The compiled core against the pure-Python path (issue 31), in one run.

    python benchmarks/compiled_core.py [--quick] [--sizes 10 100 1000 10000] [--repeats 3]

For ETA-1 and ETA-2 random teams (`cases.random`, seed 1) of each size, the in-process engine
(`simulate(..., sample_dt=None, sample_events=False)`: the event chain only) runs on the pure-Python
path and on the compiled one (`compiled.use_compiled`), alternating, `--repeats` times each (once at
n >= 10 000); the event chains must be equal float for float (the run stops otherwise). Reported: µs
per event and per event × (1 + mean degree), median wall and CPU of the repeats, and the speed-up
(since issue 31's second step the compiled searches run inside the compiled agenda, so the time in
them is no longer measured apart). Building the world and the agents is a fixed cost of a run, which
"whole run / events" spreads over however many events the horizon holds; so each repeat also runs the
team to T/2 and times the set-up alone (--no-marginal skips both): the marginal CPU per event
(CPU(T) - CPU(T/2)) / (events(T) - events(T/2)) and the run without its set-up are reported beside
the whole run / events. Each timed piece starts after `gc.collect()` (untimed), so that a full
collection of the garbage collector (~0.1 s at n = 1000) lands in a repeat by that repeat's own
allocations, not by what the previous one left. At the largest ETA-1 size the vectorised fixed-step simulation
(benchmarks/naive.py, dt = 1e-4) runs on the same scenario and horizon (skipped with --no-fixed-
step). Last, the start-up time and peak memory of an agent process (`import
formation_agent.ros.main` and one agent's first search, as `peak_rss.py` measures a process) with
HEAD's packages and with BASELINE_REV's (before the compiled core), alternating.

Writes benchmarks/results/<date>-compiled_core.json and prints the Markdown tables of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import gc
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from cases import build_scenario, label, random  # noqa: E402 - benchmarks/ put on sys.path first
from engine_baseline import PACKAGES, materialise  # noqa: E402 - benchmarks/ put on sys.path first

from formation_agent.core import compiled  # noqa: E402 - after the path is set up
from formation_sim.sim.engine import build_agents, simulate  # noqa: E402 - after the path is set up
from formation_sim.sim.world import World  # noqa: E402 - after the path is set up

# main before the compiled core.
BASELINE_REV = 'b089890'

# Horizons: a few thousand events at most per path (ETA-2's event rate grows with n, cases.py).
HORIZONS = {
    ('single', 10): 2.0,
    ('single', 100): 2.0,
    ('single', 1000): 0.5,
    ('single', 10000): 0.05,
    ('double', 10): 2.0,
    ('double', 100): 0.002,
    ('double', 1000): 1e-6,
    ('double', 10000): 1e-8,
}

# An agent process: the node's module, an agent of the paper's single example, its first search.
_AGENT = """
import sys, time
started = time.perf_counter()
{prelude}
import formation_agent.ros.main
from formation_agent.core.eta import Eta1Agent
from formation_msgs_py.types import SensedState, TriggerInfo
agent = Eta1Agent(agent_id=1, neighbours={{2: (1.0, 0.0), 3: (0.0, 1.0)}}, delta=3.0, alpha=1.0, beta=0.5)
agent.trigger(0.0, SensedState(agent=1, stamp=0.0, rel_positions={{2: (1.2, 0.1), 3: (0.1, 0.8)}}))
for j, rel in ((2, (-1.2, -0.1)), (3, (-0.1, -0.8))):
    agent.receive(TriggerInfo(sender=j, receiver=1, stamp=0.0, control=(0.1, -0.2), rel_position=rel))
agent.next_trigger_time(100.0)
try:
    from formation_agent.core import compiled
    which = compiled.implementation()
except ImportError:
    which = 'python (no compiled core yet)'
print(time.perf_counter() - started, which)
"""

_PRELUDE_BASELINE = """
root = {root!r}
sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, '__module__', '').startswith('__editable__')]
sys.path[:0] = [root + '/src/' + package for package in {packages!r}]
"""


def _run_engine(scenario, horizon: float, on: bool):
    compiled.use_compiled(on)
    gc.collect()  # from a collected heap: a full collection lands in this run by its own allocations
    cpu, started = time.process_time(), time.perf_counter()
    record = simulate(scenario, horizon=horizon, sample_dt=None, sample_events=False)
    return time.perf_counter() - started, time.process_time() - cpu, record.trigger_times


def _setup_cpu(scenario, on: bool) -> float:
    """CPU seconds of what `simulate` does once per run before its first event: the world and the
    agents (`World.from_scenario`, `build_agents`), as `simulate` builds them."""
    compiled.use_compiled(on)
    gc.collect()
    cpu = time.process_time()
    World.from_scenario(scenario)
    build_agents(scenario)
    return time.process_time() - cpu


def engine_case(dynamics: str, n: int, repeats: int, horizon: float, *, marginal: bool = True) -> dict:
    """Both paths on one random team, alternating. With `marginal`, each repeat also runs the team to
    horizon / 2 and times the set-up (world and agents) alone: the marginal CPU per event is
    (CPU(T) - CPU(T/2)) / (events(T) - events(T/2)), the set-up's CPU is reported beside, and the run
    without its set-up is (CPU(T) - set-up) / events(T); the whole run / events stays reported."""
    case = random(n, dynamics)
    scenario = build_scenario(case)
    degree = 2.0 * len(scenario.edges) / scenario.n
    walls = {False: [], True: []}
    cpus = {False: [], True: []}
    setups = {False: [], True: []}
    halves = {False: [], True: []}  # CPU of the same team run to horizon / 2 (the marginal cost)
    chains, half_chains = {}, {}
    for _ in range(repeats):
        for on in (False, True):
            wall, cpu, times = _run_engine(scenario, horizon, on)
            walls[on].append(wall)
            cpus[on].append(cpu)
            if on in chains and chains[on] != times:
                raise SystemExit(f'{label(case)}: two runs of one path differ')
            chains[on] = times
            if marginal:
                _, half_cpu, half_chains[on] = _run_engine(scenario, horizon / 2.0, on)
                halves[on].append(half_cpu)
                setups[on].append(_setup_cpu(scenario, on))
    if chains[False] != chains[True] or half_chains.get(False) != half_chains.get(True):
        raise SystemExit(f'{label(case)}: the compiled and the pure-Python event chains differ')
    events = sum(map(len, chains[True].values()))
    half_events = sum(map(len, half_chains[True].values())) if marginal else 0
    out = {'case': label(case), 'n': n, 'dynamics': dynamics, 'horizon': horizon, 'degree': degree}
    out.update(events=events, bit_equal=True)
    for on, name in ((False, 'python'), (True, 'compiled')):
        wall = statistics.median(walls[on])
        out[name] = {
            'walls': walls[on],
            'cpus': cpus[on],
            'wall': wall,
            'cpu': statistics.median(cpus[on]),
            'us_per_event': wall / events * 1e6,
            'us_per_event_edge': wall / events / (1.0 + degree) * 1e6,
            'cpu_us_per_event': statistics.median(cpus[on]) / events * 1e6,
        }
        if marginal:
            cpu_full, cpu_half = statistics.median(cpus[on]), statistics.median(halves[on])
            setup = statistics.median(setups[on])
            out[name].update(
                half_cpus=halves[on],
                setup_cpus=setups[on],
                setup_cpu=setup,
                run_us_per_event=(cpu_full - setup) / events * 1e6,
                marginal_us_per_event=(cpu_full - cpu_half) / (events - half_events) * 1e6,
            )
    out['speedup'] = out['python']['wall'] / out['compiled']['wall']
    out['speedup_cpu'] = out['python']['cpu'] / out['compiled']['cpu']
    if marginal:
        out['half_events'] = half_events
        for key in ('run_us_per_event', 'marginal_us_per_event'):
            out[f'speedup_{key}'] = out['python'][key] / out['compiled'][key]
    return out


def fixed_step_case(n: int, horizon: float) -> dict:
    from naive import simulate_fixed_step

    scenario = build_scenario(random(n, 'single'))
    cpu = time.process_time()
    result = simulate_fixed_step(scenario, horizon=horizon, dt=1e-4)
    return {
        'case': label(random(n, 'single')),
        'horizon': horizon,
        'events': result.total_events,
        'wall': result.wall_time,
        'cpu': time.process_time() - cpu,
        'max_overshoot': max(result.overshoot, default=0.0),
    }


def _agent_process(prelude: str) -> dict:
    code = _AGENT.format(prelude=prelude)
    with tempfile.NamedTemporaryFile('w', suffix='.log') as log:
        out = subprocess.run(
            [sys.executable, str(HERE / 'peak_rss.py'), log.name, '--', sys.executable, '-c', code],
            capture_output=True,
            text=True,
            check=True,
        )
        measured = json.loads(out.stdout)
        said = Path(log.name).read_text()
        if measured['exit'] != 0:
            raise SystemExit(f'the agent process failed: {said}')
    measured['ready_s'], measured['implementation'] = said.split(maxsplit=1)
    measured['implementation'] = measured['implementation'].strip()
    return measured


def agent_startup(repeats: int, baseline: str = BASELINE_REV) -> dict:
    """Start-up wall time and peak RSS of an agent process, before (BASELINE_REV) and now (HEAD with
    the compiled core built here), alternating; both from materialised packages on sys.path, so
    that the import machinery is the same (not the editable installs' finder)."""
    import formation_agent.core._fastcore as built

    with tempfile.TemporaryDirectory(prefix='bench_compiled_') as folder:
        roots = {'before': Path(folder) / 'before', 'now': Path(folder) / 'now'}
        materialise(baseline, roots['before'])
        materialise('HEAD', roots['now'])
        shutil.copy(built.__file__, roots['now'] / 'src' / 'formation_agent' / 'formation_agent' / 'core')
        preludes = {
            name: _PRELUDE_BASELINE.format(root=str(root), packages=PACKAGES) for name, root in roots.items()
        }
        preludes['now_pure'] = preludes['now'] + "import os; os.environ['FORMATION_PURE_PYTHON'] = '1'\n"
        runs = {name: [] for name in preludes}
        for _ in range(repeats):
            for name, prelude in preludes.items():
                runs[name].append(_agent_process(prelude))
    out = {'baseline': baseline, 'runs': runs}
    for name, values in runs.items():
        out[name] = {
            'wall_s': statistics.median(v['wall_s'] for v in values),
            'peak_rss_mib': statistics.median(v['peak_rss_mib'] for v in values),
        }
    return out


def tables(result: dict) -> str:
    lines = [
        '| case | n | d̄ | T [s] | events | Python µs/event | compiled µs/event | Python µs/(event·(1+d̄)) '
        '| compiled µs/(event·(1+d̄)) | speed-up wall (CPU) | Python → compiled CPU µs/event | bit-equal |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for c in result['engine']:
        p, f = c['python'], c['compiled']
        lines.append(
            f'| {c["case"]} | {c["n"]} | {c["degree"]:.1f} | {c["horizon"]:g} | {c["events"]} '
            f'| {p["us_per_event"]:.0f} | {f["us_per_event"]:.0f} | {p["us_per_event_edge"]:.0f} '
            f'| {f["us_per_event_edge"]:.1f} | {c["speedup"]:.2f}× ({c["speedup_cpu"]:.2f}×) '
            f'| {p["cpu"] / c["events"] * 1e6:.0f} → {f["cpu"] / c["events"] * 1e6:.0f} | yes |'
        )
    marginal = [c for c in result['engine'] if 'half_events' in c]
    if marginal:
        lines += [
            '',
            '| case | events T (T/2) | set-up CPU ms Python / compiled | whole run / events: CPU µs '
            '(speed-up) | run without set-up / events | marginal (T − T/2) / events |',
            '|---|---|---|---|---|---|',
        ]
    for c in marginal:
        p, f = c['python'], c['compiled']
        cells = [
            f'{p[key]:.0f} → {f[key]:.0f} ({p[key] / f[key]:.1f}×)'
            for key in ('cpu_us_per_event', 'run_us_per_event', 'marginal_us_per_event')
        ]
        lines.append(
            f'| {c["case"]} | {c["events"]} ({c["half_events"]}) '
            f'| {p["setup_cpu"] * 1e3:.0f} / {f["setup_cpu"] * 1e3:.0f} | ' + ' | '.join(cells) + ' |'
        )
    if result.get('fixed_step'):
        s = result['fixed_step']
        lines += [
            '',
            '| case | T [s] | fixed-step events | fixed-step wall [s] | max overshoot |',
            '|---|---|---|---|---|',
            f'| {s["case"]} | {s["horizon"]:g} | {s["events"]} | {s["wall"]:.2f} '
            f'| {s["max_overshoot"]:.3g} |',
        ]
    if result.get('startup'):
        s = result['startup']
        lines += [
            '',
            '| agent process | start-up wall [s] (median) | peak RSS [MiB] (median) |',
            '|---|---|---|',
        ]
        for name, text in (
            ('before', f'before ({s["baseline"]})'),
            ('now', 'now, compiled'),
            ('now_pure', 'now, FORMATION_PURE_PYTHON=1'),
        ):
            lines.append(f'| {text} | {s[name]["wall_s"]:.3f} | {s[name]["peak_rss_mib"]:.1f} |')
    return '\n'.join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100, 1000, 10000])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--startup-repeats', type=int, default=7)
    parser.add_argument('--quick', action='store_true', help='n = 10 and 100, one repeat (a smoke run)')
    parser.add_argument('--startup-only', action='store_true', help='the agent process only')
    parser.add_argument('--no-fixed-step', action='store_true', help='without the fixed-step comparison')
    parser.add_argument('--no-startup', action='store_true', help='without the agent process')
    parser.add_argument(
        '--no-marginal',
        action='store_true',
        help='without the half-horizon runs and the set-up timing (the marginal cost per event)',
    )
    parser.add_argument('--baseline', default=BASELINE_REV, help='the revision compared with')
    args = parser.parse_args()
    if not compiled.AVAILABLE:
        raise SystemExit('the compiled core is not built: run `make venv`')
    if args.quick:
        args.sizes, args.repeats, args.startup_repeats = [10, 100], 1, 2
    if args.startup_only:
        args.sizes = []
    result = {
        'date': dt.datetime.now(dt.UTC).isoformat(timespec='seconds'),
        'load_before': os.getloadavg(),
        'engine': [],
    }
    stamp = dt.datetime.now(dt.UTC).strftime('%Y%m%d-%H%M%S')
    out = HERE / 'results' / f'{stamp}-compiled_core.json'
    for dynamics in ('single', 'double'):
        for n in args.sizes:
            repeats = 1 if n >= 10000 else args.repeats  # minutes per run at n = 10 000
            case = engine_case(dynamics, n, repeats, HORIZONS[dynamics, n], marginal=not args.no_marginal)
            result['engine'].append(case)
            out.write_text(json.dumps(result, indent=1))  # what is done so far, should a case not end
            print(json.dumps({k: v for k, v in case.items() if k not in ('python', 'compiled')}), flush=True)
    if args.sizes and not args.no_fixed_step:
        largest = max(args.sizes)
        result['fixed_step'] = fixed_step_case(largest, HORIZONS['single', largest])
    if not args.no_startup:
        result['startup'] = agent_startup(args.startup_repeats, args.baseline)
    result['load_after'] = os.getloadavg()
    out.write_text(json.dumps(result, indent=1))
    print(tables(result))
    print(f'written: {out.relative_to(HERE.parent)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
