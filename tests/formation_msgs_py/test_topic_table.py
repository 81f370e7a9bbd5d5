"""The topic table (issue 29 item 3) and everything derived from it agree: the recorders' lists,
the launch plan's counting, the analysis' dispatch, docs/MESSAGES.md and docs/TOPICS.md."""

import re
from pathlib import Path

import pytest

from formation_msgs_py import topic_table as table
from formation_msgs_py import topics

DOCS = Path(__file__).resolve().parents[2] / 'docs'


def test_every_key_and_pattern_is_unique_and_every_name_matches_its_own_row_only():
    assert len(table.ROWS) == len(table.TOPICS)
    assert len({row.pattern for row in table.TOPICS}) == len(table.TOPICS)
    for row in table.TOPICS:
        name = row.name(3, 17)
        assert '<' not in name, row
        assert table.match_topic(name) == (row, {'run': (), 'agent': (3,), 'edge': (3, 17)}[row.per])
    assert table.match_topic('/agent_1/trigger_info/to_x') is None
    assert table.match_topic('/formation/steps') is None


def test_the_names_are_those_of_formation_msgs_py_topics():
    """The table spells no name of its own: its patterns are the topics module's names."""
    assert table.ROWS['step'].pattern == topics.STEP_TOPIC
    assert table.ROWS['trigger_info'].name(4, 2) == topics.trigger_info_topic(4, 2)
    assert table.ROWS['cmd_vel'].name(5) == topics.command_topic(5, double=False)
    assert table.ROWS['cmd_accel'].name(5) == topics.command_topic(5, double=True)
    assert table.ROWS['robot/pose'].name(2) == topics.robot_pose_topic(2)
    assert table.ROWS['robot/odom'].name(2) == topics.robot_odom_topic(2)
    assert table.ROWS['robot/true_odom'].name(2) == topics.robot_true_odom_topic(2)
    assert table.ROWS['robot/cmd_vel'].name(2) == topics.robot_command_topic(2)
    named = {value for name, value in vars(topics).items() if name.endswith('_TOPIC')}
    assert named == {row.pattern for row in table.TOPICS if row.per == 'run'}


def test_each_rows_qos_is_a_profile_of_the_qos_module():
    qos = pytest.importorskip('formation_msgs_py.qos')
    from rclpy.qos import QoSProfile

    for row in table.TOPICS:
        assert isinstance(getattr(qos, row.qos, None), QoSProfile), row


def test_the_tagged_topics_are_the_protocols_own():
    assert table.tagged_keys() == {'step', 'status', 'report', 'trigger_info'}


def _run_topics(scenario):
    from formation_sim.runtime.contract import formation_topics

    return formation_topics(scenario)


def test_the_exact_backends_recorder_list_is_the_tables_exact_rows():
    from formation_sim.model.scenario import load_scenario

    for name, command in (('paper_single', 'cmd_vel'), ('paper_double', 'cmd_accel')):
        scenario = load_scenario(name)
        listed = _run_topics(scenario)
        assert len(listed) == len(set(listed))
        keys = {table.match_topic(topic)[0].key for topic, _ in listed}
        exact = {row.key for row in table.TOPICS if table.EXACT in row.recorded}
        assert keys == exact - {'cmd_vel', 'cmd_accel'} | {command}
        edges = sum(len(scenario.neighbours(i)) for i in scenario.agent_ids)
        assert sum(1 for topic, _ in listed if '/trigger_info/' in topic) == edges
        for topic, msgtype in listed:
            assert msgtype == table.match_topic(topic)[0].msgtype, topic


def test_a_robot_runs_recorder_list_follows_its_pose_topics():
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.contract import robot_run_topics

    scenario = load_scenario('robots_square')
    for simulated, pose_type, truth, robot_topics in (
        (True, 'pose', None, {'robot/pose', 'robot/true_odom'}),
        (True, 'odom', False, {'robot/odom'}),
        (False, 'pose', None, {'robot/pose', 'robot/odom'}),
    ):
        listed = robot_run_topics(
            scenario, model='unicycle', simulated=simulated, pose_type=pose_type, truth=truth
        )
        keys = {table.match_topic(topic)[0].key for topic, _ in listed}
        assert keys == {'step', 'status', 'report', 'scenario', 'robots', 'robot/cmd_vel', 'trigger_info'} | (
            robot_topics
        ), (simulated, pose_type)
        commands = {msgtype for topic, msgtype in listed if topic.endswith('/robot/cmd_vel')}
        assert commands == {'geometry_msgs/msg/Twist'}  # the unicycle's (v, ω) in its body frame


def test_the_launch_plan_counts_the_counted_rows(tmp_path):
    from formation_sim.model.scenario import load_scenario
    from formation_sim.runtime.launch.plan import LaunchPlan, RobotOptions

    for name, backend, robots in (
        ('paper_single', 'exact', None),
        ('robots_square', 'holonomic', RobotOptions(model='holonomic', pose_type='pose')),
        ('robots_square', 'external', RobotOptions(model='unicycle')),
    ):
        plan = LaunchPlan(
            scenario=load_scenario(name),
            backend=backend,
            out_dir=tmp_path / backend,
            horizon=1.0,
            clock='lockstep' if robots is None else 'realtime',
            record=True,
            agents_per_process=1,
            sample_period=0.1,
            executor='single',
            step_listeners=0,
            inject={},
            robots=robots,
        )
        counted = plan.counted_topics()
        recorded = {topic for topic, _ in plan.recorder_topics()}
        assert counted == {topic for topic in recorded if table.match_topic(topic)[0].counted}
        assert '/formation/step' in counted and '/agent_1/trigger_info/to_2' in counted
        assert not {t for t in counted if '/robot/' in t}  # a robot's own topics are not the run's count


def test_the_analysis_has_a_handler_for_every_recorded_row_and_no_other():
    from formation_sim.analysis.load import HANDLERS

    assert set(HANDLERS) == {row.key for row in table.TOPICS if row.recorded}


def test_docs_messages_lists_every_row_with_its_type():
    """docs/MESSAGES.md's topic table names every row with the table's type (short form)."""
    text = (DOCS / 'MESSAGES.md').read_text()
    for row in table.TOPICS:
        cells = [line for line in text.splitlines() if line.startswith(f'| `{row.pattern}`')]
        assert cells, f'docs/MESSAGES.md has no row for {row.pattern}'
        if row.msgtype != table.KIND_COMMAND:
            assert f'`{row.msgtype.replace("/msg/", "/")}`' in cells[0], (row.pattern, cells[0])


def test_docs_topics_holds_the_whole_table():
    lines = (DOCS / 'TOPICS.md').read_text().splitlines()
    for row in table.TOPICS:
        found = [line for line in lines if line.startswith(f'| `{row.pattern}` |') and f'`{row.qos}`' in line]
        assert len(found) == 1, row.pattern
        flags = re.findall(r'\| (yes|no) (?=\|)', found[0])
        assert flags == ['yes' if row.counted else 'no', 'yes' if row.tagged else 'no'], found[0]
