"""docs/API.md: every example runs as written, in order, in one session (a fresh folder)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

API = Path(__file__).resolve().parents[1] / 'docs' / 'API.md'


def _examples() -> list[str]:
    return re.findall(r'^```python\n(.*?)^```', API.read_text(), flags=re.MULTILINE | re.DOTALL)


def test_the_examples_are_there():
    blocks = _examples()
    assert len(blocks) >= 8
    assert any('FormationRun' in block for block in blocks) and any(
        'load_bag_run' in block for block in blocks
    )


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.xdist_group('formation_distributed')
def test_every_example_runs_as_written(tmp_path, monkeypatch):
    program = '\n\n'.join(_examples())
    env = {
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_LOG_DIR': str(tmp_path / 'ros_log'),
        'PATH': '/usr/bin:/bin',
        'HOME': str(tmp_path),
    }
    run = subprocess.run(
        [sys.executable, '-c', program],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=400,
        check=False,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    assert (tmp_path / 'api_example' / 'single' / 'fig1.png').stat().st_size > 1000
    assert (tmp_path / 'api_example' / 'distributed' / 'bag' / 'metadata.yaml').is_file()
