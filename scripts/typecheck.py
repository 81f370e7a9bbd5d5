#!/usr/bin/env python3
"""The type checker of `make lint` (issue 29): mypy on the three packages with pyproject.toml's
[tool.mypy] (strict on formation_agent.core and on the contracts: exit codes, errors, the typed
summary.json), against the errors it found when it was added, listed in scripts/mypy_baseline.txt.

An error not in the list fails (exit 1), naming it; an error of the list that is gone is said, so
that the list can shrink (`--update` rewrites it from the tree). The list's entries carry no line
numbers ('path: [code] message'), so that an edit elsewhere in a file does not break them, and
count: a file with two such errors may not gain a third.

    python scripts/typecheck.py             # check
    python scripts/typecheck.py --update    # rewrite the list (after fixing errors, not to add any)
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / 'scripts' / 'mypy_baseline.txt'
HEADER = (
    '# mypy errors tolerated (scripts/typecheck.py): the tree as the type checker was added; fix them\n'
    '# and shrink the list with `python scripts/typecheck.py --update`, never add to it by hand.\n'
)
ERROR = re.compile(
    r'^(?P<path>[^:\s]+\.py):(?P<line>\d+):(?:\d+:)? error: (?P<message>.*?)\s+\[(?P<code>[\w-]+)\]$'
)


def entries(output: str) -> tuple[Counter[str], dict[str, list[str]]]:
    """mypy's output -> (entry -> count, entry -> the lines 'path:line: error ...' it came from)."""
    found: Counter[str] = Counter()
    where: dict[str, list[str]] = {}
    for line in output.splitlines():
        if match := ERROR.match(line):
            entry = f'{match["path"]}: [{match["code"]}] {match["message"]}'
            found[entry] += 1
            where.setdefault(entry, []).append(line)
    return found, where


def read_baseline(path: Path = BASELINE) -> Counter[str]:
    if not path.is_file():
        return Counter()
    return Counter(line for line in path.read_text().splitlines() if line and not line.startswith('#'))


def compare(found: Counter[str], baseline: Counter[str]) -> tuple[list[str], list[str]]:
    """(new errors, baseline entries now gone), each entry as often as it is over or under."""
    new = sorted((found - baseline).elements())
    gone = sorted((baseline - found).elements())
    return new, gone


def run_mypy() -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, '-m', 'mypy', '--no-error-summary', '--no-pretty'],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--update', action='store_true', help='rewrite the baseline from the tree')
    args = parser.parse_args(argv)
    run = run_mypy()
    output = run.stdout + run.stderr
    found, where = entries(output)
    if run.returncode == 2 or (run.returncode == 1 and not found):  # a crash or a bad configuration
        print(f'typecheck: mypy could not check the tree (exit {run.returncode}):\n{output}', file=sys.stderr)
        return 2
    if args.update:
        BASELINE.write_text(HEADER + ''.join(f'{entry}\n' for entry in sorted(found.elements())))
        print(f'typecheck: {sum(found.values())} errors written to {BASELINE.relative_to(ROOT)}')
        return 0
    new, gone = compare(found, read_baseline())
    if gone:
        print(
            f'typecheck: {len(gone)} errors of {BASELINE.relative_to(ROOT)} are gone: run '
            '`python scripts/typecheck.py --update` to shrink it'
        )
    if new:
        lines = [line for entry in dict.fromkeys(new) for line in where[entry]]
        print(
            f'typecheck: {len(new)} new mypy errors (not in the baseline):', *lines, sep='\n', file=sys.stderr
        )
        return 1
    print(f'typecheck: no new mypy errors ({sum(found.values())} tolerated by the baseline)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
