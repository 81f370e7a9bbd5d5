"""The topic table: every topic of a run, one row each (issue 29 item 3; ROS-free).

A row says a topic's name pattern, its type, the QoS profile its writer offers (a name in
`formation_msgs_py.qos`), which backends' recorders record it, whether the run's nodes count what
they publish on it (summary.json `extra.published`, checked against the bag), whether its messages
carry the run's tag (docs/HOSTILE_TRAFFIC.md, "Tags"), and who writes and reads it.  What is
derived from it, and tested to agree (tests/formation_msgs_py/test_topic_table.py):

- the recorder's lists: `formation_sim.runtime.contract.formation_topics` (exact backend),
  `formation_sim.runtime.contract.robot_run_topics` (robots);
- the launch plan's counting (`formation_sim.runtime.launch.plan.LaunchPlan.counted_topics`);
- the analysis' dispatch (`formation_sim.analysis.load`: one handler per recorded row);
- docs/TOPICS.md's table (`scripts/reference_docs.py`) and the topics of docs/MESSAGES.md.

Adding a recorded topic is one row here plus its publisher (docs/DESIGN.md, "The topic table").
"""

from __future__ import annotations

import functools
import re
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass

from formation_msgs_py import topics as t

EXACT = 'exact'
"""The exact backend (the simulator is the world)."""
ROBOTS = 'robots'
"""Every robot backend (simulated robots of a kind, or `external` ones; the coordinator is the keeper)."""

# Conditions of a row (`TopicRow.when`): the run has it only if the caller's conditions hold it.
SINGLE, DOUBLE = 'single', 'double'  # the scenario's dynamics (exact backend)
POSE, ODOM, TRUE_ODOM = 'pose', 'odom', 'true_odom'  # the robot pose topics a robot run records

ARRAY = 'std_msgs/msg/Float64MultiArray'
STRING = 'std_msgs/msg/String'
ODOMETRY = 'nav_msgs/msg/Odometry'
KIND_COMMAND = ''
"""`TopicRow.msgtype` of a robot's command: its robot kind says (`RobotKind.command_type`)."""


@dataclass(frozen=True, kw_only=True, slots=True)
class TopicRow:
    """One topic of a run.  `pattern` is its name with `<i>` (an agent) and `<j>` (a neighbour of
    agent i) in it; `recorded` the backends whose recorder takes it (empty: never recorded);
    `when` a condition of the run it exists under (None: always)."""

    key: str  # a short name, unique: what the analysis' dispatch is keyed by
    pattern: str
    msgtype: str
    qos: str  # the writer's profile: a name in formation_msgs_py.qos
    recorded: frozenset[str]
    counted: bool
    tagged: bool
    writer: str
    readers: str
    when: str | None = None

    @property
    def per(self) -> str:
        """'run' (one topic), 'agent' (one per agent i) or 'edge' (one per agent i and neighbour j)."""
        return 'edge' if '<j>' in self.pattern else 'agent' if '<i>' in self.pattern else 'run'

    def name(self, i: int | None = None, j: int | None = None) -> str:
        """The topic's name for agent `i` (and neighbour `j`)."""
        return self.pattern.replace('<i>', str(i)).replace('<j>', str(j))

    @property
    def regex(self) -> re.Pattern:
        return re.compile(
            '^' + re.escape(self.pattern).replace('<i>', r'(\d+)').replace('<j>', r'(\d+)') + '$'
        )


def _row(key: str, pattern: str, msgtype: str, qos: str, recorded: str, **rest) -> TopicRow:
    backends = {'both': (EXACT, ROBOTS), 'exact': (EXACT,), 'robots': (ROBOTS,), 'none': ()}[recorded]
    return TopicRow(key=key, pattern=pattern, msgtype=msgtype, qos=qos, recorded=frozenset(backends), **rest)


_AGENT = '/agent_<i>'
# Order: the run's topics first, then each agent's in this order (the recorder's lists keep it).
TOPICS: tuple[TopicRow, ...] = (
    _row(
        'step',
        t.STEP_TOPIC,
        ARRAY,
        'SIMULATOR_QOS',
        'both',
        counted=True,
        tagged=True,
        writer='time keeper',
        readers='agents, recorder (its clock)',
    ),
    _row(
        'status',
        t.STATUS_TOPIC,
        ARRAY,
        'PROTOCOL_QOS',
        'both',
        counted=True,
        tagged=True,
        writer='agents',
        readers='time keeper',
    ),
    _row(
        'state',
        t.STATE_TOPIC,
        ARRAY,
        'SIMULATOR_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='simulator',
        readers='recorder, tools',
    ),
    _row(
        'ground_truth',
        t.GROUND_TRUTH_TOPIC,
        'geometry_msgs/msg/PoseArray',
        'SIMULATOR_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='simulator',
        readers='recorder, tools',
    ),
    _row(
        'sensing_log',
        t.SENSING_LOG_TOPIC,
        STRING,
        'SIMULATOR_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='simulator',
        readers='recorder, tools',
    ),
    _row(
        'clock',
        t.CLOCK_TOPIC,
        'rosgraph_msgs/msg/Clock',
        'SIMULATOR_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='simulator',
        readers='recorder, tools',
    ),
    _row(
        'report',
        t.REPORT_TOPIC,
        STRING,
        'PROTOCOL_QOS',
        'both',
        counted=True,
        tagged=True,
        writer='agents',
        readers='time keeper, recorder',
    ),
    _row(
        'scenario',
        t.SCENARIO_TOPIC,
        STRING,
        'SIMULATOR_QOS',
        'both',
        counted=True,
        tagged=False,
        writer='time keeper',
        readers='recorder, tools',
    ),
    _row(
        'markers',
        t.MARKERS_TOPIC,
        'visualization_msgs/msg/MarkerArray',
        'SIMULATOR_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='simulator',
        readers='recorder, Foxglove',
    ),
    _row(
        'robots',
        t.ROBOTS_TOPIC,
        STRING,
        'SIMULATOR_QOS',
        'robots',
        counted=True,
        tagged=False,
        writer='coordinator',
        readers='recorder, tools',
    ),
    _row(
        'recorder',
        t.RECORDER_TOPIC,
        STRING,
        'PROTOCOL_QOS',
        'none',
        counted=False,
        tagged=False,
        writer='the recorder',
        readers='time keeper (not recorded)',
    ),
    _row(
        'cmd_vel',
        f'{_AGENT}/cmd_vel',
        'geometry_msgs/msg/Twist',
        'PROTOCOL_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='agent i',
        readers='simulator (its plant), recorder',
        when=SINGLE,
    ),
    _row(
        'cmd_accel',
        f'{_AGENT}/cmd_accel',
        'geometry_msgs/msg/Accel',
        'PROTOCOL_QOS',
        'exact',
        counted=True,
        tagged=False,
        writer='agent i',
        readers='simulator (its plant), recorder',
        when=DOUBLE,
    ),
    _row(
        'robot/pose',
        f'{_AGENT}/robot/pose',
        'geometry_msgs/msg/PoseStamped',
        'ROBOT_POSE_QOS',
        'robots',
        counted=False,
        tagged=False,
        writer='robot i (motion capture, simulated robot)',
        readers='agent i and its neighbours, coordinator, recorder',
        when=POSE,
    ),
    _row(
        'robot/odom',
        f'{_AGENT}/robot/odom',
        ODOMETRY,
        'ROBOT_POSE_QOS',
        'robots',
        counted=False,
        tagged=False,
        writer='robot i',
        readers='agent i and its neighbours, coordinator, recorder',
        when=ODOM,
    ),
    _row(
        'robot/true_odom',
        f'{_AGENT}/robot/true_odom',
        ODOMETRY,
        'ROBOT_POSE_QOS',
        'robots',
        counted=False,
        tagged=False,
        writer='simulated robot i',
        readers='coordinator, recorder',
        when=TRUE_ODOM,
    ),
    _row(
        'robot/cmd_vel',
        f'{_AGENT}/robot/cmd_vel',
        KIND_COMMAND,
        'ROBOT_COMMAND_QOS',
        'robots',
        counted=False,
        tagged=False,
        writer='agent i (coordinator: the zero command)',
        readers='robot i, recorder',
    ),
    _row(
        'trigger_info',
        f'{_AGENT}/trigger_info/to_<j>',
        ARRAY,
        'PROTOCOL_QOS',
        'both',
        counted=True,
        tagged=True,
        writer='agent i',
        readers='agent j, recorder',
    ),
)
ROWS: Mapping[str, TopicRow] = {row.key: row for row in TOPICS}


def recorded_topics(
    *, backend: str, agent_ids: Iterable[int], neighbours, conditions: Collection[str], command_type: str = ''
) -> list[tuple[str, str]]:
    """Every topic the recorder of a `backend` run records, with its type, in the table's order:
    the run's topics, then each agent's.  `neighbours(i)` gives agent i's neighbour ids;
    `conditions` the run's (`SINGLE`/`DOUBLE`, `POSE`, `ODOM`, `TRUE_ODOM`); `command_type` the
    robot kind's command type (`KIND_COMMAND` rows)."""
    rows = [row for row in TOPICS if backend in row.recorded and (row.when is None or row.when in conditions)]
    listed = [(row.pattern, row.msgtype) for row in rows if row.per == 'run']
    for i in agent_ids:
        for row in rows:
            msgtype = row.msgtype or command_type
            if row.per == 'agent':
                listed.append((row.name(i), msgtype))
            elif row.per == 'edge':
                listed += [(row.name(i, j), msgtype) for j in neighbours(i)]
    return listed


@functools.lru_cache(maxsize=4096)
def match_topic(topic: str) -> tuple[TopicRow, tuple[int, ...]] | None:
    """The row a topic's name belongs to and its agent ids (i, and j), or None for a topic not
    in the table."""
    for row in TOPICS:
        if match := row.regex.fullmatch(topic):
            return row, tuple(int(group) for group in match.groups())
    return None


def counted_keys() -> frozenset[str]:
    return frozenset(row.key for row in TOPICS if row.counted)


def tagged_keys() -> frozenset[str]:
    return frozenset(row.key for row in TOPICS if row.tagged)
