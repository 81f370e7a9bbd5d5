"""The size rule, as CI enforces it (docs/DESIGN.md, "Sizes"): no class over 300 lines, no function
or method over 80, in every module under src/*/.

A unit's size is the span Python reports for it: from its `def`/`class` line to its last line
(docstring, comments and blank lines included, decorators not). A nested function or class is a
unit of its own and also counts towards the one that holds it.

The units that broke the rule when it came are named in ALLOWED with their size then, as a
ceiling: such a unit may shrink but never grow past it, and once it is within the rule (or gone)
its entry must go. The list only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / 'src'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')
LIMITS = {'class': 300, 'function': 80}

# (module under src/<package>/, qualified name) -> lines, the ceiling. Each entry says why it is
# still long; split it (behaviour-preserving, under its tests) and delete its line.
ALLOWED: dict[tuple[str, str], int] = {
    # `ruff format` (the tree was formatted in one commit, every `fmt: skip` removed) took these past
    # the rule: one argument or item per line. Each is to be split along its seams.
}


def units(source: str, filename: str = '<probe>') -> dict[str, tuple[str, int]]:
    """Every class and function in `source`, by qualified name (`Class.method`, `f.inner`): its
    kind ('class' or 'function') and its number of lines."""
    found: dict[str, tuple[str, int]] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = prefix + child.name
                kind = 'class' if isinstance(child, ast.ClassDef) else 'function'
                found[name] = (kind, child.end_lineno - child.lineno + 1)
                visit(child, name + '.')
            else:
                visit(child, prefix)

    visit(ast.parse(source, filename), '')
    return found


def _all_units() -> dict[tuple[str, str], tuple[str, int]]:
    found = {}
    for package in PACKAGES:
        root = SRC / package
        for path in sorted((root / package).rglob('*.py')):
            module = path.relative_to(root).as_posix()
            for name, unit in units(path.read_text(), str(path)).items():
                found[module, name] = unit
    return found


UNITS = _all_units()


def _over(kind: str, lines: int) -> bool:
    return lines > LIMITS[kind]


def test_the_units_are_found() -> None:
    assert len(UNITS) > 500
    assert UNITS['formation_agent/core/eta.py', 'Eta1Agent'][0] == 'class'
    assert UNITS['formation_agent/core/eta.py', 'Eta2Agent._fast_probe'][0] == 'function'


def test_no_class_over_300_lines_and_no_function_over_80() -> None:
    over = [
        f'src/{module.split("/")[0]}/{module}: {kind} {name} is {lines} lines (limit {LIMITS[kind]})'
        for (module, name), (kind, lines) in sorted(UNITS.items())
        if _over(kind, lines) and (module, name) not in ALLOWED
    ]
    assert not over, 'split these into named helpers:\n' + '\n'.join(over)


@pytest.mark.parametrize(('module', 'name'), sorted(ALLOWED))
def test_an_allowed_unit_never_grows_and_leaves_the_list_once_within_the_rule(module: str, name: str) -> None:
    ceiling = ALLOWED[module, name]
    assert (module, name) in UNITS, f'{module}: {name} is gone: delete its entry in ALLOWED'
    kind, lines = UNITS[module, name]
    assert _over(kind, lines), (
        f'{module}: {kind} {name} is {lines} lines, within the rule ({LIMITS[kind]}): '
        'delete its entry in ALLOWED'
    )
    assert lines <= ceiling, (
        f'{module}: {kind} {name} grew to {lines} lines past its ceiling {ceiling}: split it'
    )


def test_the_rule_can_fail() -> None:
    # A method of 81 lines (def, docstring, 79 statements) in a class of 379 are both found over.
    body = ''.join(f'        x{i} = {i}\n' for i in range(79))
    methods = ''.join(f'    def m{i}(self):\n        return {i}\n\n' for i in range(99))
    probe = f'class Outer:\n    def long(self):\n        """81 lines."""\n{body}\n{methods}'
    found = units(probe)
    assert found['Outer.long'] == ('function', 81) and _over(*found['Outer.long'])
    assert found['Outer'][0] == 'class' and _over(*found['Outer'])
    assert found['Outer.m0'] == ('function', 2) and not _over(*found['Outer.m0'])
