"""Progress of long work (reading big bags, rendering animations) on stderr."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Call with (done, total); prints at most one update every `period` seconds.

    On a terminal the line is rewritten in place; otherwise (logs, CI) each update is a new line,
    at most every `period` * 10 seconds so logs stay short. `close()` prints the final state.
    """

    def __init__(
        self, label: str, *, stream: TextIO | None = None, period: float = 0.5, enabled: bool = True
    ) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self._tty = bool(getattr(self.stream, 'isatty', lambda: False)())
        self._period = period if self._tty else 10.0 * period
        self._last = -float('inf')
        self._state: tuple[int, int | None] = (0, None)
        self._shown = False

    def _line(self) -> str:
        done, total = self._state
        if total:
            return f'{self.label}: {done}/{total} ({100.0 * done / total:.0f}%)'
        return f'{self.label}: {done}'

    def __call__(self, done: int, total: int | None = None) -> None:
        self._state = (done, total)
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < self._period:
            return
        self._last = now
        self._write(self._line(), final=False)

    def _write(self, text: str, *, final: bool) -> None:
        if self._tty:
            self.stream.write(f'\r\033[K{text}' + ('\n' if final else ''))
        else:
            self.stream.write(text + '\n')
        self.stream.flush()
        self._shown = True

    def close(self, message: str | None = None) -> None:
        """Print the final state (or `message`) if anything was shown or a message is given."""
        if not self.enabled:
            return
        if message is not None or self._shown:
            self._write(message if message is not None else self._line(), final=True)
