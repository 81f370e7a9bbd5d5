"""The lint markers that `make lint` cannot judge (docs/DESIGN.md, "Lint"): every `# noqa` names its
rules and says why on its line, and nothing opts out of `ruff format`."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TREES = ('src', 'tests', 'benchmarks', 'scripts', 'docs')
# A marker names its rules after 'noqa:' and then its reason, after '-', '—', ':' or in parentheses.
NOQA = re.compile(r'#\s*noqa\b(?P<rest>.*)$', re.IGNORECASE)
REASONED = re.compile(r':\s*[A-Z]+[0-9]+(?:\s*,\s*[A-Z]+[0-9]+)*\s*(?:[-—:(]\s*)\w')
FORMAT_OFF = re.compile(r'#\s*fmt:\s*(?:off|skip)\b')


def _comments(path: Path) -> list[tuple[int, str]]:
    """Every comment in a Python file, with its line (tokenized: a '#' inside a string is not one)."""
    tokens = tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
    return [(token.start[0], token.string) for token in tokens if token.type == tokenize.COMMENT]


def _python_files() -> list[Path]:
    return sorted(path for tree in TREES for path in (ROOT / tree).rglob('*.py') if '.venv' not in path.parts)


def problems(comments: list[tuple[int, str]]) -> list[str]:
    found = []
    for line, text in comments:
        match = NOQA.search(text)
        if match and not REASONED.match(match['rest']):
            found.append(f'line {line}: {text.strip()!r} names no rule or gives no reason')
        if FORMAT_OFF.search(text):
            found.append(f'line {line}: {text.strip()!r} opts out of ruff format')
    return found


@pytest.mark.parametrize(
    ('comment', 'fine'),
    [
        ('# noqa: E402 - after the sys.path fix above', True),
        ('# noqa: S603, S607 — our own processes', True),
        ('# noqa: PLW0108 (see above)', True),
        ('# noqa', False),
        ('# noqa: E402', False),
        ('# noqa: E402 -', False),
        ('# fmt: skip', False),
        ('# fmt: off', False),
        ('# a comment about noqa-free code', True),
    ],
)
def test_the_rule_tells_a_reasoned_marker_from_a_bare_one(comment: str, fine: bool) -> None:
    assert (not problems([(1, comment)])) is fine


def test_every_noqa_says_why_and_nothing_opts_out_of_formatting() -> None:
    files = _python_files()
    assert len(files) > 100, f'found only {len(files)} Python files under {TREES}'
    bad = [f'{path.relative_to(ROOT)}: {p}' for path in files for p in problems(_comments(path))]
    assert not bad, 'lint markers without a reason:\n' + '\n'.join(bad)
