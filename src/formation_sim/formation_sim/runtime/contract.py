"""What the parent of a run (`launch`) and its node programs (`nodes`) agree on, without ROS.

The launch side writes the run folder and starts the node programs; the node programs read it.
Both import this module, and the launch side imports no node module (tests/test_layout.py):

- the parameter files' names in a run folder (`SIMULATOR_FILE`, `COORDINATOR_FILE`) and the
  graph the time keeper writes at the end (`GRAPH_FILE`);
- the parameters an agent's node gets (`agent_parameters`: what that agent knows of the scenario);
- the topics per backend, as a recorder wants them (`formation_topics` for `exact`,
  `robot_run_topics` for robots; both rows of `formation_msgs_py.topic_table`), and the robot
  topic the formation is measured on (`TRAJECTORY_TOPICS`).
"""

from __future__ import annotations

from formation_agent.core.kinds import robot_kind
from formation_msgs_py.topic_table import EXACT, ODOM, POSE, ROBOTS, TRUE_ODOM, recorded_topics
from formation_msgs_py.topics import robot_odom_topic, robot_pose_topic, robot_true_odom_topic
from formation_sim.model.scenario import Scenario, SingleGains

SIMULATOR_FILE = 'simulator.params.yaml'  # its parameters in a run folder (formation run, formation params)
COORDINATOR_FILE = (
    'coordinator.params.yaml'  # its parameters in a run folder (formation run, formation params)
)
GRAPH_FILE = 'graph.json'  # the ROS graph the time keeper saw, written at the end of a run

TRAJECTORY_TOPICS = {'true_odom': robot_true_odom_topic, 'odom': robot_odom_topic, 'pose': robot_pose_topic}
"""Which robot topic (agent id -> name) the formation is measured on, by `robot_trajectory`."""


def formation_topics(scenario: Scenario) -> list[tuple[str, str]]:
    """Every topic of a run of `scenario` with its type, as a recorder wants them: the exact
    backend's rows of the topic table (`formation_msgs_py.topic_table`)."""
    return recorded_topics(
        backend=EXACT,
        agent_ids=scenario.agent_ids,
        neighbours=scenario.neighbours,
        conditions={scenario.dynamics},
    )


def robot_run_topics(
    scenario: Scenario, *, model: str, simulated: bool, pose_type: str, truth: bool | None = None
) -> list[tuple[str, str]]:
    """Every topic of a robot run with its type, as a recorder wants them: the protocol, the
    triggering information, and per robot the poses its agents read (`pose_type`), its command
    and the topic the formation is measured on: with `truth` (default: simulated) a simulated
    robot's noise-free `true_odom`, else its `odom` (a noise-free simulated robot's odometry is
    exact: `launch.plan.RobotOptions.odometry_is_truth`); real robots: both pose topics, whichever
    they have."""
    truth = simulated if truth is None else truth
    conditions = {POSE} if pose_type == 'pose' or not simulated else set()
    if pose_type == 'odom' or not simulated or not truth:
        conditions.add(ODOM)
    if truth:
        conditions.add(TRUE_ODOM)
    return recorded_topics(
        backend=ROBOTS,
        agent_ids=scenario.agent_ids,
        neighbours=scenario.neighbours,
        conditions=conditions,
        command_type=robot_kind(model).command_type,
    )


def agent_parameters(
    scenario: Scenario, agent_id: int, *, horizon: float, extra_subscribers: int = 0
) -> dict[str, object]:
    """ROS parameters of agent `agent_id`'s node (what that agent knows of the scenario)."""
    # the agent's parameter table loads rclpy: imported here, so that the launch side starts without it
    from formation_agent.ros.config import SAFETY_PARAMETERS

    neighbours = scenario.neighbours(agent_id)
    gains = scenario.gains
    params: dict[str, object] = {
        'agent_id': int(agent_id),
        'neighbour_ids': [int(j) for j in neighbours],
        'neighbour_offsets': [float(v) for d in neighbours.values() for v in d],
        'dimension': scenario.dimension,
        'delta': float(scenario.delta),
        'horizon': float(horizon),
        'extra_subscribers': int(extra_subscribers),
        # κ and c0 (docs/SPEED_SCALE.md): the agent derives its real-time gains from them
        'speed_scale': float(gains.speed_scale),
        'threshold_floor': float(gains.threshold_floor),
        'trigger_rule': scenario.trigger_rule,  # the threshold's family (formation_agent.core.trigger)
    }
    if scenario.safety is not None:  # the safety layer's keys (docs/SAFETY.md), as the agent names them
        params.update({name: float(getattr(scenario.safety, key)) for key, name in SAFETY_PARAMETERS.items()})
        # on robots the agent reads these robots' poses to see those within R (sensing: poses)
        params['other_robot_ids'] = [
            int(j) for j in scenario.agent_ids if j != agent_id and j not in neighbours
        ]
    if isinstance(gains, SingleGains):  # the scenario's dynamics 'single' (its gains are checked by it)
        params.update(algorithm='eta1', alpha=float(gains.alpha), beta=float(gains.beta))
    else:
        params.update(
            algorithm='eta2',
            alpha_d=float(gains.alpha_d),
            beta_d=float(gains.beta_d),
            k1=float(gains.k1),
            k2=float(gains.k2),
            k3=float(gains.k3),
        )
    return params
