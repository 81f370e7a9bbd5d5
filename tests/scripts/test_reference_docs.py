"""docs/EXIT_CODES.md and docs/TOPICS.md (scripts/reference_docs.py) are what the code defines: the
pages are up to date, every exit status the code defines is in the table with where it is defined,
and every topic a run records is on the topics page with its type."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / 'scripts' / 'reference_docs.py'
DOCS = ROOT / 'docs'
EXIT_MODULES = (
    'formation_sim.commands.common',
    'formation_agent.ros.process',
    'formation_sim.runtime.results',
    'formation_sim.runtime.coordinator',
    'formation_sim.commands.analyze',
    'formation_sim.commands.validate',
    'formation_sim.commands.study',
)


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


def test_every_exit_status_of_the_code_is_in_the_table():
    table = {}
    for line in (DOCS / 'EXIT_CODES.md').read_text().splitlines():
        if match := re.fullmatch(r'\| (\d+) \| (.+) \| (.+) \|', line):
            table[int(match.group(1))] = match.group(3)
    defined = {}
    for name in EXIT_MODULES:
        module = importlib.import_module(name)
        for attribute, value in vars(module).items():
            if (
                attribute.startswith('EXIT_')
                and type(value) is int
                and f'{attribute} =' in Path(module.__file__).read_text()
            ):
                defined[f'{name}.{attribute}'] = value
    assert {0, 1, 2, 3, 4, 130} <= set(table)
    for where, value in defined.items():
        assert f'`{where}`' in table[value], (where, value)
    assert set(table) == set(defined.values())


def test_every_recorded_topic_is_on_the_topics_page():
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.coordinator import robot_run_topics
    from formation_sim.runtime.sim_node import formation_topics

    page = (DOCS / 'TOPICS.md').read_text()
    listed = formation_topics(load_scenario('paper_single')) + robot_run_topics(
        load_scenario('robots_square'), model='holonomic', simulated=True, pose_type='pose'
    )
    for topic, msgtype in listed:
        generic = re.sub(r'/to_\d+', '/to_<j>', re.sub(r'/agent_\d+/', '/agent_<i>/', topic))
        assert f'| `{generic}` | `{msgtype}` |' in page, topic
