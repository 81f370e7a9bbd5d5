"""Every module under src has its tests where one looks for them (docs/DESIGN.md, "Where each
module is tested").

Tests mirror the tree: src/<package>/<package>/<sub>/<x>.py is tested in
tests/<package>/<sub>/test_<x>.py; a package's `__init__.py` (one that holds code) in
test_<package name>.py inside or beside its folder. A package face that only re-exports names
(imports, `__all__`) is tested by tests/test_layout.py (every exported name resolves).

A module without its mirror must be named in DESIGN.md's table with the test files that cover it;
the table names only such modules (none that has a mirror now, none that is gone) and only test
files that exist.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / 'src'
TESTS = REPO / 'tests'
DESIGN = REPO / 'docs' / 'DESIGN.md'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')
SECTION = '## Where each module is tested'


def _is_face(path: Path) -> bool:
    """An `__init__.py` of docstring, imports and `__all__` only."""
    for node in ast.parse(path.read_text(), str(path)).body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            continue
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
            continue
        if isinstance(node, ast.Assign) and [getattr(t, 'id', None) for t in node.targets] == ['__all__']:
            continue
        return False
    return True


def mirrors(path: Path, root: Path) -> list[Path]:
    """Where the tests of `path` (a module under `root`, src/<package>/<package>) are looked for."""
    relative = path.relative_to(root.parent)
    if path.name == '__init__.py':
        folder = relative.parent
        return [TESTS / folder / f'test_{folder.name}.py', TESTS / folder.parent / f'test_{folder.name}.py']
    return [TESTS / relative.parent / f'test_{path.stem}.py']


def _module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def unmirrored() -> set[str]:
    found = set()
    for package in PACKAGES:
        root = SRC / package / package
        for path in sorted(root.rglob('*.py')):
            if path.name == '__init__.py' and _is_face(path):
                continue
            if not any(mirror.is_file() for mirror in mirrors(path, root)):
                found.add(_module_name(path, root))
    return found


def table(text: str) -> dict[str, str]:
    """DESIGN.md's section: module (first cell, in backticks) -> the rest of its row."""
    assert SECTION in text, f'docs/DESIGN.md has no section {SECTION!r}'
    section = text.split(SECTION, maxsplit=1)[1].split('\n## ', maxsplit=1)[0]
    rows = {}
    for line in section.splitlines():
        if match := re.fullmatch(r'\|\s*`([\w.]+)`\s*\|(.*)\|\s*', line):
            module, covered = match.groups()
            assert module not in rows, f'{module} is named twice in {SECTION!r}'
            rows[module] = covered
    return rows


TABLE = table(DESIGN.read_text())


def test_every_module_without_a_mirror_is_in_the_table() -> None:
    missing = sorted(unmirrored() - set(TABLE))
    assert not missing, (
        f'modules without tests/<package>/.../test_<module>.py: add one, or name the tests that cover '
        f'them in docs/DESIGN.md, {SECTION!r}: {missing}'
    )


def test_the_table_names_only_modules_without_a_mirror() -> None:
    extra = sorted(set(TABLE) - unmirrored())
    assert not extra, (
        f'{SECTION!r} names modules that have a mirror test now, or that are gone: delete their rows: {extra}'
    )


def test_every_row_names_test_files_that_exist() -> None:
    for module, covered in TABLE.items():
        files = re.findall(r'`(tests/[\w/]+\.py)`', covered)
        assert files, f'{module}: its row names no test file (`tests/....py`): {covered.strip()!r}'
        gone = [name for name in files if not (REPO / name).is_file()]
        assert not gone, f'{module}: its row names test files that do not exist: {gone}'


def test_the_rule_finds_a_module_without_a_mirror(tmp_path) -> None:
    root = tmp_path / 'formation_sim' / 'formation_sim'
    (root / 'sim').mkdir(parents=True)
    for name in ('engine.py', 'nowhere.py', '__init__.py'):
        (root / 'sim' / name).write_text('x = 1\n')
    assert mirrors(root / 'sim' / 'engine.py', root)[0].is_file()  # tests/formation_sim/sim/test_engine.py
    assert not mirrors(root / 'sim' / 'nowhere.py', root)[0].is_file()
    assert TESTS / 'formation_sim' / 'test_sim.py' in mirrors(root / 'sim' / '__init__.py', root)
    assert not _is_face(root / 'sim' / '__init__.py')
    (root / 'sim' / '__init__.py').write_text('"""Face."""\nfrom x import y\n__all__ = ["y"]\n')
    assert _is_face(root / 'sim' / '__init__.py')


def test_the_table_is_read_row_by_row() -> None:
    text = (
        f'{SECTION}\n\n| module | tested by |\n|---|---|\n| `a.b` | `tests/test_layout.py` (faces) '
        '|\n\n## Next\n| `c.d` | x |\n'
    )
    assert table(text) == {'a.b': ' `tests/test_layout.py` (faces) '}
