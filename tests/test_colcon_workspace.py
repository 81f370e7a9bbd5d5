"""The colcon workspace: its symlinks, and a colcon build of a copy of it (no ROS install needed).

colcon-ros builds ament_python packages with setuptools alone (ament itself is only needed for
ament_cmake), so the colcon from .venv checks what `colcon build` on a Jazzy machine installs.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# One worker runs this whole module, so the module-scoped build happens once per run.
pytestmark = pytest.mark.xdist_group('colcon_build')

REPO = Path(__file__).resolve().parents[1]
WORKSPACE_SRC = REPO / 'ros2_ws' / 'src'
PACKAGES = ('formation_msgs_py', 'formation_agent', 'formation_sim')


def test_workspace_holds_relative_symlinks_to_the_packages() -> None:
    links = sorted(p.name for p in WORKSPACE_SRC.iterdir() if p.is_symlink())
    assert links == sorted(PACKAGES)
    for name in PACKAGES:
        link = WORKSPACE_SRC / name
        assert link.is_symlink(), f'{link} is not a symlink'
        assert os.readlink(link) == f'../../src/{name}'
        assert (link / 'package.xml').is_file()


def _colcon(root: Path, *args: str) -> subprocess.CompletedProcess:
    colcon = Path(sys.executable).with_name('colcon')
    assert colcon.exists(), f'{colcon} is missing: run `make venv` (requirements-dev.txt)'
    env = dict(os.environ, COLCON_HOME=str(root / 'colcon_home'), COLCON_LOG_PATH=str(root / 'log'))
    return subprocess.run(
        [str(colcon), *args], cwd=root, env=env, capture_output=True, text=True, timeout=600, check=False
    )


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build a copy of the workspace (the packages, not the links) and return its install/.

    The copy keeps the repository's shape: packages in src/, and tests/ beside it (a link to the
    repository's tests), where each package's setup.cfg sends `colcon test`.
    """
    root = tmp_path_factory.mktemp('colcon_ws')
    for name in PACKAGES:
        shutil.copytree(
            WORKSPACE_SRC / name,
            root / 'src' / name,
            # *.so: the compiled core built in place by `make venv`; colcon must build its own.
            ignore=shutil.ignore_patterns('*.egg-info', '__pycache__', '*.so'),
        )
    (root / 'tests').symlink_to(REPO / 'tests')
    build = _colcon(
        root,
        'build',
        '--base-paths',
        'src',
        '--build-base',
        'build',
        '--install-base',
        'install',
        '--event-handlers',
        'console_direct+',
    )
    assert build.returncode == 0, build.stdout + build.stderr
    return root / 'install'


def install_env(install: Path) -> dict[str, str]:
    """The PYTHONPATH `source install/setup.bash` would set: each package's site-packages."""
    site_dirs = sorted(str(p) for p in install.glob('*/lib/python3*/site-packages'))
    assert len(site_dirs) == len(PACKAGES), site_dirs
    return dict(os.environ, PYTHONPATH=os.pathsep.join(site_dirs))


@pytest.mark.slow
def test_colcon_installs_the_ament_layout(colcon_install: Path) -> None:
    for package, scripts in (
        ('formation_agent', ('formation_agent',)),
        ('formation_sim', ('formation', 'formation_sim', 'formation_recorder')),
    ):
        for script in scripts:  # where `ros2 run <package> <script>` looks
            path = colcon_install / package / 'lib' / package / script
            assert path.is_file(), path
            assert os.access(path, os.X_OK), path
    for package in PACKAGES:
        share = colcon_install / package / 'share'
        assert (share / package / 'package.xml').is_file()
        assert (share / 'ament_index' / 'resource_index' / 'packages' / package).is_file()
    # The robots' example parameter files (README, "Running on robots").
    config = colcon_install / 'formation_agent' / 'share' / 'formation_agent' / 'config'
    from formation_agent.core.kinds import KIND_NAMES, robot_kind

    examples = {robot_kind(name).params_file for name in KIND_NAMES}  # one per robot kind
    assert {p.name for p in config.glob('*.params.yaml')} == examples
    # ... and where the README sends every install: `python3 -m formation_agent.config`
    probe = subprocess.run(
        [sys.executable, '-m', 'formation_agent.config'],
        env=install_env(colcon_install),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert probe.returncode == 0, probe.stderr
    folder = Path(probe.stdout.strip())
    assert (
        folder.is_relative_to(colcon_install) and {p.name for p in folder.glob('*.params.yaml')} == examples
    )
    site = next(colcon_install.glob('formation_sim/lib/python3*/site-packages'))
    installed = {p.name for p in (site / 'formation_sim' / 'model' / 'scenarios').glob('*.yaml')}
    assert installed >= {'paper_single.yaml', 'paper_double.yaml'}


@pytest.mark.slow
def test_colcon_install_is_what_python_imports(colcon_install: Path) -> None:
    probe = subprocess.run(
        [
            sys.executable,
            '-c',
            'import formation_msgs_py.types, formation_agent.core.closed_form, '
            'formation_sim.runtime.nodes.recorder as r;'
            'print(r.__file__)',
        ],
        env=install_env(colcon_install),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert probe.returncode == 0, probe.stderr
    assert Path(probe.stdout.strip()).is_relative_to(colcon_install)


@pytest.mark.slow
def test_colcon_builds_the_compiled_core(colcon_install: Path) -> None:
    # docs/COMPILED_CORE.md: the colcon install has its own _fastcore, and new searches run it.
    probe = subprocess.run(
        [
            sys.executable,
            '-c',
            'from formation_agent.core import _fastcore, compiled; '
            'print(_fastcore.__file__); print(compiled.implementation())',
        ],
        env=install_env(colcon_install),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert probe.returncode == 0, probe.stderr
    where, which = probe.stdout.split()
    assert Path(where).is_relative_to(colcon_install)
    assert which == 'compiled'


@pytest.mark.slow
def test_colcon_installed_formation_command_runs(colcon_install: Path) -> None:
    formation = colcon_install / 'formation_sim' / 'lib' / 'formation_sim' / 'formation'
    run = subprocess.run(
        [str(formation), '--help'],
        env=install_env(colcon_install),
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'simulate' in run.stdout


@pytest.mark.slow
def test_colcon_test_runs_the_package_tests(colcon_install: Path) -> None:
    # formation_msgs_py's tests (no ROS process): colcon test finds them through setup.cfg and
    # runs them against the installed package.
    import xml.etree.ElementTree as ET

    root = colcon_install.parent
    run = _colcon(
        root,
        'test',
        '--base-paths',
        'src',
        '--build-base',
        'build',
        '--install-base',
        'install',
        '--packages-select',
        'formation_msgs_py',
        '--event-handlers',
        'console_direct+',
    )
    assert run.returncode == 0, run.stdout + run.stderr
    suite = ET.parse(root / 'build' / 'formation_msgs_py' / 'pytest.xml').getroot()  # noqa: S314 - colcon's own report
    suite = suite if suite.tag == 'testsuite' else suite.find('testsuite')
    assert int(suite.get('tests')) >= 50
    assert int(suite.get('failures')) == 0 and int(suite.get('errors')) == 0
