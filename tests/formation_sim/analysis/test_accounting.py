"""What a run published against what its bag holds (no ROS process: bags written here)."""

from __future__ import annotations

import math
from collections import Counter

from formation_sim.analysis.accounting import check_recording, recorded_counts
from formation_sim.bag.io import BagWriter, read_bag


def _published(bag) -> dict[str, int]:
    return dict(Counter(message.topic for message in read_bag(bag)))


def test_a_complete_bag_matches_and_a_lost_message_is_named_with_its_counts(
    tmp_path, paper_single_record, write_run_bag
):
    complete = write_run_bag(paper_single_record, tmp_path / 'complete')
    published = _published(complete)
    check = check_recording(published, complete)
    assert check.complete and check.missing == {} and check.foreign == {}
    assert check.to_dict()['published'] == check.to_dict()['recorded'] == sum(published.values())

    # The same run with agent 2's first two messages to agent 1 lost on the way to the bag.
    lossy = write_run_bag(paper_single_record, tmp_path / 'lossy', drop={(2, 1, 0), (2, 1, 1)})
    check = check_recording(published, lossy)
    assert not check.complete
    assert check.missing == {'/agent_2/trigger_info/to_1': 2}
    sent = published['/agent_2/trigger_info/to_1']
    assert check.describe_missing() == (
        f'the bag misses 2 of {sum(published.values())} messages the run published '
        f'(recorded of published: /agent_2/trigger_info/to_1 {sent - 2} of {sent})'
    )
    assert check.to_dict() == {
        'complete': False,
        'missing': {'/agent_2/trigger_info/to_1': 2},
        'foreign': {},
        'published': sum(published.values()),
        'recorded': sum(published.values()) - 2,
    }


def test_messages_beyond_what_the_run_published_are_foreign(tmp_path, paper_single_record, write_run_bag):
    bag = write_run_bag(paper_single_record, tmp_path / 'bag')
    published = _published(bag)
    published['/agent_2/trigger_info/to_1'] -= 3  # as if 3 of them came from a node outside the run
    del published['/clock']  # a topic the run did not publish at all
    check = check_recording(published, bag)
    assert check.complete
    assert check.foreign == {'/agent_2/trigger_info/to_1': 3, '/clock': _published(bag)['/clock']}
    assert check.describe_foreign().startswith(
        f'the bag also holds {3 + _published(bag)["/clock"]} messages from publishers outside the run ('
    )


def test_the_agents_discovery_announcements_are_not_counted(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray

    from formation_msgs_py.codec import encode_status
    from formation_msgs_py.lockstep import DISCOVERY_STEP, Status

    def status(step: int) -> bytes:
        return serialize_message(
            encode_status(
                Status(
                    agent=1,
                    step_index=step,
                    next_time=0.0 if step == DISCOVERY_STEP else math.inf,
                    info_sent=0,
                    info_received=0,
                    commands_sent=0,
                    triggers=0,
                    ready=True,
                    last_planned=0.0,
                )
            )
        )

    bag = tmp_path / 'bag'
    with BagWriter(bag) as writer:
        writer.add_topic('/formation/status', 'std_msgs/msg/Float64MultiArray')
        for k, step in enumerate([DISCOVERY_STEP] * 5 + [0, 1, 2]):
            writer.write('/formation/status', k, status(step))
        writer.write(
            '/formation/status', 9, serialize_message(Float64MultiArray(data=[7.0]))
        )  # junk: not the run's
    assert recorded_counts(bag) == {'/formation/status': 4}
    check = check_recording({'/formation/status': 3}, bag)
    assert check.complete and check.foreign == {'/formation/status': 1}
