"""docs/EXIT_CODES.md and docs/TOPICS.md (scripts/reference_docs.py) are what the code defines: the
pages are up to date, every exit status of the one enum is in the table with the modules that return it,
and every topic a run records is on the topics page with its type."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / 'scripts' / 'reference_docs.py'
DOCS = ROOT / 'docs'


def _check() -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), '--check'], capture_output=True, text=True, timeout=120, check=False
    )


def test_the_pages_are_up_to_date():
    run = _check()
    assert run.returncode == 0, run.stderr


def test_check_names_a_stale_page(tmp_path, monkeypatch):
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        import reference_docs
    finally:
        sys.path.remove(str(SCRIPT.parent))
    for name in ('EXIT_CODES.md', 'TOPICS.md'):
        (tmp_path / name).write_text((DOCS / name).read_text())
    (tmp_path / 'TOPICS.md').write_text('# Processes and topics\n\nold\n')
    monkeypatch.setattr(reference_docs, 'DOCS', tmp_path)
    assert reference_docs.main(['--check']) == 1
    assert reference_docs.main([]) == 0
    assert (tmp_path / 'TOPICS.md').read_text() == (DOCS / 'TOPICS.md').read_text()
    assert reference_docs.main(['--check']) == 0


def test_every_exit_status_of_the_enum_is_in_the_table_with_the_modules_that_return_it():
    from formation_msgs_py.exit_codes import ExitCode

    table = {}
    for line in (DOCS / 'EXIT_CODES.md').read_text().splitlines():
        if match := re.fullmatch(r'\| (\d+) \| `(\w+)` \| (.+) \| (.+) \|', line):
            table[int(match.group(1))] = (match.group(2), match.group(3), match.group(4))
    assert sorted(table) == [0, 1, 2, 3, 4, 5, 130] == [int(code) for code in ExitCode]
    for code in ExitCode:
        assert table[code][:2] == (code.name, code.meaning), code
    # A module that returns a status is named in its row: the agent's command and the time keepers' process.
    assert '`formation_agent.ros.main`' in table[ExitCode.LOST][2]
    assert '`formation_sim.runtime.nodes.keeper_main`' in table[ExitCode.REFUSED][2]
    assert '`formation_sim.commands.study`' in table[ExitCode.INTERRUPTED][2]


def test_no_module_spells_an_exit_status_of_its_own():
    """Every exit status is an `ExitCode` member: no `EXIT_<NAME> = <int>` is left in src, scripts
    or benchmarks (issue 29: 130 was defined three times)."""
    found = []
    for folder in ('src', 'scripts', 'benchmarks'):
        for path in sorted((ROOT / folder).rglob('*.py')):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Assign | ast.AnnAssign):
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    names = [n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)]
                    value = node.value
                    if any(name.startswith('EXIT_') for name in names) and not (
                        isinstance(value, ast.Constant) and isinstance(value.value, float)
                    ):
                        found.append(f'{path.relative_to(ROOT)}:{node.lineno}')
    assert found == []


def test_every_recorded_topic_is_on_the_topics_page():
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.contract import formation_topics, robot_run_topics

    page = (DOCS / 'TOPICS.md').read_text()
    listed = formation_topics(load_scenario('paper_single')) + robot_run_topics(
        load_scenario('robots_square'), model='holonomic', simulated=True, pose_type='pose'
    )
    for topic, msgtype in listed:
        generic = re.sub(r'/to_\d+', '/to_<j>', re.sub(r'/agent_\d+/', '/agent_<i>/', topic))
        assert f'| `{generic}` | `{msgtype}` |' in page, topic
