"""Offered QoS in bags, as rosbag2 keeps it: what a topic's publishers offered when it was recorded,
and what a player offers again.

The recorder stores, per topic, one profile per publisher it sees (`offered_qos`, from the ROS
graph, as `rosbag2_transport`'s recorder does), in the bag's metadata (`formation_sim.bag.io`
writes them in rosbag2 Jazzy's format).  A player offers them again (`replay_offer`, rosbag2's
``adapt_offer_to_recorded_offers``): the recorded reliability, durability, deadline and liveliness
when every publisher offered the same, so a transient-local topic such as `/formation/scenario`
is latched again for late joiners; the history is the player's own (it is no part of matching).
"""

from __future__ import annotations

from collections.abc import Sequence

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

_NS_PER_S = 1_000_000_000


def _bag_time(duration: Duration) -> QosTime:
    return QosTime(sec=duration.nanoseconds // _NS_PER_S, nsec=duration.nanoseconds % _NS_PER_S)


def _ros_duration(time: QosTime) -> Duration:
    return Duration(nanoseconds=min(time.sec * _NS_PER_S + time.nsec, 2**63 - 1))


def bag_qos(profile: QoSProfile) -> Qos:
    """An rclpy profile (a publisher's, as the graph reports it) as a bag stores it."""
    return Qos(
        history=QosHistory[profile.history.name],
        depth=int(profile.depth),
        reliability=QosReliability[profile.reliability.name],
        durability=QosDurability[profile.durability.name],
        deadline=_bag_time(profile.deadline),
        lifespan=_bag_time(profile.lifespan),
        liveliness=QosLiveliness[profile.liveliness.name],
        liveliness_lease_duration=_bag_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def offered_qos(node, topic: str) -> list[Qos]:
    """The profile each publisher of `topic` that `node` sees offers."""
    return [bag_qos(info.qos_profile) for info in node.get_publishers_info_by_topic(topic)]


def _compatibility(qos: Qos) -> tuple:
    """What decides matching (rosbag2: everything but history, depth and lifespan)."""
    return (qos.reliability, qos.durability, qos.deadline, qos.liveliness, qos.liveliness_lease_duration)


def replay_offer(profiles: Sequence[Qos], *, depth: int | None = None) -> QoSProfile | None:
    """What a player offers on a topic recorded with `profiles`: the recorded policies when every
    publisher offered the same (None otherwise, or with none recorded: the player's default);
    history keep-all, or keep-last `depth`."""
    if not profiles or len({_compatibility(qos) for qos in profiles}) != 1:
        return None
    recorded = profiles[0]

    def policy(enum, value):
        known = value.name in enum.__members__ and value.name != 'UNKNOWN'
        return enum[value.name] if known else enum.SYSTEM_DEFAULT

    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if depth is None else HistoryPolicy.KEEP_LAST,
        depth=1 if depth is None else depth,
        reliability=policy(ReliabilityPolicy, recorded.reliability),
        durability=policy(DurabilityPolicy, recorded.durability),
        deadline=_ros_duration(recorded.deadline),
        lifespan=_ros_duration(recorded.lifespan),
        liveliness=policy(LivelinessPolicy, recorded.liveliness),
        liveliness_lease_duration=_ros_duration(recorded.liveliness_lease_duration),
        avoid_ros_namespace_conventions=recorded.avoid_ros_namespace_conventions,
    )
