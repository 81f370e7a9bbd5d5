"""The `formation` command of an earlier commit, from packages materialised by `engine_baseline.materialise`.

    python benchmarks/cli_baseline.py FOLDER simulate SCENARIO --out DIR ...

FOLDER holds the revision's packages (materialised once by the caller, so that this process
spends its time as the command of that revision would); the rest is that command's arguments.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from engine_baseline import use_revision


def main() -> int:
    folder, arguments = Path(sys.argv[1]), sys.argv[2:]
    use_revision(folder)
    from formation_sim.cli import main as formation

    assert Path(sys.modules['formation_sim'].__file__).is_relative_to(folder), sys.modules[
        'formation_sim'
    ].__file__
    return formation(arguments)


if __name__ == '__main__':
    sys.exit(main())
