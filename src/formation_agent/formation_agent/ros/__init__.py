"""The agent's ROS 2 shell (rclpy): the node and what every node process of the project shares.

- `node`: `FormationAgentNode` (one per agent): the lock-step and wall-clock protocol around the core.
  Its pieces: `stepping` (`TriggerSchedule`, ROS-free: when the agent triggers; `Arrivals`: what
  it takes in when), `reporting` (`AgentCounts`, ROS-free: counts, Status, AgentReport) and
  `outbox` (their writers),
  `discovery` (what discovery waits for; `SimulatorWatch`, the simulator's signs of life),
  `staleness` (ROS-free: a stale pose explained, no command from state older than pose_timeout).
- `main`: the `formation_agent` command (one or more nodes per process; exit statuses; the zero
  command on every way out).
- `config`: the node's parameter table (`AGENT_PARAMETERS`, `GAIN_PARAMETERS`) read into an `AgentConfig`.
- `sensing`: where it senses (`ServiceSensing`, `PoseSensing`); `commands`: where its commands
  go (`PlantOutput`, `RobotOutput`); `inbox`: what it refuses to read; `faults`: injected
  faults (a test facility).
- `process`: the executor a node process spins (`make_executor`), SIGINT/SIGTERM as a flag
  (`StopSignals`); the exit statuses are `formation_msgs_py.exit_codes.ExitCode`.
- `parameters`: every node's parameter table (`ParameterSpec`): descriptors for
  `ros2 param describe`, one error naming every bad parameter, the `--help` table;
  `kind_parameters`: the robot parameters every node declares alike (the kinds' shape parameters,
  the robot limits).

QoS profiles of the protocol and the robot topics: `formation_msgs_py.qos`.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'node': ('FormationAgentNode',),
        'main': ('main',),
        'config': ('AgentConfig', 'agent_help', 'read_config'),
        'process': ('EXECUTORS', 'StopSignals', 'make_executor'),
        'parameters': ('ParameterSpec', 'declare_parameters', 'parameter_help', 'read_parameters'),
        'errors': ('AgentNodeError', 'ParameterError', 'PeerLostError', 'PredictionError'),
    },
)
