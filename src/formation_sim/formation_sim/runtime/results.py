"""What a run leaves behind: the result of `FormationRun.run`, the orchestrator's view of a failure
in summary.json, and a bag rebuilt when its recorder died."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from formation_sim.runtime.supervise import Child, describe_exit

# Exit statuses of a run (and of `formation run`; 2 is bad input, refused before anything starts).
EXIT_OK = 0
EXIT_FAILED = 1
EXIT_LOST = 3  # a process of the run died or an agent was lost
EXIT_INTERRUPTED = 130


@dataclass(frozen=True, kw_only=True)
class ChildExit:
    name: str
    pid: int
    returncode: int | None  # None: did not exit by itself and had to be stopped
    signal_used: str | None  # the last signal sent to stop it, if any


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """What a run left behind and how it ended."""

    out_dir: Path
    summary: Path | None  # DIR/summary.json: complete, or partial when extra.failure is set
    bag: Path | None  # DIR/bag, None if not recorded or not readable
    exit_status: int  # EXIT_OK 0; EXIT_FAILED 1; EXIT_LOST 3 a process or agent lost; 130 interrupted
    domain_id: int
    wall_time: float
    children: tuple[ChildExit, ...] = ()
    message: str = ''
    failure: dict | None = None  # extra.failure of the summary (what failed, where, when)
    bag_recovered: bool = False  # the recorder died and its bag was rebuilt by recorder.reindex

    @property
    def ok(self) -> bool:
        return self.exit_status == 0


def lost_or_failed(child: Child) -> int:
    """EXIT_FAILED for a child that left naming an error, EXIT_LOST for one that died or vanished."""
    return EXIT_FAILED if child.failed_itself else EXIT_LOST


def recover_bag(bag: Path) -> str | None:
    """A bag left without metadata.yaml (its recorder died) is rebuilt from its MCAP file."""
    if not bag.is_dir() or (bag / 'metadata.yaml').is_file():
        return None
    from formation_sim.bag.io import BagError
    from formation_sim.bag.recovery import reindex

    try:
        recovery = reindex(bag)
    except (BagError, OSError) as error:
        return f'recovery failed: {error}'
    return f'{recovery.message_count} messages kept'


def annotate_summary(summary: Path, lost: Child | None, status: int, message: str, *, seconds_after_launch: float) -> dict | None:
    """Add the orchestrator's view of a failure to summary.json's extra.failure; return it.

    `seconds_after_launch`: when the lost child's exit was seen, counted from the launch."""
    if not summary.is_file():
        return None
    data = json.loads(summary.read_text())
    extra = data.setdefault('extra', {})
    failure = extra.get('failure')
    if failure is None and status == EXIT_OK:
        return None
    if failure is None:  # the time keeper completed, but a child failed
        failure = {'kind': 'process_failed', 'message': message, 'agents': [], 'detected_by': 'orchestrator'}
    if lost is not None:
        failure['process'] = {
            'name': lost.name,
            'pid': lost.pid,
            'returncode': lost.process.returncode,
            'exit': describe_exit(lost.process.returncode),
            'seconds_after_launch': seconds_after_launch,
            'error': lost.error_line(),
        }
        if failure['kind'] == 'interrupted':  # stopped by us because of that child
            failure['kind'] = 'process_failed' if lost.failed_itself else 'process_lost'
            failure['message'] = lost.describe()
        elif failure['kind'] == 'agent_lost' and lost.failed_itself:
            failure['kind'] = 'agent_failed'
            failure['message'] = f'{lost.describe()}; {failure["message"]}'
        if 'orchestrator' not in failure['detected_by']:
            failure['detected_by'] += ', orchestrator'
    extra['failure'] = failure
    staging = summary.with_name(summary.name + '.tmp')
    staging.write_text(json.dumps(data, indent=1, allow_nan=False) + '\n')
    staging.replace(summary)
    return failure
