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

A zero sent from here is resent until every reader acknowledged it (the robot's driver, the
recorder): the coordinator waits for that after the final reports (`unacknowledged`, in
`coordinator.RobotWorld.after_final_step`), within the bound of its wait for the robots' last
poses, `robots.POSES_AFTER_END` = 1 s.  A datagram lost on the way (a UDP receive buffer full on a
loaded machine) is repaired only at the writer's next heartbeat (every 0.1 s,
fastdds_profile.xml), so never once the coordinator has left: before this wait it left as soon
as 0.4 ms after its last zero (a killed agent's test under load, 2026-12-06).  The bound is ten
heartbeat periods; it is reached only by a reader that never answers (a robot that died: its
reader stays matched until its participant's lease lapses).
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.duration import Duration

from formation_agent.core.kinds import robot_kind
from formation_agent.ros.commands import command_message, publish_zero
from formation_msgs_py.qos import ROBOT_COMMAND_QOS
from formation_msgs_py.topics import robot_command_topic

NO_WAIT = Duration(seconds=0)  # `wait_for_all_acked` as a look: acknowledged now or not


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
        self._acknowledged: set[int] = set()  # robots whose every reader has acknowledged their zeros

    def stop(self, robots: Sequence[int], *, why: str) -> list[int]:
        """Send each of `robots` not yet stopped from here its zero command; those it sent to."""
        new = [i for i in robots if i in self._publishers and i not in self.stopped]
        for i in new:
            publish_zero(
                self._publishers[i], self._kind, dimension=self._dimension, world_frame=self._world_frame
            )
        if new:
            self.stopped += new
            self._acknowledged -= set(new)
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
        self._acknowledged.clear()
        self._node.get_logger().warning(f'{why}: the coordinator sent every robot the zero command')
        return self.sent_all

    def unacknowledged(self) -> list[int]:
        """The robots sent a zero from here that some reader of theirs (the robot, the recorder)
        has not acknowledged yet, in order: a look, no wait.  None sent: none."""
        sent = dict.fromkeys([*self.sent_all, *self.stopped])
        for i in sent:
            if i not in self._acknowledged and self._publishers[i].wait_for_all_acked(NO_WAIT):
                self._acknowledged.add(i)
        return [i for i in sent if i not in self._acknowledged]

    def note_unacknowledged(self, *, within: float) -> list[int]:
        """After the wait for them (`within` s): the robots whose zero some reader has still not
        acknowledged, logged (a reader gone: a robot that died); the robots."""
        late = self.unacknowledged()
        if late:
            self._node.get_logger().warning(
                f'robots {late}: their zero command from the coordinator was not acknowledged by every '
                f'reader within {within:g} s'
            )
        return late

    def extra(self) -> dict:
        """summary.json's `extra.robots_stopped_here`: the robots stopped from here (none: absent)."""
        return {'robots_stopped_here': list(self.stopped)} if self.stopped else {}
