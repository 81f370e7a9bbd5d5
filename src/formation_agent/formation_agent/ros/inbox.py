"""What an agent node refuses to read (README, "Reliability"; docs/MESSAGES.md, "Bad messages").

A message that breaks its layout (`formation_msgs_py.errors.MessageError`) or cannot be true is
dropped before the core sees it, logged (the first three of each reason, then every hundredth)
and counted per reason (`formation_msgs_py.lockstep.REJECT_REASONS`) for the agent's report.

A stamp no sender of the run can give (after the run's horizon, or on the wall clock more than
STAMP_AHEAD_TOLERANCE ahead of the receiver's own clock) is refused as `future` and leaves the
sender's last stamp as it was: one forged message stamped 1e300 made every real one after it look
older, refused as `time_backwards` against the real sender, and stalled lock-step (issue 28).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from formation_msgs_py.codec import decode_trigger_info
from formation_msgs_py.errors import MessageError
from formation_msgs_py.lockstep import (
    REJECT_DIMENSION,
    REJECT_DUPLICATE,
    REJECT_FUTURE,
    REJECT_RECEIVER,
    REJECT_SENDER,
    REJECT_TIME_BACKWARDS,
)
from formation_msgs_py.topics import trigger_info_topic
from formation_msgs_py.types import TriggerInfo

STAMP_AHEAD_TOLERANCE = 0.5
"""Seconds a wall-clock stamp may be ahead of the receiver's own clock (t = now - epoch): the
sender stamps when it senses, before it sends, so only the hosts' clock offset can put it ahead."""


class Rejections:
    """Messages refused, per reason; logged sparingly."""

    def __init__(self, logger, *, changed: Callable[[], None]) -> None:
        self._logger = logger
        self._changed = changed
        self.counts: dict[str, int] = {}

    def __call__(self, topic: str, reason: str, detail: str) -> None:
        """Count and log a message that cannot be used; the node carries on without it."""
        count = self.counts.get(reason, 0) + 1
        self.counts[reason] = count
        self._changed()
        if count <= 3 or count % 100 == 0:  # the first few of each kind, then a trickle
            self._logger.warning(f'rejected a message on {topic} ({reason}, {count} so far): {detail}')


def implausible(
    info: TriggerInfo,
    *,
    sender: int,
    agent_id: int,
    algorithm: str,
    dimension: int,
    last_stamp: float | None,
    latest: float = math.inf,
) -> tuple[str, str] | None:
    """Why `info`, well formed, cannot be the next information of `sender` for agent `agent_id`
    (`latest`: the latest stamp a sender of the run can give now)."""
    if info.sender != sender:
        return REJECT_SENDER, f'information from agent {info.sender} on the topic of agent {sender}'
    if info.receiver != agent_id:
        return REJECT_RECEIVER, f'information for agent {info.receiver}, not {agent_id}'
    kind_ok = (info.rel_velocity is None) == (algorithm == 'eta1')
    if len(info.control) != dimension or not kind_ok:
        return REJECT_DIMENSION, (
            f'{"ETA-1" if info.rel_velocity is None else "ETA-2"} information of dimension '
            f'{len(info.control)}; this agent runs {algorithm.upper()} with p = {dimension}'
        )
    if info.stamp > latest:
        return (
            REJECT_FUTURE,
            f'agent {sender} stamped t={info.stamp!r}, after the latest possible t={latest!r}',
        )
    if info.stamp < 0.0 or (last_stamp is not None and info.stamp < last_stamp):
        previous = 't = 0' if last_stamp is None else f'its previous one at t={last_stamp!r}'
        return REJECT_TIME_BACKWARDS, f'agent {sender} stamped t={info.stamp!r}, before {previous}'
    if info.stamp == last_stamp:
        return REJECT_DUPLICATE, f'agent {sender} already sent information stamped t={last_stamp!r}'
    return None


def read_info(
    msg,
    *,
    sender: int,
    agent_id: int,
    algorithm: str,
    dimension: int,
    heard: dict[int, float],
    reject: Rejections,
    latest: float = math.inf,
) -> TriggerInfo | None:
    """The triggering information in `msg` from `sender`, or None if it is refused (`reject`ed);
    `heard` (sender -> stamp of its last accepted information) is updated; `latest`: the latest
    stamp a sender of the run can give now (`implausible`)."""
    topic = trigger_info_topic(sender, agent_id)
    try:
        info = decode_trigger_info(msg)
    except MessageError as error:
        reject(topic, error.reason, str(error))
        return None
    problem = implausible(
        info,
        sender=sender,
        agent_id=agent_id,
        algorithm=algorithm,
        dimension=dimension,
        last_stamp=heard.get(sender),
        latest=latest,
    )
    if problem is not None:
        reject(topic, *problem)
        return None
    heard[sender] = info.stamp
    return info
