"""An agent's counts, Status (with its core's next triggering time) and AgentReport without a node."""

from __future__ import annotations

import math

import pytest

from formation_agent.core.errors import CrossingError
from formation_agent.ros.errors import AgentNodeError, PredictionError
from formation_agent.ros.reporting import AgentCounts, agent_status
from formation_agent.ros.stepping import TriggerSchedule
from formation_msgs_py.codec import decode_agent_report, decode_status, encode_agent_report, encode_status
from formation_msgs_py.lockstep import DISCOVERY_STEP


def test_a_status_tells_the_next_time_only_once_it_is_defined_and_round_trips():
    counts = AgentCounts(agent_id=3)
    counts.triggered(0.0)
    counts.commands_sent += 1
    counts.info_sent += 2
    counts.received(late=False)
    counts.status_due = True
    waiting = counts.status(step_index=4, ready=False, next_time=0.75, planned=0.0)
    assert waiting.next_time == math.inf and not counts.status_due
    ready = counts.status(step_index=4, ready=True, next_time=0.75, planned=0.5)
    assert (
        ready.next_time,
        ready.last_planned,
        ready.triggers,
        ready.commands_sent,
        ready.info_sent,
        ready.info_received,
    ) == (0.75, 0.5, 1, 1, 2, 1)
    assert decode_status(encode_status(ready)) == ready
    assert counts.status(step_index=DISCOVERY_STEP, ready=False, next_time=0.0, planned=0.0).next_time == 0.0
    with pytest.raises(
        AgentNodeError, match=r'agent 3: last_planned must be finite \(docs/MESSAGES.md, "Status"\), got inf'
    ):
        counts.status(step_index=5, ready=True, next_time=math.inf, planned=math.inf)


def test_the_report_counts_what_was_published_from_step_0_on_and_itself():
    counts = AgentCounts(agent_id=3)
    counts.count_published('/formation/status', started=False)  # discovery: a recorder may not be there yet
    counts.count_published('/formation/status', started=True)
    counts.received(late=True)
    assert counts.report_due and counts.late_infos == 1
    report = counts.report(
        final=True,
        failure='agent 3: stopped',
        rejected={'sender': 2},
        dropped=1,
        delayed=0,
        robot_commands=0,
        saturation={},
        plant=('/agent_3/cmd_vel', 4),
    )
    assert report.published == {'/formation/status': 1, '/agent_3/cmd_vel': 4}
    assert (report.late, report.failure, report.rejected, report.final) == (
        1,
        'agent 3: stopped',
        {'sender': 2},
        True,
    )
    assert decode_agent_report(encode_agent_report(report)) == report


class _Core:
    def __init__(self, *, ready: bool, next_time: float | None = None) -> None:
        self.ready = ready
        self._next_time = next_time
        self.asked: list[float] = []

    def next_trigger_time(self, limit: float) -> float:
        self.asked.append(limit)
        if self._next_time is None:
            raise CrossingError('no convergence after 100000 certified steps (t=0.5)')
        return self._next_time


def test_a_status_asks_the_core_for_its_next_time_only_once_it_is_ready():
    counts, schedule = AgentCounts(agent_id=1), TriggerSchedule(agent_id=1, timers=None)
    waiting = _Core(ready=False, next_time=0.75)
    status = agent_status(counts, schedule=schedule, core=waiting, step_index=2, ready=True, horizon=10.0)
    assert (status.ready, status.next_time, waiting.asked) == (False, math.inf, []), (
        "the core's word, not the caller's"
    )
    ready = _Core(ready=True, next_time=0.75)
    status = agent_status(counts, schedule=schedule, core=ready, step_index=2, ready=False, horizon=10.0)
    assert (status.ready, status.next_time, schedule.next_time, ready.asked) == (True, 0.75, 0.75, [10.0])
    discovery = agent_status(
        counts, schedule=schedule, core=waiting, step_index=DISCOVERY_STEP, ready=True, horizon=10.0
    )
    assert discovery.ready and waiting.asked == [], 'during discovery: the readiness given'


def test_a_next_trigger_double_precision_cannot_resolve_is_named_with_the_agent_and_its_rule():
    """A CrossingError of the core's certified search is named with the agent and the validate rule
    (as the engine names it), not left to a traceback; main() then stops the agent with status 1."""
    counts, schedule = AgentCounts(agent_id=1), TriggerSchedule(agent_id=1, timers=None)
    with pytest.raises(
        PredictionError,
        match=r'^agent 1: no convergence after 100000 certified steps \(t=0.5\); the rounded '
        r'prediction no longer resolves its threshold .*rule \[precision\]\)$',
    ):
        agent_status(
            counts, schedule=schedule, core=_Core(ready=True), step_index=3, ready=True, horizon=10.0
        )
