"""When an agent triggers, ROS-free: its triggering schedule in lock-step and on the wall clock.

`TriggerSchedule` holds the agent's next triggering time t^i_{k+1} (the one its Status reports),
the trigger in progress (its sensing asked for, not yet answered) and the last one.  In lock-step
the simulator's Steps say when it is the agent's turn (`check_step`, exact floats); on the wall
clock (`start`) a one-shot timer fires at epoch + t^i_{k+1} (`arm`), through the node's timers
(`Timers`: any object that arms and cancels one-shot callbacks).  Information that arrives for an
instant the agent is due at waits for its own trigger (`holds`; docs/DESIGN.md, "Time and
exactness"); wall-clock information that crossed the agent's own later trigger is re-anchored at
it (`rebased`).  `Arrivals` takes accepted information into the core by these rules.

`StepGate` decides which Step an agent takes (issue 28): a Step that cannot follow the run's
previous one (another epoch, a second wall-clock Step that is not final, a lock-step index that
skips or a time that goes back) is refused and counted, so that a forged or replayed Step never
makes the real next one look like a repeat; a final Step is always taken (stopping is safe).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol

from formation_agent.ros.errors import AgentNodeError
from formation_msgs_py.lockstep import REJECT_STEP_ORDER, Step
from formation_msgs_py.types import SensedState, TriggerInfo


class Timers(Protocol):
    """One-shot callbacks, as a node's timers give them (`arm` returns a handle for `cancel`)."""

    def arm(self, delay: float, callback: Callable[[], None]) -> object: ...

    def cancel(self, handle: object) -> None: ...


class TriggerSchedule:
    """An agent's triggering times: t^i_{k+1} to come, the trigger in progress, the last one."""

    def __init__(self, *, agent_id: int, timers: Timers, clock: Callable[[], float] = time.time) -> None:
        self.agent_id = agent_id
        self._timers = timers
        self._clock = clock  # Unix time (the wall clock's epoch is one)
        self.next_time = 0.0  # t^i_1 = 0
        self.last_trigger = -math.inf
        self.planned = 0.0  # the time the trigger in progress (or the last one) was planned for
        self.sensing = False  # a sensing request is in flight
        self.epoch: float | None = None  # wall clock: Unix time of t = 0
        self.stopped = False  # no trigger ever again
        self.heard: dict[int, float] = {}  # sender -> stamp of its last accepted information
        self.due_neighbours: tuple[int, ...] = ()  # lock-step: neighbours due at the current step
        self._timer = None
        # Wall clock: the Unix time the armed trigger is due at, or was armed at if that is later
        # (a time already past when planned: its timer is late from then on, not before).
        self._due_at: float | None = None
        self.fired_late: float | None = None  # how late the last armed trigger fired (until taken)
        self._last_late = 0.0  # how late the last armed trigger fired
        self._armed = 0  # the arming the live timer belongs to

    @property
    def wall_clock(self) -> bool:
        return self.epoch is not None

    def start(self, epoch: float) -> None:
        """On the wall clock from `epoch` (Unix time of t = 0) on."""
        self.epoch = epoch

    # -- lock-step ------------------------------------------------------------------------------

    def check_step(self, step: Step) -> bool:
        """Whether lock-step `step` is this agent's turn; AgentNodeError if the simulator skipped
        the agent's triggering time or lists it wrongly."""
        if step.time > self.next_time:
            raise AgentNodeError(
                f'agent {self.agent_id}: step {step.index} at t={step.time!r} skips its triggering time '
                f'{self.next_time!r}'
            )
        due = step.time == self.next_time  # the exact float this agent reported
        if due != (self.agent_id in step.due):
            raise AgentNodeError(
                f'agent {self.agent_id}: step {step.index} at t={step.time!r} lists due agents '
                f'{list(step.due)}, '
                f'but this agent reported its next triggering time {self.next_time!r}'
            )
        return due

    def complete_at(self, step: Step) -> bool:
        """Lock-step: the agent has all it will get at `step` — its own trigger if it is due, and
        the information of every neighbour the Step lists as due (which may arrive before the
        Step itself); information stamped at a later step waits for that Step."""
        if self.sensing or (step.time == self.next_time and self.last_trigger < step.time):
            return False  # due: its own trigger comes first
        if any(self.heard.get(j) != step.time for j in self.due_neighbours):
            return False
        return all(stamp <= step.time for stamp in self.heard.values())

    def sensed_time(self, sensed: SensedState, *, step: Step) -> float:
        """The time of the trigger in progress, for which `sensed` came: in lock-step `step`'s
        exact time, on the wall clock when the world was actually sensed; AgentNodeError if
        `sensed` is another agent's state or of another time."""
        t = sensed.stamp if self.wall_clock else step.time
        if sensed.agent != self.agent_id or sensed.stamp != t:
            raise AgentNodeError(
                f'agent {self.agent_id} asked to sense at t={t!r} and got the state of agent '
                f'{sensed.agent} at t={sensed.stamp!r}'
            )
        return t

    def holds(self, stamp: float) -> bool:
        """Whether information stamped `stamp` must wait for this agent's own trigger: one is in
        flight, or (lock-step) the agent triggers at that instant itself — its own sensing comes
        first, then the neighbours' information."""
        due = self.epoch is None and self.next_time > self.last_trigger  # not yet triggered at
        return self.sensing or (due and stamp >= self.next_time)

    # -- triggers -------------------------------------------------------------------------------

    def begin(self) -> bool:
        """Start a trigger (its sensing is asked for next): False while one is in flight or once
        the agent stopped."""
        self.cancel()
        if self.sensing or self.stopped:
            return False
        self.sensing = True
        self.planned = self.next_time
        return True

    def triggered(self, t: float) -> None:
        """The trigger in progress happened at t."""
        self.sensing = False
        self.last_trigger = t

    def abandon(self) -> None:
        """The trigger in progress is dropped (the agent finished while sensing)."""
        self.sensing = False

    def stop(self) -> None:
        """No trigger from now on (a timer already queued finds the schedule stopped)."""
        self.stopped = True
        self.cancel()

    # -- the wall clock -------------------------------------------------------------------------

    def delay(self) -> float | None:
        """Wall clock: seconds until t^i_{k+1} (≤ 0: past due); None if none is planned."""
        if self.stopped or self.epoch is None or not math.isfinite(self.next_time):
            return None
        return self.epoch + self.next_time - self._clock()

    def arm(self, fire: Callable[[], None]) -> bool:
        """Wall clock: `fire` at t^i_{k+1} (once), replacing any trigger armed before; False if
        none is planned.  A time already past is armed too, with no delay: the trigger then runs
        from the executor like any other, after what it has queued (news, the command timer, a
        stop signal), never by recursion from the trigger before it — a computer that cannot keep
        up with the triggering times triggers as often as it can, not ever deeper."""
        self.cancel()
        delay = self.delay()
        if delay is None:
            return False
        self._armed += 1
        armed = self._armed
        self._due_at = max(self.epoch + self.next_time, self._clock())
        self._timer = self._timers.arm(max(delay, 0.0), lambda: self._fire(armed, fire))
        return True

    def trigger_late(self, now: float) -> float | None:
        """Wall clock: how late the armed trigger's timer is at `now` (Unix time; < 0: not due
        yet); None if none is armed."""
        return None if self._due_at is None else now - self._due_at

    def lateness(self, now: float) -> float:
        """How late this agent's trigger timer runs at `now`: the armed one, else the one that
        fired last (0 if neither is late)."""
        late = self.trigger_late(now)
        return max(0.0, self._last_late if late is None else late)

    def _fire(self, armed: int, fire: Callable[[], None]) -> None:
        if armed != self._armed or self._timer is None:
            return  # cancelled after its callback was queued
        self.fired_late = self._last_late = self._clock() - self._due_at
        self.cancel()
        fire()

    def cancel(self) -> None:
        self._due_at = None
        if self._timer is not None:
            handle, self._timer = self._timer, None
            self._timers.cancel(handle)


def refuse_lock_step(step: Step, *, config, loss: float) -> None:
    """AgentNodeError if this agent cannot run lock-step `step`: robots run on the wall clock
    only, and lock-step counts every message (one dropped on purpose would stall the run)."""
    if config.wall_clock_only:
        raise AgentNodeError(
            f'agent {config.agent_id}: sensing: {config.sensing} with robot: {config.robot} runs on the '
            f'wall clock (Step 0 flagged realtime), but step {step.index} is lock-step'
        )
    if loss > 0.0:
        raise AgentNodeError(
            f'agent {config.agent_id}: inject_loss={loss!r} needs wall-clock mode '
            '(lock-step waits for every message sent; a dropped one stalls the run)'
        )


def rebased(info: TriggerInfo, *, sensed: SensedState, at: float) -> TriggerInfo:
    """Late information re-anchored at the receiver's own last trigger `at`, where it sensed `sensed`.

    The neighbour's new input has acted since info.stamp, but what it did is already in what
    this agent sensed at its trigger (exact); from then on both inputs are constant. So the
    edge is anchored at the trigger with the sensed relative state and the neighbour's new
    input, which is exactly what a prediction from that instant needs.
    """
    j = info.sender
    rel_velocity = None
    if sensed.rel_velocities is not None:
        rel_velocity = tuple(-v for v in sensed.rel_velocities[j])
    return TriggerInfo(
        sender=j,
        receiver=sensed.agent,
        stamp=at,
        control=info.control,
        rel_position=tuple(-v for v in sensed.rel_positions[j]),  # x_j - x_i, exact negation
        rel_velocity=rel_velocity,
    )


class Arrivals:
    """Accepted triggering information on its way into the agent's core (`core.receive`).

    Information the agent must not take before its own trigger (`TriggerSchedule.holds`) is held
    and goes in right after that trigger (`triggered`); on the wall clock, information stamped
    before the agent's last trigger crossed it and is re-anchored there (`rebased`, on what the
    agent sensed then).  Each piece that goes in is counted (`counts.received(late=...)`).
    """

    def __init__(self, *, schedule: TriggerSchedule, counts) -> None:
        self._schedule = schedule
        self._counts = counts
        self.held: list[TriggerInfo] = []  # information stamped at a time this agent is due
        self.sensed: SensedState | None = None  # the last SensedState, to re-base late information

    def arrive(self, info: TriggerInfo, *, core) -> bool:
        """Take `info` into `core` now, or hold it for the agent's own trigger (False)."""
        if self._schedule.holds(info.stamp):
            self.held.append(info)
            return False
        self._receive(info, core)
        return True

    def triggered(self, sensed: SensedState, *, core) -> None:
        """The agent triggered on `sensed`: what was held for its trigger goes into `core` now."""
        self.sensed = sensed
        held, self.held = self.held, []
        for info in held:
            self._receive(info, core)

    def _receive(self, info: TriggerInfo, core) -> None:
        at = self._schedule.last_trigger
        late = info.stamp < at  # only on the wall clock: it crossed this agent's trigger
        if late:
            info = rebased(info, sensed=self.sensed, at=at)
        core.receive(info)
        self._counts.received(late=late)


STEP_TAKE = 'take'
STEP_REPEAT = 'repeat'


class StepGate:
    """Which Step an agent takes: the run's own sequence only (issue 28).

    `judge(step)` returns STEP_TAKE, STEP_REPEAT (a copy of a Step already taken: transient
    local replays it to a late reader; ignored silently) or (REJECT_STEP_ORDER, why) for a Step
    that cannot be the run's next one: before step 0 anything but a step 0 at t = 0; on the wall
    clock anything after step 0 but the final Step, or a step 0 of another epoch; in lock-step an
    index that skips one, a time that goes back, a change of clock or epoch, or a second Step of
    the same index that differs.  A final Step is always taken: an agent stops on it whatever
    else it carries, so that nothing can keep a robot moving past the run's end.
    """

    def __init__(self, *, agent_id: int) -> None:
        self.agent_id = agent_id
        self.first: Step | None = None  # the step 0 taken
        self.last: Step | None = None  # the latest Step taken

    def judge(self, step: Step) -> str | tuple[str, str]:
        problem = None if step.final else self._problem(step)
        if problem == STEP_REPEAT:
            return STEP_REPEAT
        if problem is not None:
            return REJECT_STEP_ORDER, f'agent {self.agent_id}: refused {_step_text(step)}: {problem}'
        self.first = self.first or step
        self.last = step
        return STEP_TAKE

    def _problem(self, step: Step) -> str | None:
        last, first = self.last, self.first
        if last is None:
            if step.index != 0 or step.time != 0.0:
                return 'the run has not begun (no step 0 yet)'
            return None
        if step.realtime != first.realtime or step.epoch != first.epoch:
            if step.index == 0 and step == first:
                return STEP_REPEAT
            return f'the run began with {_step_text(first)}'
        if first.realtime:
            return STEP_REPEAT if step == first else 'on the wall clock only the final Step follows step 0'
        if step.index < last.index or step == last:
            return STEP_REPEAT  # an old Step again (its time was checked when it was taken)
        if step.index == last.index:
            return f'step {last.index} was {_step_text(last)}'
        if step.index > last.index + 1:
            return f'the latest step taken is {last.index}: step {last.index + 1} is missing'
        if step.time < last.time:
            return f'its time goes back from t={last.time!r} (step {last.index})'
        return None


def _step_text(step: Step) -> str:
    clock = f'wall clock, epoch {step.epoch!r}' if step.realtime else 'lock-step'
    return f'{"final " if step.final else ""}step {step.index} at t={step.time!r} ({clock})'
