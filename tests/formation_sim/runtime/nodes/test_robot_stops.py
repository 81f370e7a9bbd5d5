"""Tests of formation_sim.runtime.nodes.robot_stops: the coordinator's zero commands to the robots whose
agents sent no final report, and when `run_end.collect_final_reports` sends them."""

from __future__ import annotations

import pytest
from geometry_msgs.msg import Twist, TwistStamped
from rclpy.serialization import deserialize_message

from formation_msgs_py.qos import ROBOT_COMMAND_QOS
from formation_sim.runtime.nodes import run_end
from formation_sim.runtime.nodes.robot_stops import RobotStops


class _Publisher:
    def __init__(self, message: type, topic: str, qos) -> None:
        self.message, self.topic, self.qos = message, topic, qos
        self.sent: list[bytes] = []
        self.acked = 0  # how many of `sent` every reader has acknowledged
        self.looks: list[float] = []  # the timeouts `wait_for_all_acked` was asked with [s]

    def publish(self, data: bytes) -> None:
        self.sent.append(data)

    def wait_for_all_acked(self, timeout) -> bool:
        self.looks.append(timeout.nanoseconds * 1e-9)
        return self.acked == len(self.sent)


class _Logger:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def warning(self, line: str) -> None:
        self.lines.append(line)


class _Node:
    """What RobotStops asks of a node: publishers, a logger."""

    def __init__(self) -> None:
        self.publishers: dict[str, _Publisher] = {}
        self.logger = _Logger()

    def create_publisher(self, message: type, topic: str, qos) -> _Publisher:
        self.publishers[topic] = _Publisher(message, topic, qos)
        return self.publishers[topic]

    def get_logger(self) -> _Logger:
        return self.logger


@pytest.mark.parametrize(('model', 'message'), [('unicycle', Twist), ('holonomic', TwistStamped)])
def test_each_robot_gets_its_kinds_zero_once_as_often_as_a_robots_reader_keeps(model, message) -> None:
    node = _Node()
    stops = RobotStops(node, model=model, robots=[1, 2, 3], dimension=2, world_frame='map')
    assert sorted(node.publishers) == [f'/agent_{i}/robot/cmd_vel' for i in (1, 2, 3)]
    assert all(p.message is message and p.qos == ROBOT_COMMAND_QOS for p in node.publishers.values())
    assert stops.extra() == {}  # nothing stopped: nothing in summary.json

    assert stops.stop([2, 7], why='no final report from their agents') == [2]  # 7: no such robot
    assert stops.stop([2, 3], why='no final report from their agents') == [3]  # 2 already stopped
    sent = {topic: p.sent for topic, p in node.publishers.items()}
    assert [len(sent[f'/agent_{i}/robot/cmd_vel']) for i in (1, 2, 3)] == [0] + [ROBOT_COMMAND_QOS.depth] * 2
    for data in sent['/agent_2/robot/cmd_vel'] + sent['/agent_3/robot/cmd_vel']:
        command = deserialize_message(data, message)
        twist = command.twist if message is TwistStamped else command
        assert (twist.linear.x, twist.linear.y, twist.linear.z) == (0.0, 0.0, 0.0)
        assert (twist.angular.x, twist.angular.y, twist.angular.z) == (0.0, 0.0, 0.0)
        if message is TwistStamped:
            assert command.header.frame_id == 'map'  # the agents' world_frame
    assert stops.extra() == {'robots_stopped_here': [2, 3]}
    assert node.logger.lines == [
        'robots [2]: no final report from their agents: the coordinator sent them the zero command',
        'robots [3]: no final report from their agents: the coordinator sent them the zero command',
    ]


def test_an_operators_stop_sends_every_robot_its_zero_and_leaves_the_unreported_ones_to_be_sent_again():
    """`stop_all` (the emergency stop): every robot its zero at once; not noted as stopped from
    here, so that a robot whose agent then does not report gets its zero once more from `stop`."""
    node = _Node()
    stops = RobotStops(node, model='unicycle', robots=[1, 2, 3], dimension=2, world_frame='world')
    assert stops.stop_all(why='an operator stopped the run') == [1, 2, 3]
    assert [len(p.sent) for p in node.publishers.values()] == [ROBOT_COMMAND_QOS.depth] * 3
    for publisher in node.publishers.values():
        twist = deserialize_message(publisher.sent[-1], Twist)
        assert (twist.linear.x, twist.angular.z) == (0.0, 0.0)
    assert stops.extra() == {} and node.logger.lines == [
        'an operator stopped the run: the coordinator sent every robot the zero command'
    ]
    assert stops.stop([2], why='no final report from their agents') == [2]  # its agent did not report
    assert len(node.publishers['/agent_2/robot/cmd_vel'].sent) == 2 * ROBOT_COMMAND_QOS.depth
    assert stops.extra() == {'robots_stopped_here': [2]}


def test_a_zero_sent_from_here_is_unacknowledged_until_every_reader_acknowledged_it():
    """What the coordinator waits for before it leaves (`RobotWorld.after_final_step`): a zero
    that a reader has not acknowledged is only repaired while the coordinator lives.  Nothing sent:
    nothing to wait for, and no writer is asked (the end of a run without a stop from here is not
    slower).  Each look is a look (no wait), and a robot acknowledged is not asked again until its
    next zero."""
    node = _Node()
    stops = RobotStops(node, model='unicycle', robots=[1, 2, 3], dimension=2, world_frame='world')
    writers = {i: node.publishers[f'/agent_{i}/robot/cmd_vel'] for i in (1, 2, 3)}
    assert stops.unacknowledged() == [] and all(w.looks == [] for w in writers.values())

    stops.stop([3, 2], why='no final report from their agents')
    assert stops.unacknowledged() == [3, 2]  # in the order sent
    writers[2].acked = len(writers[2].sent)
    assert stops.unacknowledged() == [3]
    assert stops.note_unacknowledged(within=1.0) == [3]  # the wait is over: logged, by robot and bound
    assert node.logger.lines[-1] == (
        'robots [3]: their zero command from the coordinator was not acknowledged by every reader within 1 s'
    )
    writers[3].acked = len(writers[3].sent)
    assert stops.unacknowledged() == []
    assert writers[1].looks == [] and writers[2].looks == [0.0, 0.0] and writers[3].looks == [0.0] * 4
    assert stops.unacknowledged() == [] and writers[3].looks == [0.0] * 4  # acknowledged: not asked again
    lines = len(node.logger.lines)
    assert stops.note_unacknowledged(within=1.0) == [] and len(node.logger.lines) == lines  # nothing to say

    stops.stop_all(why='an operator asked to stop the run after its end')  # every robot's zero again
    assert stops.unacknowledged() == [1, 2, 3]
    for writer in writers.values():
        writer.acked = len(writer.sent)
    assert stops.unacknowledged() == []


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


class _Run:
    """A time keeper after its final Step: agent k reports at `reports[k]` s (None: never)."""

    def __init__(self, clock: _Clock, reports: dict[int, float | None]) -> None:
        self.clock, self.began, self.reports = clock, clock.now, reports
        self.stopped: list[tuple[float, list[int]]] = []
        self.world = self  # the world it holds: its robots stopped here

    def unreported(self) -> list[int]:
        return [k for k, at in self.reports.items() if at is None or self.began + at > self.clock.now]

    def final_reports_in(self) -> bool:
        return not self.unreported()

    def stop_unreported_robots(self) -> None:
        self.stopped.append((round(self.clock.now - self.began, 6), self.unreported()))

    def spin_once(self, *, timeout_sec: float) -> None:  # the executor: time passes
        self.clock.now += timeout_sec


@pytest.mark.parametrize(
    ('reports', 'stopped'),
    [
        ({1: 0.1, 2: 0.3}, None),  # every agent reports before UNREPORTED_STOP_AFTER: no robot stopped
        ({1: 0.1, 2: None}, [2]),  # agent 2 never reports: robot 2 after 0.5 s
        ({1: 0.1, 2: 0.8}, [2]),  # a late report: stopped after 0.5 s all the same
    ],
)
def test_robots_of_agents_not_reported_after_the_stop_delay_are_stopped(
    monkeypatch: pytest.MonkeyPatch, reports, stopped
) -> None:
    clock = _Clock()
    monkeypatch.setattr(run_end.time, 'monotonic', clock.monotonic)
    run = _Run(clock, reports)
    run_end.collect_final_reports(run, run)
    calls_with_robots = [(at, robots) for at, robots in run.stopped if robots]
    assert run_end.UNREPORTED_STOP_AFTER == 0.5
    if stopped is None:
        assert calls_with_robots == []
    else:  # at the first look once UNREPORTED_STOP_AFTER has passed (a look every 0.05 s)
        at, robots = calls_with_robots[0]
        assert robots == stopped and 0.5 - 1e-9 <= at <= 0.55 + 1e-9, calls_with_robots
    # Never after the wait: the wait ends at the timeout, or when the last report is in.
    assert max(at for at, _ in run.stopped) <= run_end.FINAL_REPORTS_TIMEOUT + 0.05
