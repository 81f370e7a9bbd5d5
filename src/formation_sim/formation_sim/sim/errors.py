"""The errors of the exact simulation: the world, the engine, samples, robots, run folders,
baselines. Each is a `FormationError`.
"""

from __future__ import annotations

from formation_msgs_py.errors import FormationError


class BaselineError(FormationError, ValueError):
    """Bad arguments for a baseline run, or an integration that failed."""


class EngineError(FormationError, RuntimeError):
    """The simulation could not go on (an agent rejected its input, a step did not advance)."""


class RobotError(FormationError, ValueError):
    """A robot set up with impossible values (a limit <= 0, a pose of the wrong size)."""


class RunFolderError(FormationError, ValueError):
    """An output folder that cannot be used; the message names the folder and why."""


class TrajectoryError(FormationError, ValueError):
    """A trajectory that cannot be read: incomplete, cut short, or inconsistent; the message says which file
    and why."""


class WorldError(FormationError, ValueError):
    """A request the world cannot honour (unknown agent, time going backwards, bad input)."""


class SummaryError(FormationError, ValueError):
    """A file that is not a summary.json of this schema (not JSON, another schema, keys missing)."""
