"""The run's emergency stop: `OperatorStop`, the time keeper's `/formation/stop` service.

Issue 27: a robot team could only be stopped by Ctrl-C in the terminal that started the run.  The
time keeper of every run (the coordinator of a robot run, the simulator of the exact world) serves
`formation_msgs_py.topics.STOP_SERVICE` (std_srvs/srv/Trigger) on the run's domain; `formation
stop`, `ros2 service call /formation/stop std_srvs/srv/Trigger` or any Trigger client from any
terminal or machine that reaches the domain calls it (docs/EMERGENCY_STOP.md).  On the first call:

- after step 0, the final Step goes out at once (`TimeKeeperNode.end_now`): every agent sends its
  robot its zero command and leaves, as at the horizon; and the coordinator sends every robot its
  zero itself, beside it (`robot_stops.RobotStops.stop_all`), so that a robot stops even when its
  agent is slow;
- before step 0, no Step 0 ever goes (`TimeKeeperNode._start` looks): no robot moves; the robots
  are sent a zero all the same;
- the run then ends as any run stopped early (`keeper_main.main`: the final reports, the samples
  up to the stop, summary.json), with `extra.failure.kind = stopped_by_operator` naming who asked
  when the graph tells (the nodes outside the run with a client of the service), and exit status
  `formation_msgs_py.exit_codes.ExitCode.STOPPED`.

The answer says what happens; a later call answers that the run is already stopping.  Who asked is
looked up after the stop went out, so that the lookup never delays it.
"""

from __future__ import annotations

import time

from rclpy.node import NodeNameNonExistentError
from std_srvs.srv import Trigger

from formation_msgs_py.topics import COORDINATOR_NODE, RECORDER_NODE, SIMULATOR_NODE, STOP_SERVICE
from formation_sim.runtime.errors import OperatorStopError

RUN_NODES = (SIMULATOR_NODE, COORDINATOR_NODE, RECORDER_NODE)  # a run's own nodes in the root namespace
UNKNOWN_CALLER = 'an operator'
# [s] The graph learns a caller's node name (Fast DDS: ros_discovery_info) apart from its request;
# on a loaded machine it came after the request (1 lock-step test of 2).  Looked for this long, this
# often, once the stop is out; a caller the graph never shows (another machine's ros2 service
# call, say) costs its answer this long.
CALLER_WAIT = 0.5
CALLER_LOOK = 0.05


class OperatorStop:
    """The emergency-stop service of the time keeper `node` (a `time_keeper.TimeKeeperNode`)."""

    def __init__(self, node) -> None:
        self._node = node
        self.asked: dict | None = None  # once called: {'time', 'step', 'wall_time', 'by'}
        self.service = node.create_service(Trigger, STOP_SERVICE, self._on_request)

    @property
    def requested(self) -> bool:
        return self.asked is not None

    def _on_request(self, request, response):
        response.success, response.message = self.stop()
        return response

    def stop(self) -> tuple[bool, str]:
        """Stop the run now (the first call): (success, what happens)."""
        node = self._node
        if self.asked is not None:
            return True, f'the run is already stopping (asked by {self.asked["by"]} {self._when(self.asked)})'
        if node.finished:  # at its horizon, or stopped on a failure: the final Step is out already
            robots = node.world.stop_robots(why='an operator asked to stop the run after its end')
            ended = f'the run already ended at t={node.reached_time!r} (its final Step is out)'
            return True, ended + _robots_text(robots, again=True)
        started = node.step is not None
        if started:
            node.end_now()  # the final Step first: the agents send their zero commands and leave
        robots = node.world.stop_robots(why='an operator stopped the run')
        self.asked = {
            'time': node.reached_time,
            'step': node.step.index if started else None,  # the step it stopped in (the final one is next)
            'wall_time': time.time(),
            'by': UNKNOWN_CALLER,
        }
        callers = self.callers()  # after the stop went out: the graph walk may take a while
        looked = time.monotonic()
        while not callers and time.monotonic() - looked < CALLER_WAIT:  # its node's name on its way
            time.sleep(CALLER_LOOK)
            callers = self.callers()
        self.asked['by'] = ', '.join(callers) if callers else UNKNOWN_CALLER
        error = OperatorStopError(
            f'stopped by {self.asked["by"]} {self._when(self.asked)} (the emergency stop, {STOP_SERVICE})',
            asked_by=callers,
        )
        node.fail(error)
        node.failure = error
        if started:
            what = f'stopping the run {self._when(self.asked)}'
        else:
            what = 'stopping the run before it started (no Step 0: no robot has moved)'
        return True, what + _robots_text(robots, again=False)

    @staticmethod
    def _when(asked: dict) -> str:
        if asked['step'] is None:
            return 'before step 0'
        return f'at t={asked["time"]!r} (step {asked["step"]})'

    def callers(self) -> list[str]:
        """The nodes outside the run with a client of the stop service (the run's own have none):
        who asked, if the graph shows one; sorted full names."""
        node = self._node
        found = []
        for name, namespace in node.get_node_names_and_namespaces():
            if namespace.startswith('/agent_') or (namespace == '/' and name in RUN_NODES):
                continue
            try:
                clients = node.get_client_names_and_types_by_node(name, namespace)
            except NodeNameNonExistentError:  # it left meanwhile
                clients = []
            if any(service == STOP_SERVICE for service, _ in clients):
                found.append(f'{namespace.rstrip("/")}/{name}')
        return sorted(found)


def _robots_text(robots: list[int], *, again: bool) -> str:
    """What the answer says of the robots (none: the simulator's exact world, stopped with the run)."""
    if not robots:
        return ': the final Step is out, every agent stops and leaves'
    return f': every robot is sent a zero command{" again" if again else ""} ({len(robots)} robots)'
