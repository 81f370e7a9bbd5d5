"""Run the in-process engine of an earlier commit (the speed baseline) in a separate process.

    python benchmarks/engine_baseline.py REV CASE_JSON

builds the case's scenario with the current code, then materialises the three packages of git
revision REV (`git archive`) in a temporary folder, puts them before the installed packages on
sys.path and runs REV's own `simulate` on that scenario (passed as YAML, loaded by REV's own
scenario code), printing one JSON line: events, wall time, CPU time, peak RSS. The case's
`engine` entry, if any, holds further keyword arguments of `simulate` (default: no grid).
Works for revisions before and after the sub-package layout (formation_sim.engine /
formation_sim.sim.engine). `use_revision` is shared with `cli_baseline.py`.
"""

from __future__ import annotations

import importlib
import io
import json
import resource
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')


def materialise(rev: str, folder: Path) -> None:
    """The three packages of git revision `rev` under `folder/src/<package>/`."""
    paths = [f'src/{package}/{package}' for package in PACKAGES]
    archive = subprocess.run(
        ['git', 'archive', '--format=tar', rev, *paths], cwd=ROOT, check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder, filter='data')


def use_revision(folder: Path) -> None:
    """Import the packages materialised in `folder` from now on, instead of the installed ones."""
    for name in [m for m in sys.modules if m.split('.')[0] in PACKAGES]:
        del sys.modules[name]  # from here on, every formation module is the revision's
    # Editable installs resolve what the revision lacks from the working tree: take them out of the way.
    sys.meta_path[:] = [
        finder for finder in sys.meta_path if not getattr(finder, '__module__', '').startswith('__editable__')
    ]
    for package in PACKAGES:
        sys.path.insert(0, str(Path(folder) / 'src' / package))


def _first_module(*names: str):
    for name in names:
        try:
            return importlib.import_module(name)
        except ModuleNotFoundError:
            continue
    raise ModuleNotFoundError(f'none of {names} exists at this revision')


def main() -> int:
    rev, case = sys.argv[1], json.loads(sys.argv[2])
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from cases import build_scenario

    from formation_sim.model.scenario import dump_scenario_text

    scenario_text = dump_scenario_text(build_scenario(case))
    with tempfile.TemporaryDirectory(prefix='bench_baseline_') as tmp:
        materialise(rev, Path(tmp))
        use_revision(Path(tmp))
        scenario_module = _first_module('formation_sim.model.scenario', 'formation_sim.scenario')
        engine = _first_module('formation_sim.sim.engine', 'formation_sim.engine')
        assert Path(engine.__file__).is_relative_to(tmp), engine.__file__
        scenario = scenario_module.scenario_from_dict(yaml.safe_load(scenario_text))
        cpu = time.process_time()
        record = engine.simulate(scenario, horizon=case['horizon'], **case.get('engine', {'sample_dt': None}))
        cpu = time.process_time() - cpu
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        json.dumps(
            {'events': record.total_events, 'wall_s': record.wall_time, 'cpu_s': cpu, 'peak_rss_mib': peak}
        )
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
