"""`formation recover BAG`: the bag of a recorder killed mid-run becomes readable again."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap

import pytest

from formation_sim.cli import main
from formation_sim.bag.io import read_bag

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
