"""`formation validate`: output, JSON and exit codes 0 / 1 / 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from formation_sim.cli import COMMANDS, main

GOOD = """\
name: good
dynamics: single
communication_radius: 4.0
horizon: 10.0
agents:
  1: {position: [0.0, 0.0]}
  2: {position: [0.0, 2.5]}
edges:
  - {i: 1, j: 2, d: [0.0, -2.0]}
gains: {alpha: 1.0, beta: 0.1}
"""


def write(tmp_path, text):
    path = tmp_path / 'case.yaml'
    path.write_text(text, encoding='utf-8')
    return str(path)


def test_validate_is_registered():
    assert 'validate' in COMMANDS


def test_valid_builtin_prints_the_report(capsys):
    assert main(['validate', 'paper_single']) == 0
    out = capsys.readouterr().out
    assert 'VALID' in out and 'β0 = ρ2/Δ0 = 1.5' in out and '[remark]' in out


def test_valid_file_without_warnings(tmp_path, capsys):
    # One edge: ρ2 = 2, Δ0 = 2, β0 = 1; 0.1 < 4/(2·1·4) = 0.5; slack 0.5 of 2.
    assert main(['validate', write(tmp_path, GOOD)]) == 0
    out = capsys.readouterr().out
    assert '0 error(s), 0 warning(s)' in out


def test_json_output(capsys):
    assert main(['validate', 'paper_double', '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['ok'] is True and data['scenario'] == 'paper_double'
    assert 'beta_d_corrected' in {w['rule'] for w in data['warnings']}


def test_invalid_scenario_exits_1(tmp_path, capsys):
    path = write(tmp_path, GOOD.replace('beta: 0.1', 'beta: 1.0'))  # β = β0 = 1
    assert main(['validate', path]) == 1
    out = capsys.readouterr().out
    assert 'INVALID' in out and '[beta] gains' in out and 'β0 = 1' in out
    assert main(['validate', path, '--json']) == 1
    assert json.loads(capsys.readouterr().out)['errors'][0]['rule'] == 'beta'


@pytest.mark.parametrize('text, fragment', [
    (GOOD.replace('[0.0, 2.5]}', '[0.0, 2.5]'), 'malformed YAML at line 8'),
    (GOOD.replace('horizon: 10.0', 'horizon: 0'), 'horizon'),
    (GOOD.replace('j: 2', 'j: 9'), 'j=9 is not an agent'),
])
def test_unreadable_scenario_exits_2_without_traceback(tmp_path, capsys, text, fragment):
    assert main(['validate', write(tmp_path, text)]) == 2
    captured = capsys.readouterr()
    assert fragment in captured.err and 'Traceback' not in captured.err
    if 'malformed' in fragment:
        assert 'started at line 7' in captured.err  # where the unclosed mapping begins
    assert captured.out == ''


def test_missing_file_exits_2(capsys):
    assert main(['validate', 'no_such_scenario.yaml']) == 2
    assert 'no such scenario file' in capsys.readouterr().err


def test_no_subcommand_exits_2(capsys):
    assert main([]) == 2
    assert 'validate' in capsys.readouterr().err


def test_module_entry_point(tmp_path):
    path = write(tmp_path, GOOD.replace('horizon: 10.0', 'horizon: -1'))
    result = subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', 'validate', path],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert result.returncode == 2
    assert 'horizon' in result.stderr and 'Traceback' not in result.stderr
