"""The bookkeeping of a distributed run: what the coordinator knows of every agent and recorder.

`RunBook` holds, per agent, its latest Status, its reports, its triggering times and its signs of
life, and answers the coordinator's questions (docs/MESSAGES.md): is the lock-step step settled,
which agents are due next, who is lost, did an edge reach Δ, what goes into summary.json's
`extra`.  `RecorderBook` does the same for the recorders: their signs of life and the latest step
each has written.  The nodes (`coordinator.FormationCoordinatorNode`,
`sim_node.FormationSimulatorNode`) only move messages in and out of them.

Every way a run can stop early is a `CoordinatorError` whose `kind` becomes
`extra.failure.kind` in summary.json.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from formation_msgs_py.lockstep import DISCOVERY_STEP, AgentReport, Status
from formation_msgs_py.middleware import LIVELINESS_LEASE, LOST_GRACE
from formation_msgs_py.tags import FOREIGN_REASONS
from formation_msgs_py.topics import trigger_info_topic
from formation_sim.runtime.errors import (
    AgentLostError,
    ConnectivityLostError,
    CoordinatorError,
    InitialConditionError,
    OperatorStopError,
    RecorderLostError,
    RobotLostError,
)
from formation_sim.sim.summary import lateness_extra, run_failure, saturation_extra


def ids_text(agents: list[int], *, most: int = 20) -> str:
    """Agent ids for a message, the first `most` of a long list."""
    shown = ', '.join(map(str, agents[:most]))
    return shown + (f', … ({len(agents)} in all)' if len(agents) > most else '')


def failure_extra(
    error: BaseException,
    *,
    interrupted: bool,
    time: float,
    step: int | None,
    wall_time: float,
    detected_by: str,
) -> dict:
    """summary.json's `extra.failure` for what stopped a run early: its kind (a CoordinatorError's
    own; 'interrupted' for SIGINT/SIGTERM; else 'error'), its message, the agents it names (or its
    edge), the run time (the error's own, else `time`) and step it came at, the wall time since
    t = 0 began, and who detected it; with an edge's length, or the initial condition's breaches."""
    if isinstance(error, CoordinatorError):
        kind = error.kind
    elif interrupted:
        kind = 'interrupted'
    else:
        kind = 'error'
    info = run_failure(
        kind,
        str(error)
        or ('stopped by a signal (SIGINT/SIGTERM)' if kind == 'interrupted' else type(error).__name__),
        agents=list(getattr(error, 'agents', getattr(error, 'edge', []))),
        time=getattr(error, 'time', time),
        step=step,
        wall_time=wall_time,
        detected_by=detected_by,
    )
    if isinstance(error, ConnectivityLostError):
        info.update(edge=list(error.edge), length=error.length)
    if isinstance(error, InitialConditionError):
        info.update(breaches=error.breaches)
    if isinstance(error, OperatorStopError):
        info.update(asked_by=error.asked_by)
    return info


def add_what_followed(info: dict | None, failures: dict[int, str]) -> None:
    """After the first cause (`info`, extra.failure): the agents that then stopped on errors of
    their own (`failures`: agent -> why, from their final reports), in `info['followed']` and after
    the first cause in its message.  Not after an interruption or an operator's stop: that stopped
    every agent."""
    if info is None or info['kind'] in ('interrupted', OperatorStopError.kind):
        return
    followed = {i: why for i, why in failures.items() if i not in info['agents']}
    if not followed:
        return
    info['followed'] = {str(i): why for i, why in followed.items()}
    agents = sorted(followed)
    names = f'agent {agents[0]}' if len(agents) == 1 else f'agents {ids_text(agents)}'
    info['message'] += f'; then {names} stopped: {followed[agents[0]]}'


@dataclass
class AgentBook:
    """What the coordinator knows of one agent: its latest status and what it received from it."""

    neighbours: tuple[int, ...]
    status: Status | None = None
    expected_triggers: int = 0
    commands_received: int = 0
    sensed_at_step: int = -1
    trigger_times: list[float] = field(default_factory=list)
    planned: dict[int, float] = field(default_factory=dict)  # wall clock: trigger number -> its planned time
    report: AgentReport | None = None  # its latest report (rejected and injected messages)
    alive: bool = False  # its watched writer is matched and alive (DDS liveliness)
    lost: tuple[float, str] | None = None  # (monotonic time, how) once that writer went away
    lease_expired: bool = False  # how it went: its lease expired (else its writer was deleted)


class RunBook:
    """Every agent's book, and the rules the coordinator applies to them."""

    def __init__(self, scenario, *, realtime: bool, serves_sensing: bool = True) -> None:
        self.scenario = scenario
        self.realtime = realtime
        # A simulator serves the sensing, so it knows how often each agent was due before the
        # agent reports; a coordinator learns the triggers from the agents' own messages.
        self.serves_sensing = serves_sensing
        self.agents = {i: AgentBook(neighbours=tuple(scenario.neighbours(i))) for i in scenario.agent_ids}
        self.rejected: dict[str, int] = {}  # malformed messages the coordinator itself refused
        self._announced: set[int] = set()  # agents that sent a discovery Status
        self._ready: set[int] = set()  # agents whose latest discovery Status said ready
        index = {agent: k for k, agent in enumerate(scenario.agent_ids)}
        self._edge_rows = (
            np.array([index[e.i] for e in scenario.edges], dtype=int),
            np.array([index[e.j] for e in scenario.edges], dtype=int),
        )

    # -- messages ---------------------------------------------------------------------------------

    def count_rejection(self, reason: str) -> int:
        """Count a message refused for `reason`; return how many so far."""
        self.rejected[reason] = self.rejected.get(reason, 0) + 1
        return self.rejected[reason]

    def accept_status(self, status: Status) -> bool:
        """Take an agent's Status; True when it reports a new trigger.  Raises CoordinatorError for
        a Status no working agent sends (unknown agent, counters going back, too many triggers)."""
        book = self.agents.get(status.agent)
        if book is None:
            raise CoordinatorError(
                f'status from agent {status.agent}, which is not in the scenario {sorted(self.agents)}'
            )
        previous = book.status
        if previous is not None and (
            status.step_index < previous.step_index
            or status.info_sent < previous.info_sent
            or status.info_received < previous.info_received
            or status.triggers < previous.triggers
        ):
            raise CoordinatorError(f'agent {status.agent}: status went backwards from {previous} to {status}')
        if self.serves_sensing and status.triggers > book.expected_triggers:
            raise CoordinatorError(
                f'agent {status.agent} reports {status.triggers} '
                f'triggers, but was due {book.expected_triggers} times'
            )
        new_trigger = (previous is None or status.triggers > previous.triggers) and status.triggers > 0
        if new_trigger:
            self._check_planned(status, book)
        book.status = status
        return new_trigger

    def _check_planned(self, status: Status, book: AgentBook) -> None:
        """A new trigger: lock-step, it must be the step's time; wall clock, when it was planned for."""
        if self.realtime:
            book.planned[status.triggers] = status.last_planned
            return
        t = book.trigger_times[status.triggers - 1]
        if status.last_planned != t:
            raise CoordinatorError(
                f'agent {status.agent} triggered for t={status.last_planned!r} at step time t={t!r}'
            )

    def accept_report(self, report: AgentReport) -> str | None:
        """Take an agent's report; the reason it is refused, or None."""
        book = self.agents.get(report.agent)
        if book is None:
            return f'report of agent {report.agent}, not in the scenario'
        if book.report is None or not book.report.final:
            book.report = report
        return None

    def failures(self) -> dict[int, str]:
        """Agents whose final report says they stopped on an error: agent -> the error."""
        return {
            i: book.report.failure
            for i, book in self.agents.items()
            if book.report is not None and book.report.final and book.report.failure
        }

    def unreported(self) -> list[int]:
        """Agents, alive or lost, whose final report has not come."""
        return [i for i, book in self.agents.items() if book.report is None or not book.report.final]

    def final_reports_in(self) -> bool:
        """Every agent still alive has sent its final report."""
        return all(
            book.report is not None and book.report.final
            for book in self.agents.values()
            if book.lost is None
        )

    # -- discovery and lost agents ----------------------------------------------------------------

    def not_ready(self) -> list[int]:
        """Agents that have not yet said all their endpoints are matched (discovery)."""
        return [
            i
            for i, book in self.agents.items()
            if book.status is None or book.status.step_index != DISCOVERY_STEP or not book.status.ready
        ]

    def note_announcement(self, status: Status) -> None:
        """An agent's discovery Status (taken by `accept_status`): announced, ready or not, alive."""
        self._announced.add(status.agent)
        (self._ready.add if status.ready else self._ready.discard)(status.agent)
        book = self.agents[status.agent]
        if book.lost is not None and book.lease_expired:
            # It speaks after its lease lapsed while a busy machine started many processes: alive.
            # (DDS said so again for most, but 3 agents of 1000 stayed "expired" for minutes, and
            # step 0 waited for them; ready agents announce themselves every second until step 0.)
            book.lost = None

    def all_announced(self) -> bool:
        return len(self._announced) == len(self.agents)

    def all_ready(self) -> bool:
        """Every agent's latest discovery Status said its endpoints are matched."""
        return len(self._ready) == len(self.agents)

    def note_liveliness(
        self, agent: int, *, alive_count: int, not_alive_count_change: int, finished: bool, now: float
    ) -> None:
        """A liveliness change of the writer watched for `agent`."""
        book = self.agents[agent]
        if alive_count > 0:
            book.alive = True
            book.lost = None
        elif book.alive and book.lost is None and not finished:
            # A lease that expired: the process died or the network lost it.  A writer deleted:
            # the agent left (its process exited) before the end of the run.
            book.lease_expired = not_alive_count_change > 0
            how = (
                f'no sign of life for {LIVELINESS_LEASE} s (DDS liveliness lease)'
                if book.lease_expired
                else 'its node left the graph'
            )
            book.lost = (now, how)

    def lost_error(self, now: float, *, started: bool, where: str) -> AgentLostError | None:
        """The agents lost, once the grace after the first has passed (else None).

        During discovery a lease may expire while a busy machine starts many processes: discovery
        waits for the agent to come back (bounded by its timeout); an agent that left counts.
        """
        lost = {
            i: book.lost
            for i, book in self.agents.items()
            if book.lost is not None and not (not started and book.lease_expired)
        }
        # After a short grace, so that what a lost agent sent before it went is handled first,
        # and agents lost together (one process) are named together.
        if not lost or now - min(at for at, _ in lost.values()) <= LOST_GRACE:
            return None
        agents = sorted(lost)
        names = f'agent {agents[0]}' if len(agents) == 1 else f'agents {", ".join(map(str, agents))}'
        hows = '; '.join(sorted({how for _, how in lost.values()}))
        return AgentLostError(f'{names} lost {where}: {hows}; the run stops', agents=agents)

    # -- lock-step --------------------------------------------------------------------------------

    def settled(self, step_index: int, due: set[int]) -> bool:
        """Every message of the step has been delivered and every agent has answered it
        (docs/MESSAGES.md, the lock-step protocol, step 5)."""
        sent = received = 0
        for i, book in self.agents.items():
            status = book.status
            if status is None or not status.ready or status.triggers != book.expected_triggers:
                return False
            if i in due and status.step_index != step_index:
                return False
            if status.commands_sent != book.commands_received:
                return False
            sent += status.info_sent
            received += status.info_received
        if received > sent:
            raise CoordinatorError(f'agents report {received} messages received but only {sent} sent')
        return sent == received

    def next_due(self, t: float) -> tuple[float, tuple[int, ...]]:
        """The smallest next triggering time reported and the agents that reported exactly it."""
        t_next = min(book.status.next_time for book in self.agents.values())
        if t_next < t:
            laggards = [i for i, book in self.agents.items() if book.status.next_time < t]
            raise CoordinatorError(
                f'agents {laggards} ask to trigger at t={t_next!r}, before the current t={t!r}'
            )
        return t_next, tuple(sorted(i for i, book in self.agents.items() if book.status.next_time == t_next))

    def mark_due(self, due, t: float) -> None:
        for i in due:
            self.agents[i].expected_triggers += 1
            self.agents[i].trigger_times.append(t)

    def waiting_description(self) -> str:
        return '; '.join(
            f'agent {i}: status {book.status}, expected triggers '
            f'{book.expected_triggers}, commands received {book.commands_received}'
            for i, book in self.agents.items()
        )

    # -- the world as seen ------------------------------------------------------------------------

    def check_connectivity(self, t: float, x: np.ndarray) -> None:
        """Theorems 1 (i) and 2 (i): every edge stays shorter than Δ. Stop at the first that does not."""
        rows_i, rows_j = self._edge_rows
        lengths = np.linalg.norm(x[rows_i] - x[rows_j], axis=1)
        worst = int(np.argmax(lengths))
        if lengths[worst] < self.scenario.delta:
            return
        edge = self.scenario.edges[worst]
        # After t = 0, an agent not ready never heard from some neighbour: its information was
        # lost (it triggers only at events, so nothing repeats it), and the agent waits.
        waiting = [
            i
            for i, book in self.agents.items()
            if book.status is not None and book.status.step_index >= 0 and not book.status.ready
        ]
        hint = (
            f"; agents {waiting} are still waiting for a neighbour's triggering information (lost?)"
            if waiting
            else ''
        )
        raise ConnectivityLostError(
            f'edge ({edge.i}, {edge.j}) reached the communication radius at t={t!r}: '
            f'||x_{edge.i} - x_{edge.j}|| = {lengths[worst]:.6g} >= Δ = {self.scenario.delta:g}{hint}',
            time=t,
            edge=(edge.i, edge.j),
            length=float(lengths[worst]),
        )

    # -- summary.json -----------------------------------------------------------------------------

    def information_sent(self, agent: int) -> int:
        """Triggering-information messages `agent` published: as its final report counts them, else
        as its latest Status does.  A Status lags when a run stops between an agent's trigger and
        the news of its due neighbours, which it waits for before reporting (one message per
        neighbour fewer than the bag holds, seen after SIGINT); a final report never does."""
        book = self.agents[agent]
        if book.report is not None and book.report.final:
            return sum(book.report.published.get(trigger_info_topic(agent, j), 0) for j in book.neighbours)
        return book.status.info_sent if book.status is not None else 0

    def published(self, own: dict[str, int]) -> dict[str, int]:
        """Messages published per topic by the coordinator (`own`) and by every agent whose final
        report came (the others' are unknown: reports_missing), from step 0 on: what a recorder
        must hold (`extra.published`, checked against the bag by the orchestrator)."""
        counts = dict(own)
        for book in self.agents.values():
            if book.report is not None and book.report.final:
                for topic, n in book.report.published.items():
                    counts[topic] = counts.get(topic, 0) + n
        return dict(sorted(counts.items()))

    def message_counts(self) -> dict:
        """Rejected messages per reason and agent, and faults injected, from the agents' reports."""
        books = self.agents.values()
        by_agent = {
            str(i): dict(book.report.rejected)
            for i, book in self.agents.items()
            if book.report and book.report.rejected
        }
        by_reason: dict[str, int] = {}
        for counts in (*by_agent.values(), self.rejected):
            for reason, n in counts.items():
                by_reason[reason] = by_reason.get(reason, 0) + n
        reports = [book.report for book in books if book.report is not None]
        return {
            'rejected_messages': {
                'total': sum(by_reason.values()),
                'by_reason': dict(sorted(by_reason.items())),
                'by_agent': by_agent,
                'simulator': dict(self.rejected),
            },
            # Refused for their tag (formation_msgs_py.tags): without one, or not the run's key's.
            'foreign_messages': sum(by_reason.get(reason, 0) for reason in FOREIGN_REASONS),
            'injected_faults': {
                'dropped': sum(r.dropped for r in reports),
                'delayed': sum(r.delayed for r in reports),
                'by_agent': {
                    str(r.agent): {'dropped': r.dropped, 'delayed': r.delayed}
                    for r in reports
                    if r.dropped or r.delayed
                },
            },
            'late_information': sum(r.late for r in reports),
            'reports_missing': sorted(
                i for i, book in self.agents.items() if book.report is None or not book.report.final
            ),
        }

    def saturation(self) -> dict:
        """`extra.saturation` from the agents' latest reports."""
        return saturation_extra(book.report for book in self.agents.values())

    def lateness(self, trigger_times: dict[int, list[float]]) -> dict:
        """Wall clock: how late triggers came against the times agents had planned them."""
        return lateness_extra({i: book.planned for i, book in self.agents.items()}, trigger_times)


class RunMarks:
    """When a time keeper reached each mark of its run, on the monotonic clock (summary.json's
    extra.timestamps): node_created, node_up (its endpoints exist), agents_announced (every
    agent's first discovery Status), agents_ready (every agent connected), step0, final_step,
    final_reports (every agent's final report in, or the wait for them over), delivered (what
    the keeper published acknowledged).  Every time is given: the book reads no clock."""

    def __init__(self, *, created: float) -> None:
        self.created = created
        self.started: float | None = None  # step 0 went out
        self.finished_at: float | None = None  # the final Step went out
        self._marks: dict[str, float] = {'node_created': created}

    def mark(self, name: str, now: float, *, once: bool = False) -> None:
        """The run reached `name` at `now` (`once`: only the first time counts)."""
        if not (once and name in self._marks):
            self._marks[name] = now

    def start(self, now: float) -> None:
        """Step 0 went out at `now`."""
        self.started = self._marks['step0'] = now

    def finish(self, now: float) -> None:
        """The final Step went out at `now` (the first time only)."""
        if self.finished_at is None:
            self.finished_at = now

    def since_start(self, now: float) -> float:
        """Wall time from step 0 (before it: from the node's creation) to `now`."""
        return now - (self.created if self.started is None else self.started)

    @property
    def discovery_wall_time(self) -> float:
        """From the node's creation to step 0 (0 for a run that did not start)."""
        return 0.0 if self.started is None else self.started - self.created

    def timestamps(self, *, offset: float) -> dict[str, float]:
        """Every mark reached, final_step included once sent, plus `offset` (time.time() minus
        time.monotonic(): Unix times)."""
        marks = dict(self._marks)
        if self.finished_at is not None:
            marks['final_step'] = self.finished_at
        return {name: at + offset for name, at in marks.items()}


class RecorderBook:
    """What the coordinator knows of the recorders (the run's extra subscribers): whether their
    heartbeat writers are alive, and the latest step each has written (lock-step flow control).

    A frozen recorder lets every reliable keep-last writer of the run overwrite what it did not
    acknowledge, so a recorder lost stops the run as an agent lost does."""

    def __init__(self) -> None:
        self.alive = 0  # heartbeat writers alive (DDS liveliness)
        self.recorded_steps: dict[str, int] = {}  # recorder node -> the latest step it recorded
        self.silent: dict[str, list[str]] = {}  # recorder node -> its watched topics with no message yet
        self.lost: tuple[float, str] | None = None  # (monotonic time, how) once one went away
        self.lease_expired = False  # how it went: its lease expired (else its writer was deleted)

    def note_liveliness(self, *, alive_count: int, not_alive_count_change: int, now: float) -> None:
        """A liveliness change of the recorders' heartbeat writers."""
        if alive_count >= self.alive:
            self.alive = alive_count
            self.lost = None
        elif self.lost is None:  # also after the end: no more waiting for its acknowledgements
            self.lease_expired = not_alive_count_change > 0
            how = (
                f'no sign of life for {LIVELINESS_LEASE} s (DDS liveliness lease: stopped or frozen?)'
                if self.lease_expired
                else 'it left the graph'
            )
            self.lost = (now, how)

    def accept_heartbeat(self, text: str) -> str | None:
        """Take a recorder's heartbeat (JSON: version 1, recorder, step[, silent]); the reason it is
        refused, or None."""
        try:
            beat = json.loads(text)
            name, step = str(beat['recorder']), beat['step']
            silent = beat.get('silent', [])
            if beat.get('version') != 1 or isinstance(step, bool) or not isinstance(step, int):
                raise ValueError(f'version {beat.get("version")!r}, step {step!r}')
            if not isinstance(silent, list) or not all(isinstance(topic, str) for topic in silent):
                raise ValueError(f'silent {silent!r}')
        except (ValueError, KeyError, TypeError) as error:
            return f'recorder heartbeat {text[:80]!r}: {error}'
        self.recorded_steps[name] = max(step, self.recorded_steps.get(name, -1))
        self.silent[name] = silent
        return None

    def behind(self, step: int, *, recorders: int, lag: int) -> bool:
        """Whether more than `lag` steps before `step` are not yet in the bag of one of the
        `recorders` the run has (lock-step waits for it; its heartbeat says which step it wrote)."""
        if recorders < 1:
            return False
        recorded = sorted(self.recorded_steps.values())[:recorders]
        return len(recorded) < recorders or recorded[0] < step - lag

    def lost_error(self, now: float, *, started: bool, where: str) -> RecorderLostError | None:
        """The recorder lost, once LOST_GRACE has passed (else None); during discovery a lease that
        expired waits for the recorder to come back, as an agent's does (`RunBook.lost_error`)."""
        lost = self.lost
        if lost is None or (not started and self.lease_expired) or now - lost[0] <= LOST_GRACE:
            return None
        return RecorderLostError(
            f'the recorder lost {where}: {lost[1]}; what it did '
            'not acknowledge is overwritten, so the run stops'
        )


ALL_SILENT_AFTER = 1.0  # [s] beyond the silence: every robot silent at once (or the coordinator starved)


class PoseWatch:
    """When each robot's latest pose arrived (robot runs): a robot whose poses stop while the
    others' still come is lost; its agents' poses of it go stale `silence` s later too.

    A robot's silence is measured against the newest pose of any robot, not against the clock:
    a coordinator that was not scheduled for a while (a loaded machine) finds every robot's
    poses waiting in its readers, and must not call them lost.  Every robot silent together for
    `silence` + ALL_SILENT_AFTER counts as lost too (every driver gone)."""

    def __init__(self, robots, *, silence: float) -> None:
        self.silence = silence
        self.heard: dict[int, float | None] = dict.fromkeys(
            robots
        )  # robot -> monotonic time of its latest pose
        self.stamps: dict[int, float] = {}  # robot -> run time of its latest pose

    def note(self, robot: int, *, now: float, t: float) -> None:
        self.heard[robot] = now
        self.stamps[robot] = t

    def silent(self, now: float, *, fraction: float = 1.0) -> list[int]:
        """Robots whose poses stopped `fraction` × the silence ago while others' came (or all)."""
        heard = {i: at for i, at in self.heard.items() if at is not None}
        if not heard:
            return []
        newest = max(heard.values())
        limit = fraction * self.silence
        if now - newest > limit + ALL_SILENT_AFTER:
            return sorted(heard)
        return sorted(i for i, at in heard.items() if newest - at > limit)

    def error(self, robots: list[int], *, now: float, where: str, topics: str) -> RobotLostError:
        """The robots lost, named with their last pose's time and how long they have been silent."""
        newest = max(now, *(at for at in self.heard.values() if at is not None))
        last = ', '.join(
            f'robot {i} at t={self.stamps.get(i, math.nan):.3f} ({newest - self.heard[i]:.2f} s before)'
            for i in robots
        )
        names = f'robot {robots[0]}' if len(robots) == 1 else f'robots {ids_text(robots)}'
        others = (
            'every robot at once'
            if len(robots) == len(self.heard)
            else 'while the other robots still published'
        )
        return RobotLostError(
            f'{names} lost {where}: no pose on {topics} for more than {self.silence:g} s, {others} '
            f'(last poses: {last}); the run stops',
            agents=robots,
        )
