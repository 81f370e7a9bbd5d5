"""The distributed runtime (rclpy, Fast DDS): processes, and what starts and watches them.

- `orchestrate`: `FormationRun` starts a simulator, one process per agent (or per group), and a
  recorder in a private ROS domain, watches them and stops them by PID.
- `sim_node`: the simulator node (the true world, the sensing services, the lock-step clock).
- `recorder`: the recorder node (raw subscriptions into a rosbag2 bag).
- `replay`: bags published again; `graph`: topics and messages of a live ROS graph.
- `fastdds_shm`: the Fast DDS shared-memory files a process holds, and removing those the dead
  left; `fastdds_profile.xml`: the Fast DDS settings of every process a run starts.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(globals(), {
    'orchestrate': ('FormationRun', 'RunError', 'RunResult'),
    'sim_node': ('FormationSimulatorNode', 'SimulatorError', 'agent_parameters'),
    'recorder': ('RecorderError', 'RecorderNode'),
    'replay': ('BagPlayer', 'ReplayError'),
})  # fmt: skip
