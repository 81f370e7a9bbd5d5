"""formation_sim.runtime.nodes.bag_qos: profiles as the graph reports them, stored, and offered again by a
player the way rosbag2 Jazzy's player does (adapt_offer_to_recorded_offers)."""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

from formation_msgs_py.qos import PROTOCOL_QOS
from formation_sim.runtime.nodes.bag_qos import bag_qos, replay_offer

FOREVER = QosTime(sec=9223372036, nsec=854775807)
OFFERED = Qos(
    QosHistory.UNKNOWN,
    0,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    FOREVER,
    FOREVER,
    QosLiveliness.AUTOMATIC,
    QosTime(1, 0),
    False,
)


def test_a_protocol_profile_is_stored_as_offered():
    assert bag_qos(PROTOCOL_QOS) == OFFERED._replace(
        history=QosHistory.KEEP_LAST, depth=32, deadline=QosTime(0, 0), lifespan=QosTime(0, 0)
    )


def test_the_player_offers_the_recorded_policies_with_its_own_history():
    offer = replay_offer(
        [OFFERED, OFFERED._replace(depth=7, history=QosHistory.KEEP_LAST)]
    )  # history and depth do not count
    assert (offer.reliability, offer.durability, offer.liveliness) == (
        ReliabilityPolicy.RELIABLE,
        DurabilityPolicy.TRANSIENT_LOCAL,
        LivelinessPolicy.AUTOMATIC,
    )
    assert offer.liveliness_lease_duration == Duration(seconds=1) and offer.history == HistoryPolicy.KEEP_ALL
    assert replay_offer([OFFERED], depth=5).depth == 5
    # Round trip: what the player offers is stored as what was recorded (up to the history).
    assert bag_qos(offer)._replace(history=QosHistory.UNKNOWN, depth=0) == OFFERED


def test_mixed_or_missing_offers_leave_the_players_default():
    assert replay_offer([]) is None
    assert (
        replay_offer([OFFERED, OFFERED._replace(durability=QosDurability.VOLATILE)]) is None
    )  # as rosbag2: no adapted profile
    unknown = replay_offer([OFFERED._replace(reliability=QosReliability.UNKNOWN)])
    assert unknown.reliability == ReliabilityPolicy.SYSTEM_DEFAULT
    assert isinstance(unknown, QoSProfile)
