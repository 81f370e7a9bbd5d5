"""The errors of an agent's node: its parameters, its peers, its predictions, stale state and
injected faults. Each is a `FormationError`.
"""

from __future__ import annotations

from collections.abc import Sequence

from formation_msgs_py.errors import FormationError


class FaultInjectionError(FormationError, ValueError):
    """Fault-injection parameters out of range."""


class PeerLostError(FormationError, RuntimeError):
    """A peer the agent depends on (the simulator) stopped showing signs of life."""


class ParameterError(FormationError, ValueError):
    """Parameters missing, of the wrong type, or out of range; the message lists every one."""

    def __init__(self, node_name: str, problems: Sequence[str]) -> None:
        self.problems = tuple(problems)
        super().__init__(f'{node_name}: ' + '; '.join(self.problems))


class PredictionError(FormationError, RuntimeError):
    """The agent's certified search cannot resolve its next triggering time in double precision."""


class StaleStateError(FormationError, RuntimeError):
    """The agent's state is older than its pose_timeout: it must not command from it, it stops."""


class AgentNodeError(FormationError, ValueError):
    """A violation of the lock-step protocol seen by an agent."""
