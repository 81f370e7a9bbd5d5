"""How `FormationRun` runs a scenario: its options, and the one check of them.

`RunOptions` holds every option but the scenario and the run folder; `RunOptions.check(scenario)`
refuses what cannot run (a `RunError` naming the option and its value) before any process starts
or anything on disk changes, and returns the options completed for that scenario (the horizon,
the clock, the robots and the agents per process filled in), as `RobotOptions.check` does for
the robots.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable, Mapping, Sequence

from formation_msgs_py.middleware import DEFAULT_EXECUTOR, EXECUTORS
from formation_sim.model.scenario import Scenario
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.backends import BACKENDS, EXACT, backend_kind
from formation_sim.runtime.launch.plan import (
    DISCOVERY_MODES,
    DOMAIN_RANGE,
    INJECT_KEYS,
    RobotOptions,
    discovery_server_program,
    resolve_agents_per_process,
)
from formation_sim.sim.engine import check_sample_dt
from formation_sim.sim.errors import EngineError

CLOCKS = ('lockstep', 'realtime')


@dataclasses.dataclass(frozen=True, kw_only=True)
class RunOptions:
    """How a scenario is run (every field has the default of `formation run`).

    `horizon`: the run's end [s] (None: the scenario's).  `domain_id`: the ROS domain (None: a
    free one).  `agents_per_process`: agent nodes sharing one process, or 'auto' (one process per
    agent up to 24 agents, beyond that the team in at most 6 processes:
    launch.resolve_agents_per_process).  `record`: an MCAP bag of the run.  `localhost_only`: DDS
    discovery on this machine only.  `progress`: progress lines on stderr.  `sample_period`: the
    trajectory's sampling [s].  `timeout`: give up after this long [s] (None: never).
    `backend`: 'exact' (the simulator's exact world), a robot kind ('holonomic', 'unicycle', …
    `formation_agent.core.kinds`: simulated robots of that kind), 'external' (the robots are
    whatever publishes their poses and takes their commands).  `robots`: the robots of all but
    'exact' (default: the backend's model with no limits; `external` needs it).  `clock`:
    'lockstep' (sim time, exact; the default of `exact`) or 'realtime' (wall clock; robots always
    run on it).  `executor`: the rclpy executor of the time keeper and agent processes, 'events'
    (rclpy.experimental.EventsExecutor) or 'single' (SingleThreadedExecutor).  `stop_timeouts`:
    seconds after SIGINT, then after SIGTERM, before the next signal.  `inject`: fault injection
    on the agents' arriving triggering information, keys `loss` (probability), `delay_ms`,
    `jitter_ms`, `seed` (a test facility; loss needs the wall clock).  `launch_prefix`: child name
    ('simulator', 'coordinator', 'recorder', 'agent_<i>', 'agents_<i>-<j>', 'robot_<i>', …) ->
    command put before its python, e.g. ['ip', 'netns', 'exec', 'host1'] to run it on another
    network stack.  `extra_env`: variables set for every child (e.g. FASTDDS_BUILTIN_TRANSPORTS).
    `step_listeners`: nodes outside the run (a live monitor, a test's fault injector) that must
    hear every Step: step 0 waits until that many more readers of it are matched.  `discovery`:
    'simple' (Fast DDS's simple discovery, every participant announces itself to every other) or
    'server' (a Fast DDS discovery server, started first as one of the run's children, through
    which every other child discovers the rest: ROS_DISCOVERY_SERVER).  `summary_extra`: entries
    added to summary.json's `extra` as given (`formation run --speed-scale auto` records the κ it
    chose and why: `speed_scale`).  None for a mapping: an empty one.
    """

    horizon: float | None = None
    domain_id: int | None = None
    agents_per_process: int | str = 1
    record: bool = True
    localhost_only: bool = True
    progress: bool = True
    sample_period: float = 0.01
    timeout: float | None = None
    backend: str = 'exact'
    robots: RobotOptions | None = None
    clock: str | None = None
    executor: str = DEFAULT_EXECUTOR
    stop_timeouts: tuple[float, float] = (5.0, 3.0)
    inject: Mapping[str, float] | None = dataclasses.field(default_factory=dict)
    launch_prefix: Callable[[str], Sequence[str]] | None = None
    extra_env: Mapping[str, str] | None = dataclasses.field(default_factory=dict)
    step_listeners: int = 0
    discovery: str = 'simple'
    summary_extra: Mapping | None = dataclasses.field(default_factory=dict)

    def check(self, scenario: Scenario) -> RunOptions:
        """These options completed for `scenario`; RunError naming the first one that cannot run."""
        horizon = float(scenario.horizon if self.horizon is None else self.horizon)
        _check_numbers(self, scenario, horizon)
        agents_per_process = resolve_agents_per_process(self.agents_per_process, len(scenario.agent_ids))
        if scenario.dimension > 3:
            raise RunError(
                f'distributed runs need p <= 3 (geometry_msgs commands), got p = {scenario.dimension}'
            )
        backend, clock, robots = _check_world(self, scenario)
        if self.executor not in EXECUTORS:
            raise RunError(f'executor must be one of {EXECUTORS}, got {self.executor!r}')
        _check_inject(self.inject or {}, clock)
        if self.step_listeners < 0:
            raise RunError(f'step_listeners must be >= 0, got {self.step_listeners}')
        if self.discovery not in DISCOVERY_MODES:
            raise RunError(f'discovery must be one of {DISCOVERY_MODES}, got {self.discovery!r}')
        if self.discovery == 'server':
            discovery_server_program()  # RunError now, before anything starts, if it is not installed
        return dataclasses.replace(
            self,
            horizon=horizon,
            backend=backend,
            clock=clock,
            robots=robots,
            agents_per_process=agents_per_process,
            inject=dict(self.inject or {}),
            extra_env=dict(self.extra_env or {}),
            summary_extra=dict(self.summary_extra or {}),
        )


def _check_numbers(options: RunOptions, scenario: Scenario, horizon: float) -> None:
    """The horizon, the domain, the sampling and the timeout."""
    if not (math.isfinite(horizon) and horizon >= sys.float_info.min):
        # (the smallest normal double: a ROS parameter file cannot carry a subnormal one)
        raise RunError(f'horizon must be a finite number > 0, got {horizon!r}')
    domain_id = options.domain_id
    if domain_id is not None and not (isinstance(domain_id, int) and 0 <= domain_id <= DOMAIN_RANGE[1]):
        raise RunError(f'domain id must lie in [0, {DOMAIN_RANGE[1]}], got {domain_id!r}')
    try:
        check_sample_dt(options.sample_period, horizon=horizon, scenario=scenario)
    except EngineError as error:
        raise RunError(f'sample_period: {error}') from None
    # Any backend but the exact world (a name that is none is refused after, by `_check_world`).
    if options.backend != EXACT.name and not options.sample_period:
        raise RunError(
            'sample_period must be > 0 on robots (the poses are sampled on its grid), '
            f'got {options.sample_period!r}'
        )
    timeout = options.timeout
    if timeout is not None and not (
        isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0.0
    ):
        raise RunError(f'timeout must be a finite number of seconds > 0, got {timeout!r}')


def _check_world(options: RunOptions, scenario: Scenario) -> tuple[str, str, RobotOptions | None]:
    """The backend, its clock and its robots: (backend, clock, robots) completed."""
    backend, robots = options.backend, options.robots
    kind = backend_kind(backend)  # RunError: not one of BACKENDS
    clock = options.clock if options.clock is not None else kind.default_clock
    if clock not in CLOCKS:
        raise RunError(
            f"clock must be 'lockstep' (sim time, exact) or 'realtime' (wall clock), got {clock!r}"
        )
    if not kind.on_robots:
        if robots is not None:
            raise RunError(
                f'robots are options of the robot backends {tuple(BACKENDS[1:])}, not of {EXACT.name!r}'
            )
        return backend, clock, None
    if clock not in kind.clocks:
        raise RunError(
            f'robots run on the wall clock: backend {backend!r} needs clock=realtime, got {clock!r}'
        )
    if robots is None:
        if not kind.simulated_robots:  # external: the run cannot tell what they are
            raise RunError("backend 'external' needs robots=RobotOptions(model=...): what the robots are")
        robots = RobotOptions(model=backend)
    if kind.simulated_robots and backend != robots.model:
        raise RunError(
            f'backend {backend!r} simulates {backend} robots, but robots.model is {robots.model!r}'
        )
    robots.check(scenario)
    return backend, clock, robots


def _check_inject(inject: Mapping[str, float], clock: str) -> None:
    """Fault injection: known keys, finite values >= 0, a loss probability on the wall clock."""
    if unknown := set(inject) - set(INJECT_KEYS):
        raise RunError(f'inject: unknown keys {sorted(unknown)} (known: {list(INJECT_KEYS)})')
    for key, value in inject.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
            raise RunError(f'inject: {key} must be a finite number >= 0, got {value!r}')
    if inject.get('loss', 0.0) > 1.0:
        raise RunError(f'inject: loss is a probability in [0, 1], got {inject["loss"]!r}')
    if inject.get('loss', 0.0) > 0.0 and clock != 'realtime':
        raise RunError(
            'inject: loss needs the wall clock (clock=realtime, --real-time): lock-step waits for '
            'every message sent, so a dropped one stalls the run'
        )
