"""The errors of the distributed runtime: every way a run can stop early is a `CoordinatorError`
whose `kind` becomes `extra.failure.kind` in summary.json; the orchestrator's, the recorder's,
replay's and graph inspection's. Each is a `FormationError`.
"""

from __future__ import annotations

from formation_msgs_py.errors import FormationError
from formation_sim.bag.errors import BagError


class InspectError(FormationError, ValueError):
    """A topic that does not exist or whose type cannot be imported."""


class RunError(FormationError, RuntimeError):
    """The run could not be set up (bad arguments, no free ROS domain, existing output)."""


class RecorderError(BagError):
    """The recorder could not be set up or could not write its bag."""


class ReplayError(FormationError, ValueError):
    """Bad replay arguments, an unreadable bag, or subscribers that never came."""


class CoordinatorError(FormationError, RuntimeError):
    """The distributed run cannot go on: a protocol violation, a stall, or a dead peer."""

    kind = 'protocol'  # extra.failure.kind in summary.json


class ForeignWriterError(CoordinatorError):
    """A node outside the run writes a topic that moves a robot or the world."""

    kind = 'foreign_writer'

    def __init__(self, message: str, *, nodes: list[str], agents: list[int]) -> None:
        super().__init__(message)
        self.nodes = nodes
        self.agents = agents


class DuplicateAgentError(ForeignWriterError):
    """Two processes claim the same agent."""

    kind = 'duplicate_agent'


class ForeignInformationError(ForeignWriterError):
    """On the wall clock the agents took more triggering information than they sent: forged
    information, well formed and plausible, was taken as a neighbour's (no tag can tell it yet)."""

    kind = 'foreign_information'


class KeeperFrozenError(CoordinatorError):
    """The time keeper itself was frozen or starved: what it then saw lost followed from that."""

    kind = 'keeper_frozen'


class StallError(CoordinatorError):
    """No step settled within the stall timeout."""

    kind = 'stall'


class DiscoveryError(CoordinatorError):
    """The agents did not all connect within the discovery timeout."""

    kind = 'discovery'


class ConnectivityLostError(CoordinatorError):
    """An edge of the graph reached the communication radius Δ in the true world."""

    kind = 'connectivity_lost'

    def __init__(self, message: str, *, time: float, edge: tuple[int, int], length: float) -> None:
        super().__init__(message)
        self.time = time
        self.edge = edge
        self.length = length


class InitialConditionError(CoordinatorError):
    """The robots' measured start breaks the initial condition (initial) on an edge: the run does
    not start (no Step 0, no command)."""

    kind = 'initial_condition'

    def __init__(self, message: str, *, agents: list[int], breaches: list[dict[str, object]]) -> None:
        super().__init__(message)
        self.agents = agents
        self.breaches = breaches


class RecorderLostError(CoordinatorError):
    """A recorder stopped showing signs of life (or left) before the end of the run."""

    kind = 'recorder_lost'


class AgentLostError(CoordinatorError):
    """One or more agents stopped showing signs of life (or left) before the end of the run."""

    kind = 'agent_lost'

    def __init__(self, message: str, *, agents: list[int]) -> None:
        super().__init__(message)
        self.agents = agents


class RobotLostError(CoordinatorError):
    """A robot's poses stopped coming (its process or driver died, froze, or lost the network)
    while the other robots' still came: the run stops at once, every agent with it."""

    kind = 'robot_lost'

    def __init__(self, message: str, *, agents: list[int]) -> None:
        super().__init__(message)
        self.agents = agents


class AgentFailedError(CoordinatorError):
    """An agent stopped on an error it named (its final report's `failure`): the run stops at once."""

    kind = 'agent_failed'

    def __init__(self, message: str, *, agents: list[int]) -> None:
        super().__init__(message)
        self.agents = agents


class OperatorStopError(CoordinatorError):
    """An operator called the run's emergency stop (`topics.STOP_SERVICE`, `formation stop`): the
    run ends at once, every robot sent a zero command (`operator_stop.OperatorStop`)."""

    kind = 'stopped_by_operator'

    def __init__(self, message: str, *, asked_by: list[str]) -> None:
        super().__init__(message)
        self.asked_by = asked_by
