"""Studies on Dask: a real scheduler with a worker killed mid-study, an interrupted study resumed,
the same rows whatever the workers, a broken case refused before anything runs.

Each test starts its own processes (ports chosen free, processes ended by PID) and runs small cases.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from formation_sim.study.case import TIMING_COLUMNS, run_case
from formation_sim.study.errors import StudyError
from formation_sim.study.runner import run_study
from formation_sim.study.spec import build_study, load_study
from formation_sim.study.store import ROWS_FILE, read_rows

BIN = Path(sys.executable).parent
pytestmark = pytest.mark.xdist_group('dask')  # one worker of pytest-xdist: the cores are few


def _sigint_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _deterministic(rows):
    return [{k: v for k, v in row.items() if k not in TIMING_COLUMNS} for row in rows]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _wait_for(condition, what: str, timeout: float = 60.0) -> None:
    """Poll `condition` until it holds (a process's visible state), or fail naming `what`."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out waiting for {what}')
        time.sleep(0.05)


def _end(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


SMALL = {
    'name': 'small',
    'seed': 9,
    'defaults': {'horizon': 0.3, 'alpha': 10.0, 'slack': 0.5},
    'cases': [
        {
            'draws': 25,
            'n': {'integers': [2, 4]},
            'p': {'integers': [1, 2]},
            'algorithm': ['eta1', 'eta2'],
            'graph': ['star', 'path', 'complete', 'geometric'],
        }
    ],
}


@pytest.mark.timeout(180)
def test_a_study_on_a_dask_scheduler_survives_a_worker_killed_mid_study(tmp_path):
    study = build_study(SMALL)
    assert len(study.cases) == 200
    port = _free_port()
    address = f'tcp://127.0.0.1:{port}'
    env = {**os.environ, 'DASK_DISTRIBUTED__WORKER__DAEMON': 'False'}
    scheduler = subprocess.Popen(
        [BIN / 'dask', 'scheduler', '--host', '127.0.0.1', '--port', str(port), '--no-dashboard'],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    workers = []
    try:
        for _ in range(2):
            workers.append(
                subprocess.Popen(
                    [
                        BIN / 'dask',
                        'worker',
                        address,
                        '--nthreads',
                        '1',
                        '--no-nanny',
                        '--no-dashboard',
                        '--host',
                        '127.0.0.1',
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    env=env,
                )
            )
        from distributed import Client

        with Client(address, timeout='30s') as client:
            client.wait_for_workers(2, timeout=60)
        seen, killed = [], {}

        def on_row(row):  # the driver's thread, as each row is written
            seen.append(row)
            if not killed and len(seen) == 30:
                victim = next(w for w in workers if row['worker'].endswith(f':{w.pid}'))
                os.kill(victim.pid, signal.SIGKILL)  # by PID, mid-study
                killed.update(pid=victim.pid, at=len(seen))

        summary = run_study(study, out=tmp_path / 'out', scheduler=address, on_row=on_row)
    finally:
        for process in [*workers, scheduler]:
            _end(process)
    rows = read_rows(tmp_path / 'out')
    assert summary.complete and summary.ran == 200 and summary.failed == 0
    assert (
        len(rows) == 200
        and len({r['key'] for r in rows})
        == 200
        == len((tmp_path / 'out' / ROWS_FILE).read_text().splitlines()) - 1
    )
    assert [r['case'] for r in rows] == list(range(200)) and all(r['status'] == 'ok' for r in rows)
    assert killed and 30 <= killed['at'] < 200, 'the worker was killed before the study ended'
    later = [r['worker'] for r in seen[killed['at'] :]]
    # The rest ran on the survivor (a row or two the driver had already fetched may still come).
    assert len(later) == 170 and sum(w.endswith(f':{killed["pid"]}') for w in later) <= 2
    for case, row in list(zip(study.cases, rows))[::40]:  # a sample against the same case run here
        assert _deterministic([row]) == _deterministic([run_case(case)])


@pytest.mark.timeout(180)
def test_an_interrupted_study_runs_only_what_is_missing_and_ends_with_the_same_rows(tmp_path):
    # Cases of ~0.25 s each (horizon 6): the interrupt, sent once three rows are in, finds most of the
    # study still to run (at horizon 1 the margin was under a second).
    spec = {
        **SMALL,
        'defaults': {**SMALL['defaults'], 'horizon': 6.0},
        'cases': [
            {'draws': 12, 'n': {'integers': [6, 10]}, 'algorithm': ['eta1', 'eta2'], 'graph': 'geometric'}
        ],
    }
    (tmp_path / 'spec.yaml').write_text(yaml.safe_dump(spec))
    study = load_study(tmp_path / 'spec.yaml')
    out = tmp_path / 'out'
    command = [BIN / 'formation', 'study', tmp_path / 'spec.yaml', '--out', out, '--workers', '2']
    # SIGINT as from a terminal: a test run started in the background of a non-interactive shell
    # inherits it ignored, and Python then installs no KeyboardInterrupt (the study ran to its end).
    first = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_sigint_default,  # noqa: PLW1509 - signal only
    )
    try:
        _wait_for(lambda: len(read_rows(out)) >= 3 or first.poll() is not None, 'three rows')
        first.send_signal(signal.SIGINT)
        stdout, stderr = first.communicate(timeout=60)
    finally:
        _end(first)
    assert first.returncode == 130, stderr
    before = {r['key']: r for r in read_rows(out)}
    assert 3 <= len(before) < len(study.cases), 'the study ended before the interrupt'
    assert 'interrupted: run it again with the same --out to finish' in stdout
    second = subprocess.run(command, capture_output=True, text=True, timeout=150, check=False)
    assert second.returncode == 0, second.stderr
    assert (
        f'{len(study.cases)} cases, {len(before)} done in {out}, {len(study.cases) - len(before)} to run'
        in second.stderr
    )
    assert (
        f'{len(before)} done before, {len(study.cases) - len(before)} run now, 0 failed in all'
        in second.stdout
    )
    rows = read_rows(out)
    assert len(rows) == len(study.cases) == len({r['key'] for r in rows})
    for row in rows:  # the rows of the first run were not run again: same worker, same wall time
        if row['key'] in before:
            assert row == before[row['key']]
    assert _deterministic(rows) == _deterministic(
        [run_case(case) for case in study.cases]
    )  # as uninterrupted


@pytest.mark.timeout(120)
def test_a_case_breaking_a_hypothesis_stops_the_study_before_any_run(tmp_path):
    study = build_study(
        {
            'name': 'bad',
            'cases': [
                {'n': 3, 'horizon': 0.2, 'alpha': 10.0},
                {'n': 30, 'graph': 'path', 'slack': 0.001, 'alpha': 0.01},
            ],
        }
    )
    with pytest.raises(
        StudyError,
        match=r'1 of 2 cases break a hypothesis of their theorem; nothing was run:\n  case 1 .*\[precision\]',
    ):
        run_study(study, out=tmp_path / 'out', workers=1)
    assert not (tmp_path / 'out').exists()
