"""The distributed runtime (rclpy, Fast DDS), in three roles (docs/DESIGN.md, "Packages and layers").

- `nodes`: the node programs, each run in a child process: the time keeper (`time_keeper` with
  its books `run_book` and its end `run_end`) holding a `world.World`: `sim_node`'s exact world of
  the `exact` backend with `exact_world` and `sim_view`, or `coordinator`'s robots with
  `robot_poses` and `robot_stops`; the simulated
  robot `robot_node`, the `recorder` (with `bag_qos`), `operator_stop` and `intruders`.
- `launch`: what the parent does: `orchestrate` (`FormationRun` starts a run in a private ROS
  domain, watches it and stops it by PID), `plan` (the backend's launch plan: inputs, processes,
  environment, ROS domain), `run_options`, `supervise` (the children, their Fast DDS files removed
  by `fastdds_shm`), `results`, `fleet` (simulated robots on their own); the Fast DDS settings
  of every process a run starts are formation_msgs_py's (`middleware.FASTDDS_PROFILE`).
- `tools`: live tools: `replay` (bags published again), `graph` (topics and messages of a live graph).
- `contract`: what both sides agree on (parameter-file names, an agent's parameters, the topics
  per backend); nothing under `launch` imports `nodes` (tests/test_layout.py).
- `errors`: every way a run stops early; `testing`: a bag replayed in a test.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'launch.orchestrate': ('FormationRun', 'RunResult'),
        'launch.plan': ('RobotOptions',),
        'nodes.time_keeper': ('TimeKeeperNode',),
        'nodes.world': ('World',),
        'nodes.coordinator': ('FormationCoordinatorNode', 'RobotWorld'),
        'nodes.sim_node': ('FormationSimulatorNode', 'SimulatorError', 'SimulatorWorld'),
        'contract': ('agent_parameters',),
        'nodes.robot_node': ('SimulatedRobotNode',),
        'nodes.recorder': ('RecorderNode',),
        'tools.replay': ('BagPlayer',),
        'errors': ('RecorderError', 'ReplayError', 'RunError'),
    },
)
