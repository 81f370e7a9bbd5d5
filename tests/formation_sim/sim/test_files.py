"""Result files are written whole or not at all."""

from __future__ import annotations

import errno

import pytest

from formation_sim.sim.files import write_atomically


def test_a_file_is_replaced_whole_by_text_bytes_or_a_writer(tmp_path):
    target = tmp_path / 'summary.json'
    write_atomically(target, '{"a": 1}\n')
    assert target.read_text() == '{"a": 1}\n'
    write_atomically(target, b'\x00\x01')
    assert target.read_bytes() == b'\x00\x01'
    write_atomically(target, lambda handle: handle.write(b'written'))
    assert target.read_bytes() == b'written'
    assert sorted(path.name for path in tmp_path.iterdir()) == ['summary.json']


def test_a_full_disk_leaves_the_previous_file_and_no_temporary(small_disk):
    disk = small_disk(0.5)
    target = disk / 'summary.json'
    write_atomically(target, 'the previous run\n')
    with pytest.raises(OSError) as failed:
        write_atomically(target, 'x' * 1_000_000)
    assert failed.value.errno == errno.ENOSPC
    assert str(failed.value) == f"[Errno 28] No space left on device: '{target}'"
    assert target.read_text() == 'the previous run\n'
    assert sorted(path.name for path in disk.iterdir()) == ['summary.json']


def test_a_failing_writer_leaves_nothing(tmp_path):
    def broken(handle):
        handle.write(b'half')
        raise RuntimeError('stopped half way')

    with pytest.raises(RuntimeError, match='half way'):
        write_atomically(tmp_path / 'trajectory.npz', broken)
    assert list(tmp_path.iterdir()) == []
