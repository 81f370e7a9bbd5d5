"""`formation simulate` through the command line, measured from outside, against the code before
the streaming record (issue 14) run in the same benchmark run.

Each run is a process of its own: its wall time, its peak resident memory (the kernel's
`ru_maxrss` of that process, taken by `peak_rss.py`), and the engine's own wall time from its
summary.json (the event loop alone). The previous code is `CLI_BASELINE_REV` (main before the
streaming record), materialised once (`engine_baseline.materialise`) and run by `cli_baseline.py`
on the YAML form of the same scenario (it reads no JSON); its triggering times are compared with
the current run's. At n = 10 000 the previous command could not run at all (its YAML loader
refuses files above 300 000 nodes, and its record would hold every event state, ~12 GB): its
baseline is its Python API with grid samples only (`simulate(..., sample_events=False)`), as the
issue measured it, via `engine_baseline.py`.

Also: how long `load_scenario` takes for the same team as YAML and as JSON.
"""

from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CLI_BASELINE_REV = '07d9656'  # main before the streaming record (issue 14)


def scenario_files(folder: Path, case: dict) -> tuple[Path, Path]:
    """The case's scenario as YAML (for the previous code) and as JSON."""
    from cases import build_scenario

    from formation_sim.model.scenario import dump_scenario

    scenario = build_scenario(case).replace(horizon=case['horizon'])
    paths = folder / f'{scenario.name}.yaml', folder / f'{scenario.name}.json'
    for path in paths:
        dump_scenario(scenario, path)
    return paths


def measure_process(command: list[str], log: Path) -> dict:
    """Wall time, peak RSS (MiB) and exit status of `command`, through `peak_rss.py`; its output in `log`."""
    done = subprocess.run(
        [sys.executable, str(HERE / 'peak_rss.py'), str(log), '--', *command],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout)


def run_process(command: list[str], out: Path) -> dict:
    """Run `command` (a formation simulate writing into `out`); wall, peak RSS, engine wall, triggers."""
    log = out.with_name(out.name + '.log')
    row = measure_process(command, log)
    if row['exit'] != 0:
        row['error'] = log.read_text(errors='replace')[-500:]
        return row
    summary = json.loads((out / 'summary.json').read_text())
    row.update(
        engine_wall_s=summary['wall_time'],
        events=summary['total_events'],
        trigger_times=summary['trigger_times'],
    )
    row['ratio'] = row['wall_s'] / summary['wall_time']
    row['trajectory_mib'] = (
        sum(path.stat().st_size for path in out.rglob('*') if path.is_file() and path.name != 'formation.png')
        / 2**20
    )
    return row


def measure_case(case: dict, *, repeats: int, baseline_folder: Path | None, work: Path) -> dict:
    """The current command (default options, and --no-plot) and the previous one, `repeats` times each."""
    yaml_path, json_path = scenario_files(work, case)
    rows: dict[str, list[dict]] = {'now': [], 'now_no_plot': [], 'before': []}
    for repeat in range(repeats):
        for key, extra in (('now', []), ('now_no_plot', ['--no-plot'])):
            out = work / f'{key}-{repeat}'
            rows[key].append(
                run_process(
                    [
                        sys.executable,
                        '-m',
                        'formation_sim.cli',
                        'simulate',
                        str(json_path),
                        '--out',
                        str(out),
                        '--quiet',
                        *extra,
                    ],
                    out,
                )
            )
            shutil.rmtree(out, ignore_errors=True)
        if baseline_folder is not None:
            out = work / f'before-{repeat}'
            command = [
                sys.executable,
                str(HERE / 'cli_baseline.py'),
                str(baseline_folder),
                'simulate',
                str(yaml_path),
                '--out',
                str(out),
                '--quiet',
            ]
            rows['before'].append(run_process(command, out))
            shutil.rmtree(out, ignore_errors=True)
    if baseline_folder is None and case.get('api_baseline'):
        for repeat in range(case.get('api_repeats', 1)):
            log = work / f'api-{repeat}.log'
            command = [
                sys.executable,
                str(HERE / 'engine_baseline.py'),
                CLI_BASELINE_REV,
                json.dumps({**case, 'engine': {'sample_events': False}}),
            ]
            process = measure_process(command, log)
            engine = json.loads(log.read_text().strip().splitlines()[-1])
            # The process (scenario built from the case, the revision's engine) and the engine's own
            # wall time.
            rows['before'].append(
                {
                    'wall_s': process['wall_s'],
                    'peak_rss_mib': process['peak_rss_mib'],
                    'engine_wall_s': engine['wall_s'],
                    'ratio': process['wall_s'] / engine['wall_s'],
                    'events': engine['events'],
                }
            )
    result = {'case': case, 'repeats': repeats, 'runs': rows}
    for key, runs in rows.items():
        done = [run for run in runs if run.get('exit', 0) == 0]
        if not done:
            continue
        result[key] = {
            name: statistics.median(run[name] for run in done)
            for name in ('wall_s', 'peak_rss_mib', 'engine_wall_s', 'ratio', 'trajectory_mib', 'events')
            if all(name in run for run in done)
        }
    triggers = [run['trigger_times'] for runs in rows.values() for run in runs if 'trigger_times' in run]
    result['trigger_times_equal'] = all(t == triggers[0] for t in triggers) if len(triggers) > 1 else None
    for runs in rows.values():
        for run in runs:
            run.pop('trigger_times', None)
    return result


def measure(cases: list[dict], *, repeats: int, progress) -> list[dict]:
    from engine_baseline import materialise

    results = []
    with tempfile.TemporaryDirectory(prefix='bench_cli_') as tmp:
        baseline = Path(tmp) / 'baseline'
        materialise(CLI_BASELINE_REV, baseline)
        for case in cases:
            progress(f'cli n={case["n"]} T={case["horizon"]}')
            work = Path(tmp) / f'n{case["n"]}'
            work.mkdir()
            results.append(
                measure_case(
                    case,
                    repeats=repeats,
                    baseline_folder=None if case.get('api_baseline') else baseline,
                    work=work,
                )
            )
            shutil.rmtree(work, ignore_errors=True)
    return results


def load_times(sizes: list[int], *, repeats: int = 3) -> list[dict]:
    """Median seconds of `load_scenario` for random teams as YAML and as JSON (the same team)."""
    from cases import build_scenario, random

    from formation_sim.model.errors import ScenarioError
    from formation_sim.model.scenario import dump_scenario, load_scenario

    rows = []
    with tempfile.TemporaryDirectory(prefix='bench_load_') as tmp:
        for n in sizes:
            scenario = build_scenario(random(n))
            row = {'n': n, 'edges': len(scenario.edges)}
            for kind in ('yaml', 'json'):
                path = Path(tmp) / f'team.{kind}'
                dump_scenario(scenario, path)
                row[f'{kind}_mib'] = path.stat().st_size / 2**20
                walls, refused = [], None
                for _ in range(repeats):
                    started = time.perf_counter()
                    try:
                        assert load_scenario(path) == scenario
                    except ScenarioError as error:
                        refused = str(error).split(': ', 1)[1][:90]
                    walls.append(time.perf_counter() - started)
                row[f'{kind}_s'] = statistics.median(walls)
                row[f'{kind}_refused'] = refused
            rows.append(row)
    return rows
