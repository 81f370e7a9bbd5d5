"""The end of a run, driven by `keeper_main.main` once the time keeper's callbacks are done with it.

At the horizon: the agents' final reports, then every reader's acknowledgement of what the node
published, then the results on disk (summary.json, graph.json).  A run that stops early (a fault,
SIGINT/SIGTERM) ends the same way after a final Step at the instant it stopped, so that the bag
ends where the summary does.  Every wait spins the node's executor and is bounded: an agent or a
recorder that went away must not hold the end of the run up.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import rclpy
from rclpy.duration import Duration

from formation_sim.runtime.contract import GRAPH_FILE
from formation_sim.runtime.nodes.run_book import RecorderBook
from formation_sim.runtime.nodes.time_keeper import TimeKeeperNode, run_extra
from formation_sim.sim.files import write_atomically
from formation_sim.sim.summary import SUMMARY_FILE, unstarted_summary, write_summary, write_summary_file

FINAL_REPORTS_TIMEOUT = 3.0  # [s] the longest wait for the agents' final reports
# [s] after the final Step, the robots of agents that have not reported get the zero command from
# the time keeper (a coordinator's `robot_stops.RobotStops`; the exact world stops with the run)
UNREPORTED_STOP_AFTER = 0.5
DELIVERY_TIMEOUT = 5.0  # [s] the longest wait for the readers' acknowledgements


def collect_final_reports(
    node: TimeKeeperNode, executor, *, timeout_sec: float = FINAL_REPORTS_TIMEOUT
) -> None:
    """After the final step: wait (bounded) for every live agent's last report; the robots of
    those not reported after `UNREPORTED_STOP_AFTER` s (or lost) are stopped from here."""
    began = time.monotonic()
    while not node.final_reports_in() and time.monotonic() < began + timeout_sec:
        executor.spin_once(timeout_sec=0.05)
        if time.monotonic() >= began + UNREPORTED_STOP_AFTER:
            node.world.stop_unreported_robots()
    node.world.stop_unreported_robots()


def wait_for_delivery(node: TimeKeeperNode, executor, *, timeout_sec: float = DELIVERY_TIMEOUT) -> None:
    """What is left published, wait (bounded) until every reader acknowledged the Steps and the
    tools' topics."""
    node.world.flush()
    _wait_acknowledged(
        executor, node.delivery_publishers(with_steps=True), recorders=node.recorders, timeout_sec=timeout_sec
    )


def stop_agents(node: TimeKeeperNode, executor) -> None:
    """The run failed: a final Step sends the agents home, with their final reports."""
    if node.step is None or not rclpy.ok():
        return
    node.end_now()
    node.world.flush()
    collect_final_reports(node, executor)
    node.mark('final_reports')
    node.world.after_final_step(executor)  # as at the horizon: the world up to where the run stopped
    # A live agent's final report says it got the final Step; a dead agent (or robot) is still
    # matched as a reader until DDS drops it and would hold an acknowledgement wait up to its
    # timeout: the recorders' heartbeats say when they have the final Step, the tools' topics
    # (the recorders' alone) are acknowledged.  As at the horizon: the bag ends where the summary does.
    _wait_acknowledged(
        executor,
        node.delivery_publishers(with_steps=False),
        recorders=node.recorders,
        timeout_sec=DELIVERY_TIMEOUT,
        final_step=node.step.index + 1,
        recorders_expected=node.extra_subscribers,
    )
    node.mark('delivered')


def _wait_acknowledged(
    executor,
    publishers,
    *,
    recorders: RecorderBook,
    timeout_sec: float,
    final_step: int | None = None,
    recorders_expected: int = 0,
) -> None:
    """Wait (bounded) until every reader acknowledged what `publishers` wrote and, with
    `final_step`, until each of the `recorders_expected` recorders' heartbeats says it recorded
    that Step; not for a recorder that lost its liveliness meanwhile (a frozen one would hold each
    wait up to the end: what it lacks is counted against the bag after the run)."""
    deadline = time.monotonic() + timeout_sec
    pending = list(publishers)

    def recorded() -> bool:
        steps = recorders.recorded_steps.values()
        return final_step is None or (
            len(steps) >= recorders_expected and all(step >= final_step for step in steps)
        )

    while (pending or not recorded()) and recorders.lost is None and time.monotonic() < deadline:
        pending = [pub for pub in pending if not pub.wait_for_all_acked(Duration(seconds=0.05))]
        executor.spin_once(timeout_sec=0.0 if pending else 0.02)


def write_unstarted(node: TimeKeeperNode) -> None:
    """summary.json of a run that failed before t = 0 (discovery): no samples, its failure and
    timestamps (the start-up it spent)."""
    out = Path(node.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    mode = 'distributed' if node.world.serves_sensing else 'robots'
    extra = {**run_extra(node, 0.0), 'started': False}
    write_summary_file(
        unstarted_summary(node.scenario, horizon=node.horizon, mode=mode, extra=extra), out / SUMMARY_FILE
    )


def write_results(node: TimeKeeperNode) -> None:
    """summary.json (through formation_sim.sim.summary) and graph.json into the node's out_dir."""
    out = Path(node.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_summary(node.world.record(), out)
    write_atomically(out / GRAPH_FILE, json.dumps(node.graph, indent=1, sort_keys=True) + '\n')
