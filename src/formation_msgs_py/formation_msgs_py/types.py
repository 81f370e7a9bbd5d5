"""ROS-free message payloads exchanged by agents and the simulator.

These are what the algorithm core consumes and produces; `formation_msgs_py.codec` maps them
onto standard Jazzy interface types for transport and recording.
"""

from __future__ import annotations

from dataclasses import dataclass

Vector = tuple[float, ...]

# Agent ids are integers in [0, MAX_AGENT_ID]: they name topics (/agent_<i>/...), travel as int64
# ROS parameters and, in the message layouts, as float64 fields checked against this bound (a
# 32-bit signed range, which every robot stack's integer types hold).
MAX_AGENT_ID = 2**31 - 1


@dataclass(frozen=True, kw_only=True, slots=True)
class TriggerInfo:
    """Triggering information agent `sender` broadcasts to neighbour `receiver` at its trigger.

    ETA-1: {t^i_k, u_i(t^i_k), x_i(t^i_k) - x_j(t^i_k)}; ETA-2 adds q_i(t^i_k) - q_j(t^i_k) and
    carries u^d_i(t^i_k) as `control` (paper, Sections 3 and 4).
    """

    sender: int
    receiver: int
    stamp: float
    control: Vector
    rel_position: Vector
    rel_velocity: Vector | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class SensedState:
    """What agent `agent` senses at its triggering time `stamp`.

    `rel_positions[j]` is x_i - x_j; for double integrators also `rel_velocities[j]` = q_i - q_j
    and the agent's own velocity q_i.  With the safety layer (docs/SAFETY.md) `nearby[j]` is
    x_i - x_j of every other robot j within the sensing radius that is not a neighbour (None: the
    layer is off, nothing sensed beyond the neighbours).
    """

    agent: int
    stamp: float
    rel_positions: dict[int, Vector]
    rel_velocities: dict[int, Vector] | None = None
    velocity: Vector | None = None
    nearby: dict[int, Vector] | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class RobotPose:
    """A robot's pose as it arrives on its pose topic (README, "Running on robots").

    From geometry_msgs/PoseStamped: the pose only.  From nav_msgs/Odometry also the twist, which
    REP 105 gives in the robot's body frame (`child_frame_id`): `linear` [m/s], `angular` [rad/s].
    """

    stamp: float  # header stamp in seconds, on the publisher's clock
    frame: str  # header frame_id: the frame of the pose
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]  # unit quaternion (x, y, z, w)
    linear: tuple[float, float, float] | None = None  # body-frame twist (Odometry only)
    angular: tuple[float, float, float] | None = None
