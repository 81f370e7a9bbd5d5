"""The agent's algorithm, ROS-free: what one agent computes from what it alone knows.

- `eta`: `Eta1Agent` (ETA-1) and `Eta2Agent` (ETA-2): sense-and-broadcast at a trigger, receive
  a neighbour's triggering information, predict the neighbours' relative states in closed form
  ((statexixj), (statexixjd), (stateqiqj)) and find the next triggering time.
- `neighbourhood`: an agent's edges (d_ij, Δ - ||d_ij||, Assumption 1) and the checks of what it is
  handed (`AgentError`).
- `crossing`: the certified search for the first t with ||e_i(t)|| = θ(t), the threshold of a
  triggering rule; `trigger`: the rules (`TriggerRule`; the paper's c0 + α e^{-βt},
  `ExponentialRule`), registered by name.
- `speed_scale`: the speed scale κ and the threshold floor c0: the real-time gains of the agents,
  the exact world and a robot's velocity reference, derived in one place (docs/SPEED_SCALE.md).
- `tension`: ω_ij and its derivatives (the edge-tension weights); `closed_form`: the ETA-2
  closed-loop motion without cancellation.
- On robots (README, "Running on robots"): `kinds` (the registry of robot kinds: each kind's
  control point, command adapter, message type, limits and simulated model), `limits` (`Limits`,
  saturation counts), `kinematics` (control points, the unicycle's diffeomorphism), `pose_sensing`
  (`PoseBook`: SensedState from poses, stale poses refused),
  `velocity_reference` (ETA-2's q_i(t) for velocity-commanded robots), `commander`
  (`RobotCommander`: velocity commands within a robot's `Limits`, clips counted).
"""

from formation_msgs_py._lazy import lazy_exports

__all__ = lazy_exports(
    globals(),
    {
        'eta': ('ALGORITHM_GAINS', 'Eta1Agent', 'Eta2Agent', 'TriggerOutput', 'make_agent'),
        'crossing': (
            'CrossingSearch',
            'DEFAULT_TOLERANCE',
            'ErrorModel',
            'MAX_STEPS',
            'PRECISION_HINT',
            'first_crossing',
        ),
        'trigger': (
            'DEFAULT_RULE',
            'ExponentialRule',
            'TriggerRule',
            'make_rule',
            'register_rule',
            'rule_names',
        ),
        'tension': ('omega', 'omega_prime', 'omega_second'),
        'closed_form': ('advance_double',),
        'speed_scale': ('check_speed_scale', 'check_threshold_floor', 'eta1_gains', 'eta2_gains'),
        'kinematics': ('control_point', 'control_point_velocity', 'rotate', 'unicycle_velocity', 'yaw'),
        'pose_sensing': ('PoseBook',),
        'velocity_reference': ('VelocityReference',),
        'commander': ('Limits', 'RobotCommander', 'SaturationLog'),
        'kinds': ('KIND_NAMES', 'RobotKind', 'register', 'robot_kind'),
        'errors': ('AgentError', 'CrossingError', 'PoseError', 'ScaleError'),
    },
)
