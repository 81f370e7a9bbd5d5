"""Run the in-process engine of an earlier commit (the speed baseline) in a separate process.

    python benchmarks/engine_baseline.py REV CASE_JSON

materialises `src/formation_agent/formation_agent/*.py` and `src/formation_sim/formation_sim/engine.py`
of git revision REV in a temporary folder, puts them before the installed packages on sys.path
and runs `simulate` on the case (the current scenario, world and generator code), printing one
JSON line: events, wall time, CPU time.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
AGENT_FILES = ('__init__.py', 'closed_form.py', 'crossing.py', 'eta.py', 'tension.py')


def materialise(rev: str, folder: Path) -> None:
    package = folder / 'formation_agent'
    package.mkdir(parents=True)
    for name in AGENT_FILES:
        text = subprocess.run(
            ['git', 'show', f'{rev}:src/formation_agent/formation_agent/{name}'], cwd=ROOT, check=True, capture_output=True, text=True
        ).stdout
        (package / name).write_text(text)
    engine = subprocess.run(
        ['git', 'show', f'{rev}:src/formation_sim/formation_sim/engine.py'], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout
    (folder / 'baseline_engine.py').write_text(engine)


def main() -> int:
    rev, case = sys.argv[1], json.loads(sys.argv[2])
    with tempfile.TemporaryDirectory(prefix='bench_baseline_') as tmp:
        materialise(rev, Path(tmp))
        sys.path.insert(0, tmp)
        import baseline_engine  # noqa: PLC0415 - from the materialised revision
        import formation_agent  # noqa: PLC0415

        assert Path(formation_agent.__file__).is_relative_to(tmp)
        sys.path.insert(1, str(Path(__file__).resolve().parent))
        from cases import build_scenario  # noqa: PLC0415

        scenario = build_scenario(case)
        cpu = time.process_time()
        record = baseline_engine.simulate(scenario, horizon=case['horizon'], sample_dt=None)
        cpu = time.process_time() - cpu
    print(json.dumps({'events': record.total_events, 'wall_s': record.wall_time, 'cpu_s': cpu}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
