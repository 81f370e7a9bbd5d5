"""The errors of the analysis of runs: loading, comparing, markers. Each is a `FormationError`."""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class CompareError(FormationError, ValueError):
    """Runs that cannot be compared (unreadable, or of different agents)."""


class AnalysisError(FormationError, ValueError):
    """A bag or run folder that cannot be analysed; the message says what is missing or wrong."""


class MarkerError(FormationError, ValueError):
    """A state that cannot be drawn (wrong shape, dimension above 3, non-finite values)."""
