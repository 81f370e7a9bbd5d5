"""Loading a large team from YAML against the same team from JSON, now and at an earlier revision.

    python benchmarks/yaml_load.py [--before REV] [--repeats 5] [--n 3000 ...]

For each team (random, `formation_sim.model.generate.random_scenario(n, seed=1)`, ETA-1 and ETA-2)
the scenario is written once as YAML and as JSON; then, `repeats` times, alternating, this
process times `load_scenario` of both files with the current code, and a child process
(`--child`) times them with the packages of revision REV (materialised from git by
`engine_baseline.materialise`, put first on the path by `use_revision`): every number comes from
the same run on the same files. libyaml's own loader (`yaml.load(..., CSafeLoader)`, no checks)
is timed as a reference. Prints a markdown table and writes benchmarks/results/<date>-yaml.json.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from engine_baseline import materialise, use_revision  # noqa: E402 - benchmarks/ put on the path first

BEFORE = 'ff7503e'  # main before the libyaml loader (issue 21)


def _time(load, path: Path) -> float:
    started = time.perf_counter()
    load(path)
    return time.perf_counter() - started


def child(folder: Path, paths: list[Path]) -> None:
    """Time the revision in `folder` on `paths`; one JSON line: seconds per path."""
    use_revision(folder)
    from formation_sim.model.scenario import load_scenario

    assert Path(sys.modules['formation_sim'].__file__).is_relative_to(folder)
    print(json.dumps([_time(load_scenario, path) for path in paths]))


def _teams(sizes: list[int], folder: Path) -> list[dict]:
    from formation_sim.model.generate import random_scenario
    from formation_sim.model.scenario import dump_scenario

    teams = []
    for n in sizes:
        for dynamics in ('single', 'double'):
            scenario = random_scenario(n=n, seed=1, dynamics=dynamics)
            files = {kind: folder / f'{dynamics}_{n}.{kind}' for kind in ('yaml', 'json')}
            for path in files.values():
                dump_scenario(scenario, path)
            teams.append(
                {
                    'n': n,
                    'dynamics': dynamics,
                    'edges': len(scenario.edges),
                    'files': files,
                    'scenario': scenario,
                }
            )
    return teams


def run(sizes: list[int], before: str, repeats: int) -> dict:
    import yaml

    from formation_sim.model.scenario import load_scenario

    with tempfile.TemporaryDirectory(prefix='bench_yaml_') as tmp:
        folder = Path(tmp)
        materialise(before, folder / 'before')
        teams = _teams(sizes, folder)
        paths = [team['files'][kind] for team in teams for kind in ('yaml', 'json')]
        times: dict[str, list[list[float]]] = {'now': [], 'before': [], 'libyaml': []}
        for _ in range(repeats):
            times['now'].append([_time(load_scenario, path) for path in paths])
            times['libyaml'].append(
                [_time(lambda p: yaml.load(p.read_text(), Loader=yaml.CSafeLoader), path) for path in paths]
            )
            out = subprocess.run(
                [sys.executable, __file__, '--child', str(folder / 'before'), *map(str, paths)],
                check=True,
                capture_output=True,
                text=True,
            ).stdout
            times['before'].append(json.loads(out.strip().splitlines()[-1]))
        for team in teams:  # the current loader reads back exactly what was written
            assert (
                load_scenario(team['files']['yaml'])
                == team['scenario']
                == load_scenario(team['files']['json'])
            )
        rows = []
        for k, team in enumerate(teams):
            median = {
                label: [statistics.median(r[2 * k + j] for r in runs) for j in (0, 1)]
                for label, runs in times.items()
            }
            rows.append(
                {
                    'n': team['n'],
                    'dynamics': team['dynamics'],
                    'edges': team['edges'],
                    'yaml_bytes': team['files']['yaml'].stat().st_size,
                    'json_bytes': team['files']['json'].stat().st_size,
                    'yaml_s': median['now'][0],
                    'json_s': median['now'][1],
                    'before_yaml_s': median['before'][0],
                    'before_json_s': median['before'][1],
                    'libyaml_s': median['libyaml'][0],
                    'walls': {label: [r[2 * k : 2 * k + 2] for r in runs] for label, runs in times.items()},
                }
            )
    return {'before': before, 'repeats': repeats, 'load_average': os.getloadavg(), 'rows': rows}


def markdown(result: dict) -> str:
    lines = [
        '| team | n | YAML [kB] | JSON [kB] | JSON load [s] | YAML load [s] | YAML / JSON | before '
        f'({result["before"]}): YAML load [s] '
        '| before: YAML / JSON | libyaml alone [s] | YAML before / now |',
        '|---|---|---|---|---|---|---|---|---|---|---|',
    ]
    for row in result['rows']:
        team = 'ETA-1' if row['dynamics'] == 'single' else 'ETA-2'
        lines.append(
            f'| {team} | {row["n"]} | {row["yaml_bytes"] / 1e3:.0f} | {row["json_bytes"] / 1e3:.0f} '
            f'| {row["json_s"]:.3f} '
            f'| {row["yaml_s"]:.3f} | {row["yaml_s"] / row["json_s"]:.1f}× | {row["before_yaml_s"]:.2f} '
            f'| {row["before_yaml_s"] / row["before_json_s"]:.1f}× | {row["libyaml_s"]:.3f} | '
            f'{row["before_yaml_s"] / row["yaml_s"]:.1f}× |'
        )
    return '\n'.join(lines)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == '--child':
        child(Path(sys.argv[2]), [Path(p) for p in sys.argv[3:]])
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--before', default=BEFORE, help=f'the revision to compare with (default {BEFORE})')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--n', type=int, nargs='+', default=[3000])
    args = parser.parse_args()
    result = run(args.n, args.before, args.repeats)
    text = markdown(result)
    print(text)
    out = HERE / 'results' / f'{dt.datetime.now(dt.UTC).strftime("%Y%m%d-%H%M%S")}-yaml'
    out.with_suffix('.json').write_text(json.dumps(result, indent=1) + '\n')
    out.with_suffix('.md').write_text(text + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
