"""An agent node's peers: discovery (what it still waits for before step 0, its announcements)
and the simulator's signs of life.

Until step 0 the agent looks at its endpoints every DISCOVERY_CHECK seconds and announces its
readiness in a Status of step −1 (docs/MESSAGES.md, "Discovery"); from then on `SimulatorWatch`
tells when the simulator or coordinator is lost (docs/MESSAGES.md, "Lost peers").
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator

from formation_msgs_py.lockstep import DISCOVERY_STEP
from formation_msgs_py.middleware import KEEPER_LEASE_GRACE, LIVELINESS_LEASE, LOST_GRACE
from formation_msgs_py.topics import STEP_TOPIC, trigger_info_topic

DISCOVERY_CHECK = 0.1
"""Seconds between an agent's looks at its endpoints during discovery: it announces its Status
(step −1) when its readiness changes, not every look (reliable, transient local: a simulator that
matches later still gets the latest), and once ready again every DISCOVERY_REANNOUNCE seconds
until step 0: a sign of life for a simulator that saw its liveliness lease lapse meanwhile (a
machine starting 1000 agents is slow to assert it)."""

DISCOVERY_REANNOUNCE = 1.0

DISCOVERY_LOG_AFTER = 2.0
DISCOVERY_LOG_PERIOD = 5.0
"""An agent not yet connected says what it waits for after DISCOVERY_LOG_AFTER seconds, then
every DISCOVERY_LOG_PERIOD seconds."""


class Discovery:
    """The discovery of one agent node (`node`: a FormationAgentNode), until its step 0."""

    def __init__(self, node) -> None:
        self._node = node
        self._created = time.monotonic()
        self._announced: bool | None = None  # the readiness of the last discovery Status
        self._next_announcement = 0.0
        self._next_log = self._created + DISCOVERY_LOG_AFTER
        self._timer = node.create_timer(DISCOVERY_CHECK, self._announce)

    def close(self) -> None:
        """Step 0 has come: no more looks."""
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None

    def gaps(self) -> Iterator[str]:
        """What discovery still waits for, one at a time (`connected` stops at the first: with
        many agents in one process, every look at a match count costs)."""
        node = self._node
        extra = node.config.extra_subscribers
        listeners = 1 + extra
        others = ['a recorder'] if extra == 1 else [f'{extra} listeners'] if extra else []

        def readers(publisher, peer: str) -> Iterator[str]:
            have = publisher.get_subscription_count()
            if have < listeners:
                who = ', '.join([peer, *others])
                yield f'readers of {publisher.topic_name}: {have} of {listeners} ({who})'

        for j, publisher in node.info_publishers.items():
            yield from readers(publisher, f'agent {j}')
        for j, subscription in zip(node.neighbour_ids, node.info_subscriptions):
            if subscription.get_publisher_count() < 1:
                yield f'a writer of {trigger_info_topic(j, node.agent_id)} (agent {j})'
        yield from readers(
            node.output.publisher, 'the robot' if node.config.robot != 'none' else 'the simulator'
        )
        yield from readers(node.status_publisher, 'the simulator or coordinator')
        yield from readers(node.report_publisher, 'the simulator or coordinator')
        if node.step_subscription.get_publisher_count() < 1:
            yield f'a writer of {STEP_TOPIC} (the simulator or coordinator)'
        # Last: whether a service is there is looked up in the whole ROS graph (rmw_fastrtps
        # walks every endpoint it knows), where a match count is one number.
        yield from node.sensing.gaps()

    def _announce(self) -> None:
        """A Status (step −1) whenever the agent's readiness changes and every
        DISCOVERY_REANNOUNCE seconds once ready, and now and then a log line saying what it still
        waits for."""
        node = self._node
        if node.step is not None:
            return
        now = time.monotonic()
        logging = now >= self._next_log
        gaps = list(self.gaps()) if logging else list(itertools.islice(self.gaps(), 1))
        ready = not gaps
        changed = ready != self._announced
        if changed or (ready and now >= self._next_announcement):
            self._announced = ready
            self._next_announcement = now + DISCOVERY_REANNOUNCE
            node.publish_status(step_index=DISCOVERY_STEP, ready=ready)
            if ready and changed:
                node.get_logger().info(
                    f'agent {node.agent_id}: every endpoint matched {time.monotonic() - self._created:.1f} s '
                    'after the node started; waiting for step 0'
                )
        if gaps and logging:
            self._next_log = now + DISCOVERY_LOG_PERIOD
            node.get_logger().info(
                f'agent {node.agent_id}: discovery for {now - self._created:.0f} s, still waiting for: '
                + '; '.join(gaps)
            )


class SimulatorWatch:
    """The simulator's (or coordinator's) signs of life: the liveliness of its Step writer.

    A writer that left the graph, or whose liveliness lease lapsed, is lost after a grace
    (docs/MESSAGES.md, "Lost peers"); `lost` says so, or None.
    """

    def __init__(self, agent_id: int) -> None:
        self.agent_id = agent_id
        self.seen = False
        self.lost_at: float | None = None  # time.monotonic() when its writer was last seen alive
        self.lease_expired = False

    def on_liveliness(self, info) -> None:
        if info.alive_count > 0:
            self.seen = True
            self.lost_at = None
        elif self.seen and self.lost_at is None:
            self.lost_at = time.monotonic()
            self.lease_expired = info.not_alive_count_change > 0  # else: writer deleted

    def lost(self, step, *, finished: bool) -> str | None:
        """Why the simulator counts as lost now (after its grace), or None."""
        if self.lost_at is None or finished:
            return None
        # During discovery a lease may expire on a machine busy starting many processes: keep
        # waiting for step 0 (a simulator that left deletes its writer, which does count).
        if step is None and self.lease_expired:
            return None
        lockstep = step is not None and not step.realtime
        grace = KEEPER_LEASE_GRACE if lockstep and self.lease_expired else LOST_GRACE
        if time.monotonic() - self.lost_at <= grace:
            return None
        where = 'during discovery' if step is None else f'after step {step.index} (t={step.time!r})'
        how = (
            f'no sign of life for {LIVELINESS_LEASE} s (liveliness lease)'
            if self.lease_expired
            else 'it left the graph'
        )
        return f'agent {self.agent_id}: the simulator (writer of {STEP_TOPIC}) is lost {where}: {how}'
