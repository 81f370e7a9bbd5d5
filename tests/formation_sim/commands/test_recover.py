"""`formation recover BAG`: the bag of a recorder killed mid-run becomes readable again."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap

import pytest

from formation_sim.bag.errors import BagReadError
from formation_sim.bag.io import read_bag
from formation_sim.cli import main

# A recorder's writer that flushes twice, then dies by SIGKILL with messages still in memory.
KILLED = textwrap.dedent("""
    import json, os, signal, sys
    from formation_sim.bag.io import BagWriter

    bag = BagWriter(sys.argv[1])
    bag.open()
    bag.add_topic('/formation/sensing_log', 'std_msgs/msg/String')
    kept = []
    for k in range(20):
        text = json.dumps({'k': k}).encode()
        # CDR std_msgs/String
        data = b'\\x00\\x01\\x00\\x00' + (len(text) + 1).to_bytes(4, 'little') + text + b'\\x00'
        bag.write('/formation/sensing_log', 1000 * k, data)
        kept.append(data.hex())
        if k in (9, 19):
            bag.flush()
    bag.write('/formation/sensing_log', 10**9, b'lost with the process')
    with open(sys.argv[2], 'w') as listing:
        json.dump(kept, listing)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def test_recover_makes_a_killed_recorders_bag_readable(tmp_path, capsys):
    bag, listing = tmp_path / 'bag', tmp_path / 'kept.json'
    child = subprocess.run(
        [sys.executable, '-c', KILLED, str(bag), str(listing)], capture_output=True, timeout=120, check=False
    )
    assert child.returncode == -signal.SIGKILL, child.stderr.decode()
    assert not (bag / 'metadata.yaml').exists()
    with pytest.raises(Exception):  # noqa: B017 - rosbags refuses a bag without metadata
        list(read_bag(bag))

    assert main(['recover', str(bag)]) == 0
    out = capsys.readouterr().out
    assert 'recovered 20 messages' in out and '.mcap.damaged' in out and '/formation/sensing_log' in out
    kept = [bytes.fromhex(data) for data in json.loads(listing.read_text())]
    assert [m.rawdata for m in read_bag(bag)] == kept
    assert [m.timestamp_ns for m in read_bag(bag)] == [1000 * k for k in range(20)]

    # Again on the recovered bag: healthy now, left exactly as it is.
    before = {path.name: path.read_bytes() for path in bag.iterdir()}
    assert main(['recover', str(bag)]) == 0
    assert (
        'healthy (metadata.yaml and a complete MCAP file, 20 messages); left as it is'
        in capsys.readouterr().out
    )
    assert {path.name: path.read_bytes() for path in bag.iterdir()} == before
    assert [m.rawdata for m in read_bag(bag)] == kept


def test_recover_leaves_a_recorders_healthy_bag_and_its_custom_data_alone(tmp_path, capsys):
    import yaml

    from formation_sim.bag.io import BagWriter

    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.set_custom_data('formation_timestamps', 'simulation time of /formation/step')
        writer.add_topic('/formation/sensing_log', 'std_msgs/msg/String')
        writer.write('/formation/sensing_log', 5, b'\x00\x01\x00\x00\x01\x00\x00\x00\x00')
    metadata = (bag / 'metadata.yaml').read_bytes()
    assert main(['recover', str(bag)]) == 0
    assert 'left as it is' in capsys.readouterr().out
    assert (bag / 'metadata.yaml').read_bytes() == metadata
    custom = yaml.safe_load(metadata)['rosbag2_bagfile_information']['custom_data']
    assert custom['formation_timestamps'] == 'simulation time of /formation/step'


def test_recover_names_what_it_cannot_do(tmp_path, capsys):
    assert main(['recover', str(tmp_path / 'missing')]) == 2
    assert 'is not a directory' in capsys.readouterr().err
    (tmp_path / 'empty').mkdir()
    assert main(['recover', str(tmp_path / 'empty')]) == 2  # bad input, like every command
    assert 'expected exactly one .mcap file, found []' in capsys.readouterr().err


# -- issue 28: damaged bags, in words, and recovered chunk by chunk ------------------------------


def _chunked_bag(path, *, chunks: int = 6, per_chunk: int = 20):
    """A bag of `chunks` MCAP chunks (a flush after each) of `per_chunk` messages each, stamped
    k ns; returns the messages' data in order."""
    from formation_sim.bag.io import BagWriter

    kept = []
    with BagWriter(path) as writer:
        writer.add_topic('/formation/sensing_log', 'std_msgs/msg/String')
        for k in range(chunks * per_chunk):
            text = f'message {k:04d} '.encode() * 4 + b'\x00'
            data = b'\x00\x01\x00\x00' + len(text).to_bytes(4, 'little') + text
            writer.write('/formation/sensing_log', k, data)
            kept.append(data)
            if k % per_chunk == per_chunk - 1:
                writer.flush()
    return kept


def _chunk_offsets(mcap):
    """Where each chunk record starts in the file (opcode 0x06), walking the records."""
    import struct

    data, offset, found = mcap.read_bytes(), 8, []
    while offset + 9 <= len(data):
        opcode, length = struct.unpack_from('<BQ', data, offset)
        if opcode == 0x06:
            found.append((offset, 9 + length))
        if opcode == 0x02:  # footer
            break
        offset += 9 + length
    return found


def test_a_bag_with_flipped_bytes_is_named_damaged_and_recover_keeps_every_intact_chunk(tmp_path, capsys):
    """Issue 28: 100 flipped bytes gave 'Chunk checksum mismatch.', then `formation recover` called
    the bag 'healthy … left as it is'."""
    bag = tmp_path / 'bag'
    kept = _chunked_bag(bag)
    mcap = bag / 'bag_0.mcap'
    chunks = _chunk_offsets(mcap)
    assert len(chunks) == 6
    data = bytearray(mcap.read_bytes())
    start, length = chunks[2]
    for k in range(100):  # 100 bytes flipped inside the third chunk's messages
        data[start + length - 120 + k] ^= 0xFF
    mcap.write_bytes(bytes(data))

    with pytest.raises(BagReadError) as refused:
        list(read_bag(bag))
    said = str(refused.value)
    assert 'a chunk of its MCAP file is damaged' in said and f'formation recover {bag}' in said

    assert main(['recover', str(bag)]) == 0
    out = capsys.readouterr().out
    assert 'recovered 100 messages' in out and 'bag_0.mcap.damaged' in out
    assert f'dropped: bytes {start}-{start + length}: a chunk dropped, its checksum does not match' in out
    assert [m.rawdata for m in read_bag(bag)] == kept[:40] + kept[60:]  # chunk 3 of 6 dropped, no other
    assert (bag / 'bag_0.mcap.damaged').read_bytes() == bytes(data)  # the original kept
    assert main(['recover', str(bag)]) == 0 and 'healthy' in capsys.readouterr().out


def test_a_truncated_bag_and_an_empty_metadata_file_are_named_with_what_to_do(tmp_path, capsys):
    """Issue 28: 'File end magic is invalid.' and "'NoneType' object is not subscriptable"."""
    cut = tmp_path / 'cut'
    kept = _chunked_bag(cut)
    mcap = cut / 'cut_0.mcap'
    (_, _), (second, length) = _chunk_offsets(mcap)[:2]
    mcap.write_bytes(mcap.read_bytes()[: second + length // 2])  # cut inside the second chunk
    with pytest.raises(BagReadError) as refused:
        list(read_bag(cut))
    assert 'its MCAP file is cut short or its end is damaged' in str(refused.value)
    assert f'`formation recover {cut}`' in str(refused.value)
    assert main(['recover', str(cut)]) == 0
    assert 'recovered 20 messages' in capsys.readouterr().out
    assert [m.rawdata for m in read_bag(cut)] == kept[:20]

    empty = tmp_path / 'empty'
    kept = _chunked_bag(empty)
    (empty / 'metadata.yaml').write_text('')
    with pytest.raises(BagReadError) as refused:
        list(read_bag(empty))
    assert str(refused.value) == (
        f'{empty / "metadata.yaml"} is empty (its writer was cut short?); `formation recover {empty}` '
        'rebuilds it from the MCAP file (the old one kept as metadata.yaml.damaged)'
    )
    assert main(['recover', str(empty)]) == 0
    assert [m.rawdata for m in read_bag(empty)] == kept
