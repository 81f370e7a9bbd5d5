"""Which Fast DDS shared-memory files are left by the dead, and removing only those.

Files made here mimic Fast DDS's names with port numbers of ROS domain 231 (ports 65150-65399,
used by no test) and random segment names, so no real participant's files are touched.
"""

from __future__ import annotations

import fcntl
import mmap
import os
import secrets
from pathlib import Path

import pytest

from formation_sim.runtime.launch.fastdds_shm import (
    SHM_DIR,
    domain_port_files,
    held_files,
    in_use,
    remove_orphans,
)

pytestmark = pytest.mark.skipif(not SHM_DIR.is_dir(), reason='no /dev/shm here')


def _port(number: int) -> list[Path]:
    files = [
        SHM_DIR / f'fastrtps_port{number}',
        SHM_DIR / f'sem.fastrtps_port{number}_mutex',
        SHM_DIR / f'fastrtps_port{number}_el',
    ]
    for file in files:
        file.write_bytes(b'\0' * 64)
    return files


def _segment() -> list[Path]:
    name = f'fastrtps_{secrets.token_hex(8)}'
    files = [SHM_DIR / name, SHM_DIR / f'{name}_el']
    for file in files:
        file.write_bytes(b'\0' * 64)
    return files


@pytest.fixture
def made():
    files: list[Path] = []
    yield files
    for file in files:
        file.unlink(missing_ok=True)


def test_the_files_of_a_dead_owner_go_whole_and_those_held_or_mapped_stay(made):
    dead_port, dead_segment = _port(65390 + os.getpid() % 3), _segment()
    locked, mapped, unnamed = _port(65393 + os.getpid() % 3), _segment(), _segment()
    made += dead_port + dead_segment + locked + mapped + unnamed
    lock = os.open(locked[-1], os.O_RDONLY)  # an owner alive holds its lock file
    fcntl.flock(lock, fcntl.LOCK_EX)
    handle = mapped[0].open('r+b')  # a peer alive maps a segment whose owner is gone
    view = mmap.mmap(handle.fileno(), 0)
    try:
        assert in_use(str(path) for path in dead_port + dead_segment + locked + mapped) == {
            str(path) for path in locked + mapped
        }
        named = [dead_port[0], dead_segment[1], locked[0], mapped[1]]  # any one file names its family
        removed = remove_orphans(str(path) for path in named)
        # Issue 28: a dead owner's segment that a live peer (an outside node) still maps goes too:
        # only its name; the peer's mapping stays valid (it reads what was there).
        assert sorted(removed) == sorted(str(path) for path in dead_port + dead_segment + mapped)
        assert not [path for path in dead_port + dead_segment + mapped if path.exists()]
        assert all(path.exists() for path in locked + unnamed)
        assert view[:4] == b'\0\0\0\0'
    finally:
        view.close()
        handle.close()
        os.close(lock)
    # Once its holder is gone, the port is left by the dead too; what was not named still stays.
    assert sorted(remove_orphans([str(locked[1])])) == sorted(str(path) for path in locked)
    assert all(path.exists() for path in unnamed)


def test_a_dead_owners_port_that_a_live_peer_maps_goes_and_one_without_a_lock_file_stays(made):
    """Issue 28: ports of a killed simulator that an outside node mapped outlived the run. With
    its lock file free the owner is dead: the names go, the peer's mapping stays valid. Without a
    lock file a mapped file may be a live owner's: it stays until nobody maps it."""
    port = _port(65390 + (os.getpid() + 1) % 3)
    unlocked = _segment()
    unlocked[1].unlink()  # no lock file
    made += port + unlocked
    handles = [port[0].open('r+b'), unlocked[0].open('r+b')]
    views = [mmap.mmap(handle.fileno(), 0) for handle in handles]
    try:
        assert sorted(remove_orphans([str(port[0]), str(unlocked[0])])) == sorted(str(path) for path in port)
        assert not [path for path in port if path.exists()] and unlocked[0].exists()
        views[0][:3] = b'abc'  # the peer's mapping still works
        assert views[0][:3] == b'abc'
    finally:
        for view in views:
            view.close()
        for handle in handles:
            handle.close()
    assert remove_orphans([str(unlocked[0])]) == [str(unlocked[0])]


def test_a_process_holds_its_segment_its_ports_and_their_lock_files(made):
    files = _port(65396 + os.getpid() % 3)
    made += files
    lock = os.open(files[-1], os.O_RDONLY)
    handle = files[0].open('r+b')
    view = mmap.mmap(handle.fileno(), 0)
    try:
        held = held_files(os.getpid())
        assert {str(files[0]), str(files[-1])} <= held
        assert all(
            Path(path).parent == SHM_DIR and Path(path).name.startswith(('fastrtps_', 'sem.fastrtps_'))
            for path in held
        )
    finally:
        view.close()
        handle.close()
        os.close(lock)


def test_the_port_files_of_a_domain_are_found_by_their_port_numbers(made):
    # Domain 231: ports 7400 + 250 * 231 + [0, 250) = [65150, 65400).
    names = ['fastrtps_port65150', 'fastrtps_port65151_el', 'sem.fastrtps_port65399_mutex']
    outside = ['fastrtps_port65400', 'fastrtps_port65149', 'fastrtps_65150', 'fastrtps_port65150x']
    made += [SHM_DIR / name for name in names + outside]
    for path in made:
        path.touch()
    assert {Path(path).name for path in domain_port_files(231)} >= set(names)
    assert not {Path(path).name for path in domain_port_files(231)} & set(outside)
