"""Every shell or Python example of README.md and docs/**/*.md either runs as written, or says why
not: a comment right before it, `<!-- not run: REASON -->` (needs robots, several machines, a ROS
installation, takes long) or `<!-- run by: tests/PATH.py -->` (another test runs it, and names the
page).

The examples that run, run page by page in a fresh folder each (the blocks of a page in order,
in one folder, as a reader would type them), with the repository's `studies/` and `benchmarks/`
beside them and .venv's commands first on the PATH; shell blocks under `bash -euo pipefail`."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LANGUAGES = ('bash', 'sh', 'shell', 'console', 'python')
FENCE = re.compile(r'^( *)```(' + '|'.join(LANGUAGES) + r')[ \t]*\n(.*?)^\1```', re.MULTILINE | re.DOTALL)
MARKER = re.compile(r'<!-- (not run|run by): (.+?) -->')


@dataclass(frozen=True, kw_only=True)
class Example:
    page: str  # relative to the repository
    line: int
    language: str
    code: str
    marker: tuple[str, str] | None  # ('not run', reason) or ('run by', test path)


def pages() -> list[Path]:
    docs = [p for p in sorted((ROOT / 'docs').rglob('*.md')) if '_build' not in p.parts]
    return [ROOT / 'README.md', ROOT / 'BENCHMARKS.md', *docs]


def examples(path: Path, *, root: Path = ROOT) -> list[Example]:
    text = path.read_text()
    found = []
    for match in FENCE.finditer(text):
        before = text[: match.start()].rstrip('\n').rsplit('\n', 1)[-1].strip()
        marker = MARKER.fullmatch(before)
        indent = len(match.group(1))
        code = '\n'.join(line[indent:] for line in match.group(3).splitlines())
        found.append(
            Example(
                page=str(path.relative_to(root)),
                line=text[: match.start()].count('\n') + 1,
                language=match.group(2),
                code=code,
                marker=marker.groups() if marker else None,
            )
        )
    return found


ALL = [example for path in pages() for example in examples(path)]
RUN = [example for example in ALL if example.marker is None]


def test_the_examples_are_found():
    assert len(ALL) >= 40
    assert {'README.md', 'docs/GETTING_STARTED.md', 'docs/ROBOTS.md', 'docs/API.md'} <= {e.page for e in ALL}
    # The scanner sees indented blocks (in a list) and every language it names.
    assert any(e.page == 'docs/SEPARATE_MACHINES.md' for e in ALL)
    assert {'bash', 'python', 'sh'} <= {e.language for e in ALL}


def test_every_example_runs_or_says_why_not():
    for example in ALL:
        if example.marker is None:
            continue
        kind, said = example.marker
        where = f'{example.page}:{example.line}'
        assert len(said.split()) >= 2 or kind == 'run by', f'{where}: the reason is too short: {said!r}'
        if kind == 'run by':
            test = ROOT / said
            assert test.is_file(), f'{where}: {said} does not exist'
            assert Path(example.page).name in test.read_text(), (
                f'{where}: {said} does not read {example.page}'
            )


def test_the_scanner_reads_markers_and_indented_blocks(tmp_path):
    page = tmp_path / 'page.md'
    page.write_text(
        'text\n\n<!-- not run: needs robots -->\n```bash\nformation measure x\n```\n\n'
        '- a list\n\n  ```python\n  print(1)\n    print(2)\n  ```\n'
    )
    first, second = examples(page, root=tmp_path)
    assert first.marker == ('not run', 'needs robots') and first.code == 'formation measure x'
    assert second.marker is None and second.code == 'print(1)\n  print(2)' and second.line == 10


def _environment(home: Path) -> dict[str, str]:
    return {
        'PATH': f'{Path(sys.executable).parent}:/usr/bin:/bin',
        'HOME': str(home),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(home / 'ros_log'),
        'MPLBACKEND': 'Agg',
        **{k: v for k, v in os.environ.items() if k in ('LANG', 'LC_ALL', 'TMPDIR')},
    }


def _run(example: Example, folder: Path) -> subprocess.CompletedProcess:
    if example.language == 'python':
        command = [sys.executable, '-c', example.code]
    else:
        command = ['bash', '-euo', 'pipefail', '-c', example.code]
    return subprocess.run(
        command,
        cwd=folder,
        env=_environment(folder),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


RUN_PAGES = sorted({example.page for example in RUN})


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(600)
@pytest.mark.parametrize('page', RUN_PAGES)
def test_the_examples_run_as_written(page, tmp_path):
    folder = tmp_path / 'reader'
    folder.mkdir()
    for shared in ('studies', 'benchmarks'):
        (folder / shared).symlink_to(ROOT / shared)
    for example in (e for e in RUN if e.page == page):
        run = _run(example, folder)
        where = f'{example.page}:{example.line}'
        assert run.returncode == 0, (
            f'{where} exited {run.returncode}\n{run.stdout[-2000:]}\n{run.stderr[-4000:]}'
        )
