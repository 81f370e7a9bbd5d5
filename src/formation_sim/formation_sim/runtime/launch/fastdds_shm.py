"""Fast DDS shared-memory files: which a process holds, and removing those a dead process left.

Every Fast DDS participant creates, in /dev/shm, a segment `fastrtps_<hex>` and the ports it
listens on, `fastrtps_port<N>` with a semaphore `sem.fastrtps_port<N>_mutex`; each comes with a
lock file `<name>_el` that its owner keeps open and flock-locked while it lives.  Port numbers
are the RTPS ports of the domain (7400 + 250 d + …) and, machine-wide, 7000, 7001, … for
whichever participant takes the next free one.  A process killed hard cannot remove its files,
and a peer that mapped one of its ports keeps that port's reference, so the file outlives both.

A file is left by the dead when nobody holds its lock (a live owner always does: the kernel
releases a flock when its holder dies), even when a live peer still maps it (issue 28: an outside
node in the domain kept a killed simulator's ports mapped, and they outlived it): only the names
are removed, the peer's mapping stays valid and its memory is freed when it unmaps.  A file
without a lock file is left by the dead only when no live process maps it.  `remove_orphans` removes
such files among those it is given, holding the lock while it does, so that a participant
starting at that moment cannot take the port over between the check and the removal.  It never
looks beyond the names it is given: files of other runs stay where they are.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path

from formation_msgs_py.middleware import domain_ports

SHM_DIR = Path('/dev/shm')  # noqa: S108 - where Fast DDS keeps its segments, not a temporary file of ours

# fastrtps_<hex> or fastrtps_port<N>, with the lock file `_el` or the semaphore `sem.…_mutex`.
_FILE = re.compile(r'^(?:sem\.)?(fastrtps_(?:port\d+|[0-9a-f]+))(?:_el|_mutex)?$')
_PORT_FILE = re.compile(r'^(?:sem\.)?fastrtps_port(\d+)(?:_el|_mutex)?$')


def _base(name: str) -> str | None:
    """'fastrtps_port7011' for each of the port's files, 'fastrtps_<hex>' for a segment's; None for others."""
    match = _FILE.match(name)
    return match[1] if match else None


def _family(base: str) -> list[Path]:
    """The files of one segment or port: the file itself, its semaphore, and its lock file last."""
    return [SHM_DIR / base, SHM_DIR / f'sem.{base}_mutex', SHM_DIR / f'{base}_el']


def fastdds_names() -> set[str]:
    """The names of the Fast DDS files in /dev/shm now (of every process on the machine)."""
    with contextlib.suppress(OSError):
        return {name for name in os.listdir(SHM_DIR) if _base(name)}
    return set()


def held_files(pid: int) -> set[str]:
    """The Fast DDS files process `pid` maps (segments, ports) or holds open (its lock files)."""
    held = set()
    with contextlib.suppress(OSError):
        for line in Path(f'/proc/{pid}/maps').read_text().splitlines():
            path = line.rsplit(' ', 1)[-1]
            if path.startswith(str(SHM_DIR)) and _base(Path(path).name):
                held.add(path)
    with contextlib.suppress(OSError):
        for fd in os.scandir(f'/proc/{pid}/fd'):
            with contextlib.suppress(OSError):
                path = os.readlink(fd.path)
                if path.startswith(str(SHM_DIR)) and _base(Path(path).name):
                    held.add(path)
    return held


def mapped_by_anyone(paths: Iterable[str]) -> set[str]:
    """Those of `paths` some live process maps."""
    wanted = set(paths)
    mapped = set()
    for proc in Path('/proc').iterdir():
        if not proc.name.isdigit():
            continue
        with contextlib.suppress(OSError):
            for line in (proc / 'maps').read_text().splitlines():
                path = line.rsplit(' ', 1)[-1]
                if path in wanted:
                    mapped.add(path)
    return mapped


def domain_port_files(domain_id: int) -> set[str]:
    """The port files of ROS domain `domain_id` (RTPS ports 7400 + 250 d + [0, 250)) in /dev/shm."""
    ports = domain_ports(domain_id)
    return {
        str(path)
        for path in SHM_DIR.iterdir()
        if (match := _PORT_FILE.match(path.name)) and int(match[1]) in ports
    }


@contextlib.contextmanager
def _lock_if_free(lock: Path) -> Iterator[bool]:
    """Hold `lock` (a Fast DDS `_el` file) if no live process does; yield whether we hold it.

    A missing lock file counts as free: its owner, alive, would hold it open.
    """
    try:
        fd = os.open(lock, os.O_RDONLY)
    except FileNotFoundError:
        yield True
        return
    except OSError:
        yield False
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            yield False
            return
        yield True
    finally:
        os.close(fd)  # releases the lock


def in_use(paths: Iterable[str]) -> set[str]:
    """Those of `paths` whose segment or port a live process holds (its lock) or maps.

    Ports 7000, 7001, … are taken by whichever participant comes next: a file of a dead process
    may be made anew by a live one.
    """
    paths = set(paths)
    bases = {path: _base(Path(path).name) for path in paths}
    family = {str(file) for base in set(bases.values()) - {None} for file in _family(base)}
    mapped = mapped_by_anyone(family)
    used = set()
    for path, base in bases.items():
        if base is None:
            continue
        if any(str(file) in mapped for file in _family(base)):
            used.add(path)
            continue
        with _lock_if_free(SHM_DIR / f'{base}_el') as free:
            if not free:
                used.add(path)
    return used


def remove_orphans(paths: Iterable[str]) -> list[str]:
    """Remove the files of every segment or port named in `paths` whose owner is gone; return them.

    A segment or port goes whole (file, semaphore, lock file) once nobody holds its lock file
    (a live peer may still map it: only the names go); one without a lock file goes only when no
    live process maps any of its files; any other is left alone.
    """
    families = {}
    for path in paths:
        base = _base(Path(path).name)
        if base is not None and base not in families:
            existing = [file for file in _family(base) if file.exists()]
            if existing:
                families[base] = existing
    if not families:
        return []
    mapped = mapped_by_anyone(str(file) for files in families.values() for file in files)
    removed = []
    for base, files in sorted(families.items()):
        # A live peer that still maps a dead owner's file (an outside node in the domain, issue 28:
        # the run's ports outlived it) keeps its mapping when the name goes, and the memory is freed
        # when it unmaps; the owner's lock file, free, says the owner is dead.  Without a lock file
        # a mapped file may be a live owner's: it stays.
        lock_file = SHM_DIR / f'{base}_el'
        if not lock_file.exists() and any(str(file) in mapped for file in files):
            continue
        with _lock_if_free(SHM_DIR / f'{base}_el') as free:
            if not free:
                continue
            for file in files:  # the lock file last: while it exists, we hold it
                with contextlib.suppress(FileNotFoundError):
                    file.unlink()
                    removed.append(str(file))
    return removed
