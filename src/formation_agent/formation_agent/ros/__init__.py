"""The agent's ROS 2 shell (rclpy): the node and what every node process of the project shares.

- `node`: `FormationAgentNode` (one per agent; the `formation_agent` command runs one or more).
- `process`: the executor a node process spins (`make_executor`), SIGINT/SIGTERM as a flag
  (`StopSignals`), and exit statuses (`EXIT_PEER_LOST`).
- `parameters`: every node's parameter table (`ParameterSpec`): descriptors for
  `ros2 param describe`, one error naming every bad parameter, the `--help` table.

QoS profiles of the protocol: `formation_msgs_py.qos`.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(globals(), {
    'node': ('AgentNodeError', 'FormationAgentNode', 'PeerLostError', 'main'),
    'process': ('EXECUTORS', 'EXIT_PEER_LOST', 'StopSignals', 'make_executor'),
    'parameters': ('ParameterError', 'ParameterSpec', 'declare_parameters', 'parameter_help'),
})  # fmt: skip
