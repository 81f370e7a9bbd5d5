"""The errors of the agent's core (ROS-free): bad input to an agent, its search, its robot kind,
sensing, speed scale, time warp and safety layer. Each is a `FormationError`.
"""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class CrossingError(FormationError, RuntimeError):
    """The search could not proceed (non-finite error, or a step that does not advance)."""


class KindError(FormationError, ValueError):
    """An unknown kind, a kind registered twice, or a robot its kind cannot be (named, with the rule)."""


class AgentError(FormationError, ValueError):
    """Input the agent cannot accept: bad parameters, malformed or inconsistent information."""


class ShapeError(FormationError, ValueError):
    """A shape parameter declared twice differently, or a name no kind declares."""


class PoseError(FormationError, ValueError):
    """A pose the agent needs is missing, too old, or from the future: the agent must stop."""


class SafetyError(FormationError, ValueError):
    """A safety configuration or input outside its rules (the message names the rule and the value)."""


class ScaleError(FormationError, ValueError):
    """A speed scale or threshold floor outside its rule; the message names the rule and the value."""


class WarpError(FormationError, ValueError):
    """A time warp outside its rule; the message names the rule time_warp and the value."""


class RuleError(FormationError, ValueError):
    """An unknown triggering rule, one registered twice, or numbers its family refuses (rule trigger_rule)."""
