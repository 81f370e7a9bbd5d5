"""What every ROS process of a run agrees on besides its messages (ROS-free): the ROS domain ids a
run may use, the ports Fast DDS takes in a domain, the rclpy executors a node process spins, and
the liveliness lease and graces of the protocol (its QoS profiles: formation_msgs_py.qos), and
Fast DDS's settings every node process of ours starts with (`fastdds_profile.xml`).

The one place these are spelled: the `formation` command (ROS-free) checks its arguments against
them, the runtime (rclpy) reserves domains and cleans shared memory with them, the node processes
pick their executor by these names.
"""

from __future__ import annotations

import os
from pathlib import Path

# ROS_DOMAIN_ID: Fast DDS maps domain d to the UDP ports RTPS_PORT_BASE + RTPS_DOMAIN_GAIN d + …;
# 232 is the ROS 2 documentation's largest id on Linux (there, participant p's unicast ports
# 7400 + 250 d + 10 + 2p (+1) stay below 65536 for p <= 62).
DOMAIN_ID_MAX = 232
RTPS_PORT_BASE = 7400
RTPS_DOMAIN_GAIN = 250  # ports of one domain: [base + gain d, base + gain (d + 1))
UNICAST_OFFSET = 10  # participant 0's unicast discovery port: base + gain d + 10 (metatraffic), + 11 (user)

FASTDDS_PROFILE = Path(__file__).with_name('fastdds_profile.xml')
"""Fast DDS's settings for every node process of ours: participants announce themselves every
0.1 s at first, writers heartbeat every 0.1 s (the file says why).  A robot's agent started on
its own needs them as much as a run's processes: with Fast DDS's default 3 s heartbeat, a robot
whose driver was frozen for 3 s while its agent stopped never took the zero command (the agent
waited DELIVERY_TIMEOUT for its acknowledgement and left; 4 runs of 4 here), and on CI a 2 s
freeze failed the same way (tests/formation_agent/ros/test_main.py)."""

FASTDDS_PROFILE_VARIABLE = 'FASTRTPS_DEFAULT_PROFILES_FILE'  # the name Jazzy's Fast DDS 2.14 reads


def use_our_fastdds_profile(env: dict[str, str] | os._Environ[str] = os.environ) -> None:
    """Point Fast DDS at FASTDDS_PROFILE in `env` (default: this process's, before its first
    participant is made), unless it names a file already: a user's own file wins."""
    env.setdefault(FASTDDS_PROFILE_VARIABLE, str(FASTDDS_PROFILE))


EXECUTORS = ('events', 'single')
"""Executors a node process can spin: rclpy's EventsExecutor (default) or SingleThreadedExecutor."""
DEFAULT_EXECUTOR = EXECUTORS[0]


def domain_id_ok(domain_id: int) -> bool:
    """Whether `domain_id` is a ROS_DOMAIN_ID a run may use: 0 <= d <= DOMAIN_ID_MAX."""
    return 0 <= domain_id <= DOMAIN_ID_MAX


def domain_ports(domain_id: int) -> range:
    """The RTPS ports of ROS domain `domain_id` (7400 + 250 d + [0, 250)) under Fast DDS' port mapping."""
    first = RTPS_PORT_BASE + RTPS_DOMAIN_GAIN * domain_id
    return range(first, first + RTPS_DOMAIN_GAIN)


def participant0_ports(domain_id: int) -> tuple[int, int]:
    """The unicast ports (metatraffic, user) of participant 0 in `domain_id`: free when no run uses it."""
    first = domain_ports(domain_id).start + UNICAST_OFFSET
    return first, first + 1


# -- liveliness (formation_msgs_py.qos builds the profiles with these) ------------------------------

LIVELINESS_LEASE = 1.0
"""Seconds without a sign of life after which DDS declares a writer of the protocol lost.

Liveliness is asserted by DDS itself (AUTOMATIC), not by Python code, so a busy agent stays alive
and only a dead process, or a network that no longer reaches it, is declared lost.  Every node of
a run must use the same lease: a reader asking for a shorter lease than its writer offers does
not match it.
"""

LOST_GRACE = 0.5
"""Seconds a node waits after a peer is declared lost before acting, so that what the peer sent
before it left (already delivered, not yet taken) is handled first."""

KEEPER_LEASE_GRACE = 3.0
"""Seconds a lock-step agent waits after its time keeper's lease lapsed (its writer still in the
graph) before leaving. Nothing moves while the keeper is silent, and a keeper that is briefly
unable to assert its liveliness must be left the time to end the run itself: after a SIGKILLed
agent, Fast DDS's shared-memory port health check stalled the keeper's writers for ~1.4 s here,
its neighbours left too, and the run reported them lost along with the dead one. Longer than the
keeper's own LIVELINESS_LEASE + LOST_GRACE toward a lost agent; on the wall clock (robots) an
agent keeps LOST_GRACE, since there its robot would go on moving."""
