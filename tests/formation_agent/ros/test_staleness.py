"""Stale state without a node (issue 19): a dead pose feed told from a starved agent, and no
command from state older than pose_timeout after a freeze."""

from __future__ import annotations

import pytest

from formation_agent.core.errors import PoseError
from formation_agent.core.pose_sensing import PoseBook
from formation_agent.ros.errors import StaleStateError
from formation_agent.ros.staleness import CommandGuard, Staleness, WriterWatch, explained
from formation_agent.ros.stepping import TriggerSchedule
from formation_msgs_py.types import RobotPose

EPOCH = 1_000_000.0


class NoTimers:
    def arm(self, delay, callback):
        return object()

    def cancel(self, handle) -> None:
        pass


def _book() -> PoseBook:
    return PoseBook(
        agent_id=1,
        neighbour_ids=(2,),
        dimension=2,
        offset=(0.0, 0.0, 0.0),
        world_frame='world',
        timeout=0.5,
        topic=lambda robot: f'/agent_{robot}/robot/odom',
    )


def _pose(stamp: float) -> RobotPose:
    return RobotPose(stamp=stamp, frame='world', position=(0.0, 0.0, 0.0), orientation=(0.0, 0.0, 0.0, 1.0))


@pytest.fixture
def rig():
    """Agent 1 on the wall clock since EPOCH, its pose and robot 2's; `writers` the topics' counts."""
    clock = [EPOCH]
    schedule = TriggerSchedule(agent_id=1, timers=NoTimers(), clock=lambda: clock[0])
    schedule.start(EPOCH)
    book = _book()
    writers = {'/agent_1/robot/odom': 1, '/agent_2/robot/odom': 1}
    staleness = Staleness(book=book, period=0.02, count_writers=writers.__getitem__, schedule=schedule)
    return clock, schedule, book, writers, staleness


def _stale_error(book, t):
    with pytest.raises(PoseError) as caught:
        book.sense(t=t, now=EPOCH + t, velocities=False)
    return caught.value


def test_a_pose_whose_writer_left_the_graph_says_when(rig):
    _clock, _schedule, book, writers, staleness = rig
    book.add(1, _pose(EPOCH + 4.2))
    book.add(2, _pose(EPOCH + 3.466))
    staleness.look(EPOCH + 3.5)
    writers['/agent_2/robot/odom'] = 0  # robot 2's driver is gone
    staleness.look(EPOCH + 3.9)
    staleness.look(EPOCH + 4.1)  # still gone: the first look without it counts
    message = str(staleness.explain(_stale_error(book, 4.2), EPOCH + 4.2))
    assert message == (
        'agent 1: the pose of robot 2 on /agent_2/robot/odom is 0.734 s old at t=4.200 (pose_timeout 0.5 s); '
        'its writer left the graph at t=3.900: the agent stops'
    )


def test_a_pose_stale_because_this_agent_ran_late_says_so(rig):
    _clock, _schedule, book, _writers, staleness = rig
    book.add(1, _pose(EPOCH + 4.2))
    book.add(2, _pose(EPOCH + 3.466))
    staleness.look(EPOCH + 3.5)
    staleness.guard.timer.tick(EPOCH + 3.56)
    staleness.guard.timer.tick(EPOCH + 4.2)  # the command timer (0.02 s) came 0.62 s late
    message = str(staleness.explain(_stale_error(book, 4.2), EPOCH + 4.2))
    assert message.endswith(
        "(pose_timeout 0.5 s); its writer is alive and this agent's timer ran 0.620 s late "
        '(an overloaded computer?): the agent stops'
    ), message


def test_a_pose_stale_while_this_agent_is_punctual_blames_the_feed(rig):
    _clock, _schedule, book, _writers, staleness = rig
    book.add(1, _pose(EPOCH + 4.2))
    book.add(2, _pose(EPOCH + 3.466))
    staleness.look(EPOCH + 3.5)
    message = str(staleness.explain(_stale_error(book, 4.2), EPOCH + 4.2))
    assert (
        "its writer is alive and this agent's timer ran 0.000 s late (its writer stalled or was stopped"
        in message
    )


def test_a_topic_that_never_had_a_writer_is_named():
    watch = WriterWatch({3: '/agent_3/robot/pose'})
    watch.look([(3, 0)], 10.0)
    assert watch.describe(3, run_time=lambda wall: wall) == 'no writer of /agent_3/robot/pose has been seen'
    assert explained('no suffix', 'a clause') == 'no suffix; a clause: the agent stops'


def test_no_command_after_a_freeze_of_the_command_timer_or_of_the_due_trigger():
    guard = CommandGuard(agent_id=4, period=0.02, timeout=0.5)
    guard.check(EPOCH, t=0.0, trigger_late=None)
    guard.check(EPOCH + 0.5, t=0.5, trigger_late=0.5)  # 0.48 s late, due 0.5 s ago: still within
    with pytest.raises(
        StaleStateError,
        match=r'^agent 4: at t=2.520 its command timer ran 2.000 s late \(pose_timeout 0.5 s; '
        r'the process was stopped, or an overloaded computer\): no command from state '
        r'that old: the agent stops$',
    ):
        guard.check(EPOCH + 2.52, t=2.52, trigger_late=None)
    with pytest.raises(StaleStateError, match=r'its trigger has been due for 0.700 s \(pose_timeout 0.5 s; '):
        guard.check(EPOCH + 2.54, t=2.54, trigger_late=0.7)


def test_a_trigger_that_fires_long_after_it_was_due_is_refused_once(rig):
    clock, schedule, _book, _writers, staleness = rig
    schedule.next_time = 1.0
    fired = []
    schedule.arm(lambda: fired.append(True))
    clock[0] = EPOCH + 3.0  # the process was stopped for two seconds
    schedule._fire(schedule._armed, lambda: fired.append(True))
    refusal = staleness.trigger_refusal(clock[0])
    assert fired == [True] and refusal is not None
    assert str(refusal).startswith(
        'agent 1: at t=3.000 its trigger came 2.000 s after it was due (pose_timeout 0.5 s;'
    )
    assert staleness.trigger_refusal(clock[0]) is None, 'taken once'


HORIZON = 10.0


@pytest.mark.parametrize(
    ('stamps', 'now', 'end'),
    [
        ({1: 9.8, 2: 9.9}, 10.4, True),  # both robots stopped at the horizon: 0.2 s old then
        ({1: 9.5, 2: 9.8}, 10.05, True),  # robot 1's pose 0.5 s old at the horizon: still fresh then
        ({1: 9.8, 2: 9.4}, 10.4, False),  # robot 2 was 0.6 s silent at the horizon: stale before it
        ({1: 9.8}, 10.4, False),  # robot 2's pose never came
        ({1: 10.5, 2: 10.5}, 11.2, True),  # poses after the horizon, then none: stale only past it
    ],
)
def test_a_pose_that_stopped_with_its_robot_at_the_horizon_is_the_end_of_the_run(rig, stamps, now, end):
    """Issue 19, part 1: between the horizon and the final Step, a pose that stops because its robot
    stopped at the horizon is no fault; one stale before the horizon, or missing, is."""
    _clock, _schedule, book, _writers, staleness = rig
    for robot, stamp in stamps.items():
        book.add(robot, _pose(EPOCH + stamp))
    error = _stale_error(book, now)
    assert staleness.after_horizon(error, EPOCH + now, horizon=HORIZON) is end
    assert not staleness.after_horizon(RuntimeError('not a pose'), EPOCH + now, horizon=HORIZON)


def test_the_poses_waiting_in_a_reader_are_taken_before_a_pose_is_called_stale():
    """A neighbour's poses are taken only at triggers: one that waits in its reader is the latest."""
    clock = [EPOCH]
    schedule = TriggerSchedule(agent_id=1, timers=NoTimers(), clock=lambda: clock[0])
    schedule.start(EPOCH)
    book = _book()
    waiting = {2: _pose(EPOCH + 9.9)}
    staleness = Staleness(
        book=book,
        period=0.02,
        count_writers=lambda topic: 1,
        schedule=schedule,
        take=lambda robot: robot in waiting and book.add(robot, waiting.pop(robot)),
    )
    book.add(1, _pose(EPOCH + 9.9))
    book.add(2, _pose(EPOCH + 0.0))  # taken at the trigger at t = 0
    error = _stale_error(book, 10.5)
    assert staleness.stale_robots(EPOCH + 10.5) == [1, 2] and not waiting
    assert staleness.after_horizon(error, EPOCH + 10.5, horizon=HORIZON)
