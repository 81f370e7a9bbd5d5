"""The errors of the message layer, and `FormationError`, the base of every error the project
raises on purpose (issue 29): `except FormationError` catches them all, and each keeps its
built-in base (`ValueError`, `RuntimeError`) so that older handlers still catch it.
"""

from __future__ import annotations

from formation_msgs_py.lockstep import REJECT_FIELD


class FormationError(Exception):
    """The base of every error the project raises on purpose: bad input refused with the rule
    and the value named, a run that cannot go on, a file that cannot be read."""


class MessageError(FormationError, ValueError):
    """A message that does not follow its documented layout.

    `reason` says which kind of rule it broke (`formation_msgs_py.lockstep.LAYOUT_REASONS`): an
    unsupported layout version, a length that does not match its header, a NaN or infinite
    value, or a field out of its range (ids, counts, kinds, flags).
    """

    def __init__(self, message: str, *, reason: str = REJECT_FIELD) -> None:
        super().__init__(message)
        self.reason = reason


class TagError(FormationError, ValueError):
    """A message refused by its tag (`formation_msgs_py.tags`); `reason` is one of tags.TAG_REASONS."""

    def __init__(self, message: str, *, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class KeyFileError(FormationError, ValueError):
    """A key file that cannot be the run's key (its mode, its length, its text)."""
