"""What an agent node tells the run, ROS-free: its counts, its Status and its AgentReport.

The counts are totals since the start (docs/MESSAGES.md, "Status" and "AgentReport"): the
protocol's (triggering information sent and received, commands, triggers) and what a recorder
must hold (`published`: messages per topic from step 0 on, when every listener is matched for
sure — the simulator starts step 0 only once every agent has matched all of them).  A Status
carries the core's next triggering time (`agent_status`).
"""

from __future__ import annotations

import math

from formation_agent.core.crossing import PRECISION_HINT
from formation_agent.core.errors import CrossingError
from formation_agent.ros.errors import AgentNodeError, PredictionError
from formation_msgs_py.lockstep import DISCOVERY_STEP, AgentReport, Status


class AgentCounts:
    """An agent's counts and whether its Status and report have news to tell."""

    def __init__(self, *, agent_id: int) -> None:
        self.agent_id = agent_id
        self.info_sent = 0
        self.info_received = 0
        self.commands_sent = 0
        self.triggers = 0
        self.trigger_times: list[float] = []
        self.late_infos = 0  # wall clock: information re-anchored at this agent's later trigger
        self.published: dict[str, int] = {}  # topic -> messages published from step 0 on
        self.status_due = False  # knowledge changed since the last Status
        self.report_due = False  # a count of the report changed since the last one
        self.final_sent = False

    def changed(self) -> None:
        """A count the report carries changed."""
        self.report_due = True

    def count_published(self, topic: str, *, started: bool) -> None:
        """One message on `topic`; counted from step 0 on (`started`)."""
        if started:
            self.published[topic] = self.published.get(topic, 0) + 1

    def triggered(self, t: float) -> None:
        """A trigger at t (its command and information are counted as they go out)."""
        self.triggers += 1
        self.trigger_times.append(t)

    def received(self, *, late: bool) -> None:
        self.info_received += 1
        if late:
            self.late_infos += 1
            self.changed()

    def status(self, *, step_index: int, ready: bool, next_time: float, planned: float) -> Status:
        """The Status at `step_index`: `next_time` only once it is defined (ready, or 0 during
        discovery), +inf otherwise; `planned` (last_planned) always finite."""
        if not math.isfinite(planned):  # a trigger is planned only for a finite time
            raise AgentNodeError(
                f'agent {self.agent_id}: last_planned must be finite (docs/MESSAGES.md, "Status"), '
                f'got {planned!r}'
            )
        self.status_due = False
        defined = ready or step_index == DISCOVERY_STEP
        return Status(
            agent=self.agent_id,
            step_index=step_index,
            next_time=next_time if defined else math.inf,
            info_sent=self.info_sent,
            info_received=self.info_received,
            commands_sent=self.commands_sent,
            triggers=self.triggers,
            ready=ready,
            last_planned=planned,
        )

    def report(
        self,
        *,
        final: bool,
        failure: str | None,
        rejected: dict[str, int],
        dropped: int,
        delayed: int,
        robot_commands: int,
        saturation: dict,
        plant: tuple[str, int] | None = None,
    ) -> AgentReport:
        """The AgentReport; `plant`: (topic, commands) sent to a simulator's plant, which the
        output counts itself."""
        published = dict(self.published)
        if plant is not None and plant[1]:
            published[plant[0]] = plant[1]
        return AgentReport(
            agent=self.agent_id,
            final=final,
            rejected=dict(rejected),
            dropped=dropped,
            delayed=delayed,
            late=self.late_infos,
            robot_commands=robot_commands,
            saturation=saturation,
            failure=failure,
            published=published,
        )


def agent_status(
    counts: AgentCounts, *, schedule, core, step_index: int, ready: bool, horizon: float
) -> Status:
    """The agent's Status at `step_index` (`schedule`: its `TriggerSchedule`).

    During discovery (DISCOVERY_STEP) `ready` is its readiness, as given.  After it the agent is
    ready once its core is (it has triggered and heard every neighbour), and only then is a next
    triggering time defined: the core's, within `horizon`, kept in `schedule.next_time`
    (PredictionError, naming the agent and the rule, when the certified search cannot resolve it).
    """
    if step_index != DISCOVERY_STEP:
        ready = bool(core.ready)
        if ready:
            try:
                schedule.next_time = float(core.next_trigger_time(horizon))
            except CrossingError as error:
                raise PredictionError(f'agent {counts.agent_id}: {error}; {PRECISION_HINT}') from error
    return counts.status(
        step_index=step_index, ready=ready, next_time=schedule.next_time, planned=schedule.planned
    )
