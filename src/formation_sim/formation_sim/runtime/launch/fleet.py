"""Simulated robots started on their own, as real robots would be: the world of `formation run
--backend external` when no real robots are at hand (README, "Running on robots").

```python
fleet = RobotFleet('robots_square', robots=RobotOptions(model='unicycle'),
                   out_dir='runs/fleet', domain_id=42)  # out_dir new or empty
fleet.run()   # until Ctrl-C / SIGTERM, fleet.stop(), or `duration`
```

Each robot is a `robot_node` process (or `robots_per_process` to one) placed at its agent's
scenario position, in the given ROS domain; the run started there with `--backend external`
finds them by their topics.  The fleet takes no lock on the domain: the run does.

A robot process that dies takes only its own robots with it: the others run on until the fleet
is stopped, as independent robots would (each stops on its agent's zero command, or on its own
command timeout).  Before, the fleet stopped every robot within its 0.25 s poll, so a run on it
saw every robot's poses stop nearly together and once named an agent's stale pose as the first
cause instead of the dead robot (1 external `robot_kill` run of 3, BENCHMARKS.md "Robot faults").
"""

from __future__ import annotations

import dataclasses
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

from formation_agent.ros.process import SignalFlag
from formation_msgs_py.middleware import DEFAULT_EXECUTOR, DOMAIN_ID_MAX, domain_id_ok
from formation_sim.model.scenario import Scenario, load_scenario
from formation_sim.runtime.errors import RunError
from formation_sim.runtime.launch.plan import LOG_DIR, LaunchPlan, RobotOptions
from formation_sim.runtime.launch.supervise import POLL_PERIOD, Supervisor
from formation_sim.sim.errors import RunFolderError
from formation_sim.sim.run_folder import check_out_dir, claim_out_dir


class RobotFleet:
    """The simulated robots of a scenario, each its own process, until stopped."""

    def __init__(
        self,
        scenario: Scenario | str | Path,
        *,
        robots: RobotOptions,
        out_dir: str | Path | None = None,
        force: bool = False,
        domain_id: int,
        localhost_only: bool = True,
        extra_env: dict[str, str] | None = None,
    ) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        if not domain_id_ok(domain_id):
            raise RunError(f'domain id must lie in [0, {DOMAIN_ID_MAX}], got {domain_id}')
        robots.check(self.scenario)
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.force = force
        if self.out_dir is not None:
            try:
                check_out_dir(self.out_dir, force=force)
            except RunFolderError as error:
                raise RunError(str(error)) from None
        self.domain_id = domain_id
        self.localhost_only = localhost_only
        self.extra_env = dict(extra_env or {})
        self.plan = LaunchPlan(
            scenario=self.scenario,
            backend=robots.model,
            out_dir=self.out_dir,
            horizon=self.scenario.horizon,
            clock='realtime',
            record=False,
            agents_per_process=1,
            sample_period=0.01,
            executor=DEFAULT_EXECUTOR,
            step_listeners=0,
            inject={},
            robots=robots,
            localhost_only=localhost_only,
        )
        self.supervisor: Supervisor | None = None
        self.died: list = []  # robot processes that exited on their own, in the order seen
        self._stop = SignalFlag()  # set in a signal handler: no lock (process.SignalFlag)

    def stop(self) -> None:
        self._stop.set()

    def run(self, *, duration: float | None = None, on_death: Callable[[object], None] | None = None) -> int:
        """Start the robots and keep them until stopped; 0, or 3 if a robot process died (the others
        run on; `on_death` is told of each dead process, a `supervise.Child`, when it is seen)."""
        try:
            out = claim_out_dir(
                self.out_dir, scenario_name=self.scenario.name, kind='robots', force=self.force
            )
        except RunFolderError as error:
            raise RunError(str(error)) from None
        self.plan = dataclasses.replace(self.plan, out_dir=out)
        params = self.plan.write_robot_inputs()
        (out / LOG_DIR).mkdir(exist_ok=True)
        env = self.plan.environment(self.domain_id, extra_env=self.extra_env)
        self.supervisor = Supervisor(log_dir=self.plan.out_dir / LOG_DIR, env=env)
        trapped = threading.current_thread() is threading.main_thread()
        previous = (
            {sig: signal.signal(sig, lambda *_: self._stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
            if trapped
            else {}
        )
        try:
            for spec in self.plan.robot_processes(params):
                self.supervisor.start(spec)
            deadline = None if duration is None else time.monotonic() + duration
            while not self._stop.is_set() and (deadline is None or time.monotonic() < deadline):
                self.supervisor.note_exits(time.monotonic())
                for child in self.supervisor.children:
                    if child.exited_at is not None and child not in self.died:
                        self.died.append(child)
                        if on_death is not None:
                            on_death(child)
                if len(self.died) == len(self.supervisor.children):
                    break  # nothing left to run
                self.supervisor.note_shm_files(time.monotonic())
                time.sleep(max(POLL_PERIOD, 0.25))
        finally:
            self.supervisor.stop((5.0, 3.0), domain_id=self.domain_id)
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        return 3 if self.died else 0
