"""Every exit status of the project, in one enum (ROS-free): the `formation` command, its
subcommands and the node processes (agents, time keepers, robots, the recorder) end with one of
these, and nothing else spells one.

Here because an agent on a robot installs only formation_agent and formation_msgs_py and exits
with them too. Written from this enum: the `formation --help` epilog (`formation_sim.cli`),
docs/EXIT_CODES.md (`scripts/reference_docs.py`) and the README's sentence (`SENTENCE`); a test
checks that they agree (tests/formation_msgs_py/test_exit_codes.py).

`ExitCode` is an `IntEnum`: `sys.exit(ExitCode.LOST)` leaves with 3, `f'{ExitCode.LOST}'` and
`json.dumps(ExitCode.LOST)` write `3`, and `ExitCode.LOST == 3`.
"""

from __future__ import annotations

import enum


class ExitCode(enum.IntEnum):
    """An exit status; `meaning` says what it means, `brief` how the one-line sentence says it."""

    OK = 0
    FAILED = 1
    BAD_INPUT = 2
    LOST = 3
    REFUSED = 4
    STOPPED = 5
    INTERRUPTED = 130

    @property
    def meaning(self) -> str:
        """What the status means, in full (docs/EXIT_CODES.md's table)."""
        return _MEANING[self]

    @property
    def brief(self) -> str:
        """What the status means in the one-line sentence (`SENTENCE`)."""
        return _BRIEF[self]

    @property
    def every_command(self) -> bool:
        """Whether every command may end with it (0, 1, 2), or only `formation run` and the nodes."""
        return self in _EVERY_COMMAND


_EVERY_COMMAND = frozenset({ExitCode.OK, ExitCode.FAILED, ExitCode.BAD_INPUT})

_MEANING: dict[ExitCode, str] = {
    ExitCode.OK: 'done: the command did what was asked and every check holds',
    ExitCode.FAILED: 'the command ran and the answer is no (a run failed, a check does not hold)',
    ExitCode.BAD_INPUT: 'bad arguments or unreadable input: refused, nothing started, nothing changed; '
    'a node refused its parameters (every problem named on stderr; nothing started)',
    ExitCode.LOST: 'a process of the run died, or an agent, a robot or the recorder was lost; a node '
    'left because a peer it depends on was lost',
    ExitCode.REFUSED: "a robot run's time keeper refused to start: the robots' measured start breaks a "
    'hypothesis (no Step 0, no command was sent)',
    ExitCode.STOPPED: 'a time keeper (and `formation run`) whose run an operator stopped: a call of its '
    'emergency-stop service (`formation_msgs_py.topics.STOP_SERVICE`, `formation stop`)',
    ExitCode.INTERRUPTED: 'interrupted (Ctrl-C, SIGINT or SIGTERM)',
}

_BRIEF: dict[ExitCode, str] = {
    ExitCode.OK: 'done',
    ExitCode.FAILED: 'the command ran and the answer is no',
    ExitCode.BAD_INPUT: 'bad input, refused before anything started or changed',
    ExitCode.LOST: 'a process, an agent, a robot or the recorder was lost',
    ExitCode.REFUSED: "the robots' measured start breaks the initial condition",
    ExitCode.STOPPED: 'an operator stopped it',
    ExitCode.INTERRUPTED: 'interrupted',
}


def _sentence() -> str:
    every = '; '.join(f'{code} {code.brief}' for code in ExitCode if code.every_command)
    run = [f'{code} ({code.brief})' for code in ExitCode if not code.every_command]
    return f'{every}; `formation run` also {", ".join(run[:-1])} and {run[-1]}.'


SENTENCE = _sentence()
"""Every status in one sentence: '0 done; 1 ...; `formation run` also 3 (...), ... and 130
(interrupted).' The `formation --help` epilog, docs/EXIT_CODES.md and the README say it."""
