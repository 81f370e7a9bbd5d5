"""Replay a recorded bag in your own tests: `BagReplay` plays it into a private ROS domain and
lets your node, or the collectors it makes, read it as the run's readers did.

```python
from formation_sim.runtime.testing import BagReplay

with BagReplay('runs/demo/bag') as replay:                 # a free ROS domain, its own context
    steps = replay.collect('/formation/step')               # typed messages, in arrival order
    mine = MyNode(context=replay.context)                   # or any node of yours
    replay.add_node(mine)
    result = replay.play()                                  # returns once every message is in
assert len(steps) == result.per_topic['/formation/step']
```

The replay is `formation replay`'s (`formation_sim.runtime.tools.replay.BagPlayer`): every message
republished byte for byte, with the QoS its publishers offered when it was recorded, keep-all,
reliable readers miss nothing. `play` publishes from a thread of its own while this thread spins
the nodes (rclpy's `SingleThreadedExecutor`, one `spin_once` at a time), and returns when every
replayed message has reached every collector, or raises `ReplayError` naming the topics still
short after `timeout`.

The domain is chosen free and locked as `formation run` does (`launch.reserve_domain`), or pinned
with `domain_id=`; discovery stays on this machine (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`
unless the environment says otherwise). Nothing here runs at import: rclpy is imported when a
replay is entered.

A test that uses a ROS domain of its own without a run or a replay holds it with
`with hold_domain(152):` (the same lock, waiting while a run has it), so that no run of another
test that picks a free domain joins it.
"""

from __future__ import annotations

import contextlib
import math
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from formation_sim.bag.io import read_bag
from formation_sim.runtime.errors import ReplayError
from formation_sim.runtime.tools.replay import BagPlayer, ReplayResult, _bag_topics

SPIN_STEP = 0.05  # seconds one spin_once waits for work


@contextlib.contextmanager
def hold_domain(domain_id: int, *, timeout: float = 300.0) -> Iterator[int]:
    """Hold ROS domain `domain_id` with the lock `formation run` takes (`launch.reserve_domain`),
    waiting up to `timeout` s while a run holds it (then `RunError`, as for a bad id). For a test
    that uses a domain without a run or a replay: a run that picks a free domain skips it meanwhile
    (once, a run picked the domain a recorder test used raw, and the recorder took its Steps)."""
    from formation_sim.runtime.launch.plan import reserve_domain

    with reserve_domain(domain_id, wait=timeout) as domain:
        yield domain


class BagReplay:
    """A bag replayed into a private ROS domain; a context manager (rclpy is up inside it)."""

    def __init__(
        self,
        bag: str | Path,
        *,
        domain_id: int | None = None,
        rate: float = 0.0,
        topics: list[str] | None = None,
        clock: bool = False,
    ) -> None:
        bag = Path(bag)
        if bag.is_file():
            bag = bag.parent
        if not (bag / 'metadata.yaml').is_file():
            raise ReplayError(f'{bag}: no bag there (no metadata.yaml)')
        if not (math.isfinite(rate) and rate >= 0.0):
            raise ReplayError(f'rate must be a finite number >= 0 (0: as fast as possible), got {rate!r}')
        self.bag = bag
        self.rate = rate
        self.clock = clock
        self.recorded = _bag_topics(bag)  # topic -> (type, offered QoS)
        unknown = sorted(set(topics or ()) - set(self.recorded))
        if unknown:
            raise ReplayError(f'{bag}: no topic {unknown} in the bag (it holds {sorted(self.recorded)})')
        self.topics = list(topics) if topics is not None else None
        self._domain_id = domain_id
        self._held = contextlib.ExitStack()
        self._nodes: list[Any] = []
        self._collected: dict[str, list] = {}
        self.context = None
        self.domain_id: int | None = None
        self._own = None  # the node that publishes and owns the collectors

    def __enter__(self) -> BagReplay:
        import rclpy
        from rclpy.node import Node

        from formation_sim.runtime.launch.plan import reserve_domain

        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        try:
            self.domain_id = self._held.enter_context(reserve_domain(self._domain_id))
            self.context = rclpy.Context()
            rclpy.init(context=self.context, domain_id=self.domain_id)
            self._held.callback(rclpy.try_shutdown, context=self.context)
            self._own = Node('formation_bag_replay', context=self.context, start_parameter_services=False)
            self._held.callback(self._own.destroy_node)
        except BaseException:
            self._held.close()
            raise
        return self

    def __exit__(self, *exc_info) -> None:
        self._held.close()

    def add_node(self, node) -> None:
        """Spin `node` (made with `context=replay.context`) while the bag plays."""
        self._nodes.append(node)

    def collect(self, topic: str, *, raw: bool = False) -> list:
        """A list that fills with `topic`'s messages as they arrive (typed; CDR bytes if `raw`),
        subscribed with the QoS the bag's publishers offered."""
        from formation_sim.runtime.nodes.bag_qos import replay_offer
        from formation_sim.runtime.nodes.recorder import import_message_class
        from formation_sim.runtime.tools.replay import replay_qos

        if self._own is None:
            raise ReplayError('collect() inside the `with BagReplay(...)` block only')
        if topic not in self.recorded:
            raise ReplayError(f'{self.bag}: no topic {topic!r} in the bag (it holds {sorted(self.recorded)})')
        msgtype, offered = self.recorded[topic]
        received = self._collected.setdefault(topic, [])
        qos = replay_offer(offered) or replay_qos()
        self._own.create_subscription(import_message_class(msgtype), topic, received.append, qos, raw=raw)
        return received

    def play(self, *, timeout: float = 30.0) -> ReplayResult:
        """Wait for the collectors' and nodes' readers, replay the bag, spin until every collector
        holds every message of its topic; the player's counts."""
        from rclpy.executors import SingleThreadedExecutor

        if self._own is None:
            raise ReplayError('play() inside the `with BagReplay(...)` block only')
        topics = self.topics if self.topics is not None else (sorted(self._collected) or None)
        player = BagPlayer(self._own, self.bag, rate=self.rate, topics=topics, clock=self.clock)
        executor = SingleThreadedExecutor(context=self.context)
        for node in (self._own, *self._nodes):
            executor.add_node(node)
        deadline = time.monotonic() + timeout
        try:
            self._spin_until(executor, lambda: self._readers_matched(player), deadline, 'no reader matched')
            outcome: dict[str, Any] = {}
            thread = threading.Thread(target=self._play, args=(player, outcome), daemon=True)
            thread.start()
            self._spin_until(executor, lambda: not thread.is_alive(), deadline, 'the replay did not end')
            if 'error' in outcome:
                raise outcome['error']
            result = outcome['result']
            self._spin_until(executor, lambda: not self._short(result), deadline, 'messages missing')
            return result
        finally:
            executor.shutdown(timeout_sec=1.0)

    @staticmethod
    def _play(player: BagPlayer, outcome: dict[str, Any]) -> None:
        try:
            outcome['result'] = player.play()
        except Exception as error:  # noqa: BLE001 - handed to the spinning thread, raised there
            outcome['error'] = error

    def _readers_matched(self, player: BagPlayer) -> bool:
        return all(player.publishers[t].get_subscription_count() >= 1 for t in self._collected)

    def _short(self, result: ReplayResult) -> dict[str, str]:
        return {
            topic: f'{len(got)} of {result.per_topic.get(topic, 0)}'
            for topic, got in self._collected.items()
            if len(got) < result.per_topic.get(topic, 0)
        }

    def _spin_until(self, executor, done, deadline: float, what: str) -> None:
        while not done():
            if time.monotonic() > deadline:
                raise ReplayError(f'{self.bag}: {what} within the timeout (collected: {self._counts()})')
            executor.spin_once(timeout_sec=SPIN_STEP)

    def _counts(self) -> dict[str, int]:
        return {topic: len(got) for topic, got in self._collected.items()}


def bag_counts(bag: str | Path) -> dict[str, int]:
    """Messages per topic in `bag` (read without ROS): what a replay must deliver."""
    counts: dict[str, int] = {}
    for message in read_bag(bag):
        counts[message.topic] = counts.get(message.topic, 0) + 1
    return counts
