"""Why an agent's state is stale, ROS-free: a dead pose feed or a starved computer.

`pose_timeout` is the agent's safety stop (`formation_agent.core.pose_sensing`): a pose older
than it is never used.  When a pose is too old, the agent says why it may be (issue 19): whether
the pose's writer is still in the ROS graph (`WriterWatch`: its topic's publisher count, looked
at now and then) and how late the agent's own timers ran (`TimerWatch`), so that "the robot's
driver died" reads differently from "this computer is overloaded".

A command is computed from the agent's last trigger and its own latest pose.  After a freeze
(the process stopped, or starved of the CPU) the command timer comes late and the trigger that
was due has not come: `CommandGuard` refuses to send a command from state older than
`pose_timeout` (`StaleStateError`), and the agent stops instead.  `Staleness` puts these
together for an agent node that senses poses.

The end of a robot run is no failure: a pose that goes stale because its robot stopped at the
horizon, while the final Step is on its way, stops the robot without a failure
(`Staleness.after_horizon`: every stale pose was fresh at the horizon).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from formation_agent.core.errors import PoseError
from formation_agent.core.pose_sensing import PoseBook
from formation_agent.ros.errors import StaleStateError

OVERLOADED = 'an overloaded computer?'
NOT_PUBLISHING = 'its writer stalled or was stopped, or its messages are lost?'


class TimerWatch:
    """How late a periodic timer ran: each tick against the previous one plus the period."""

    def __init__(self, period: float) -> None:
        self.period = period
        self._last: float | None = None
        self.late = 0.0  # at the last tick [s]

    def tick(self, now: float) -> float:
        """A tick at `now` (Unix time); returns how late it came."""
        self.late = 0.0 if self._last is None else max(0.0, now - self._last - self.period)
        self._last = now
        return self.late


class WriterWatch:
    """Whether each pose topic still has a writer and, if it has none, since when (Unix time)."""

    def __init__(self, topics: dict[int, str]) -> None:
        self.topics = dict(topics)  # robot -> its pose topic
        self.seen: set[int] = set()  # robots whose topic has had a writer
        self.left_at: dict[int, float] = {}  # robot -> when its topic was first seen without one

    def look(self, counts: Iterable[tuple[int, int]], now: float) -> None:
        """(robot, writers on its topic now), looked at `now`."""
        for robot, writers in counts:
            if writers > 0:
                self.seen.add(robot)
                self.left_at.pop(robot, None)
            elif robot in self.seen:
                self.left_at.setdefault(robot, now)

    def describe(self, robot: int, *, run_time: Callable[[float], float]) -> str | None:
        """Where the writer of `robot`'s poses is, in words (None: nothing to say, it is there)."""
        if robot in self.left_at:
            return f'its writer left the graph at t={run_time(self.left_at[robot]):.3f}'
        if robot not in self.seen:
            return f'no writer of {self.topics[robot]} has been seen'
        return None


def diagnosis(*, writer: str | None, timer_late: float, timeout: float) -> str:
    """The clause that tells a dead feed from a starved agent (`timer_late`: how late this agent's
    own timer ran, s)."""
    if writer is not None:
        return writer
    cause = OVERLOADED if timer_late >= 0.5 * timeout else NOT_PUBLISHING
    return f"its writer is alive and this agent's timer ran {timer_late:.3f} s late ({cause})"


def explained(message: str, clause: str) -> str:
    """A PoseError's `message` with `clause` before its last words (': the agent stops')."""
    ending = ': the agent stops'
    head = message.removesuffix(ending)
    return f'{head}; {clause}{ending}'


class CommandGuard:
    """Refuses a command from state older than `timeout` after a freeze: the command timer came
    that late, or the trigger that was due that long ago has not come."""

    def __init__(self, *, agent_id: int, period: float, timeout: float) -> None:
        self.agent_id = agent_id
        self.timeout = timeout
        self.timer = TimerWatch(period)

    def check(self, now: float, *, t: float, trigger_late: float | None) -> None:
        """Before a command at `now` (run time t); `trigger_late`: how long the due trigger has
        been waiting (None: none is due).  StaleStateError if the state is too old."""
        late = self.timer.tick(now)
        where = f'agent {self.agent_id}: at t={t:.3f}'
        if late > self.timeout:
            raise StaleStateError(
                f'{where} its command timer ran {late:.3f} s late (pose_timeout {self.timeout:g} s; '
                f'the process was stopped, or {OVERLOADED[:-1]}): no command from state that old: '
                'the agent stops'
            )
        if trigger_late is not None and trigger_late > self.timeout:
            raise StaleStateError(
                f'{where} its trigger has been due for {trigger_late:.3f} s '
                f"(pose_timeout {self.timeout:g} s; this agent's timer ran {late:.3f} s late, "
                f'{OVERLOADED}): no command from state that old: the agent stops'
            )


class Staleness:
    """An agent's watch over the age of what it commands from (sensing from poses).

    `count_writers(topic)` gives the writers a topic has now; `schedule` is the agent's
    `formation_agent.ros.stepping.TriggerSchedule`; `take(robot)` puts the poses of `robot` that
    wait in its reader into the book (`formation_agent.ros.sensing.PoseReaders.take`: a neighbour's
    are taken only at triggers).
    """

    def __init__(
        self,
        *,
        book: PoseBook,
        period: float,
        count_writers: Callable[[str], int],
        schedule,
        take: Callable[[int], None] = lambda robot: None,
    ) -> None:
        self.book = book
        self._take = take
        self.guard = CommandGuard(agent_id=book.agent_id, period=period, timeout=book.timeout)
        self.writers = WriterWatch({robot: book.topic(robot) for robot in book.robots})
        self._count_writers = count_writers
        self._schedule = schedule

    def look(self, now: float) -> None:
        """Look at the pose topics' writers (now and then, and when a pose is stale)."""
        self.writers.look(
            ((robot, self._count_writers(topic)) for robot, topic in self.writers.topics.items()), now
        )

    def check_command(self, now: float, t: float) -> None:
        """Before a command at `now`: StaleStateError after a freeze (`CommandGuard`)."""
        self.guard.check(now, t=t, trigger_late=self._schedule.trigger_late(now))

    def trigger_refusal(self, now: float) -> StaleStateError | None:
        """Why the trigger that is starting must not run (its timer fired more than pose_timeout
        after it was due: the process was stopped or starved), or None."""
        late, self._schedule.fired_late = self._schedule.fired_late, None
        timeout = self.book.timeout
        if late is None or late <= timeout:
            return None
        t = now - self._schedule.epoch
        return StaleStateError(
            f'agent {self.book.agent_id}: at t={t:.3f} its trigger came {late:.3f} s after it was due '
            f'(pose_timeout {timeout:g} s; the process was stopped, or {OVERLOADED[:-1]}): '
            'no command from state that old: the agent stops'
        )

    def stale_robots(self, now: float) -> list[int]:
        """The robots whose latest pose (taken now) is not fresh at `now` (Unix time)."""
        t = now - (self._schedule.epoch or 0.0)
        for robot in self.book.robots:
            self._take(robot)
        return [robot for robot in self.book.robots if _refused(self.book, robot, t=t, now=now)]

    def after_horizon(self, error: Exception, now: float, *, horizon: float) -> bool:
        """Whether `error` is only the end of the run (issue 19): a pose that stopped because its
        robot stopped at the horizon while the final Step was on its way.  True when `error` is a
        PoseError and every pose stale at `now` was fresh at the horizon (its age then at most
        pose_timeout; so `now` is past the horizon).  A pose stale before the horizon, or one that
        never came, stays a fault."""
        epoch = self._schedule.epoch
        if not isinstance(error, PoseError) or epoch is None:
            return False
        stale = self.stale_robots(now)
        end = epoch + horizon
        return bool(stale) and not any(_refused(self.book, robot, t=horizon, now=end) for robot in stale)

    def explain(self, error: PoseError, now: float) -> PoseError:
        """`error` with why its pose may be stale: the writer gone, or this agent late."""
        schedule = self._schedule
        if schedule.epoch is None:
            return error
        stale = next(iter(self.stale_robots(now)), None)
        if stale is None:
            return error
        self.look(now)
        late = max(self.guard.timer.late, schedule.lateness(now))
        writer = self.writers.describe(stale, run_time=lambda wall: wall - schedule.epoch)
        return PoseError(
            explained(str(error), diagnosis(writer=writer, timer_late=late, timeout=self.book.timeout))
        )


def _refused(book: PoseBook, robot: int, *, t: float, now: float) -> bool:
    """`book` refuses `robot`'s pose at `now` (run time t): missing, too old or from the future."""
    try:
        book.fresh(robot, t=t, now=now)
    except PoseError:
        return True
    return False
