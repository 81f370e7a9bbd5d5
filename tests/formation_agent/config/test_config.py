"""The example robot parameter files are where the README says, in every kind of install:
`python3 -m formation_agent.config` prints their folder (editable, regular pip, colcon), and a
regular install also copies them to <prefix>/share/formation_agent/config/ (colcon's test:
tests/test_colcon_workspace.py)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from formation_agent.core.kinds import KIND_NAMES, robot_kind

REPO = Path(__file__).resolve().parents[3]

EXAMPLES = {robot_kind(name).params_file for name in KIND_NAMES}  # one per robot kind


def _config_folder(env: dict[str, str] | None = None) -> Path:
    done = subprocess.run(
        [sys.executable, '-m', 'formation_agent.config'],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return Path(done.stdout.strip())


def test_the_editable_install_prints_the_folder_of_the_examples():
    from formation_agent.config import params_files

    folder = _config_folder()  # this .venv: the editable install `make venv` makes
    assert {path.name for path in folder.glob('*.params.yaml')} == EXAMPLES
    assert set(params_files()) == EXAMPLES and all(path.parent == folder for path in params_files().values())


@pytest.mark.slow
def test_a_regular_pip_install_has_them_in_the_package_and_in_share(tmp_path):
    # pip builds the wheel in an isolated environment (setuptools and wheel from the index, as on
    # any machine `make venv` runs on); --ignore-installed keeps it from uninstalling the .venv's
    # editable install first. (Installing `wheel` into .venv instead would turn `make venv`'s
    # editable installs into legacy `setup.py develop` ones, whose scripts go to lib/<package>/.)
    source = tmp_path / 'formation_agent'
    shutil.copytree(
        REPO / 'src' / 'formation_agent',
        source,
        ignore=shutil.ignore_patterns('*.egg-info', '__pycache__', 'build'),
    )
    prefix = tmp_path / 'prefix'
    install = subprocess.run(
        [
            sys.executable,
            '-m',
            'pip',
            'install',
            '-q',
            '--disable-pip-version-check',
            '--no-deps',
            '--ignore-installed',
            '--prefix',
            str(prefix),
            str(source),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert install.returncode == 0, install.stdout + install.stderr
    assert {
        path.name for path in (prefix / 'share' / 'formation_agent' / 'config').glob('*.params.yaml')
    } == EXAMPLES
    site = next(prefix.glob('lib/python3*/site-packages'))
    env = dict(os.environ, PYTHONPATH=f'{site}{os.pathsep}{REPO / "src" / "formation_msgs_py"}')
    env.pop('PYTHONSAFEPATH', None)
    folder = _config_folder(env)
    assert folder == (site / 'formation_agent' / 'config').resolve()
    assert {path.name for path in folder.glob('*.params.yaml')} == EXAMPLES
