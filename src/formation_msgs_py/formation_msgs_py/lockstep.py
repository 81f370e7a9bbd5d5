"""ROS-free payloads of the lock-step protocol between the simulator and the agent nodes.

The simulator publishes a `Step` for every event time; every agent answers with `Status`
messages carrying cumulative counters, from which the simulator decides that all messages of
the step have been delivered (see docs/MESSAGES.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

STEP_FLAG_FINAL = 1
"""Step flag: the run is over (the horizon is reached); agents leave."""

STEP_FLAG_REALTIME = 2
"""Step flag: wall-clock mode; sim time t is wall time minus `Step.epoch` (Unix seconds)."""

DISCOVERY_STEP = -1
"""`Status.step_index` of an agent that is connected and waits for step 0."""

# Why an agent rejected a triggering-information message (docs/MESSAGES.md, "Bad messages").
REJECT_VERSION = 'version'  # unsupported layout version
REJECT_LENGTH = 'length'  # length does not match the header
REJECT_NON_FINITE = 'non_finite'  # NaN or infinite value
REJECT_FIELD = 'field'  # an id, kind or dimension out of range
REJECT_SENDER = 'sender'  # the sender is not the agent whose topic carried it
REJECT_RECEIVER = 'receiver'  # addressed to another agent
REJECT_DIMENSION = 'dimension'  # p differs from the receiver's, or ETA-1/ETA-2 mixed up
REJECT_TIME_BACKWARDS = 'time_backwards'  # stamped before t = 0 or before the sender's previous one
REJECT_DUPLICATE = 'duplicate'  # stamped at the very time of the sender's previous one
REJECT_FRAME = 'frame'  # a robot pose in another frame than the world frame
# stamped ahead of the reader's clock beyond a tolerance, or after the run's horizon (issue 28)
REJECT_FUTURE = 'future'
REJECT_JUMP = 'jump'  # a robot pose further from the last one than the robot's speed limit allows
REJECT_STEP_ORDER = 'step_order'  # a Step that cannot follow the run's previous one (issue 28)
# The run's tag refuses (formation_msgs_py.tags): the reasons, defined here as the other rejections.
UNTAGGED = 'untagged'  # no tag, where the reader holds the run's key
FORGED = 'forged'  # a tag that is not the run's key's: malformed, or another key's
REPLAYED = 'replayed'  # a valid tag whose sequence the reader has already had from its writer
FOREIGN_REASONS = (UNTAGGED, FORGED)
TAG_REASONS = (*FOREIGN_REASONS, REPLAYED)

LAYOUT_REASONS = (REJECT_VERSION, REJECT_LENGTH, REJECT_NON_FINITE, REJECT_FIELD)
REJECT_REASONS = (
    *LAYOUT_REASONS,
    REJECT_SENDER,
    REJECT_RECEIVER,
    REJECT_DIMENSION,
    REJECT_TIME_BACKWARDS,
    REJECT_DUPLICATE,
    REJECT_FRAME,
    REJECT_FUTURE,
    REJECT_JUMP,
    REJECT_STEP_ORDER,
    *TAG_REASONS,  # untagged, forged (foreign), replayed: the run's tag (formation_msgs_py.tags)
)

# What a robot's command adapter clips (AgentReport.saturation; README, "Running on robots").
SATURATION_LINEAR_SPEED = 'linear_speed'  # m/s: world-frame speed (holonomic), |v| (unicycle)
SATURATION_ANGULAR_SPEED = 'angular_speed'  # rad/s: |ω| (unicycle)
SATURATION_LINEAR_ACCELERATION = 'linear_acceleration'  # m/s²: ||dq/dt|| of the ETA-2 velocity reference
SATURATION_STEERING = (
    'steering'  # rad: the steering angle a car would need for (v, ω), atan(L |ω| / |v|) (π/2 at v = 0)
)
SATURATION_KINDS = (
    SATURATION_LINEAR_SPEED,
    SATURATION_ANGULAR_SPEED,
    SATURATION_LINEAR_ACCELERATION,
    SATURATION_STEERING,
)


@dataclass(frozen=True, kw_only=True, slots=True)
class Step:
    """The simulator's announcement that simulated time is now `time` (exact float).

    In wall-clock mode only step 0 (and the final step) exist; `epoch` is the Unix time at
    which sim time 0 began, and `due` is empty (agents keep their own timers).
    """

    index: int
    time: float
    flags: int = 0
    epoch: float = 0.0
    # Lock-step: the agents due at `time` (sorted ids).  A receiving agent reports once it has
    # the information of each of its neighbours in here, so it reports once per step.
    due: tuple[int, ...] = ()

    @property
    def final(self) -> bool:
        return bool(self.flags & STEP_FLAG_FINAL)

    @property
    def realtime(self) -> bool:
        return bool(self.flags & STEP_FLAG_REALTIME)


@dataclass(frozen=True, kw_only=True, slots=True)
class Status:
    """An agent's report after it handled everything it knows of for step `step_index`.

    Counters are totals since the start, so they only grow and a later report supersedes an
    earlier one.  `next_time` is the agent's next triggering time (inf: none before the horizon);
    `last_planned` the time its latest trigger had been planned for (0 before any: t^i_1 = 0).
    """

    agent: int
    step_index: int
    next_time: float
    info_sent: int
    info_received: int
    commands_sent: int
    triggers: int
    ready: bool
    last_planned: float = 0.0


@dataclass(frozen=True, kw_only=True, slots=True)
class WorldState:
    """Exact true state of all agents at `time` (rows in the order of `agent_ids`)."""

    time: float
    agent_ids: tuple[int, ...]
    positions: np.ndarray
    velocities: np.ndarray | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class Saturation:
    """Commands a robot adapter clipped to one of its limits (one kind of SATURATION_KINDS).

    For the speeds, `count` counts published robot commands; for the ETA-2 acceleration, the
    triggers from which the velocity reference had to be held to the limit (it only ever starts
    there: between triggers the requested acceleration only shrinks).
    """

    count: int  # commands clipped
    largest_requested: float  # the largest value asked for (a norm, >= 0)
    allowed: float  # the limit it was clipped to


@dataclass(frozen=True, kw_only=True, slots=True)
class AgentReport:
    """What an agent node counted besides the protocol: rejected and fault-injected messages,
    commands clipped to a robot's limits, and why it failed, if it did.

    Totals since the start (a later report supersedes an earlier one); `final` marks the report
    an agent sends when it leaves (at the final step, or on its way out whatever the reason).
    """

    agent: int
    final: bool
    rejected: dict[str, int]  # reason (REJECT_REASONS) -> messages rejected; zero counts omitted
    dropped: int = 0  # fault injection: messages dropped on arrival
    delayed: int = 0  # fault injection: messages handed on after a delay
    late: int = 0  # wall clock: information that arrived after the receiver's own later trigger
    robot_commands: int = 0  # velocity commands published to the robot (robot adapters only)
    saturation: dict[str, Saturation] = field(default_factory=dict)  # kind -> clipped; none: omitted
    failure: str | None = None  # final report of an agent that stops on an error: the error
    # topic -> messages the agent published there from step 0 on (this report included): what a
    # recorder matched before step 0 must hold
    published: dict[str, int] = field(default_factory=dict)
    # the safety layer (docs/SAFETY.md), None when it is off: triggers at which it changed the
    # nominal command, and the latest such time (None: none yet)
    safety_interventions: int | None = None
    safety_last_intervention: float | None = None

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())
