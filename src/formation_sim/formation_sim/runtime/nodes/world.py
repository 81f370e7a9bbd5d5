"""What a time keeper holds: its run's world, an object behind the `World` Protocol.

The time keeper (`time_keeper.TimeKeeperNode`) holds the run's life cycle (discovery, step 0, the
agents and recorders watched, the end); the world is everything a backend adds to it.  One class
per backend (as crazyswarm2 has one object per backend), picked by the node program: the exact
world of the simulator (`sim_node.SimulatorWorld`: the exact integration, every agent's sensing
service, the tools' view) and the robots (`coordinator.RobotWorld`: their poses, their zero
commands, the measured start).

A world class is made with the keeper (`WorldClass(keeper)`, once the keeper's own publishers and
readers exist) and reads what it needs of the run from it (its scenario, books, step, publishers).
What the keeper asks of it, and when (member: when the keeper uses it; what it is for):

Before the node exists (class attributes and static methods):
- `PARAMETERS`, `COMMAND`, `PARAMS_FILE`, `DESCRIPTION`, `NODE_NAME`: `keeper_main.main` (`--help`
  before ROS starts) and the keeper's constructor; the node's parameters, console script,
  parameter file, `--help` text and node name.
- `problems(values, scenario)`: reading the parameters, before anything is set up; the rules
  between the world's parameters and the scenario, each broken one named (one `ParameterError`).
- `clock_mode_of(values)`: likewise; 'lockstep' or 'realtime'.
- `serves_sensing`: the books (`RunBook`), the watched topics, an unstarted summary's mode; it
  answers the agents' sensing (knows when each is due), else it learns triggers from the agents.
- `watched_writer`: discovery's progress lines; which writer of an agent is its sign of life.
- `batched_spin`: `keeper_main.main`; 0.1 s of events per look (else one event per look).

Discovery and step 0:
- `watch_agents()`: once, right after the world is made; per agent, a reader whose writer's DDS
  liveliness is the agent's sign of life.
- `gaps()`: every discovery tick; what discovery still waits for in the world.
- `check_start()`: once, everything connected, before step 0; raises if the world breaks a
  hypothesis (nothing was sent yet), else a note for the progress line ('' or ending in '; ').
- `begin()`: once, after `check_start`; t = 0: Step 0.

The run:
- `tick()`: every keeper tick from step 0 to the end; the world's checks, the final Step at the
  horizon.
- `after_status()`: each Status and each recorder heartbeat; lock-step settles steps here.
- `agent_failed(agent, failure)`: an agent's final report names a failure before the end; the
  world decides what follows.
- `reached_time`: progress lines, failures, the end; the run's time now.
- `stop_robots(why=...)`: an operator's emergency stop (`operator_stop`); every robot its zero
  now, the robots stopped.

The end:
- `stop_unreported_robots()`: after the final Step (`run_end.collect_final_reports`); the robots
  of agents with no final report stopped.
- `after_final_step(executor)`: before the summary; what the world still waits for.
- `flush()`: before delivery; anything still to publish.
- `extra()`: `time_keeper.run_extra`; summary.json's `extra` of the world, also for a run that
  did not start.
- `record()`: `run_end.write_results`; the run as a `RunRecord` (summary.json).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from collections.abc import Sequence

    from formation_agent.ros.parameters import ParameterSpec
    from formation_sim.model.scenario import Scenario
    from formation_sim.sim.record import RunRecord


class World(Protocol):
    """A run's world as its time keeper holds it (the module's table: what each member is for,
    and when the keeper uses it).  The first eight are class attributes: read before the world
    (or the node) exists."""

    PARAMETERS: Sequence[ParameterSpec]
    COMMAND: str
    PARAMS_FILE: str
    DESCRIPTION: str
    NODE_NAME: str
    serves_sensing: bool
    watched_writer: str
    batched_spin: bool

    @staticmethod
    def problems(values: dict, scenario: Scenario) -> list[str]: ...

    @staticmethod
    def clock_mode_of(values: dict) -> str: ...

    def __init__(self, keeper: Any) -> None: ...  # its `time_keeper.TimeKeeperNode` (no import back)

    def watch_agents(self) -> dict: ...

    def gaps(self) -> list[str]: ...

    def check_start(self) -> str: ...

    def begin(self) -> None: ...

    def tick(self) -> None: ...

    def after_status(self) -> None: ...

    def agent_failed(self, agent: int, failure: str) -> None: ...

    @property
    def reached_time(self) -> float: ...

    def stop_robots(self, *, why: str) -> list[int]: ...

    def stop_unreported_robots(self) -> None: ...

    def after_final_step(self, executor) -> None: ...

    def flush(self) -> None: ...

    def extra(self) -> dict: ...

    def record(self) -> RunRecord: ...
