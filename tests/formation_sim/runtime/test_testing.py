"""formation_sim.runtime.testing.BagReplay: a recorded run replayed into a private domain reaches
the test's own readers whole and byte for byte, with the run's QoS; bad arguments are named.

The first test is the example of docs/REPLAY_IN_TESTS.md (included from here, between the
`example` markers): the suite runs it as written."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from formation_sim.runtime.errors import ReplayError
from formation_sim.runtime.testing import BagReplay, bag_counts

DOMAIN_ID = 164  # the replays' domain; the recording run picks a free one of its own


@pytest.fixture(scope='module')
def recorded_run(tmp_path_factory) -> Path:
    """A short distributed run of the paper's example, recorded (about 5 s)."""
    import os

    from formation_sim.runtime.launch.orchestrate import FormationRun

    folder = tmp_path_factory.mktemp('recorded') / 'run'
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    result = FormationRun('paper_single', out_dir=folder, horizon=0.05, progress=False, timeout=240.0).run()
    assert result.exit_status == 0, result.message
    return folder


# example: start
@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_a_replayed_run_reaches_my_readers(recorded_run):
    """Agent 1's triggering information to agent 2, replayed, carries the triggering times the
    run's summary.json has for agent 1."""
    from formation_msgs_py.codec import decode_trigger_info

    with BagReplay(recorded_run / 'bag', domain_id=DOMAIN_ID) as replay:
        infos = replay.collect('/agent_1/trigger_info/to_2')
        steps = replay.collect('/formation/step')
        result = replay.play(timeout=60.0)

    summary = json.loads((recorded_run / 'summary.json').read_text())
    stamps = [decode_trigger_info(message).stamp for message in infos]
    assert stamps == summary['trigger_times']['1']
    assert len(steps) == result.per_topic['/formation/step'] > 1


# example: end


@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
@pytest.mark.timeout(300)
def test_every_message_arrives_byte_for_byte(recorded_run):
    from formation_sim.bag.io import read_bag

    bag = recorded_run / 'bag'
    topic = '/agent_2/trigger_info/to_1'
    recorded = [bytes(m.rawdata) for m in read_bag(bag) if m.topic == topic]
    with BagReplay(bag, domain_id=DOMAIN_ID, rate=20.0) as replay:
        raw = replay.collect(topic, raw=True)
        result = replay.play(timeout=60.0)
    assert result.per_topic == {topic: bag_counts(bag)[topic]}
    assert [bytes(m)[: len(r)] for m, r in zip(raw, recorded, strict=True)] == recorded


def test_a_folder_without_a_bag_is_named(tmp_path):
    with pytest.raises(ReplayError, match=r'no bag there \(no metadata.yaml\)'):
        BagReplay(tmp_path)


@pytest.mark.ros
@pytest.mark.xdist_group('formation_distributed')
def test_bad_rates_and_topics_are_named(recorded_run):
    bag = recorded_run / 'bag'
    with pytest.raises(
        ReplayError, match=r'rate must be a finite number >= 0 \(0: as fast as possible\), got -1.0'
    ):
        BagReplay(bag, rate=-1.0)
    with pytest.raises(ReplayError, match=r"no topic \['/nowhere'\] in the bag \(it holds \["):
        BagReplay(bag, topics=['/nowhere'])
    replay = BagReplay(bag, domain_id=DOMAIN_ID)
    with pytest.raises(ReplayError, match=r'collect\(\) inside the `with BagReplay\(...\)` block only'):
        replay.collect('/formation/step')
    with replay, pytest.raises(ReplayError, match=r"no topic '/nowhere' in the bag"):
        replay.collect('/nowhere')


def test_a_held_domain_is_refused_to_a_run_and_waited_for_by_another_holder():
    from formation_sim.runtime.errors import RunError
    from formation_sim.runtime.launch.plan import reserve_domain
    from formation_sim.runtime.testing import hold_domain

    with hold_domain(199) as domain:
        assert domain == 199
        held = 'ROS domain 199 is held by another formation run'
        with pytest.raises(RunError, match=held), reserve_domain(199):
            pass
        began = time.monotonic()
        with pytest.raises(RunError, match='held by another formation run'), hold_domain(199, timeout=0.3):
            pass
        assert time.monotonic() - began >= 0.3  # it waited for the holder
    with reserve_domain(199) as domain:  # released
        assert domain == 199
    with pytest.raises(RunError, match='domain id must lie in'), hold_domain(300):
        pass


def test_a_waiting_holder_gets_the_domain_once_it_is_released():
    """reserve_domain(wait=...) takes the domain as soon as its holder lets go, not before."""
    import threading

    from formation_sim.runtime.launch.plan import reserve_domain

    taken, release = threading.Event(), threading.Event()

    def holder():
        with reserve_domain(198):
            taken.set()
            release.wait(30.0)

    thread = threading.Thread(target=holder)
    thread.start()
    try:
        assert taken.wait(30.0)
        released_at = []
        timer = threading.Timer(0.5, lambda: (released_at.append(time.monotonic()), release.set()))
        timer.start()
        with reserve_domain(198, wait=60.0) as domain:  # generous: a loaded machine is slow
            got_at = time.monotonic()
        assert domain == 198 and released_at and got_at >= released_at[0]
    finally:
        release.set()
        thread.join(30.0)
