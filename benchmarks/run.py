"""Benchmarks of the exact engine and the distributed runtime (`make bench`).

    python benchmarks/run.py                      # everything (about an hour on 2 cores)
    python benchmarks/run.py --only engine naive  # some sections
    python benchmarks/run.py --quick              # small cases only, one repeat

Sections: `engine` (in-process speed, ETA-1/ETA-2, paper examples and random teams, against the
implementation before the speed work, measured in the same run), `naive` (a fixed-step
simulation of the same controllers, dt = 1e-4: speed and accuracy), `comm` (messages and
sensing: event-triggered, periodic, continuous), `distributed` (lock-step throughput, start-up,
memory, messages per event, against a bare rclpy round trip), `long` (peak memory of long
distributed runs), `cli` (`formation simulate` as a process at n = 1000, 3000, 10 000: wall time
against the engine's, peak memory, against the code before the streaming record; scenario load
times, YAML and JSON), `startup` (time to first result of `formation run`: every phase, against the
code before the start-up work, alternating), `large` (100 to 1000 agents: simple discovery and a
discovery server, against the code before; `startup.py`).
Results go to benchmarks/results/<date>.json and .md; BENCHMARKS.md at the repository root holds
the tables of a full run with the machine they came from.

Timing: wall-clock and process CPU time; each engine case is repeated and the median reported.
The machine is shared, so ratios against baselines measured in the same run are the numbers to
compare, and the load average is recorded before and after each section.
"""

from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from cases import build_scenario, builtin, label, random  # noqa: E402 - benchmarks/ put on sys.path first

# The implementation before the speed work (its parent commit), for the speed-up columns.
BASELINE_REV = 'fe95009^'
# ROS_DOMAIN_IDs of the benchmarks' runs, one after the other (ping-pong uses 201); no test pins
# one of these (tests/ use 200, 201, 224, 231, 232 of formation run's range).
DOMAINS = itertools.cycle(range(204, 224))


def machine() -> dict:
    import numpy as np
    import scipy

    cpu = next(
        (
            line.split(':', 1)[1].strip()
            for line in Path('/proc/cpuinfo').read_text().splitlines()
            if line.startswith('model name')
        ),
        '?',
    )
    try:
        from importlib.metadata import version

        rclpy_version = version('rclpy')
    except Exception:  # noqa: BLE001 - informative only
        rclpy_version = '?'
    rev = subprocess.run(
        ['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    return {
        'date': dt.datetime.now(dt.UTC).strftime('%Y-%m-%d %H:%M UTC'),
        'nproc': os.cpu_count(),
        'cpu': cpu,
        'python': platform.python_version(),
        'numpy': np.__version__,
        'scipy': scipy.__version__,
        'rclpy': rclpy_version,
        'git': rev,
        'memory_gib': round(os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30, 1),
    }


def load() -> float:
    return os.getloadavg()[0]


def _degree(scenario) -> float:
    return 2.0 * len(scenario.edges) / len(scenario.agent_ids)


# -- engine -----------------------------------------------------------------------------------


def engine_cases(quick: bool) -> list[dict]:
    if quick:
        return [
            {**builtin('paper_single'), 'horizon': 10.0, 'repeats': 1, 'baseline': True},
            {**random(100), 'horizon': 2.0, 'repeats': 1, 'baseline': True},
        ]
    return [
        {**builtin('paper_single'), 'horizon': 10.0, 'repeats': 5, 'baseline': True},
        {**builtin('paper_double'), 'horizon': 10.0, 'repeats': 5, 'baseline': True},
        {**random(10), 'horizon': 2.0, 'repeats': 5, 'baseline': True},
        {**random(100), 'horizon': 2.0, 'repeats': 3, 'baseline': True},
        {**random(1000), 'horizon': 2.0, 'repeats': 3, 'baseline': False},
        {**random(1000), 'horizon': 0.5, 'repeats': 1, 'baseline': True},
        {**random(10000), 'horizon': 0.2, 'repeats': 1, 'baseline': False},
        {**random(10, 'double'), 'horizon': 2.0, 'repeats': 3, 'baseline': True},
        {**random(100, 'double'), 'horizon': 0.01, 'repeats': 3, 'baseline': True},
        {**random(1000, 'double'), 'horizon': 1e-6, 'repeats': 1, 'baseline': False},
        {**random(10000, 'double'), 'horizon': 1e-8, 'repeats': 1, 'baseline': False},
    ]


def run_engine(case: dict) -> dict:
    from formation_sim.sim.engine import simulate

    scenario = build_scenario(case)
    walls, cpus = [], []
    for _ in range(case['repeats']):
        cpu = time.process_time()
        record = simulate(scenario, horizon=case['horizon'], sample_dt=None, sample_events=False)
        cpus.append(time.process_time() - cpu)
        walls.append(record.wall_time)
    wall, cpu = statistics.median(walls), statistics.median(cpus)
    row = {
        'case': label(case),
        'n': scenario.n,
        'mean_degree': _degree(scenario),
        'horizon': case['horizon'],
        'events': record.total_events,
        'wall_s': wall,
        'cpu_s': cpu,
        'walls': walls,
        'events_per_s': record.total_events / wall,
        'us_per_event': 1e6 * wall / record.total_events,
        'us_per_event_degree': 1e6 * wall / (record.total_events * (1.0 + _degree(scenario))),
    }
    if case.get('baseline'):
        out = subprocess.run(
            [sys.executable, str(HERE / 'engine_baseline.py'), BASELINE_REV, json.dumps(case)],
            capture_output=True,
            text=True,
            timeout=3600,
            check=True,
        )
        base = json.loads(out.stdout.strip().splitlines()[-1])
        row['baseline'] = base
        row['speedup'] = base['wall_s'] / wall
    return row


def engine_recording_cost() -> dict:
    """The default record (state at every event and every 0.01 s) against trigger times only."""
    from formation_sim.sim.engine import simulate

    scenario = build_scenario(random(1000))
    lean = simulate(scenario, horizon=0.5, sample_dt=None, sample_events=False)
    full = simulate(scenario, horizon=0.5)
    return {
        'case': 'random ETA-1 n=1000, T=0.5',
        'lean_wall_s': lean.wall_time,
        'full_wall_s': full.wall_time,
        'full_samples': len(full.sample_times),
        'full_sample_mib': full.sample_positions.nbytes / 2**20,
    }


# -- cli --------------------------------------------------------------------------------------


def cli_cases(quick: bool) -> list[dict]:
    if quick:
        return [{**random(300), 'horizon': 2.0}]
    return [
        {**random(1000), 'horizon': 2.0},
        {**random(3000), 'horizon': 2.0},
        # The previous command cannot run it (below): its Python API with grid samples is the baseline.
        {**random(10000), 'horizon': 2.0, 'api_baseline': True, 'api_repeats': 2},
    ]


def _cli_markdown(results: dict) -> list[str]:
    lines = [
        '| n | T [s] | events | engine wall [s] | process wall [s] | process / engine | peak RSS '
        '[MiB] | trajectory [MiB] | '
        '--no-plot: process / engine | before: process wall [s] | before: process / engine | '
        'before: peak RSS [MiB] | '
        'wall before / now | RSS before / now | same triggering times |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for r in results['cli']:
        now, bare, before = r.get('now', {}), r.get('now_no_plot', {}), r.get('before', {})
        api = r['case'].get('api_baseline')
        before_wall = before.get('wall_s')
        before_text = f'{_fmt(before_wall)} (Python API, grid samples)' if api else _fmt(before_wall)
        lines.append(
            f'| {r["case"]["n"]} | {_fmt(r["case"]["horizon"])} | {_fmt(now.get("events"))} | '
            f'{_fmt(now.get("engine_wall_s"))} | '
            f'{_fmt(now.get("wall_s"))} | {_fmt(now.get("ratio"), 3)}× | '
            f'{_fmt(now.get("peak_rss_mib"))} | {_fmt(now.get("trajectory_mib"))} | '
            f'{_fmt(bare.get("ratio"), 3)}× | {before_text} | '
            f'{_fmt(before.get("ratio"), 3) + "×" if "ratio" in before else "–"} | '
            f'{_fmt(before.get("peak_rss_mib"))} | '
            f'{_fmt(before_wall / now["wall_s"] if before_wall and now.get("wall_s") else None)}× | '
            f'{_fmt(_ratio(before.get("peak_rss_mib"), now.get("peak_rss_mib")))}× | '
            f'{"yes" if r["trigger_times_equal"] else "NO" if r["trigger_times_equal"] is False else "–"} |'
        )
    return lines


# -- naive ------------------------------------------------------------------------------------


def naive_cases(quick: bool) -> list[dict]:
    if quick:
        return [{**random(100), 'horizon': 2.0}]
    return [
        {**builtin('paper_single'), 'horizon': 10.0},
        {**builtin('paper_double'), 'horizon': 10.0},
        {**random(10), 'horizon': 2.0},
        {**random(100), 'horizon': 2.0},
        {**random(1000), 'horizon': 2.0},
        {**random(10000), 'horizon': 0.2},
        {**random(10, 'double'), 'horizon': 2.0},
        {**random(100, 'double'), 'horizon': 0.01},
    ]


def run_naive(case: dict, dt_step: float = 1e-4) -> dict:
    import numpy as np
    from naive import simulate_fixed_step

    from formation_sim.sim.engine import simulate

    scenario = build_scenario(case)
    exact = simulate(scenario, horizon=case['horizon'], sample_dt=None, sample_events=False)
    naive = simulate_fixed_step(scenario, horizon=case['horizon'], dt=dt_step)
    overshoot = np.array(naive.overshoot) if naive.overshoot else np.zeros(1)
    return {
        'case': label(case),
        'horizon': case['horizon'],
        'dt': dt_step,
        'exact_events': exact.total_events,
        'exact_wall_s': exact.wall_time,
        'naive_events': naive.total_events,
        'naive_wall_s': naive.wall_time,
        'naive_over_exact_time': naive.wall_time / exact.wall_time,
        'overshoot_max': float(overshoot.max()),
        'overshoot_median': float(np.median(overshoot)),
        'connectivity_lost': naive.connectivity_lost,
        'reached': naive.reached,
    }


# -- comm -------------------------------------------------------------------------------------


def comm_cases(quick: bool) -> list[dict]:
    if quick:
        return [{**random(10), 'horizon': 10.0}]
    return [
        {**builtin('paper_single'), 'horizon': 10.0},
        {**builtin('paper_double'), 'horizon': 10.0},
        {**random(10), 'horizon': 10.0},
        {**random(100), 'horizon': 10.0},
        {**random(10, 'double'), 'horizon': 10.0},
    ]


def run_comm(case: dict) -> dict:
    from comm import compare

    row = compare(build_scenario(case), horizon=case['horizon'])
    row['case'] = label(case)
    return row


# -- distributed ------------------------------------------------------------------------------


def distributed_cases(quick: bool, *, three_agents: bool = False) -> list[dict]:
    if quick:
        return [{**builtin('paper_single'), 'horizon': 10.0, 'per_process': 1}]
    small = [
        {**builtin('paper_single'), 'horizon': 10.0, 'per_process': 1},
        # The same with rclpy's SingleThreadedExecutor (the runtime before the EventsExecutor),
        # and without the tools' state samples (the protocol alone).
        {**builtin('paper_single'), 'horizon': 10.0, 'per_process': 1, 'executor': 'single'},
        {**builtin('paper_single'), 'horizon': 10.0, 'per_process': 1, 'sample_period': 0.0},
    ]
    if three_agents:
        return small
    return [
        *small,
        {**random(10), 'horizon': 2.0, 'per_process': 1},
        {**random(30), 'horizon': 1.0, 'per_process': 1},
        {**random(100), 'horizon': 0.5, 'per_process': 25},
        {**random(300), 'horizon': 0.2, 'per_process': 50},
    ]


def run_distributed(case: dict, out: Path, *, record: bool = False) -> dict:
    from distributed import measure_run

    scenario = build_scenario(case)
    row = measure_run(
        scenario,
        out_dir=out,
        horizon=case['horizon'],
        domain_id=next(DOMAINS),
        agents_per_process=case['per_process'],
        record=record,
        sample_period=case.get('sample_period', 0.01),
        executor=case.get('executor', 'events'),
    )
    row['case'] = label(case) + ''.join(
        note
        for key, note in (
            ('executor', ' (SingleThreadedExecutor)'),
            ('sample_period', ' (events only, no samples)'),
        )
        if key in case
    )
    return row


# -- time to first result, large teams ---------------------------------------------------------------


def startup_cases(quick: bool) -> list[dict]:
    cases = [{**builtin('paper_single'), 'horizon': 10.0, 'label': 'paper_single T=10 (make demo)'}]
    if not quick:
        cases.append({**random(6), 'horizon': 2.0, 'label': 'random n=6 T=2'})
    return cases


def large_cases(quick: bool) -> list[dict]:
    if quick:
        return [
            {
                **random(100),
                'horizon': 0.5,
                'per_process': 25,
                'variants': ['simple', 'server'],
                'label': 'n=100',
            }
        ]
    return [
        {
            **random(100),
            'horizon': 0.5,
            'per_process': 25,
            'variants': ['before', 'simple', 'server'],
            'label': 'n=100',
        },
        {
            **random(300),
            'horizon': 0.2,
            'per_process': 50,
            'variants': ['before', 'simple', 'server'],
            'label': 'n=300',
        },
        {
            **random(1000),
            'horizon': 0.05,
            'per_process': 'auto',
            'variants': ['simple', 'server'],
            'label': 'n=1000',
        },
    ]


PROTOCOL_TOPICS = ('trigger_info', 'command', '/formation/step', '/formation/status')


def issue_bound(results: dict) -> dict:
    """The issue's lower bound per event: a bare round trip times the messages an event needs.

    Messages of the protocol per event, counted in the recorded 3-agent run (triggering
    information, commands, Steps, Statuses after discovery: topic round trips; sensing calls:
    service round trips), times the round trips measured in the same run, for both executors.
    """
    per_event = results['messages']['messages_per_event']
    topic_messages = sum(per_event.get(name, 0.0) for name in PROTOCOL_TOPICS)
    calls = per_event.get('/formation/sensing_log', 0.0)
    bound = {'topic_messages_per_event': topic_messages, 'sensing_calls_per_event': calls}
    for key, pingpong in (('single', results['pingpong']), ('events', results['pingpong_events_executor'])):
        bound[f'{key}_s'] = (
            topic_messages * pingpong['topic']['median_s'] + calls * pingpong['service']['median_s']
        )
    return bound


def run_pingpong(count: int, executor: str = 'single') -> dict:
    from pingpong import measure

    return measure(domain_id=201, count=count, executor=executor)


# -- report -----------------------------------------------------------------------------------


def _ratio(before, now):
    """before / now, or None when either is missing or zero."""
    return before / now if before and now else None


def _fmt(value, digits: int = 3) -> str:
    if value is None:
        return '–'
    if isinstance(value, float):
        if math.isinf(value):
            return '∞'
        return f'{value:.{digits}g}'
    return str(value)


def markdown(results: dict) -> str:
    lines: list[str] = []
    info = results['machine']
    lines += [
        f'Machine: {info["nproc"]} cores, {info["cpu"]}, {info["memory_gib"]} GiB; Python {info["python"]}, '
        f'numpy {info["numpy"]}, scipy {info["scipy"]}, rclpy {info["rclpy"]}; commit '
        f'{info["git"]}; {info["date"]}.',
        '',
    ]
    if 'engine' in results:
        lines += [
            '| case | n | mean degree | T [s] | events | wall [s] (median) | events/s | µs/event | '
            'µs/(event·(1+d̄)) | before [s] | speed-up |',
            '|---|---|---|---|---|---|---|---|---|---|---|',
        ]
        for r in results['engine']:
            base = r.get('baseline')
            speedup = f'{r["speedup"]:.1f}×' if base else '–'
            lines.append(
                f'| {r["case"]} | {r["n"]} | {r["mean_degree"]:.1f} | {_fmt(r["horizon"])} | '
                f'{r["events"]} | {r["wall_s"]:.3g} | '
                f'{r["events_per_s"]:.0f} | {r["us_per_event"]:.0f} | {r["us_per_event_degree"]:.0f} | '
                f'{_fmt(base["wall_s"]) if base else "–"} | {speedup} |'
            )
        lines.append('')
        if 'engine_recording' in results:
            rec = results['engine_recording']
            lines += [
                f'Recording cost ({rec["case"]}): trigger times only {rec["lean_wall_s"]:.2f} s; '
                'default record (state at every '
                f'event and every 0.01 s: {rec["full_samples"]} samples, '
                f'{rec["full_sample_mib"]:.0f} MiB) {rec["full_wall_s"]:.2f} s.',
                '',
            ]
    if 'naive' in results:
        lines += [
            '| case | T [s] | exact events | exact wall [s] | fixed-step events | fixed-step wall '
            '[s] | time ratio | max overshoot | median overshoot | connectivity |',
            '|---|---|---|---|---|---|---|---|---|---|',
        ]
        for r in results['naive']:
            lines.append(
                f'| {r["case"]} | {_fmt(r["horizon"])} | {r["exact_events"]} | '
                f'{r["exact_wall_s"]:.3g} | {r["naive_events"]} | '
                f'{r["naive_wall_s"]:.3g} | {r["naive_over_exact_time"]:.1f}× | '
                f'{r["overshoot_max"]:.3g} | {r["overshoot_median"]:.2g} | '
                f'{r["connectivity_lost"] or "kept"} |'
            )
        lines.append('')
    if 'comm' in results:
        lines += [
            '| case | T [s] | controller | period [s] | messages | sensing calls | final formation '
            'error | converged (< 1e-3) at [s] |',
            '|---|---|---|---|---|---|---|---|',
        ]
        for r in results['comm']:
            for name, row in r['rows'].items():
                if name == 'periodic' and row.get('period') is None:
                    lines.append(
                        f'| {r["case"]} | {_fmt(r["horizon"])} | periodic | none ≥ 1e-5 works | | | | |'
                    )
                    continue
                sensing = (
                    row['sensing_calls']
                    if name != 'continuous'
                    else f'continuous ({row["rhs_evaluations"]} evaluations)'
                )
                lines.append(
                    f'| {r["case"]} | {_fmt(r["horizon"])} | {name} | {_fmt(row.get("period"))} | '
                    f'{row["messages"]} | {sensing} | '
                    f'{_fmt(row["final_error"])} | {_fmt(row["convergence_time"])} |'
                )
        lines.append('')
    if 'pingpong' in results:
        p = results['pingpong']
        lines += [
            f'Bare rclpy round trip between two processes (PROTOCOL_QOS, {p["count"]} each, median '
            '/ p90): topic '
            f'{1e3 * p["topic"]["median_s"]:.2f} / {1e3 * p["topic"]["p90_s"]:.2f} ms, service '
            f'{1e3 * p["service"]["median_s"]:.2f} / {1e3 * p["service"]["p90_s"]:.2f} ms.',
            '',
        ]
        if 'pingpong_events_executor' in results:
            e = results['pingpong_events_executor']
            lines += [
                'The same with rclpy.experimental.EventsExecutor: topic '
                f'{1e3 * e["topic"]["median_s"]:.2f} / '
                f'{1e3 * e["topic"]["p90_s"]:.2f} ms, service {1e3 * e["service"]["median_s"]:.2f} '
                f'/ {1e3 * e["service"]["p90_s"]:.2f} ms.',
                '',
            ]
    if 'distributed' in results:
        bound = results.get('step_bound_s')
        bound_events = results.get('step_bound_events_s')
        if bound:
            lines += [
                'Lower bound per lock-step step (1.5 topic + 1 service round trip): '
                f'{1e3 * bound:.2f} ms with the '
                f'SingleThreadedExecutor, {1e3 * bound_events:.2f} ms with the EventsExecutor.',
                '',
            ]
        lines += [
            '| case | agents/process | processes | T [s] | events | steps | stepping wall [s] | '
            'events/s | steps/s | ms/step | × bound (single) | × bound (events) | discovery [s] | '
            'outside stepping [s] | RSS/agent [MiB] | simulator RSS [MiB] |',
            '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|',
        ]
        for r in results['distributed']:
            if not r.get('events'):
                lines.append(
                    f'| {r["case"]} | {r["agents_per_process"]} | {r["processes"]} | '
                    f'{_fmt(r["horizon"])} | failed: {r["message"][:80]} |'
                )
                continue
            ms = 1e3 / r['steps_per_s']
            lines.append(
                f'| {r["case"]} | {r["agents_per_process"]} | {r["processes"]} | '
                f'{_fmt(r["horizon"])} | {r["events"]} | {r["steps"]} | '
                f'{r["stepping_wall_s"]:.3g} | {r["events_per_s"]:.1f} | {r["steps_per_s"]:.1f} | {ms:.1f} | '
                f'{_fmt(ms / 1e3 / bound if bound else None, 2)} | '
                f'{_fmt(ms / 1e3 / bound_events if bound_events else None, 2)} | '
                f'{r["discovery_s"]:.2f} | {r["outside_stepping_s"]:.1f} | '
                f'{_fmt(r["memory"]["per_agent_mib"])} | {_fmt(r["memory"]["simulator_peak_mib"])} |'
            )
        lines.append('')
        if 'messages' in results:
            per_step = results['messages']['messages_per_step']
            lines += [
                'Messages per lock-step step (3 agents, recorded run, counted in the bag): '
                + ', '.join(f'{k} {v:.2f}' for k, v in per_step.items())
                + '.',
                '',
            ]
        if 'issue_bound' in results:
            b = results['issue_bound']
            first = next(r for r in results['distributed'] if r.get('events'))
            ms_event = 1e3 * first['stepping_wall_s'] / first['events']
            lines += [
                "The issue's bound (round trip × messages per event: "
                f'{b["topic_messages_per_event"]:.2f} topic messages and '
                f'{b["sensing_calls_per_event"]:.2f} sensing calls per event): '
                f'{1e3 * b["single_s"]:.2f} ms (SingleThreadedExecutor), '
                f'{1e3 * b["events_s"]:.2f} ms (EventsExecutor); {first["case"]}: {ms_event:.2f} ms '
                'per event = '
                f'{ms_event / 1e3 / b["single_s"]:.2f}× / {ms_event / 1e3 / b["events_s"]:.2f}×.',
                '',
            ]
    if 'scenario_load' in results:
        lines += [
            '| n | edges | YAML [MiB] | YAML load [s] | JSON [MiB] | JSON load [s] | YAML / JSON |',
            '|---|---|---|---|---|---|---|',
        ]
        for r in results['scenario_load']:
            yaml_text = (
                f'refused after {r["yaml_s"]:.2f} s ({r["yaml_refused"]})'
                if r['yaml_refused']
                else f'{r["yaml_s"]:.3g}'
            )
            ratio = '–' if r['yaml_refused'] else f'{r["yaml_s"] / r["json_s"]:.0f}×'
            lines.append(
                f'| {r["n"]} | {r["edges"]} | {r["yaml_mib"]:.2f} | {yaml_text} | '
                f'{r["json_mib"]:.2f} | {r["json_s"]:.3g} | {ratio} |'
            )
        lines.append('')
    if 'cli' in results:
        lines += [*_cli_markdown(results), '']
    if 'startup' in results:
        lines += [
            '| case | code | runs | `formation run` wall [s] | stepping [s] | outside stepping [s] '
            '| outside / stepping | discovery [s] | now / before: wall | now / before: outside |',
            '|---|---|---|---|---|---|---|---|---|---|',
        ]
        for r in results['startup']['table']:
            lines.append(
                f'| {r["case"]} | {r["code"]} | {r["runs"]} | {r["total_wall_s"]:.2f} | '
                f'{r["stepping_s"]:.2f} | {r["outside_stepping_s"]:.2f} | '
                f'{r["outside_over_stepping"]:.2f} | {_fmt(r["discovery_s"])} | '
                f'{_fmt(r.get("total_now_over_before"), 2)} | '
                f'{_fmt(r.get("outside_now_over_before"), 2)} |'
            )
        lines.append('')
        for r in results['startup']['table']:
            if r.get('timeline'):
                marks = ', '.join(f'{name} {at:.2f}' for name, at in r['timeline'].items())
                lines += [
                    f'{r["case"]}, {r["code"]}, marks of the run [s since FormationRun.run began, '
                    f'medians]: {marks}.',
                    '',
                ]
    if 'large' in results:
        lines += [
            '| team | code | discovery | agents/process | processes | ok | `formation run` wall '
            '[s] | discovery [s] | step 0 at [s] | steps | ms/step | end [s] | agents RSS [MiB] | '
            'simulator RSS [MiB] | equal to the engine |',
            '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|',
        ]
        for r in results['large']:
            code = 'before' if r['variant'] == 'before' else 'now'
            discovery = 'server' if r['variant'] == 'server' else 'simple'
            agents = r['memory_mib'].get('agents', {}).get('sum')
            simulator = r['memory_mib'].get('simulator', {}).get('max')
            head = (
                f'| {r["case"]} T={r["horizon"]:g} | {code} | {discovery} | {r["per_process"]} | '
                f'{r["processes"]} |'
            )
            if not r.get('events'):
                lines.append(
                    f'{head} no: {r["message"][:120]} | {r["total_wall_s"]:.0f} | | | | | | '
                    f'{_fmt(agents, 4)} | {_fmt(simulator, 3)} | – |'
                )
                continue
            timeline = r.get('timeline') or {}
            phases = r.get('phases') or {}
            lines.append(
                f'{head} {"yes" if r["exit_status"] == 0 else "no"} | {r["total_wall_s"]:.1f} | '
                f'{r["discovery_s"]:.1f} | {_fmt(timeline.get("step0"), 3)} | '
                f'{r["steps"]} | {1e3 * r["stepping_s"] / r["steps"]:.1f} | '
                f'{_fmt(phases.get("end"), 3)} | {_fmt(agents, 4)} | {_fmt(simulator, 3)} | '
                f'{"yes (max difference 0)" if r.get("equal") else r.get("equal")} |'
            )
        lines.append('')
    if 'long' in results:
        lines += [
            '| case | T [s] | ok | events | stepping wall [s] | agent process peak RSS [MiB] | '
            'simulator peak RSS [MiB] |',
            '|---|---|---|---|---|---|---|',
        ]
        for r in results['long']:
            lines.append(
                f'| {r["case"]} | {_fmt(r["horizon"])} | {"yes" if r["ok"] else r["message"][:90]} '
                f'| {r.get("events", "–")} | '
                f'{_fmt(r.get("stepping_wall_s"))} | '
                f'{_fmt(r["memory"]["agent_process_peak_mib_median"])} | '
                f'{_fmt(r["memory"]["simulator_peak_mib"])} |'
            )
        lines.append('')
    return '\n'.join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description='Benchmarks (see BENCHMARKS.md).')
    parser.add_argument(
        '--only',
        nargs='+',
        choices=('engine', 'naive', 'comm', 'distributed', 'long', 'cli', 'startup', 'large'),
        default=None,
    )
    parser.add_argument(
        '--repeats', type=int, default=5, help='startup: runs of each case and code (default 5)'
    )
    parser.add_argument('--quick', action='store_true', help='small cases, one repeat (a smoke run)')
    parser.add_argument(
        '--three-agents',
        action='store_true',
        help='distributed: only the 3-agent cases (the lock-step target)',
    )
    parser.add_argument(
        '--cli-agents',
        type=int,
        nargs='+',
        default=None,
        metavar='N',
        help='cli: only the teams of these sizes (1000, 3000, 10000)',
    )
    parser.add_argument('--out', type=Path, default=HERE / 'results')
    args = parser.parse_args()
    sections = args.only or ['engine', 'naive', 'comm', 'distributed', 'long', 'cli', 'startup', 'large']
    results: dict = {'machine': machine(), 'sections': sections, 'load': {}}
    args.out.mkdir(parents=True, exist_ok=True)
    stamp = dt.datetime.now(dt.UTC).strftime('%Y%m%d-%H%M%S')
    runs = Path(tempfile.mkdtemp(prefix=f'formation-bench-{stamp}-'))  # run folders (bags, logs): not kept

    def progress(text: str) -> None:
        print(f'[bench {time.strftime("%H:%M:%S")} load {load():.1f}] {text}', file=sys.stderr, flush=True)

    def save() -> None:
        (args.out / f'{stamp}.json').write_text(json.dumps(results, indent=1, default=str))
        (args.out / f'{stamp}.md').write_text(markdown(results) + '\n')

    if 'engine' in sections:
        results['load']['engine'] = [load()]
        results['engine'] = []
        for case in engine_cases(args.quick):
            progress(f'engine {label(case)} T={case["horizon"]}')
            results['engine'].append(run_engine(case))
            save()
        if not args.quick:
            progress('engine recording cost')
            results['engine_recording'] = engine_recording_cost()
        results['load']['engine'].append(load())
        save()
    if 'naive' in sections:
        results['naive'] = []
        for case in naive_cases(args.quick):
            progress(f'naive {label(case)} T={case["horizon"]}')
            results['naive'].append(run_naive(case))
            save()
    if 'comm' in sections:
        results['comm'] = []
        for case in comm_cases(args.quick):
            progress(f'comm {label(case)} T={case["horizon"]}')
            results['comm'].append(run_comm(case))
            save()
    if 'distributed' in sections:
        progress('ping-pong')
        results['pingpong'] = run_pingpong(300 if args.quick else 2000)
        results['pingpong_events_executor'] = run_pingpong(300 if args.quick else 2000, 'events')
        p = results['pingpong']
        # Critical path of one lock-step step (docs/MESSAGES.md): Step out, the due agent's
        # sensing call (a service round trip), its TriggerInfo to a neighbour, that neighbour's
        # Status back: 1.5 topic round trips and one service round trip.
        results['step_bound_s'] = 1.5 * p['topic']['median_s'] + p['service']['median_s']
        e = results['pingpong_events_executor']
        results['step_bound_events_s'] = 1.5 * e['topic']['median_s'] + e['service']['median_s']
        results['distributed'] = []
        for case in distributed_cases(args.quick, three_agents=args.three_agents):
            progress(f'distributed {label(case)} T={case["horizon"]} ({case["per_process"]} per process)')
            results['distributed'].append(run_distributed(case, runs / f'dist-{len(results["distributed"])}'))
            save()
        progress('distributed, recorded (messages per step)')
        recorded = run_distributed(
            {**builtin('paper_single'), 'horizon': 10.0, 'per_process': 1}, runs / 'recorded', record=True
        )
        results['messages'] = {
            k: recorded.get(k) for k in ('messages_per_event', 'messages_per_step', 'events', 'steps')
        }
        results['issue_bound'] = issue_bound(results)
        save()
    if 'long' in sections:
        results['long'] = []
        long_cases = [
            {**builtin('paper_single'), 'horizon': 20.0, 'per_process': 1},
            {**builtin('paper_single'), 'horizon': 40.0, 'per_process': 1},
            {**builtin('paper_single', beta=0.05), 'horizon': 20.0, 'per_process': 1},
            {**builtin('paper_single', beta=0.05), 'horizon': 200.0, 'per_process': 1},
        ]
        for case in long_cases[:1] if args.quick else long_cases:
            progress(f'long {label(case)} T={case["horizon"]}')
            results['long'].append(run_distributed(case, runs / f'long-{len(results["long"])}'))
            save()
    if 'cli' in sections:
        from cli import load_times, measure

        results['load']['cli'] = [load()]
        progress('scenario load times')
        cases = [
            case for case in cli_cases(args.quick) if args.cli_agents is None or case['n'] in args.cli_agents
        ]
        results['scenario_load'] = load_times([case['n'] for case in cases])
        save()
        results['cli'] = measure(cases, repeats=1 if args.quick else 3, progress=progress)
        results['load']['cli'].append(load())
        save()
    if 'startup' in sections:
        from startup import summarise, time_to_first_result

        results['load']['startup'] = [load()]
        rows = time_to_first_result(
            startup_cases(args.quick),
            repeats=1 if args.quick else args.repeats,
            runs=runs,
            domains=DOMAINS,
            progress=progress,
        )
        results['startup'] = {'runs': rows, 'table': summarise(rows)}
        results['load']['startup'].append(load())
        save()
    if 'large' in sections:
        from startup import large_teams

        results['load']['large'] = [load()]
        results['large'] = large_teams(
            large_cases(args.quick), runs=runs, domains=DOMAINS, progress=progress, timeout=900.0
        )
        results['load']['large'].append(load())
        save()
    save()
    print(markdown(results))
    print(f'\nresults: {args.out / stamp}.json, .md', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
