"""The distributed runtime (rclpy, Fast DDS): processes, and what starts and watches them.

- `orchestrate`: `FormationRun` starts a run in a private ROS domain, watches it and stops it by
  PID; its pieces: `launch` (the backend's plan: inputs, processes, environment, ROS domain),
  `supervise` (the children, stopped by PID, their Fast DDS files removed by `fastdds_shm`), `results`.
- `time_keeper`: the base of the time keepers (opens, watches and ends a run, whatever its world);
  `run_book`: its books (statuses, reports, lock-step settlement, lost agents and recorders);
  `run_end`: the end of a run (final reports, delivery, summary.json and graph.json).
- `coordinator`: the coordinator node = the time keeper of a robot run (the robots are the world),
  and `main()` of both time keepers.
- `sim_node`: the simulator node = the time keeper plus the exact world, the sensing services and
  the lock-step clock (backend `exact`).
- `robot_node`: a simulated kinematic robot (backends `holonomic`, `unicycle`).
- `recorder`: the recorder node (raw subscriptions into a rosbag2 bag).
- `replay`: bags published again; `graph`: topics and messages of a live ROS graph.
- `fastdds_shm`: the Fast DDS shared-memory files a process holds, and removing those the dead
  left; `fastdds_profile.xml`: the Fast DDS settings of every process a run starts.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'orchestrate': ('FormationRun', 'RunResult'),
        'launch': ('RobotOptions',),
        'time_keeper': ('TimeKeeperNode',),
        'coordinator': ('FormationCoordinatorNode',),
        'sim_node': ('FormationSimulatorNode', 'SimulatorError', 'agent_parameters'),
        'robot_node': ('SimulatedRobotNode',),
        'recorder': ('RecorderNode',),
        'replay': ('BagPlayer',),
        'errors': ('RecorderError', 'ReplayError', 'RunError'),
    },
)
