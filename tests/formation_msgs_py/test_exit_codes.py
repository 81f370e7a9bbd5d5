"""`ExitCode` (formation_msgs_py.exit_codes): every exit status in one enum, and the places that
say them — the `formation --help` epilog, docs/EXIT_CODES.md and the README — agree with it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from formation_msgs_py.exit_codes import SENTENCE, ExitCode

ROOT = Path(__file__).resolve().parents[2]


def _words(text: str) -> str:
    return ' '.join(text.split())


def test_the_statuses_are_the_conventional_numbers_and_travel_as_plain_ints():
    assert {code.name: int(code) for code in ExitCode} == {
        'OK': 0,
        'FAILED': 1,
        'BAD_INPUT': 2,
        'LOST': 3,
        'REFUSED': 4,
        'STOPPED': 5,
        'INTERRUPTED': 130,
    }
    # A status is written as its number wherever it goes: JSON (summary.json), f-strings (log lines
    # such as process.TEARDOWN_MARK's), and a process's exit status.
    assert json.dumps({'status': ExitCode.LOST}) == '{"status": 3}'
    assert f'{ExitCode.INTERRUPTED}' == str(ExitCode.INTERRUPTED) == '130'
    run = subprocess.run(
        [
            sys.executable,
            '-c',
            'import sys; from formation_msgs_py.exit_codes import ExitCode; sys.exit(ExitCode.REFUSED)',
        ],
        timeout=60,
    )
    assert run.returncode == 4


def test_every_status_has_a_meaning_and_the_sentence_names_each_once_in_order():
    places = []
    for code in ExitCode:
        assert code.meaning.strip() and code.brief.strip(), code
        said = f'{code} {code.brief}' if code.every_command else f'{code} ({code.brief})'
        assert SENTENCE.count(said) == 1, (code, SENTENCE)
        places.append(SENTENCE.index(said))
    assert places == sorted(places)
    every = [ExitCode.OK, ExitCode.FAILED, ExitCode.BAD_INPUT]
    assert [code for code in ExitCode if code.every_command] == every


def test_the_cli_epilog_the_exit_code_page_and_the_readme_say_the_sentence():
    from formation_sim.cli import EPILOG, build_parser

    assert f'Exit status of every command: {SENTENCE}' == EPILOG
    assert _words(SENTENCE) in _words(build_parser().format_help())
    assert SENTENCE in (ROOT / 'docs' / 'EXIT_CODES.md').read_text().splitlines()
    readme = _words((ROOT / 'README.md').read_text())
    assert f'Exit codes, the same for every command: {SENTENCE}' in readme
