"""The `formation` command: --version, help, and one exit-code convention for every command (bad
input = 2)."""

from __future__ import annotations

import subprocess
import sys
from importlib import metadata

import pytest

from formation_sim.cli import COMMANDS, main


def test_version_names_every_package(capsys):
    assert main(['--version']) == 0
    out = capsys.readouterr().out.strip()
    version = metadata.version('formation_sim')
    assert out.startswith(f'formation {version} (formation_sim {version}, formation_agent ')
    assert 'formation_msgs_py ' in out and '; Python 3.' in out and '\n' not in out


def test_echo_explains_its_topic_argument(capsys):
    assert main(['echo', '--help']) == 0
    assert "TOPIC the topic's name, e.g. /formation/step" in ' '.join(capsys.readouterr().out.split())


def test_the_exit_codes_are_documented_in_the_top_level_help(capsys):
    assert main(['--help']) == 0
    help_text = ' '.join(capsys.readouterr().out.split())
    assert '0 done; 1 the command ran and the answer is no' in help_text
    assert '2 bad input, refused before anything started or changed' in help_text
    # Every status of the one enum, as docs/EXIT_CODES.md and the README say them.
    from formation_msgs_py.exit_codes import SENTENCE, ExitCode

    assert f'Exit status of every command: {SENTENCE}' in help_text
    assert all(
        f'{code} {code.brief}' in help_text or f'{code} ({code.brief})' in help_text for code in ExitCode
    )


def _bad_input(tmp_path):
    """(command line, what the refusal says) per command: each must exit 2 without a traceback."""
    (tmp_path / 'empty').mkdir(exist_ok=True)
    (tmp_path / 'a_file').write_text('not a folder')
    (tmp_path / 'a_run').mkdir(exist_ok=True)
    (tmp_path / 'a_run' / 'summary.json').write_text('{}')
    missing = str(tmp_path / 'missing')
    return [
        (['validate', missing], 'no such scenario file and not a built-in scenario'),
        (['validate', str(tmp_path)], 'is a folder, not a scenario file'),
        (
            ['generate', '--agents', '3', '--out', str(tmp_path / 'a_run' / 'summary.json')],
            'summary.json exists; nothing was changed',
        ),
        (
            ['generate', '--agents', '3', '--slack', '0', '--out', str(tmp_path / 'x.json')],
            'argument --slack: must be a number in (0, 1], got 0.0',
        ),
        (
            ['simulate', 'paper_single', '--sample-dt', '-1'],
            'argument --sample-dt: must be a finite number >= 0, got -1.0',
        ),
        (['simulate', 'no_such_scenario'], 'no such scenario file'),
        (
            ['run', 'paper_single', '--timeout', '-5'],
            'argument --timeout: must be a finite number > 0, got -5.0',
        ),
        (
            ['run', 'paper_single', '--out', str(tmp_path / 'x'), '--domain-id', '999'],
            'argument --domain-id: must be an integer in [0, 232]',
        ),
        (['recover', missing], 'is not a directory'),
        (['recover', str(tmp_path / 'empty')], 'expected exactly one .mcap file, found []'),
        (['analyze', missing], 'missing: no such file or folder'),
        (['analyze', missing, '--fps', '0'], 'argument --fps: must be an integer in [1, 100], got 0'),
        (['compare', missing, missing], 'missing: no such file or folder'),
        (
            ['compare', missing, missing, '--tolerance', '-1'],
            'argument --tolerance: must be a finite number >= 0, got -1.0',
        ),
        (['replay', missing], missing),
        (['replay', missing, '--rate', '-2'], 'argument --rate: must be a finite number >= 0, got -2.0'),
        (['replay', missing, '--domain-id', '233'], 'argument --domain-id: must be an integer in [0, 232]'),
        (['topics', '--wait', '-1'], 'argument --wait: must be a finite number >= 0, got -1.0'),
        (
            ['topics', '--domain-id', 'x'],
            "argument --domain-id: must be an integer in [0, 232] (a ROS_DOMAIN_ID), got 'x'",
        ),
        (
            ['measure', 'robots_lab', '--robot', 'unicycle', '--out', str(tmp_path / 'a_file')],
            'a_file: exists; choose a new file',
        ),
        (
            ['measure', 'robots_lab', '--robot', 'tank', '--out', str(tmp_path / 'm.yaml')],
            "argument --robot: invalid choice: 'tank'",
        ),
        (['echo', 'not a topic'], 'argument TOPIC: Invalid topic name'),
        (['echo', '/formation/step', '--count', '0'], 'argument --count: must be an integer >= 1, got 0'),
        (
            ['echo', '/formation/step', '--timeout', 'inf'],
            'argument --timeout: must be a finite number > 0, got inf',
        ),
        (['simulate', 'paper_single', '--out', str(tmp_path / 'a_file')], 'a_file is a file, not a folder'),
        (
            ['simulate', 'paper_single', '--out', str(tmp_path / 'a_file' / 'run')],
            'a_file is a file, so no folder can be made under it',
        ),
        (
            ['simulate', 'paper_single', '--out', str(tmp_path / 'a_run')],
            'a_run already holds an earlier run (summary.json)',
        ),
        (
            ['simulate', 'paper_single', '--period', 'nan'],
            'argument --period: must be a finite number > 0, got nan',
        ),
        (['study', str(tmp_path / 'no_spec.yaml'), '--out', str(tmp_path / 'x')], 'cannot read the SPEC'),
        (['study', 'report'], 'report: the study folder is required'),
        (
            ['run', 'paper_single', '--out', str(tmp_path / 'a_file' / 'run')],
            'a_file is a file, so no folder can be made under it',
        ),
        (
            [
                'run',
                'paper_single',
                '--out',
                str(tmp_path / 'a_run'),
                '--force',
                '--domain-id',
                '100',
                '--sample-dt',
                '1e-12',
            ],
            'asks for 1e+13 samples',
        ),
        (
            ['run', 'paper_single', '--agents-per-process', '1.5'],
            "argument --agents-per-process: must be an integer >= 1 or 'auto', got '1.5'",
        ),
        (
            ['analyze', missing, '--out', str(tmp_path / 'a_run')],
            'a_run holds a run (summary.json or bag/) whose files the report would overwrite',
        ),
        (
            ['compare', missing, missing, '--out', str(tmp_path / 'a_run')],
            'whose files the report would overwrite',
        ),
        (['replay', missing, '--depth', '0'], 'argument --depth: must be an integer >= 1, got 0'),
        (
            ['echo', '/formation/step', '--domain-id', '233'],
            'argument --domain-id: must be an integer in [0, 232]',
        ),
        (['validate', ''], "'': no such scenario file"),
        (
            ['validate', 'robots_square', '--max-speed', '0'],
            'argument --max-speed: must be a finite number > 0, got 0.0',
        ),
        (
            ['run', 'robots_square', '--backend', 'external'],
            '--backend external needs --robot holonomic|unicycle',
        ),
        (
            ['run', 'robots_square', '--backend', 'unicycle', '--latency', '-0.02'],
            'argument --latency: must be a finite number >= 0, got -0.02',
        ),
        (
            ['params', 'paper_single', '--out', str(tmp_path / 'a_run')],
            'a_run already holds an earlier run (summary.json)',
        ),
        (
            ['params', 'robots_square', '--backend', 'external', '--out', str(tmp_path / 'x')],
            '--backend external needs --robot holonomic|unicycle',
        ),
        (
            ['params', 'paper_single', '--sample-dt', '-1'],
            'argument --sample-dt: must be a finite number >= 0, got -1.0',
        ),
        (['robots', 'robots_square', '--domain-id', '42'], '--model holonomic|unicycle|car is required'),
        (
            [
                'robots',
                'robots_square',
                '--model',
                'unicycle',
                '--domain-id',
                '42',
                '--out',
                str(tmp_path / 'a_run'),
            ],
            'a_run already holds an earlier run (summary.json)',
        ),
        (['stop', '--domain-id', '233'], 'argument --domain-id: must be an integer in [0, 232]'),
        (['stop', '--timeout', '0'], 'argument --timeout: must be a finite number > 0, got 0.0'),
        (['no_such_command'], "invalid choice: 'no_such_command'"),
        (['validate', 'paper_single', '--no-such-option'], 'unrecognized arguments: --no-such-option'),
        ([], 'COMMAND'),
    ]


def test_every_command_has_a_bad_input_case():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        covered = {case[0][0] for case in _bad_input(Path(folder)) if case[0]}
    assert set(COMMANDS) <= covered


@pytest.mark.timeout(120)
def test_bad_input_exits_2_in_every_command(tmp_path, capsys):
    for arguments, complaint in _bad_input(tmp_path):
        assert main(arguments) == 2, arguments
        captured = capsys.readouterr()
        assert complaint in captured.err, (arguments, captured.err)
        assert 'Traceback' not in captured.err
    assert not (tmp_path / 'x').exists() and sorted(p.name for p in tmp_path.iterdir()) == [
        'a_file',
        'a_run',
        'empty',
    ]
    assert [p.name for p in (tmp_path / 'a_run').iterdir()] == ['summary.json'] and not list(
        (tmp_path / 'empty').iterdir()
    )


@pytest.mark.timeout(300)
@pytest.mark.parametrize('command', COMMANDS)
def test_a_real_formation_process_exits_2_on_bad_input(tmp_path, command):
    arguments, complaint = next(case for case in _bad_input(tmp_path) if case[0] and case[0][0] == command)
    done = subprocess.run(
        [sys.executable, '-m', 'formation_sim.cli', *arguments],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=tmp_path,
    )
    assert done.returncode == 2, done.stderr
    assert complaint in done.stderr and 'Traceback' not in done.stderr
