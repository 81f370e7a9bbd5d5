"""Fault injection on arriving triggering information: a test facility (README, "Reliability").

Parameters `inject_loss`, `inject_delay_ms`, `inject_jitter_ms`, `inject_seed` make an agent
drop or delay its neighbours' triggering information on arrival, as a bad network would, before
it even reads it.  Loss needs the wall clock (lock-step waits for every message sent).
"""

from __future__ import annotations

import heapq
import math
import random
import time
from collections.abc import Callable

from formation_agent.ros.errors import FaultInjectionError


class FaultInjection:
    """The random choices: drop or delay triggering information on arrival, as a bad network would.

    Each message is dropped with probability `loss`; a kept one is handed on after `delay_ms` plus
    a uniform extra in [0, `jitter_ms`].  Messages of one edge stay in order (a reliable DDS writer
    never reorders).  The random stream is seeded per agent, so a run's drop pattern depends only
    on (seed, agent, arrival order).
    """

    def __init__(self, *, agent_id: int, loss: float, delay_ms: float, jitter_ms: float, seed: int) -> None:
        if not (math.isfinite(loss) and 0.0 <= loss <= 1.0):
            raise FaultInjectionError(
                f'agent {agent_id}: inject_loss must be a probability in [0, 1], got {loss!r}'
            )
        for name, value in (('inject_delay_ms', delay_ms), ('inject_jitter_ms', jitter_ms)):
            if not (math.isfinite(value) and value >= 0.0):
                raise FaultInjectionError(
                    f'agent {agent_id}: {name} must be a finite number >= 0, got {value!r}'
                )
        self.loss = loss
        self.delay = delay_ms / 1000.0
        self.jitter = jitter_ms / 1000.0
        self._random = random.Random(f'formation-inject:{seed}:{agent_id}')
        self._last_due: dict[int, float] = {}

    @property
    def active(self) -> bool:
        return self.loss > 0.0 or self.delay > 0.0 or self.jitter > 0.0

    @property
    def delays(self) -> bool:
        return self.delay > 0.0 or self.jitter > 0.0

    def drop(self) -> bool:
        return self.loss > 0.0 and self._random.random() < self.loss

    def due(self, sender: int, now: float) -> float:
        """When a message of edge sender -> this agent arriving at `now` is handed on."""
        extra = self._random.uniform(0.0, self.jitter) if self.jitter > 0.0 else 0.0
        due = max(now + self.delay + extra, self._last_due.get(sender, -math.inf))
        self._last_due[sender] = due
        return due


class InjectedFaults:
    """The network's side of an agent node: what arrives is dropped, delayed or handed on at once.

    `hand_on(msg, sender)` reads a message; `changed()` tells the node its counts moved (for its
    report).  Delayed messages wait in a line on a one-shot node timer.
    """

    def __init__(
        self, node, injection: FaultInjection, *, hand_on: Callable, changed: Callable[[], None]
    ) -> None:
        self._node = node
        self.injection = injection
        self._hand_on = hand_on
        self._changed = changed
        self.dropped = 0
        self.delayed = 0
        self.closed = False  # the agent has finished: delayed messages are counted, not read
        self._line: list[tuple[float, int, int, object]] = []  # (due, seq, sender, msg)
        self._seq = 0
        self._timer = None

    def arrive(self, msg, sender: int) -> None:
        if not self.injection.active:
            self._hand_on(msg, sender)
            return
        if self.injection.drop():
            self.dropped += 1
            self._changed()
            return
        if not self.injection.delays:
            self._hand_on(msg, sender)
            return
        now = time.monotonic()
        due = self.injection.due(sender, now)
        self._seq += 1
        entry = (due, self._seq, sender, msg)
        heapq.heappush(self._line, entry)
        if self._timer is None or self._line[0] is entry:
            # Only a new earliest message moves the timer: junk may arrive by the thousand per
            # second, and each message would otherwise destroy and create a timer.
            self._arm(now)

    def _arm(self, now: float) -> None:
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None
        if self._line:
            self._timer = self._node.create_timer(max(self._line[0][0] - now, 0.0), self._release)

    def _release(self) -> None:
        now = time.monotonic()
        while self._line and self._line[0][0] <= now:
            _, _, sender, msg = heapq.heappop(self._line)
            self.delayed += 1
            self._changed()
            if not self.closed:
                self._hand_on(msg, sender)
        self._arm(now)
