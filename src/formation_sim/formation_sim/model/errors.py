"""The errors of the problem model: scenarios, gains, theory, limits, generated teams (a
scenario that breaks a hypothesis is `formation_sim.model.validate.ValidationError`, which
holds its report). Each is a `FormationError`.
"""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class GainsError(FormationError, ValueError):
    """Gains outside what (riccatti) or Theorem 2 can take (the message names the rule and value)."""


class GenerateError(FormationError, ValueError):
    """Parameters for which no scenario can be generated."""


class ScenarioError(FormationError, ValueError):
    """A scenario that cannot be read or is structurally unsound; the message names key and value."""


class LimitsError(FormationError, ValueError):
    """Limits that cannot be met, or that no speed scale applies to (the message names the rule)."""


class JamError(LimitsError):
    """With the safety layer, an exact run whose robots block each other and trigger without end
    (docs/SAFETY.md, "Ties"): `jams` holds (the tie-break turn λ, the events, the paper's time) of
    each run that jammed; the message names them."""

    def __init__(self, message: str, *, jams: tuple[tuple[float, int, float], ...] = ()) -> None:
        super().__init__(message)
        self.jams = jams


class TheoryError(FormationError, ValueError):
    """A quantity requested outside the hypotheses it needs (the message names the rule and values)."""
