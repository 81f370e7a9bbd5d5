"""Fast DDS shared-memory files of a run's children: noted while they live, removed when killed.

A process killed by a signal cannot unlink its Fast DDS shared-memory files, and once it is gone
nobody can tell which were its own: `mapped_shm_files` notes them while it lives (the supervisor
looks often), `remove_orphaned` removes, after the run, those of children killed by a signal that
no live process maps any more.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable
from pathlib import Path


def mapped_shm_files(pid: int) -> set[str]:
    """Fast DDS shared-memory files mapped by process `pid`."""
    try:
        maps = Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return set()
    return {line.split()[-1] for line in maps.splitlines() if '/dev/shm/fastrtps_' in line or '/dev/shm/sem.fastrtps_' in line}


_PORT_FILE = re.compile(r'^(?:sem\.)?fastrtps_port(\d+)(?:_el|_mutex)?$')


def domain_port_files(domain_id: int) -> set[str]:
    """Fast DDS shared-memory port files of ROS domain `domain_id`, with their lock and semaphore.

    Fast DDS names a port's files after its port number, and the ports of domain d are
    7400 + 250 d + [0, 250) (the RTPS well-known port mapping).
    """
    first = 7400 + 250 * domain_id
    return {
        str(path)
        for path in Path('/dev/shm').iterdir()
        if (match := _PORT_FILE.match(path.name)) and first <= int(match[1]) < first + 250
    }


def mapped_by_anyone(paths: set[str]) -> set[str]:
    """Those of `paths` still mapped by some live process."""
    in_use = set()
    for proc in Path('/proc').iterdir():
        if proc.name.isdigit():
            in_use |= mapped_shm_files(int(proc.name)) & paths
    return in_use


def remove_orphaned(killed_files: Iterable[set[str]], domain_id: int) -> list[str]:
    """Remove the files children killed by a signal had mapped, once nobody maps them; return them.

    A killed child may also have mapped a peer's port file after the last look (a port is mapped
    when it is first sent to), which then outlives the peer: so the port files of the run's own
    domain that nobody maps any more go too (a live participant always maps its own port).
    """
    orphaned = set().union(*killed_files)
    if orphaned:
        orphaned |= domain_port_files(domain_id)
    in_use = mapped_by_anyone(orphaned)
    # A lock file (_el) is never mapped: it goes only with its port file.
    removable = {path for path in orphaned - in_use if not (path.endswith('_el') and path[:-3] in in_use)}
    for path in removable:
        with contextlib.suppress(OSError):
            os.unlink(path)
    return sorted(removable)
