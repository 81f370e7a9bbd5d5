"""Messages of the formation runtime: ROS-free dataclasses, topic names, the lock-step protocol,
and their encoding over standard Jazzy types.

- `types`: `TriggerInfo` (what an agent broadcasts at its triggering times), `SensedState`
  (what its sensing service returns) and `RobotPose` (a robot's pose as it arrives);
  `lockstep`: `Step`, `Status`, `WorldState`, `AgentReport` (with `Saturation`) and the reasons
  a message is rejected; `topics`: every topic, service and node name; `middleware`: ROS domain
  ids and their ports, executors, the liveliness lease and graces; `exit_codes`: `ExitCode`, every
  exit status of the project.
- `codec` (rclpy message classes, imported lazily): encoders and decoders; `qos` (rclpy): the
  protocol's quality of service.

Everything here but `codec` and `qos` imports without ROS.
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'types': ('MAX_AGENT_ID', 'RobotPose', 'SensedState', 'TriggerInfo'),
        'lockstep': (
            'AgentReport',
            'Saturation',
            'Status',
            'Step',
            'WorldState',
            'DISCOVERY_STEP',
            'STEP_FLAG_FINAL',
            'STEP_FLAG_REALTIME',
            'REJECT_REASONS',
            'SATURATION_KINDS',
        ),
        'topics': (
            'STEP_TOPIC',
            'STATUS_TOPIC',
            'REPORT_TOPIC',
            'STATE_TOPIC',
            'GROUND_TRUTH_TOPIC',
            'SENSING_LOG_TOPIC',
            'SCENARIO_TOPIC',
            'MARKERS_TOPIC',
            'CLOCK_TOPIC',
            'ROBOTS_TOPIC',
            'agent_namespace',
            'trigger_info_topic',
            'sense_service',
            'command_topic',
            'robot_pose_topic',
            'robot_odom_topic',
            'robot_command_topic',
            'robot_true_odom_topic',
        ),
        'codec': (),
        'exit_codes': ('ExitCode',),
        'errors': ('FormationError', 'MessageError'),
    },
)
