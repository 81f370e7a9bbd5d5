"""The agent's outbox: delivery before the node goes away, bounded by a deadline that may move."""

from __future__ import annotations

import time

from formation_agent.ros.outbox import Outbox
from formation_agent.ros.reporting import AgentCounts


class _Unacknowledged:
    """A writer one of whose readers is dead: never all acknowledged."""

    topic_name = '/x'

    def __init__(self) -> None:
        self.waits = 0

    def wait_for_all_acked(self, timeout) -> bool:
        self.waits += 1
        time.sleep(0.001)
        return False


class _Node:
    step = None

    def create_publisher(self, msg_type, topic, qos):
        return _Unacknowledged()


def test_the_wait_for_acknowledgements_ends_when_a_moving_deadline_passes() -> None:
    outbox = Outbox(_Node(), AgentCounts(agent_id=1), neighbour_ids=(2, 3))
    began = time.monotonic()
    moved = [began + 60.0]

    def deadline() -> float:
        if outbox.status.waits >= 5:  # a stop signal came: the deadline is now
            moved[0] = began
        return moved[0]

    outbox.wait_for_delivery(deadline)
    assert outbox.status.waits == 5 and time.monotonic() - began < 30.0


def test_a_fixed_deadline_bounds_the_wait() -> None:
    outbox = Outbox(_Node(), AgentCounts(agent_id=1), neighbour_ids=(2,))
    outbox.wait_for_delivery(time.monotonic() + 0.05)
    assert outbox.status.waits >= 1 and outbox.info[2].waits == outbox.status.waits
