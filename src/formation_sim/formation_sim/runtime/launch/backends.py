"""The kinds of backend, one table: what the launch side decides by a run's backend, in one place.

A backend's name picks its kind (as crazyswarm2 picks one backend object by name): `exact` is the
simulator's exact world; a registered robot kind's name (`holonomic`, `unicycle`, ...) is simulated
robots of that kind; `external` is robots the run does not start.  Each kind says which time
keeper keeps the run (its child's name, its module, its node, its parameter file), the summary's
mode, the clock a run takes unless told, how long the orchestrator gives the keeper to stop the
run itself after an agent's process is gone, and whether the run starts the robots.  The node side
says the same of itself in its `world.World` classes (`sim_node.SimulatorWorld`,
`coordinator.RobotWorld`: `PARAMS_FILE`, `NODE_NAME`, `clock_mode_of`); the launch side imports no
node module (tests/test_layout.py), so tests/formation_sim/runtime/launch/test_backends.py holds
the two to agreement.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from formation_agent.core.kinds import KindNames
from formation_msgs_py.topics import COORDINATOR_NODE, SIMULATOR_NODE
from formation_sim.runtime.contract import COORDINATOR_FILE, SIMULATOR_FILE
from formation_sim.runtime.errors import RunError

# How long the time keeper may take to notice a lost agent by itself: the DDS liveliness lease, its
# grace, one 0.1 s tick, and margin for a loaded machine (formation_msgs_py.qos.LIVELINESS_LEASE).
LOST_DETECTION = 1.0 + 0.5 + 0.1 + 2.0
# On robots, how long the coordinator may take to stop the run on an agent's final report that
# names its error (it does so at once; margin for a loaded machine).
AGENT_REPORT_DETECTION = 1.0

BACKENDS = KindNames(before=('exact',), after=('external',))  # a simulated robot backend per registered kind


@dataclass(frozen=True, kw_only=True)
class BackendKind:
    """What a kind of backend decides on the launch side (the module's table)."""

    name: str  # the kind: 'exact', 'simulated' or 'external'
    keeper: str  # the time keeper's child name ('simulator' | 'coordinator')
    keeper_module: str  # the module its process runs (`python -m`)
    keeper_node: str  # its node's fully qualified name: the key of its parameter file
    keeper_file: str  # its parameter file in a run folder (runtime.contract)
    mode: str  # summary.json's mode: 'distributed' (the exact world) or 'robots'
    on_robots: bool  # robots are the world: the agents sense poses and command velocities
    default_clock: str  # the clock unless told: 'lockstep' (sim time, exact) or 'realtime'
    clocks: tuple[str, ...]  # the clocks it can run on
    agent_killed_detection: float  # [s] the keeper's time to stop the run after an agent's process died
    agent_failed_detection: float  # [s] ... after an agent's process left naming its error
    simulated_robots: bool  # the run starts the robots (`robot_node`, one per agent)
    endless_poses: bool  # the robots outlive the run: their poses do not hold the recorder's drain up


EXACT = BackendKind(
    name='exact',
    keeper='simulator',
    keeper_module='formation_sim.runtime.nodes.sim_node',
    keeper_node=f'/{SIMULATOR_NODE}',
    keeper_file=SIMULATOR_FILE,
    mode='distributed',
    on_robots=False,
    default_clock='lockstep',
    clocks=('lockstep', 'realtime'),
    # The keeper sees the agent's liveliness lease lapse (lock-step: it waits for it anyway).
    agent_killed_detection=LOST_DETECTION,
    agent_failed_detection=LOST_DETECTION,
    simulated_robots=False,
    endless_poses=False,
)
SIMULATED = BackendKind(
    name='simulated',
    keeper='coordinator',
    keeper_module='formation_sim.runtime.nodes.coordinator',
    keeper_node=f'/{COORDINATOR_NODE}',
    keeper_file=COORDINATOR_FILE,
    mode='robots',
    on_robots=True,
    default_clock='realtime',
    clocks=('realtime',),  # robots run on the wall clock
    # Robots must not wait for a liveliness lease: the orchestrator stops the run at once.
    agent_killed_detection=0.0,
    agent_failed_detection=AGENT_REPORT_DETECTION,
    simulated_robots=True,
    endless_poses=False,
)
EXTERNAL = dataclasses.replace(SIMULATED, name='external', simulated_robots=False, endless_poses=True)


def backend_kind(backend: str) -> BackendKind:
    """The kind of the backend named `backend` (one of `BACKENDS`; else RunError naming it)."""
    if backend == EXACT.name:
        return EXACT
    if backend == EXTERNAL.name:
        return EXTERNAL
    if backend in BACKENDS:  # a registered robot kind, read at this use
        return SIMULATED
    raise RunError(f'backend must be one of {BACKENDS}, got {backend!r}')
