"""scripts/typecheck.py (`make lint`'s mypy): an error beyond the baseline fails, one that moved
lines does not, a fixed one is said; the contracts of issue 29 and the agent's core are checked
strictly, and the contracts have no tolerated error."""

from __future__ import annotations

import sys
import tomllib
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / 'scripts'))
import typecheck  # noqa: E402 - the script's folder goes on the path first

OUTPUT = """\
src/formation_sim/formation_sim/runtime/testing.py:92: error: Incompatible types in assignment (expression has type "Node", variable has type "None")  [assignment]
src/formation_sim/formation_sim/runtime/testing.py:93: error: "None" has no attribute "destroy_node"  [attr-defined]
src/formation_sim/formation_sim/runtime/testing.py:120: error: "None" has no attribute "destroy_node"  [attr-defined]
src/formation_sim/formation_sim/runtime/testing.py:121: note: See https://mypy.readthedocs.io
"""  # noqa: E501 - mypy's lines as it prints them


def test_entries_drop_line_numbers_and_count():
    found, where = typecheck.entries(OUTPUT)
    path = 'src/formation_sim/formation_sim/runtime/testing.py'
    entry = f'{path}: [attr-defined] "None" has no attribute "destroy_node"'
    assert found[entry] == 2 and sum(found.values()) == 3
    assert [line.split(':')[1] for line in where[entry]] == ['93', '120']


def test_a_new_error_fails_a_moved_one_does_not_and_a_fixed_one_is_said():
    baseline, _ = typecheck.entries(OUTPUT)
    moved, _ = typecheck.entries(OUTPUT.replace(':92:', ':95:').replace(':93:', ':96:'))
    assert typecheck.compare(moved, baseline) == ([], [])
    one_more = moved + Counter({'src/x.py: [arg-type] Argument 1 has incompatible type "str"': 1})
    assert typecheck.compare(one_more, baseline) == (
        ['src/x.py: [arg-type] Argument 1 has incompatible type "str"'],
        [],
    )
    fewer = moved - Counter({next(iter(moved)): 1})
    new, gone = typecheck.compare(fewer, baseline)
    assert new == [] and len(gone) == 1


def test_the_baseline_file_reads_back_and_tolerates_nothing_in_the_contracts_nor_the_core():
    baseline = typecheck.read_baseline()
    assert baseline and all(': [' in entry for entry in baseline)
    assert [entry for entry in baseline if 'formation_agent/core/' in entry] == []
    contracts = (
        'formation_msgs_py/exit_codes.py',
        'formation_msgs_py/errors.py',
        '/errors.py',
        'formation_sim/sim/summary.py',
    )
    assert [entry for entry in baseline if entry.split(':')[0].endswith(contracts)] == []


def test_the_core_and_the_contracts_are_checked_strictly():
    config = tomllib.loads((ROOT / 'pyproject.toml').read_text())['tool']['mypy']
    (strict,) = config['overrides']
    assert {'formation_agent.core.*', 'formation_msgs_py.exit_codes', 'formation_sim.sim.summary'} <= set(
        strict['module']
    )
    assert all(
        strict[flag]
        for flag in (
            'disallow_untyped_defs',
            'disallow_any_generics',
            'warn_return_any',
            'disallow_untyped_calls',
        )
    )
