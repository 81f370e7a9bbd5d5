"""Run folders: where a run's files go, and the rule that no run replaces another unless asked.

Policy (README, "Run folders"): `formation simulate` and `formation run` (and `FormationRun`)
write into a folder that is new or empty.  A folder that holds anything is refused, naming what
is there, before anything on disk changes; `force=True` (`--force`) replaces an earlier run:
its files are removed first, so no stale bag or figure is left beside the new run, and a
folder holding files no run writes is refused even then.  Without an explicit folder a run gets
a new one under `runs/`, named after the scenario (sanitised, so it stays inside `runs/`) and
the time, with a numbered suffix if that name is taken: it never collides with another run.

ROS-free; checks raise `RunFolderError` (a ValueError) with the folder and the reason.
"""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

from formation_msgs_py.tags import KEY_FILE
from formation_sim.sim.errors import RunFolderError

RUNS_ROOT = Path('runs')

# Every entry a run or its analysis leaves at the top of its folder (a test keeps this list true
# for real runs): `formation simulate`, `formation run` (inputs, logs, bag, graph), the figure,
# and what `formation analyze` / `formation compare` write there by default.
RUN_ENTRIES = frozenset(
    {
        'summary.json',
        'summary.json.tmp',
        'trajectory',
        'trajectory.incomplete',
        'trajectory.npz',  # runs written before the trajectory folder
        'formation.png',
        'scenario.yaml',
        'agents.params.yaml',
        'recorder.params.yaml',
        'robots.params.yaml',
        'simulator.params.yaml',
        'coordinator.params.yaml',
        KEY_FILE,  # the run's key (docs/HOSTILE_TRAFFIC.md, Tags)
        'graph.json',
        'bag',
        'logs',
        'analysis',
    }
)
_DERIVED_PREFIX = 'compare-'  # formation compare's default output: RUN_A/compare-<RUN_B>
_SHOWN = 6  # entries named in a refusal
_NAME_LIMIT = 64  # characters of a scenario name kept in a folder name


def _is_run_entry(name: str) -> bool:
    return name in RUN_ENTRIES or name.startswith(_DERIVED_PREFIX)


def _listing(names: list[str], folder: Path) -> str:
    shown = [f'{name}/' if (folder / name).is_dir() else name for name in names[:_SHOWN]]
    more = f' and {len(names) - _SHOWN} more' if len(names) > _SHOWN else ''
    return ', '.join(shown) + more


def holds_run(folder: Path) -> bool:
    """Whether `folder` holds a run's results (summary.json or a bag)."""
    return (folder / 'summary.json').is_file() or (folder / 'bag').is_dir()


def _existing_ancestor(path: Path) -> Path:
    """The deepest existing path on the way to `path`; refuses a file met on the way."""
    absolute = Path(os.path.abspath(path))
    for candidate in (absolute, *absolute.parents):
        if candidate.exists():
            if not candidate.is_dir():
                if candidate == absolute:
                    raise RunFolderError(f'{path} is a file, not a folder')
                raise RunFolderError(f'{path}: {candidate} is a file, so no folder can be made under it')
            return candidate
    return Path(absolute.anchor)  # pragma: no cover - the root always exists


def bag_around(path: Path) -> Path | None:
    """The bag folder (one holding metadata.yaml or an .mcap file) that `path` is or lies in, or None."""
    absolute = Path(os.path.abspath(path))
    for candidate in (absolute, *absolute.parents):
        if candidate.is_dir() and ((candidate / 'metadata.yaml').is_file() or any(candidate.glob('*.mcap'))):
            return candidate
    return None


def _refuse_bag(out: Path) -> None:
    """Issue 28: `analyze --out RUN/bag` and `run --out RUN/bag/x` wrote inside a bag's folder."""
    if (bag := bag_around(out)) is not None:
        where = 'is' if bag == Path(os.path.abspath(out)) else 'lies inside'
        raise RunFolderError(
            f'{out} {where} the bag folder {bag} (it holds a recording: metadata.yaml or .mcap); files '
            'written there would be mixed into the recording; nothing was changed: choose another --out'
        )


def check_out_dir(out: Path, *, force: bool = False) -> None:
    """Refuse `out` unless a run may write there; changes nothing on disk.

    Accepted: a folder that does not exist yet (in a writable place) or is empty; with `force`,
    a folder holding only an earlier run's files (RUN_ENTRIES).  Never a bag's folder nor one
    inside it.
    """
    out = Path(out)
    ancestor = _existing_ancestor(out)
    _refuse_bag(out)
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise RunFolderError(f'{out}: cannot write in {ancestor} (permission denied)')
    if ancestor != Path(os.path.abspath(out)):
        return  # does not exist yet
    try:
        names = sorted(entry.name for entry in out.iterdir())
    except OSError as error:
        raise RunFolderError(f'{out}: cannot list the folder: {error.strerror or error}') from None
    if not names:
        return
    foreign = [name for name in names if not _is_run_entry(name)]
    if not force:
        what = 'an earlier run' if holds_run(out) else 'files'
        raise RunFolderError(
            f'{out} already holds {what} ({_listing(names, out)}); nothing was changed. Choose another '
            f'--out (or none: a new folder under {RUNS_ROOT}/), or add --force to replace the earlier run'
        )
    if foreign:
        raise RunFolderError(
            f'{out} holds {_listing(foreign, out)}, which no run writes; --force replaces only an earlier '
            f"run's files, so nothing was changed: move them away or choose another --out"
        )


def clear_out_dir(out: Path, *, force: bool = False) -> list[str]:
    """Check `out` again, remove an earlier run's files (with `force`), create it; the names removed."""
    out = Path(out)
    check_out_dir(out, force=force)
    removed = sorted(entry.name for entry in out.iterdir()) if out.is_dir() else []
    try:
        for name in removed:
            path = out / name
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink()
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise RunFolderError(f'{out}: cannot prepare the run folder: {error.strerror or error}') from None
    return removed


def folder_name(scenario_name: str) -> str:
    """`scenario_name` as one safe path component: letters, digits and _ kept, any other run of
    characters (/, .., spaces) becomes one '-'; never empty, never leaves its parent folder."""
    name = re.sub(r'[^A-Za-z0-9_]+', '-', scenario_name).strip('-')[:_NAME_LIMIT].strip('-')
    return name or 'scenario'


def new_run_folder(scenario_name: str, kind: str, *, root: Path = RUNS_ROOT) -> Path:
    """Create and return a new folder root/<scenario>-<kind>-<YYYYmmdd-HHMMSS>[-k] (never an existing one)."""
    base = f'{folder_name(scenario_name)}-{kind}-{time.strftime("%Y%m%d-%H%M%S")}'
    root = Path(root)
    _existing_ancestor(root)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise RunFolderError(f'cannot create {root}: {error.strerror or error}') from None
    for attempt in range(1, 1000):
        folder = root / (base if attempt == 1 else f'{base}-{attempt}')
        try:
            folder.mkdir()  # atomic: two runs started in the same second get different folders
        except FileExistsError:
            continue
        except OSError as error:
            raise RunFolderError(f'cannot create {folder}: {error.strerror or error}') from None
        return folder
    raise RunFolderError(f'{root}: 999 folders named {base}[-k] exist already')  # pragma: no cover


def claim_out_dir(out: Path | None, *, scenario_name: str, kind: str, force: bool = False) -> Path:
    """The folder a run writes into, ready: `out` cleared by `clear_out_dir`, or a new one."""
    if out is None:
        return new_run_folder(scenario_name, kind)
    clear_out_dir(out, force=force)
    return Path(out)


def check_report_dir(out: Path) -> None:
    """Refuse an output folder for a report (analyze, compare) that holds a run it would overwrite."""
    out = Path(out)
    ancestor = _existing_ancestor(out)
    _refuse_bag(out)
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise RunFolderError(f'{out}: cannot write in {ancestor} (permission denied)')
    if out.is_dir() and holds_run(out):
        raise RunFolderError(
            f'{out} holds a run (summary.json or bag/) whose files the report would overwrite; '
            f'choose another --out'
        )
