"""The trigger schedule without a node: lock-step turns, information held for the agent's own
trigger, the wall clock's one-shot timers (cancelled ones never fire), late information re-based,
the sensed state checked against the trigger it was asked for."""

from __future__ import annotations

import math

import pytest

from formation_agent.ros.errors import AgentNodeError
from formation_agent.ros.reporting import AgentCounts
from formation_agent.ros.stepping import Arrivals, TriggerSchedule, rebased
from formation_msgs_py.lockstep import Step
from formation_msgs_py.types import SensedState, TriggerInfo


class FakeTimers:
    """One-shot timers run by hand: `due()` lists the callbacks whose time has come, as an executor
    would queue them; a cancelled timer's callback may still be queued (EventsExecutor)."""

    def __init__(self, clock) -> None:
        self.clock = clock
        self.live: dict[int, tuple[float, object]] = {}
        self._next = 0

    def arm(self, delay, callback):
        self._next += 1
        self.live[self._next] = (self.clock.now + delay, callback)
        return self._next

    def cancel(self, handle) -> None:
        del self.live[handle]

    def due(self) -> list:
        return [
            callback
            for at, callback in sorted(self.live.values(), key=lambda entry: entry[0])
            if at <= self.clock.now
        ]


class Clock:
    def __init__(self, now: float = 1000.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock():
    return Clock()


@pytest.fixture
def schedule(clock):
    return TriggerSchedule(agent_id=2, timers=FakeTimers(clock), clock=clock)


def test_a_lock_step_turn_is_the_exact_float_the_agent_reported(schedule):
    schedule.next_time = 0.1 + 0.2
    assert schedule.check_step(Step(index=3, time=0.1 + 0.2, due=(1, 2)))
    assert not schedule.check_step(Step(index=3, time=0.25, due=(1,)))
    with pytest.raises(
        AgentNodeError, match=r'agent 2: step 4 at t=0.4 skips its triggering time 0.30000000000000004'
    ):
        schedule.check_step(Step(index=4, time=0.4, due=(2,)))
    with pytest.raises(
        AgentNodeError, match=r'step 4 at t=0.3 lists due agents \[2\], but this agent reported'
    ):
        schedule.check_step(Step(index=4, time=0.3, due=(2,)))  # one ulp before its time
    with pytest.raises(
        AgentNodeError,
        match=r'lists due agents \[1\], but this agent reported its next triggering time 0.30000000000000004',
    ):
        schedule.check_step(Step(index=4, time=0.1 + 0.2, due=(1,)))


def test_information_for_the_instant_the_agent_is_due_waits_for_its_own_trigger(schedule):
    schedule.next_time = 0.5
    assert schedule.holds(0.5) and schedule.holds(0.7) and not schedule.holds(0.25)
    assert schedule.begin() and schedule.sensing and schedule.planned == 0.5
    assert not schedule.begin(), 'one trigger at a time'
    assert schedule.holds(0.25), 'while sensing everything waits'
    schedule.triggered(0.5)
    assert not schedule.holds(0.5) and schedule.last_trigger == 0.5
    schedule.start(epoch=1000.0)
    schedule.next_time = 2.0
    assert not schedule.holds(2.0), 'the wall clock holds information only while sensing'


def test_a_lock_step_status_waits_for_the_own_trigger_and_every_due_neighbour(schedule):
    schedule.next_time = 1.0
    step = Step(index=5, time=1.0, due=(2, 3))
    schedule.due_neighbours = (3,)
    assert not schedule.complete_at(step), 'due: its own trigger first'
    schedule.begin()
    schedule.triggered(1.0)
    schedule.next_time = 1.5
    assert not schedule.complete_at(step), "neighbour 3's information is missing"
    schedule.heard[3] = 1.0
    assert schedule.complete_at(step)
    schedule.heard[4] = 1.25
    assert not schedule.complete_at(step), 'information of a later step waits for that step'


def test_a_stopped_schedule_never_triggers_again(schedule, clock):
    schedule.start(epoch=clock.now)
    fired = []
    assert schedule.arm(lambda: fired.append(clock.now))
    queued = schedule._timers.due()
    schedule.stop()
    for callback in queued:  # the executor's last spin
        callback()
    assert fired == [] and not schedule.begin() and schedule.delay() is None


def test_a_timer_cancelled_after_its_callback_was_queued_does_not_fire(schedule, clock):
    schedule.start(epoch=clock.now)
    fired = []
    schedule.next_time = 0.5
    schedule.arm(lambda: fired.append('first'))
    clock.now += 0.5
    queued = schedule._timers.due()
    schedule.next_time = math.inf  # a re-plan: no trigger before the horizon
    schedule.cancel()
    assert schedule.delay() is None
    for callback in queued:  # rclpy's EventsExecutor runs a destroyed timer's queued callback
        callback()
    assert fired == [] and schedule.planned == 0.0 and not schedule.sensing, 'no trigger planned for t = inf'


def test_thousands_of_past_due_triggers_in_a_row_run_from_the_executor_not_by_recursion(schedule, clock):
    """An agent whose computer cannot keep up: every trigger plans its next one at a time already
    past (issue 19: a unicycle square died of RecursionError).  Arming a past time never calls the
    trigger itself; the executor runs it, at a constant stack depth, as often as it is asked."""
    import sys

    def depth() -> int:
        frame, n = sys._getframe(), 0
        while frame is not None:
            frame, n = frame.f_back, n + 1
        return n

    schedule.start(epoch=clock.now)
    depths = []

    def trigger():
        assert schedule.begin()
        clock.now += 0.001  # sensing and the core take a millisecond
        schedule.triggered(clock.now - schedule.epoch)
        schedule.next_time = schedule.last_trigger - 0.0005  # the next time has already passed
        depths.append(depth())
        assert schedule.arm(trigger)  # the re-plan: armed, not run

    schedule.next_time = 0.0
    assert schedule.arm(trigger) and depths == []
    executor = schedule._timers
    for _ in range(5000):  # the executor's spins
        (callback,) = executor.due()
        callback()
    assert len(depths) == 5000 and len(set(depths)) == 1
    # Due half a millisecond before it was planned: its timer is late only from the re-plan on.
    assert schedule.trigger_late(clock.now) == 0.0 and schedule.lateness(clock.now + 0.25) == 0.25


def test_late_information_is_re_anchored_at_the_own_trigger_by_exact_negation():
    sensed = SensedState(
        agent=1,
        stamp=2.5,
        rel_positions={3: (0.1, -0.30000000000000004)},
        rel_velocities={3: (1e-17, 0.0)},
        velocity=(0.0, 0.0),
    )
    info = TriggerInfo(
        sender=3, receiver=1, stamp=2.0, control=(0.5, 0.25), rel_position=(9.0, 9.0), rel_velocity=(9.0, 9.0)
    )
    late = rebased(info, sensed=sensed, at=2.5)
    assert late == TriggerInfo(
        sender=3,
        receiver=1,
        stamp=2.5,
        control=(0.5, 0.25),
        rel_position=(-0.1, 0.30000000000000004),
        rel_velocity=(-1e-17, -0.0),
    )


def test_the_sensed_state_must_be_the_agents_own_at_the_trigger_time(schedule):
    step = Step(index=2, time=0.75, due=(2,))
    own = SensedState(agent=2, stamp=0.75, rel_positions={1: (0.0, 1.0)})
    assert schedule.sensed_time(own, step=step) == 0.75
    with pytest.raises(
        AgentNodeError, match=r'^agent 2 asked to sense at t=0.75 and got the state of agent 3 at t=0.75$'
    ):
        schedule.sensed_time(SensedState(agent=3, stamp=0.75, rel_positions={}), step=step)
    with pytest.raises(
        AgentNodeError, match=r'asked to sense at t=0.75 and got the state of agent 2 at t=0.5$'
    ):
        schedule.sensed_time(SensedState(agent=2, stamp=0.5, rel_positions={}), step=step)
    schedule.start(epoch=1000.0)  # the wall clock: the time the world was actually sensed
    assert schedule.sensed_time(SensedState(agent=2, stamp=0.8125, rel_positions={}), step=step) == 0.8125


class Core:
    def __init__(self) -> None:
        self.received: list[TriggerInfo] = []

    def receive(self, info: TriggerInfo) -> None:
        self.received.append(info)


def _info(stamp: float, sender: int = 1) -> TriggerInfo:
    return TriggerInfo(sender=sender, receiver=2, stamp=stamp, control=(0.5, 0.0), rel_position=(1.0, 2.0))


def test_information_held_for_the_own_trigger_goes_in_right_after_it_in_arrival_order(schedule):
    counts, core = AgentCounts(agent_id=2), Core()
    arrivals = Arrivals(schedule=schedule, counts=counts)
    schedule.next_time = 0.0  # t^i_1 = 0: due
    assert not arrivals.arrive(_info(0.0, sender=3), core=core)
    assert not arrivals.arrive(_info(0.0), core=core)
    assert core.received == [] and counts.info_received == 0
    sensed = SensedState(agent=2, stamp=0.0, rel_positions={1: (-1.0, -2.0), 3: (0.0, 0.0)})
    assert schedule.begin()
    schedule.triggered(0.0)
    arrivals.triggered(sensed, core=core)
    assert core.received == [_info(0.0, sender=3), _info(0.0)], 'as they came, not re-based'
    assert arrivals.held == [] and arrivals.sensed is sensed
    assert (counts.info_received, counts.late_infos, counts.report_due) == (2, 0, False)
    schedule.next_time = 0.5
    assert arrivals.arrive(_info(0.25), core=core) and core.received[-1] == _info(0.25)


def test_wall_clock_information_that_crossed_the_own_trigger_is_re_based_and_counted_late(schedule, clock):
    counts, core = AgentCounts(agent_id=2), Core()
    arrivals = Arrivals(schedule=schedule, counts=counts)
    schedule.start(epoch=clock.now)
    sensed = SensedState(agent=2, stamp=1.5, rel_positions={1: (0.25, -0.5)})
    assert schedule.begin()
    schedule.triggered(1.5)
    arrivals.triggered(sensed, core=core)
    schedule.next_time = 2.0
    assert arrivals.arrive(_info(1.25), core=core)  # sent at 1.25, read after this agent's trigger
    assert core.received == [rebased(_info(1.25), sensed=sensed, at=1.5)]
    assert core.received[0].stamp == 1.5 and core.received[0].rel_position == (-0.25, 0.5)
    assert (counts.info_received, counts.late_infos, counts.report_due) == (1, 1, True)
    assert arrivals.arrive(_info(1.5), core=core) and core.received[-1] == _info(1.5), (
        'at the trigger: not late'
    )
    assert counts.late_infos == 1


# -- which Step an agent takes (issue 28) -------------------------------------------------------------


def _wall(index, *, epoch=1000.0, final=False, t=0.0):
    from formation_msgs_py.lockstep import STEP_FLAG_FINAL, STEP_FLAG_REALTIME

    return Step(
        index=index, time=t, flags=STEP_FLAG_REALTIME | (STEP_FLAG_FINAL if final else 0), epoch=epoch
    )


def test_a_forged_wall_clock_step_is_refused_and_the_real_final_step_still_taken():
    """The finding: a forged Step (index 1, epoch 100 s earlier) was taken, and the real final
    Step (index 1 too) then looked like a repeat: the robots drove on 7.6 s past the end."""
    from formation_agent.ros.stepping import STEP_REPEAT, STEP_TAKE, StepGate

    gate = StepGate(agent_id=2)
    assert gate.judge(_wall(0)) == STEP_TAKE
    assert gate.judge(_wall(0)) == STEP_REPEAT  # transient local replays it: silent
    reason, why = gate.judge(_wall(1, epoch=900.0))
    assert reason == 'step_order'
    assert why == (
        'agent 2: refused step 1 at t=0.0 (wall clock, epoch 900.0): the run began with step 0 at t=0.0 '
        '(wall clock, epoch 1000.0)'
    )
    assert gate.judge(_wall(0, epoch=900.0))[0] == 'step_order'  # a step 0 of another run
    assert gate.judge(_wall(5))[1].endswith('on the wall clock only the final Step follows step 0')
    assert gate.judge(_wall(1, final=True, t=10.0)) == STEP_TAKE
    assert gate.last == _wall(1, final=True, t=10.0) and gate.first == _wall(0)


@pytest.mark.parametrize('first', [None, 'lock-step', 'wall clock'])
def test_a_final_step_is_always_taken(first):
    """Stopping is always safe: whatever index, time or epoch a final Step carries, it is taken."""
    from formation_agent.ros.stepping import STEP_TAKE, StepGate

    gate = StepGate(agent_id=1)
    if first == 'lock-step':
        assert gate.judge(Step(index=0, time=0.0, due=(1,))) == STEP_TAKE
    elif first == 'wall clock':
        assert gate.judge(_wall(0)) == STEP_TAKE
    assert gate.judge(_wall(0, epoch=-5.0, final=True, t=1e300)) == STEP_TAKE


def test_lock_step_steps_that_skip_or_go_back_are_refused_and_the_real_next_one_taken():
    """The finding: a Step going backwards made the real next one look like a repeat (60 s stall)."""
    from formation_agent.ros.stepping import STEP_REPEAT, STEP_TAKE, StepGate

    gate = StepGate(agent_id=1)
    assert gate.judge(Step(index=3, time=0.0))[1].endswith('the run has not begun (no step 0 yet)')
    assert gate.judge(Step(index=0, time=0.5))[0] == 'step_order'  # step 0 is at t = 0
    assert gate.judge(Step(index=0, time=0.0, due=(1, 2))) == STEP_TAKE
    assert gate.judge(Step(index=1, time=0.25, due=(2,))) == STEP_TAKE
    refusals = [
        (Step(index=2, time=0.125, due=(1,)), 'its time goes back from t=0.25 (step 1)'),
        (Step(index=7, time=0.5, due=(1,)), 'the latest step taken is 1: step 2 is missing'),
        (Step(index=1, time=0.25, due=(1,)), 'step 1 was step 1 at t=0.25 (lock-step)'),
        (_wall(2, epoch=0.0, t=0.5), 'the run began with step 0 at t=0.0 (lock-step)'),
    ]
    for step, why in refusals:
        reason, text = gate.judge(step)
        assert reason == 'step_order' and text.endswith(why), text
    assert gate.judge(Step(index=1, time=0.25, due=(2,))) == STEP_REPEAT
    assert gate.judge(Step(index=0, time=0.0, due=(1, 2))) == STEP_REPEAT
    assert gate.judge(Step(index=2, time=0.25, due=(1,))) == STEP_TAKE  # the same instant again: allowed
    assert gate.last.index == 2
