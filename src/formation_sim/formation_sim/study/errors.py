"""The errors of studies. Each is a `FormationError`."""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class StudyError(FormationError, ValueError):
    """A SPEC, a study folder or a case the study refuses (the message names the rule and value)."""
