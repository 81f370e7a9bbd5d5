"""Names of every topic, service and node of a run: the one place they are spelled (ROS-free).

Agent-side names are absolute defaults; the agent node resolves them in its own namespace
`/agent_<i>`, so a robot integration can remap them (docs/MESSAGES.md).
"""

from __future__ import annotations

STEP_TOPIC = '/formation/step'  # lock-step: simulator -> agents
STATUS_TOPIC = '/formation/status'  # lock-step: agents -> simulator
REPORT_TOPIC = '/formation/agent_report'  # agents' rejected/injected counts
STATE_TOPIC = '/formation/state'  # exact world state (tools only)
GROUND_TRUTH_TOPIC = '/formation/ground_truth'  # PoseArray (tools only)
SENSING_LOG_TOPIC = '/formation/sensing_log'  # one record per sensing call (tools only)
SCENARIO_TOPIC = '/formation/scenario'  # the run's scenario YAML, once (tools only)
MARKERS_TOPIC = '/formation/markers'  # Foxglove view (tools only)
RECORDER_TOPIC = '/formation/recorder'  # the recorder's heartbeat: its liveliness is its sign of life
CLOCK_TOPIC = '/clock'
ROBOTS_TOPIC = '/formation/robots'  # what the robots of a robot run are (JSON, once; tools only)
STOP_SERVICE = '/formation/stop'  # std_srvs/srv/Trigger: the run's emergency stop (its time keeper serves it)
WORLD_FRAME = 'world'  # the default frame_id of poses, holonomic commands and the tools' views

# Node names: the time keepers and the recorder in the root namespace, agents and simulated robots
# each in its agent's namespace (agent_namespace(i)/AGENT_NODE).
SIMULATOR_NODE = 'formation_simulator'
COORDINATOR_NODE = 'formation_coordinator'
RECORDER_NODE = 'formation_recorder'
AGENT_NODE = 'formation_agent'
ROBOT_NODE = 'simulated_robot'


def agent_namespace(agent_id: int) -> str:
    return f'/agent_{agent_id}'


def trigger_info_topic(sender: int, receiver: int) -> str:
    """The per-edge topic on which `sender` broadcasts its triggering information to `receiver`."""
    return f'{agent_namespace(sender)}/trigger_info/to_{receiver}'


def sense_service(agent_id: int) -> str:
    return f'{agent_namespace(agent_id)}/sense'


def command_topic(agent_id: int, *, double: bool) -> str:
    return f'{agent_namespace(agent_id)}/{"cmd_accel" if double else "cmd_vel"}'


# -- robots (README, "Running on robots"): what a robot, real or simulated, speaks --------------


def robot_pose_topic(agent_id: int) -> str:
    """geometry_msgs/PoseStamped of robot i in the world frame (motion capture, a simulated robot)."""
    return f'{agent_namespace(agent_id)}/robot/pose'


def robot_odom_topic(agent_id: int) -> str:
    """nav_msgs/Odometry of robot i: pose in the world frame, twist in its body frame (REP 105)."""
    return f'{agent_namespace(agent_id)}/robot/odom'


def robot_command_topic(agent_id: int) -> str:
    """Velocity command to robot i: geometry_msgs/TwistStamped in the world frame (holonomic) or
    geometry_msgs/Twist in its body frame, (v, ω) (differential drive)."""
    return f'{agent_namespace(agent_id)}/robot/cmd_vel'


def robot_true_odom_topic(agent_id: int) -> str:
    """nav_msgs/Odometry of a *simulated* robot i as it truly is: no noise, no latency.  For tools
    and the run's summary only; an agent never reads it (a real robot has no such topic)."""
    return f'{agent_namespace(agent_id)}/robot/true_odom'
