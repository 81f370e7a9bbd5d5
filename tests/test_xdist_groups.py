"""`make test` runs pytest-xdist with `--dist loadgroup`: the tests of one `xdist_group` run on one
worker, and so do the tests of a module that use the `ros` fixture (one ROS domain per module,
tests/conftest.py).  pytest 9.2 with pytest-xdist 3.8 silently ignored every group
(pytest-dev/pytest-xdist#1386): two robots 1 of one module then published on one topic at once.
This runs a small suite on two workers and reads where each test ran."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CONFTEST = Path(__file__).with_name('conftest.py')

# Each test notes the worker it ran on in RAN_DIR/<kind>-<k>.
RAN = """
import os, time, pytest


def _ran(kind, k):
    time.sleep(0.05)
    with open(os.path.join(os.environ['RAN_DIR'], f'{kind}-{k}'), 'w') as out:
        out.write(os.environ['PYTEST_XDIST_WORKER'])
"""

GROUPED = """
@pytest.mark.xdist_group('together')
@pytest.mark.parametrize('k', range(6))
def test_grouped(k):
    _ran('grouped', k)
"""

ONE_DOMAIN = """
DOMAIN_ID = 7


@pytest.fixture(scope='module')
def ros():  # stands in for tests/conftest.py's rclpy context: only its name matters here
    yield None


@pytest.mark.parametrize('k', range(6))
def test_on_the_domain(ros, k):
    _ran('domain', k)
"""

FREE = """
@pytest.mark.parametrize('k', range(6))
def test_free(k):
    _ran('free', k)
"""


@pytest.mark.timeout(120)
def test_a_group_and_a_ros_domain_module_each_run_on_one_worker(tmp_path):
    # The project's hook, without its fixtures (they start rclpy): only the collection hook.
    source = CONFTEST.read_text()
    start = source.index('@pytest.hookimpl(tryfirst=True)')
    end = source.index('@pytest.fixture', start)
    (tmp_path / 'conftest.py').write_text('import pytest\n\n\n' + source[start:end])
    (tmp_path / 'test_grouped.py').write_text(RAN + GROUPED)
    (tmp_path / 'test_one_domain.py').write_text(RAN + ONE_DOMAIN)
    (tmp_path / 'test_free.py').write_text(RAN + FREE)
    (tmp_path / 'pytest.ini').write_text('[pytest]\n')
    ran = tmp_path / 'ran'
    ran.mkdir()
    command = [
        sys.executable,
        '-m',
        'pytest',
        '-n',
        '2',
        '--dist',
        'loadgroup',
        '-q',
        '-p',
        'no:cacheprovider',
    ]
    done = subprocess.run(
        command,
        cwd=tmp_path,
        # The inner run's options are the command's alone, not the caller's PYTEST_ADDOPTS.
        env={**{k: v for k, v in os.environ.items() if k != 'PYTEST_ADDOPTS'}, 'RAN_DIR': str(ran)},
        capture_output=True,
        text=True,
        timeout=110,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    workers: dict[str, set[str]] = {}
    for path in ran.iterdir():
        workers.setdefault(path.name.split('-')[0], set()).add(path.read_text())
    assert set(workers) == {'grouped', 'domain', 'free'}, done.stdout
    assert len(workers['grouped']) == 1, f'one xdist_group ran on {sorted(workers["grouped"])}'
    assert len(workers['domain']) == 1, f'one ROS domain module ran on {sorted(workers["domain"])}'
