"""What an agent node publishes to the run besides commands: triggering information, Status and
AgentReport, each counted (`formation_agent.ros.reporting.AgentCounts`), and their delivery
before the node goes away.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

from rclpy.duration import Duration
from std_msgs.msg import Float64MultiArray, String

from formation_agent.ros.reporting import AgentCounts
from formation_msgs_py.codec import encode_agent_report, encode_status, tag_array, tag_string
from formation_msgs_py.lockstep import AgentReport, Status
from formation_msgs_py.qos import PROTOCOL_QOS
from formation_msgs_py.tags import Signer
from formation_msgs_py.topics import REPORT_TOPIC, STATUS_TOPIC, trigger_info_topic


class Outbox:
    """The agent's writers of triggering information (one per neighbour), Status and report."""

    def __init__(self, node, counts: AgentCounts, neighbour_ids, *, signer: Signer | None = None) -> None:
        self._node = node
        self.counts = counts
        self._signer = signer  # the run's tag (formation_msgs_py.tags); None: untagged
        self.info = {
            j: node.create_publisher(Float64MultiArray, f'trigger_info/to_{j}', PROTOCOL_QOS)
            for j in neighbour_ids
        }
        self.status = node.create_publisher(Float64MultiArray, STATUS_TOPIC, PROTOCOL_QOS)
        self.report = node.create_publisher(String, REPORT_TOPIC, PROTOCOL_QOS)

    def publish(self, publisher, msg) -> None:
        self._count(publisher)
        publisher.publish(msg)

    def _count(self, publisher) -> None:
        """Count what a recorder must hold: everything from step 0 on, when it is matched for sure
        (the simulator starts step 0 only once every agent has matched all its listeners)."""
        self.counts.count_published(publisher.topic_name, started=self._node.step is not None)

    def publish_info(self, receiver: int, msg) -> None:
        """Triggering information for `receiver`, tagged for its topic's name in the run."""
        topic = trigger_info_topic(self._node.agent_id, receiver)
        self.publish(self.info[receiver], tag_array(msg, self._signer, topic))

    def publish_status(self, status: Status) -> None:
        self.publish(self.status, tag_array(encode_status(status), self._signer, STATUS_TOPIC))

    def publish_report(self, report: AgentReport) -> None:
        self.counts.report_due = False
        self.counts.final_sent = report.final
        self._count(self.report)  # a report counts itself (it was built before this count)
        if (counted := self.counts.published.get(REPORT_TOPIC)) is not None:
            report = dataclasses.replace(report, published={**report.published, REPORT_TOPIC: counted})
        self.report.publish(tag_string(encode_agent_report(report), self._signer, REPORT_TOPIC))

    def wait_for_delivery(self, deadline: float | Callable[[], float], *others) -> None:
        """Let reliable writers hand over what they still hold before the node goes away (until
        `deadline`, time.monotonic(); a callable is asked again between waits, so that a stop
        signal can bring it forward: a dead reader never acknowledges)."""
        limit = deadline if callable(deadline) else lambda: deadline
        pending = [self.status, self.report, *others, *self.info.values()]
        while pending and time.monotonic() < limit():
            pending = [pub for pub in pending if not pub.wait_for_all_acked(Duration(seconds=0.05))]
