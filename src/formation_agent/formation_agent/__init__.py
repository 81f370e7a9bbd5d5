"""The event-triggered formation agent of Yi et al. (2017): a ROS-free core and its ROS 2 node.

- `formation_agent.core` (no ROS): `Eta1Agent` (ETA-1, Theorem 1) and `Eta2Agent` (ETA-2,
  Theorem 2) — one object per agent holding only what that agent knows —, the certified
  first-crossing search that finds its next triggering time, the edge weights ω_ij.
- `formation_agent.ros` (rclpy): `FormationAgentNode`, the thin node around one core agent,
  and the process plumbing (executors, stop signals, exit statuses) shared by every node.

A robot needs only this package and `formation_msgs_py`. The names below are the core's.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'core.eta': ('ALGORITHM_GAINS', 'Eta1Agent', 'Eta2Agent', 'TriggerOutput', 'make_agent'),
        'core.crossing': ('CrossingSearch', 'first_crossing'),
        'core.errors': ('AgentError', 'CrossingError'),
    },
)
