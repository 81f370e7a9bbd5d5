"""scripts/run_formation.py: runs as the README shows it, with no arguments (the demo's scenario,
a new folder)."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path
from typing import ClassVar

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / 'scripts' / 'run_formation.py'


class _Recorded:
    """Stands in for FormationRun: records its arguments, starts nothing."""

    calls: ClassVar[list] = []

    def __init__(self, scenario, **options):
        _Recorded.calls.append((scenario, options))

    def run(self):
        from formation_sim.runtime.launch.orchestrate import RunResult

        return RunResult(
            out_dir=Path('runs/x'), summary=None, bag=None, exit_status=0, domain_id=100, wall_time=0.0
        )


def _run_script(monkeypatch, *arguments):
    from formation_sim.runtime.launch import orchestrate

    monkeypatch.setattr(orchestrate, 'FormationRun', _Recorded)
    monkeypatch.setattr(sys, 'argv', [str(SCRIPT), *arguments])
    _Recorded.calls = []
    with pytest.raises(SystemExit) as done:
        runpy.run_path(str(SCRIPT), run_name='__main__')
    return done.value.code


def test_without_arguments_it_runs_the_demo_scenario_into_a_new_folder(monkeypatch, capsys):
    assert _run_script(monkeypatch) == 0
    assert _Recorded.calls == [('paper_single', {'out_dir': None, 'force': False, 'horizon': None})]
    assert 'folder:  runs/x' in capsys.readouterr().out


def test_its_arguments_reach_the_run(monkeypatch):
    assert _run_script(monkeypatch, 'paper_double', '--horizon', '5', '--out', 'runs/double', '--force') == 0
    assert _Recorded.calls == [('paper_double', {'out_dir': 'runs/double', 'force': True, 'horizon': 5.0})]
