"""Strangers, duplicates and a frozen keeper, ROS-free: what a time keeper tells from the ROS graph
and from its own clock (issue 28; docs/HOSTILE_TRAFFIC.md).

Every topic a run's nodes write has its legitimate writers, known by node name: the keeper's Step,
agent i's triggering information, status, report and commands, its sensing requests; a robot's
command has its agent and the coordinator, a robot's pose topic one writer, whoever it is.
`GraphWatch` holds these rules (`Watched`) and judges the writers a keeper sees in the graph
(node name and endpoint gid, `Writer`): a writer that is neither is a stranger, named; two writers
with agent i's node name are two processes claiming agent i.  A stranger on a robot's topic, or
on the simulator's plant, moves a robot or the world: the run fails at once naming it
(`ForeignWriterError`); a duplicate agent fails the run too (`DuplicateAgentError`).  A stranger
on a protocol topic (Steps, triggering information) is named and counted, and the agents refuse
what cannot be true; the first failure that follows is blamed on it first (`blame`).

`FreezeWatch` tells a keeper frozen (SIGSTOP) or starved from lost robots and agents: its own
periodic tick came late by more than the liveliness lease, so what it then sees lost (every robot
silent, agents gone after they saw *it* lost) follows from its own freeze.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from formation_msgs_py.middleware import LIVELINESS_LEASE, LOST_GRACE
from formation_msgs_py.topics import (
    AGENT_NODE,
    SIMULATOR_NODE,
    STEP_TOPIC,
    agent_namespace,
    command_topic,
    robot_command_topic,
    robot_odom_topic,
    robot_pose_topic,
    robot_true_odom_topic,
    sense_service,
    trigger_info_topic,
)
from formation_sim.runtime.errors import (
    CoordinatorError,
    DuplicateAgentError,
    ForeignInformationError,
    ForeignWriterError,
    KeeperFrozenError,
)

TOPICS_PER_LOOK = 32
"""Topics a keeper looks up in the graph per look (about one look a second): a graph query costs
~0.8 ms here, so a run of any size spends at most ~3 % of a core on it; larger runs cycle through
their topics over several looks."""

UNKNOWN_NODE = '_NODE_NAME_UNKNOWN_'
"""What rmw_fastrtps gives as the node name of a writer whose participant has not (yet) said which
ROS nodes it holds: a raw DDS writer, or one seen before its node's graph information."""

UNKNOWN_GRACE = 5.0
"""Seconds a writer of no known ROS node is given for its node's name to come before it is judged:
DDS announces an endpoint before rmw's graph information names its node, and on a loaded machine
that can take seconds (a fresh-clone CI run named agent 2's own writer a stranger, and the run's
failure was blamed on it).  A raw DDS writer stays nameless and is judged after this."""

FREEZE_BLAME_WINDOW = LIVELINESS_LEASE + LOST_GRACE + 1.0
"""Seconds after a keeper's freeze during which a loss it sees is blamed on the freeze: what its
peers did when they saw it lost (the lease, then their grace) and what waited while it was frozen."""


def agent_node(agent: int) -> str:
    """The fully qualified name of agent `agent`'s node."""
    return f'{agent_namespace(agent)}/{AGENT_NODE}'


@dataclass(frozen=True, kw_only=True)
class Writer:
    """A writer seen in the graph: its node's fully qualified name and its endpoint gid (hex)."""

    node: str
    gid: str

    def __str__(self) -> str:
        if UNKNOWN_NODE in self.node:  # a DDS writer whose ROS node the graph does not (yet) know
            return f'a writer of no known ROS node (writer gid {self.gid})'
        return f'{self.node} (writer gid {self.gid})'


@dataclass(frozen=True, kw_only=True)
class Watched:
    """A topic and who may write it: `allowed` node names (empty: any, at most `most` writers)."""

    topic: str
    what: str  # in words: "robot 2's command", "agent 2's triggering information"
    allowed: frozenset[str] = frozenset()
    most: int = 1
    agent: int | None = None  # writers named like this agent's node are that agent
    fatal: bool = False  # a stranger here changes the run: it fails at once
    mangled: bool = False  # a service's request topic (rq/...Request): looked up as is


@dataclass(frozen=True, kw_only=True)
class Intrusion:
    """Strangers (or a duplicate) seen on a watched topic."""

    kind: str  # 'stranger' | 'duplicate'
    watched: Watched
    writers: tuple[Writer, ...]

    @property
    def fatal(self) -> bool:
        return self.kind == 'duplicate' or self.watched.fatal

    def text(self) -> str:
        names = ' and '.join(map(str, self.writers))
        if self.kind == 'duplicate':
            return f'two processes claim agent {self.watched.agent}: {names} both write {self.watched.topic}'
        one = len(self.writers) == 1
        return (
            f'{"a node" if one else "nodes"} outside the run, {names}, '
            f'{"writes" if one else "write"} {self.watched.what} ({self.watched.topic})'
        )

    def extra(self) -> dict:
        return {
            'kind': self.kind,
            'topic': self.watched.topic,
            'writers': [{'node': w.node, 'gid': w.gid} for w in self.writers],
        }


def intrusions(watched: Watched, writers: Iterable[Writer]) -> list[Intrusion]:
    """What is wrong with `writers` of `watched.topic`: strangers, and two writers of one agent."""
    writers = sorted(set(writers), key=lambda w: (w.node, w.gid))
    found = []
    if watched.agent is not None:
        own = [w for w in writers if w.node == agent_node(watched.agent)]
        if len(own) > 1:
            found.append(Intrusion(kind='duplicate', watched=watched, writers=tuple(own)))
    if watched.allowed:
        strangers = [w for w in writers if w.node not in watched.allowed]
    else:
        strangers = writers if len(writers) > watched.most else []
    if strangers:
        found.append(Intrusion(kind='stranger', watched=watched, writers=tuple(strangers)))
    return found


@dataclass
class GraphWatch:
    """The watched topics of a run, looked at a slice at a time, and what was found on them."""

    watched: Sequence[Watched]
    found: dict[tuple[str, str, tuple[str, ...]], Intrusion] = field(default_factory=dict)
    _next: int = 0
    _nameless: dict[str, float] = field(default_factory=dict)  # gid -> first seen without a name

    def due(self, most: int = TOPICS_PER_LOOK) -> list[Watched]:
        """The next `most` topics to look at (round robin)."""
        if not self.watched:
            return []
        count = min(most, len(self.watched))
        chosen = [self.watched[(self._next + k) % len(self.watched)] for k in range(count)]
        self._next = (self._next + count) % len(self.watched)
        return chosen

    def note(self, watched: Watched, writers: Iterable[Writer], *, now: float) -> list[Intrusion]:
        """The writers of `watched.topic` seen at `now` (monotonic s); the intrusions not seen
        before.  A writer of no known node is judged only once it stayed nameless UNKNOWN_GRACE s;
        one named since as a writer the topic allows is taken back from what was found."""
        writers = list(writers)
        judged = []
        for writer in writers:
            if UNKNOWN_NODE in writer.node:
                first = self._nameless.setdefault(writer.gid, now)
                if now - first < UNKNOWN_GRACE:
                    continue
            judged.append(writer)
        self._take_back(watched, [w for w in writers if UNKNOWN_NODE not in w.node])
        new = []
        for intrusion in intrusions(watched, judged):
            key = (intrusion.kind, watched.topic, tuple(sorted(w.gid for w in intrusion.writers)))
            if key not in self.found:
                new.append(intrusion)
            self.found[key] = intrusion  # the latest names (a node's name may come after its writer)
        return new

    def _take_back(self, watched: Watched, named: list[Writer]) -> None:
        """Strangers found on `watched.topic` while nameless that are now `named` writers the topic
        allows: no strangers (their node's name came after the grace)."""
        if not watched.allowed:
            return
        cleared = {w.gid for w in named if w.node in watched.allowed}
        for key, intrusion in list(self.found.items()):
            if intrusion.watched.topic != watched.topic or intrusion.kind != 'stranger':
                continue
            if not any(w.gid in cleared and UNKNOWN_NODE in w.node for w in intrusion.writers):
                continue
            del self.found[key]
            rest = tuple(w for w in intrusion.writers if w.gid not in cleared)
            if rest:
                kept = Intrusion(kind='stranger', watched=intrusion.watched, writers=rest)
                self.found[(kept.kind, watched.topic, tuple(sorted(w.gid for w in rest)))] = kept

    def error(self) -> ForeignWriterError | None:
        """The failure the first fatal intrusion makes (None: none yet)."""
        fatal = [i for i in self.found.values() if i.fatal]
        if not fatal:
            return None
        first = fatal[0]
        cls = DuplicateAgentError if first.kind == 'duplicate' else ForeignWriterError
        agents = sorted({i.watched.agent for i in fatal if i.watched.agent is not None})
        return cls(
            '; '.join(_grouped(fatal)) + ': the run stops',
            nodes=sorted({w.node for i in fatal for w in i.writers}),
            agents=agents,
        )

    def blame(self, message: str) -> str:
        """`message` of a failure, with the strangers seen before it named first."""
        if not self.found:
            return message
        return '; '.join(i.text() for i in self.found.values()) + f'; then: {message}'

    def extra(self) -> dict:
        """summary.json's `extra.foreign_writers` (none seen: absent)."""
        return {'foreign_writers': [i.extra() for i in self.found.values()]} if self.found else {}


def _grouped(found: list[Intrusion]) -> list[str]:
    """The texts of `found`, one per kind and set of nodes: the same nodes on several topics (one
    process writes each of an agent's topics) are named once, with every topic."""
    groups: dict[tuple, list[Intrusion]] = {}
    for intrusion in found:
        key = (intrusion.kind, intrusion.watched.agent, tuple(w.node for w in intrusion.writers))
        groups.setdefault(key, []).append(intrusion)
    texts = []
    for group in groups.values():
        text = group[0].text()
        if len(group) > 1:
            if group[0].kind == 'duplicate':
                text = text.removesuffix(group[0].watched.topic) + ', '.join(i.watched.topic for i in group)
            else:
                text += ''.join(f', {i.watched.what} ({i.watched.topic})' for i in group[1:])
        texts.append(text)
    return texts


def protocol_watched(scenario, *, keeper: str) -> list[Watched]:
    """The protocol's topics of a run of `scenario` and their writers: the Steps (the keeper
    `keeper`, a fully qualified node name) and each agent's triggering information (that agent).
    A stranger there is named, and what it sends is refused by what cannot be true."""
    watched = [Watched(topic=STEP_TOPIC, what='Steps', allowed=frozenset({keeper}))]
    for i in scenario.agent_ids:
        for j in scenario.neighbours(i):
            topic = trigger_info_topic(i, j)
            watched.append(
                Watched(
                    topic=topic,
                    what=f"agent {i}'s triggering information to agent {j}",
                    allowed=frozenset({agent_node(i)}),
                    agent=i,
                )
            )
    return watched


def robot_watched(scenario, *, keeper: str) -> list[Watched]:
    """A robot run's robot topics: each robot's command (its agent, and the coordinator `keeper`'s
    zero commands) and each of its pose topics (one writer, whoever it is).  A stranger here moves a
    robot, or shows the agents a robot where it is not: fatal."""
    watched = []
    for i in scenario.agent_ids:
        watched.append(
            Watched(
                topic=robot_command_topic(i),
                what=f"robot {i}'s command",
                allowed=frozenset({agent_node(i), keeper}),
                agent=i,
                fatal=True,
            )
        )
        for topic in (robot_pose_topic(i), robot_odom_topic(i), robot_true_odom_topic(i)):
            watched.append(Watched(topic=topic, what=f"robot {i}'s poses", most=1, fatal=True))
    return watched


def simulator_watched(scenario) -> list[Watched]:
    """The simulator's plant and sensing: agent i's command to the plant (fatal: a stranger moves
    the exact world), its sensing requests (a stranger reads; named) and the service's answers
    (the simulator's: another server may answer agent i in the world's place; fatal, named)."""
    double = scenario.dynamics == 'double'
    watched = []
    for i in scenario.agent_ids:
        own = frozenset({agent_node(i)})
        watched.append(
            Watched(
                topic=command_topic(i, double=double),
                what=f"agent {i}'s command to the simulator",
                allowed=own,
                agent=i,
                fatal=True,
            )
        )
        watched.append(
            Watched(
                topic=f'rq{sense_service(i)}Request',
                what=f'sensing requests to {sense_service(i)}',
                allowed=own,
                agent=i,
                mangled=True,
            )
        )
        # A second server of the service: agent i's client may take its answer for the world's.
        watched.append(
            Watched(
                topic=f'rr{sense_service(i)}Reply',
                what=f'answers of {sense_service(i)}',
                allowed=frozenset({f'/{SIMULATOR_NODE}'}),
                fatal=True,
                mangled=True,
            )
        )
    return watched


def information_excess(statuses: Iterable, *, slack: int) -> tuple[int, int] | None:
    """(received, sent) over the agents' latest Statuses when they took more triggering information
    than `slack` beyond what they all sent, else None.  Each message an agent takes was sent by a
    neighbour; `slack` covers the Statuses still on their way (a receiver's may come before its
    sender's): one trigger's messages per directed edge."""
    sent = received = 0
    for status in statuses:
        if status is not None:
            sent += status.info_sent
            received += status.info_received
    return (received, sent) if received > sent + slack else None


def foreign_information_error(received: int, sent: int, watch: GraphWatch) -> ForeignInformationError:
    """The failure for agents that took `received` messages of triggering information when only
    `sent` were sent: the strangers seen on the information's topics named first."""
    strangers = [i for i in watch.found.values() if i.kind == 'stranger' and i.watched.agent is not None]
    who = '; '.join(i.text() for i in strangers) if strangers else 'no stranger seen in the graph yet'
    return ForeignInformationError(
        f'{who}: the agents took {received} messages of triggering information, but sent only {sent}: '
        f'{received - sent} came from outside the run, and the run is not its own any more: the run stops',
        nodes=sorted({w.node for i in strangers for w in i.writers}),
        agents=sorted({i.watched.agent for i in strangers}),
    )


class SensingCalls:
    """The wall-clock simulator's sensing calls, and which of them were triggers.

    Any node can call `/agent_<i>/sense` (std_srvs/Trigger names no caller): a call is agent i's
    trigger only once agent i's own triggering information stamped with the time it was answered
    follows (`triggered`); the calls answered before it, and those never followed, are foreign
    (500 calls a second from outside became agent 2's "triggers": 1 062 sensing calls for 63
    events).  In lock-step a call that is not agent i's turn while a stranger calls its service
    is refused and counted here too (`foreign_call`), not blamed on agent i.
    """

    def __init__(self, agents: Iterable[int]) -> None:
        self._pending: dict[int, list[float]] = {i: [] for i in agents}
        self.foreign: dict[int, int] = dict.fromkeys(self._pending, 0)
        self.triggers = 0  # calls confirmed as triggers

    def asked(self, agent: int, t: float) -> None:
        """A call for `agent` answered with its state at run time `t`."""
        self._pending[agent].append(t)

    def triggered(self, agent: int, stamp: float) -> bool:
        """`agent`'s triggering information stamped `stamp` came: True if that makes a pending call
        its trigger (the calls answered before it are foreign); False for a stamp no call gave
        (a copy replayed to a late reader, or a forgery)."""
        calls = self._pending.get(agent)
        if not calls or stamp not in calls:
            return False
        self.foreign[agent] += sum(1 for t in calls if t < stamp)
        self._pending[agent] = [t for t in calls if t > stamp]
        self.triggers += 1
        return True

    def foreign_call(self, agent: int) -> None:
        self.foreign[agent] += 1

    def extra(self) -> dict:
        """summary.json's `extra.foreign_sensing_calls` (agent -> calls that were no trigger of
        its own, those still unanswered by a trigger included); none: absent."""
        counts = {i: n + len(self._pending[i]) for i, n in self.foreign.items()}
        counts = {str(i): n for i, n in counts.items() if n}
        return {'foreign_sensing_calls': counts} if counts else {}


class FreezeWatch:
    """A keeper's own periodic tick: how long it was frozen, and when that ended."""

    def __init__(self, *, period: float, limit: float = LIVELINESS_LEASE) -> None:
        self.period = period
        self.limit = limit  # a gap this much longer than the period is a freeze
        self._last: float | None = None
        self.frozen_for = 0.0  # the latest freeze [s]
        self.ended_at: float | None = None  # when it ended (the tick after it)

    def tick(self, now: float) -> None:
        gap = self.gap(now)
        if gap > self.limit:
            self.frozen_for, self.ended_at = gap, now
        self._last = now

    def gap(self, now: float) -> float:
        """Seconds since the last tick beyond its period (0 before the first)."""
        return 0.0 if self._last is None else max(0.0, now - self._last - self.period)

    def blame(self, error: BaseException, now: float, *, who: str) -> BaseException:
        """`error` as the keeper's freeze if the keeper was frozen just before (or is now): a
        KeeperFrozenError that names the freeze first and `error` after it."""
        if isinstance(error, KeeperFrozenError) or not isinstance(error, CoordinatorError):
            return error
        gap = self.gap(now)
        if gap > self.limit:
            frozen = gap
        elif self.ended_at is not None and now - self.ended_at <= FREEZE_BLAME_WINDOW:
            frozen = self.frozen_for
        else:
            return error
        return KeeperFrozenError(
            f'the {who} itself was stopped or starved for {frozen:.2f} s (its {self.period:g} s timer came '
            f'that late; SIGSTOP, or an overloaded computer), longer than the liveliness lease its peers '
            f'watch it by: what it saw then follows from its own freeze: {error}'
        )
