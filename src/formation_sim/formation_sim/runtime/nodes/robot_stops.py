"""The coordinator's zero commands: a robot whose agent did not stop it is stopped from here.

An agent stops its robot itself on every way out it lives to take (the final Step, a fault, a
signal: `formation_agent.ros.commands.publish_zero`) and then sends its final report.  An agent
that is gone (SIGKILL, a crash, OOM) sends neither, and its robot would drive on under its last
command until its own command timeout, if it has one.  So after the final Step the coordinator
waits `run_end.UNREPORTED_STOP_AFTER` s for the final reports (`run_end.collect_final_reports`), and sends
the robot of every agent that has not reported the same zero command, through a writer of its
own on the robot's command topic, made when the run is set up (matched by then: no discovery
when it is needed).  It sends only zeros, and only after the run's final Step: a live agent
sends no other command after that Step either.

An operator's emergency stop (`operator_stop.OperatorStop`) does not wait: every robot gets its
zero from here at once, beside the final Step (`stop_all`), so that a robot stops within the
bound even when its agent is slow; a robot whose agent then sends no final report within
`UNREPORTED_STOP_AFTER` gets its zero again as above (a slow agent may have sent one more
command of its own before it took the final Step).
"""

from __future__ import annotations

from collections.abc import Sequence

from formation_agent.core.kinds import robot_kind
from formation_agent.ros.commands import command_message, publish_zero
from formation_msgs_py.qos import ROBOT_COMMAND_QOS
from formation_msgs_py.topics import robot_command_topic


class RobotStops:
    """A zero-command writer per robot (`stop` sends each robot its zero once)."""

    def __init__(self, node, *, model: str, robots: Sequence[int], dimension: int, world_frame: str) -> None:
        self._node = node
        self._kind = robot_kind(model)
        self._dimension = dimension
        self._world_frame = world_frame  # a holonomic robot's TwistStamped frame_id, as its agent's
        message = command_message(self._kind)
        self._publishers = {
            i: node.create_publisher(message, robot_command_topic(i), ROBOT_COMMAND_QOS) for i in robots
        }
        self.stopped: list[int] = []  # robots sent their zero from here, in order
        self.sent_all: list[int] = []  # every robot, once `stop_all` sent them their zero

    def stop(self, robots: Sequence[int], *, why: str) -> list[int]:
        """Send each of `robots` not yet stopped from here its zero command; those it sent to."""
        new = [i for i in robots if i in self._publishers and i not in self.stopped]
        for i in new:
            publish_zero(
                self._publishers[i], self._kind, dimension=self._dimension, world_frame=self._world_frame
            )
        if new:
            self.stopped += new
            self._node.get_logger().warning(
                f'robots {new}: {why}: the coordinator sent them the zero command'
            )
        return new

    def stop_all(self, *, why: str) -> list[int]:
        """Every robot its zero command now, whatever was sent before (an operator's stop): the
        robots, in order.  Not noted in `stopped`, so that `stop` sends a robot whose agent does
        not report its zero once more."""
        for publisher in self._publishers.values():
            publish_zero(publisher, self._kind, dimension=self._dimension, world_frame=self._world_frame)
        self.sent_all = list(self._publishers)
        self._node.get_logger().warning(f'{why}: the coordinator sent every robot the zero command')
        return self.sent_all

    def extra(self) -> dict:
        """summary.json's `extra.robots_stopped_here`: the robots stopped from here (none: absent)."""
        return {'robots_stopped_here': list(self.stopped)} if self.stopped else {}
