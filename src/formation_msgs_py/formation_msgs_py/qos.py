"""Quality of service of the formation protocol's topics (reasons: docs/MESSAGES.md).

Every node of a run uses these profiles: a reader asking for more than its writer offers (a
shorter liveliness lease, reliability) does not match it.
"""

from __future__ import annotations

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy

# The leases and graces every node of a run agrees on live in the ROS-free middleware module, so
# that a ROS-free book (formation_sim.runtime.nodes.run_book) can use them; re-exported here.
from formation_msgs_py.middleware import KEEPER_LEASE_GRACE, LIVELINESS_LEASE, LOST_GRACE  # noqa: F401 - re-exported

# Every message of the protocol matters, and a reader that matches a writer late must still get
# what was written before: reliable + transient local.  Depth bounds what may be outstanding; the
# lock-step never has more than one message per edge and step in flight.  Reasons per topic:
# docs/MESSAGES.md, "Quality of service".
PROTOCOL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=32,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    liveliness=LivelinessPolicy.AUTOMATIC,
    liveliness_lease_duration=Duration(seconds=LIVELINESS_LEASE),
)

# The simulator's writers carry up to several messages per lock-step step (state samples at every
# grid point and event), and the recorder, a reliable keep-all reader, can fall behind them on a
# loaded machine; a reliable keep-last writer drops what its reader has not acknowledged once
# its history is full.  A deeper history keeps it (depth is not part of QoS matching).  Not for
# the views (ground truth, markers): transient local keeps `depth` samples for late joiners, and a
# marker array of 300 agents is ~200 KB; they come at most every viz_period.
SIMULATOR_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    reliability=PROTOCOL_QOS.reliability,
    durability=PROTOCOL_QOS.durability,
    liveliness=PROTOCOL_QOS.liveliness,
    liveliness_lease_duration=PROTOCOL_QOS.liveliness_lease_duration,
)

# Every reader of the protocol keeps all it receives until the node takes it.  A reader's keep-last
# history is shared by every writer of its topic (the topics have no key: one instance), so any
# other writer can push a message out before it is taken: with 30+ agents on the simulator's Status
# and report readers (n messages per step), or a foreign node flooding a triggering-information or
# Step topic with junk (1000 messages/s evicted agents' own information and stalled lock-step).
# Kept, a message waits behind the junk but is never lost.  History is not part of QoS matching,
# so writers are unchanged.
READER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_ALL,
    reliability=PROTOCOL_QOS.reliability,
    durability=PROTOCOL_QOS.durability,
    liveliness=PROTOCOL_QOS.liveliness,
    liveliness_lease_duration=PROTOCOL_QOS.liveliness_lease_duration,
)

# -- robots (README, "Running on robots") --------------------------------------------------------

# An agent reads poses best effort, keep last: a best-effort reader matches every writer (motion
# capture drivers publish best effort, odometry usually reliable), and only the latest pose
# matters (a pose that is late is refused by its age anyway).
ROBOT_POSE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)

# What a robot's driver subscribes its cmd_vel with: ROS's default profile (reliable, volatile,
# keep last 10; rclpy's QoSProfile(depth=10)).  History is not part of QoS matching.
DEFAULT_READER_DEPTH = 10

# Velocity commands: reliable (the final zero command must arrive, and the agent waits for its
# acknowledgement), volatile (a robot that connects late must never get an old command replayed),
# and the protocol's liveliness lease, so a coordinator can tell that an agent's command writer is
# gone.  A robot's reader matches if it asks for volatile durability (best effort or reliable) and
# any liveliness lease of at least ours (the default: infinite).
#
# A robot whose process was frozen (SIGSTOP; a driver stalled) finds on resuming every command
# sent meanwhile waiting in its transport (shared memory or its socket): its DDS reader takes them
# in one burst into its history, which keeps the newest `depth` of them, and its callback then runs
# on each in turn: measured, 26 commands sent during a 2 s freeze and a zero, a keep-last-10
# reader's callback ran on 9 stale commands and then the zero, whatever this writer's depth (1 or
# 10: the commands are not re-sent, they were delivered).  Hence the stop publishes the zero command
# `depth` times (`formation_agent.ros.commands`): a default reader holds only zeros then (measured:
# 10 zeros and nothing else), and a robot of ours reads keep-last 1 (ROBOT_COMMAND_READER_QOS).
# The writer's history keeps as many, so a repair re-sends zeros only.
ROBOT_COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=DEFAULT_READER_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    liveliness=LivelinessPolicy.AUTOMATIC,
    liveliness_lease_duration=Duration(seconds=LIVELINESS_LEASE),
)

# A simulated robot's command reader (`formation_sim.runtime.nodes.robot_node`): a robot acts on the
# newest command only, so it keeps only the newest; after a freeze it takes the zero alone
# (measured: only the zero after SIGCONT, where keep-last 10 took 9 stale commands first).
ROBOT_COMMAND_READER_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
