"""The Fast DDS settings every node process of ours starts with (formation_msgs_py.middleware).

The module's other rules are tested where they are used: a domain's ports (7400 + 250 d) in
tests/formation_sim/runtime/launch/test_fastdds_shm.py, `--domain-id` in [0, 232] in
tests/formation_sim/test_cli.py and tests/formation_sim/commands/test_run.py."""

import xml.etree.ElementTree as ET

from formation_msgs_py.middleware import FASTDDS_PROFILE, FASTDDS_PROFILE_VARIABLE, use_our_fastdds_profile

NS = {'dds': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}


def test_the_profile_ships_with_the_messages_package_and_sets_what_it_says():
    """A robot installs formation_agent and formation_msgs_py only: the file is in the latter, and
    it is the default profile of writers (heartbeat 0.1 s) and participants (announcements)."""
    assert FASTDDS_PROFILE.parent.name == 'formation_msgs_py' and FASTDDS_PROFILE.is_file()
    root = ET.parse(FASTDDS_PROFILE).getroot()  # noqa: S314 - our own file
    writer = root.find('dds:profiles/dds:data_writer', NS)
    assert writer is not None and writer.get('is_default_profile') == 'true'
    period = writer.find('dds:times/dds:heartbeatPeriod', NS)
    assert (period.findtext('dds:sec', namespaces=NS), period.findtext('dds:nanosec', namespaces=NS)) == (
        '0',
        '100000000',
    )
    participant = root.find('dds:profiles/dds:participant', NS)
    assert participant is not None and participant.get('is_default_profile') == 'true'


def test_our_profile_is_used_unless_the_user_names_one():
    env: dict[str, str] = {}
    use_our_fastdds_profile(env)
    assert env == {FASTDDS_PROFILE_VARIABLE: str(FASTDDS_PROFILE)}
    theirs = {FASTDDS_PROFILE_VARIABLE: '/etc/robot/fastdds.xml'}
    use_our_fastdds_profile(theirs)
    assert theirs == {FASTDDS_PROFILE_VARIABLE: '/etc/robot/fastdds.xml'}
