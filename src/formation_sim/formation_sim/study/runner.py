"""Run a study's missing cases on Dask distributed, writing each row as it finishes.

`run_study(study, out=DIR)` starts a LocalCluster of worker processes (one thread each, as many
as the machine has cores unless `workers` says otherwise), or connects to an existing scheduler
(`scheduler='tcp://host:port'`). It first validates every case still to run on the workers (a
case whose team breaks a hypothesis stops the study before any run starts), then submits the
runs and appends each row to DIR/rows.csv as it arrives. Cases with a row already are not run
again, so a study killed or interrupted is finished by running it again into the same DIR. A
worker lost mid-study is Dask's to handle: its cases run again elsewhere; a case whose workers
died every time it was tried (distributed's allowed-failures) becomes a failed row.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from formation_sim.study.case import check_case, failed_row, run_case
from formation_sim.study.errors import StudyError
from formation_sim.study.spec import Study
from formation_sim.study.store import StudyFolder

MAX_LISTED = 5  # invalid cases named in the error before "and N more"
CLOSE_TIMEOUT = 10.0  # s: the LocalCluster's close after the study (its workers idle, or ended)


@dataclass(frozen=True, kw_only=True)
class StudySummary:
    """What one invocation did, and the study as a whole."""

    cases: int  # in the study
    already_done: int  # rows found when it started (not run again)
    ran: int  # rows this invocation wrote
    failed: int  # failed rows in the whole study
    workers: int
    wall_time: float  # this invocation, validation included
    run_time: float  # from the first submitted run to the last row
    sum_of_runs: float  # the wall times of this invocation's runs, added up
    cpu_hours: float  # the CPU time of every row of the study
    complete: bool
    interrupted: bool = False  # SIGINT (KeyboardInterrupt): the rows written so far are kept

    @property
    def efficiency(self) -> float | None:
        """Sum of the single runs' wall times / (run time x workers): 1 is perfect parallelism."""
        if not self.ran or self.run_time <= 0.0 or not self.workers:
            return None
        return self.sum_of_runs / (self.run_time * self.workers)

    def format(self) -> str:
        eff = self.efficiency
        lines = [
            f'{self.cases} cases: {self.already_done} done before, {self.ran} run now, {self.failed} '
            'failed in all'
            + ('' if self.complete else f', {self.cases - self.already_done - self.ran} still missing')
            + (' (interrupted: run it again with the same --out to finish)' if self.interrupted else ''),
            f'wall time {self.wall_time:.1f} s ({self.run_time:.1f} s running) on {self.workers} '
            f'worker{"s" if self.workers != 1 else ""}; '
            f'the runs alone {self.sum_of_runs:.1f} s'
            + (
                ''
                if eff is None
                else f': speed-up {self.sum_of_runs / self.run_time:.2f}, efficiency {eff:.2f} per worker'
            ),
            f'CPU time of the study {self.cpu_hours:.4f} CPU-hours',
        ]
        return '\n'.join(lines)


class Eta:
    """'k/N rows, ETA' from the rate of this invocation's rows."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.started = time.monotonic()

    def line(self, done: int, failed: int) -> str:
        elapsed = time.monotonic() - self.started
        left = self.total - done
        eta = '?' if not done else f'{elapsed / done * left:.0f} s'
        return f'study: {done}/{self.total} runs, {failed} failed, {elapsed:.0f} s, ETA {eta}'


def _client(scheduler: str | None, workers: int | None):
    """(client, cluster or None): a Client of the scheduler, or of a new LocalCluster of processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            return Client(scheduler, timeout='20s'), None
        except (OSError, TimeoutError) as error:
            raise StudyError(f'--scheduler {scheduler}: cannot connect: {error}') from None
    count = workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=count,
        threads_per_worker=1,
        processes=True,
        dashboard_address=':0',
        silence_logs=logging.ERROR,
    )
    return Client(cluster), cluster


def _end_workers(cluster) -> None:
    """Interrupted: end the LocalCluster's own worker processes now. A worker inside a run finishes
    the run before it closes (minutes, or hours at the horizon), so it is sent SIGTERM; the case in
    progress has no row and runs again when the study is run again into the same folder."""
    for nanny in list(cluster.workers.values()):
        process = getattr(nanny, 'process', None)
        pid = getattr(process, 'pid', None)
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGTERM)


def _validate(client, cases) -> None:
    """Every case's team meets its theorem's hypotheses, or StudyError naming those that do not."""
    futures = client.map(check_case, cases, key=[f'check-{case.key}' for case in cases])
    problems = [p for p in client.gather(futures) if p is not None]
    client.cancel(futures)
    if problems:
        more = f' (and {len(problems) - MAX_LISTED} more)' if len(problems) > MAX_LISTED else ''
        raise StudyError(
            f'{len(problems)} of {len(cases)} cases break a hypothesis of their theorem; nothing was run:\n  '
            + '\n  '.join(problems[:MAX_LISTED])
            + more
        )


def _workers(client) -> int:
    return (
        len(client.scheduler_info(n_workers=-1).get('workers', {}))
        if hasattr(client, 'scheduler_info')
        else 1
    )


def run_study(
    study: Study,
    *,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    report: Callable[[str], None] | None = None,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> StudySummary:
    """Run the cases of `study` without a row in `out`; see the module docstring.

    `report(line)` gets the progress lines, `on_row(row)` every row as it is written.
    StudyError (nothing run) for a folder holding another study or a case that breaks a hypothesis.
    """
    started = time.perf_counter()
    folder = StudyFolder(out, study)
    before = len(folder.done)
    todo = [case for case in study.cases if case.key not in folder.done]
    say = report or (lambda _line: None)
    say(
        f'study {study.name!r}: {len(study.cases)} cases, {before} done in {folder.folder}, {len(todo)} '
        'to run'
    )
    tally = _Tally(started=time.perf_counter())
    count, interrupted = 0, False
    if todo:
        client, cluster = _client(scheduler, workers)
        try:
            count = _workers(client)
            _validate(client, todo)
            folder.open()
            tally.started = time.perf_counter()
            _run(client, todo, folder, tally, say, on_row)
        except KeyboardInterrupt:
            interrupted = True
            if cluster is not None:
                _end_workers(cluster)
        finally:
            folder.close()
            client.close()
            if cluster is not None:
                cluster.close(timeout=CLOSE_TIMEOUT)
    rows = folder.rows
    return StudySummary(
        cases=len(study.cases),
        already_done=before,
        ran=tally.ran,
        failed=sum(1 for row in rows if row['status'] != 'ok'),
        workers=count,
        wall_time=time.perf_counter() - started,
        run_time=time.perf_counter() - tally.started if tally.ran else 0.0,
        sum_of_runs=tally.sum_of_runs,
        cpu_hours=sum(row['cpu_time'] or 0.0 for row in rows) / 3600.0,
        complete=len(folder.done) == len(study.cases),
        interrupted=interrupted,
    )


@dataclass(kw_only=True)
class _Tally:
    started: float
    ran: int = 0
    failed: int = 0
    sum_of_runs: float = 0.0


def _run(client, todo, folder: StudyFolder, tally: _Tally, say, on_row) -> None:
    """Submit the runs and write each row as it comes (counted in `tally`)."""
    from distributed import as_completed

    by_key = {case.key: case for case in todo}
    eta = Eta(len(todo))
    futures = client.map(run_case, todo, key=[f'case-{case.key}' for case in todo])
    last = 0.0
    for future in as_completed(futures):
        case = by_key[future.key.removeprefix('case-')]
        try:
            row = future.result()
        except Exception as error:  # noqa: BLE001 - the worker died each time it ran the case (KilledWorker), ...
            row = failed_row(case, f'{type(error).__name__}: {error}')
        future.release()  # forgotten by the scheduler: never recomputed if its worker dies later
        if not folder.append(row):
            continue
        tally.ran += 1
        tally.failed += row['status'] != 'ok'
        tally.sum_of_runs += row['wall_time'] or 0.0
        if on_row is not None:
            on_row(row)
        now = time.monotonic()
        if now - last >= 2.0 or tally.ran == len(todo):
            say(eta.line(tally.ran, tally.failed))
            last = now
