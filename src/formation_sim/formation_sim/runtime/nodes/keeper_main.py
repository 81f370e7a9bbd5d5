"""The process of a time keeper, whichever its world: `main()` of `formation_sim` (the simulator,
`sim_node`) and of `formation_coordinator` (`coordinator`).

It reads the node's parameters (`--help` before ROS starts; bad ones: exit 2, nothing started),
spins the node until its run ends, then ends the run through `run_end` (final reports, delivery,
summary.json and graph.json); a run that stops early (a failure, SIGINT/SIGTERM) ends the same way
after a final Step at the instant it stopped (`stop_and_write`).  How the node is spun is its own
(`World.batched_spin`): the module asks no node for its type.  Exit status: 0 done, 1
failed, 2 bad parameters, 3 an agent or the recorder lost, 4 the robots' measured start breaks the
initial condition (no Step 0, no command), 5 an operator stopped the run (`operator_stop`), 130
interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import traceback
from collections.abc import Sequence

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future

from formation_agent.ros.errors import ParameterError
from formation_agent.ros.parameters import parameter_help
from formation_agent.ros.process import StopSignals, make_executor, release_ros, shutdown_guard
from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.topics import STOP_SERVICE
from formation_sim.runtime.errors import (
    AgentFailedError,
    AgentLostError,
    ConnectivityLostError,
    DiscoveryError,
    ForeignWriterError,
    InitialConditionError,
    KeeperFrozenError,
    OperatorStopError,
    RecorderLostError,
    RobotLostError,
)
from formation_sim.runtime.nodes.run_end import (
    collect_final_reports,
    stop_agents,
    wait_for_delivery,
    write_results,
    write_unstarted,
)
from formation_sim.runtime.nodes.time_keeper import TimeKeeperNode, blamed
from formation_sim.runtime.nodes.world import World

# What ends a run with exit status 3 (a peer lost), and the errors a run names in full (no traceback).
LOST_ERRORS = (AgentLostError, RecorderLostError, RobotLostError)
NAMED_ERRORS = (
    *LOST_ERRORS,
    AgentFailedError,
    ConnectivityLostError,
    DiscoveryError,
    InitialConditionError,
    ForeignWriterError,
    KeeperFrozenError,
    OperatorStopError,
)


def exit_status_of(node: TimeKeeperNode | None, error: Exception) -> int:
    """The time keeper's exit status for a run that stopped on `error`: its first cause decides (an
    operator's stop noted before a later error is still the operator's)."""
    first = None if node is None or node.failure_info is None else node.failure_info['kind']
    if first == OperatorStopError.kind or isinstance(error, OperatorStopError):
        return ExitCode.STOPPED
    if isinstance(error, LOST_ERRORS):
        return ExitCode.LOST
    return ExitCode.REFUSED if isinstance(error, InitialConditionError) else ExitCode.FAILED


def _parser(world_class: type[World]) -> argparse.ArgumentParser:
    return argparse.ArgumentParser(
        prog=world_class.COMMAND,
        description=world_class.DESCRIPTION,
        epilog=parameter_help(world_class.PARAMETERS)
        + f'\n\nExample: {world_class.COMMAND} --ros-args --params-file DIR/{world_class.PARAMS_FILE} '
        '(formation params SCENARIO --out DIR writes it)\n'
        'Exit status: 0 done; 1 the run failed; 2 bad parameters (every problem named, nothing started); '
        "3 an agent or the recorder was lost; 4 the robots' measured start breaks the initial condition "
        f'(nothing was sent); 5 an operator stopped the run ({STOP_SERVICE}, formation stop); '
        '130 interrupted.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def main(args: Sequence[str] | None = None, *, world_class: type[World]) -> int:
    """Run one time keeper holding a world of class `world_class` (the coordinator's robots or the
    simulator's exact world) until the run ends; its exit status."""
    argv = list(args if args is not None else sys.argv)
    _parser(world_class).parse_args(rclpy.utilities.remove_ros_args(argv)[1:])  # --help before ROS starts
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    status = 0
    with StopSignals() as stop:
        try:
            try:
                node = TimeKeeperNode(world_class=world_class)
            except ParameterError as error:  # bad input: every problem named, nothing started
                _tell(f'{world_class.COMMAND}: {error}')
                status = ExitCode.BAD_INPUT  # the shutdown guard's too
                return status
            executor = make_executor(node.executor_kind)
            executor.add_node(node)
            # A coordinator dispatches 0.1 s of events per look at its stop signals and its end (a
            # failure raises from its callback): a spin_once per pose cost it more (issue 19). The
            # simulator takes one event per look, its failure flag checked after each.
            batched, never = node.world.batched_spin, Future()
            while not node.finished:
                if batched:
                    executor.spin_until_future_complete(never, timeout_sec=0.1)
                else:
                    executor.spin_once(timeout_sec=0.1)
                stop.check()
                if node.failure is not None:
                    raise node.failure
            if node.failure is not None:  # it sent its final Step at once
                raise node.failure
            collect_final_reports(node, executor)
            node.mark('final_reports')
            node.world.after_final_step(executor)
            wait_for_delivery(node, executor)
            node.mark('delivered')
            if node.progress_period > 0.0:
                node.print_progress()
            if node.out_dir:
                try:
                    write_results(node)
                except OSError as error:  # e.g. a full disk: the run itself went well
                    _tell(f'formation_sim: cannot write the results: {error}')
                    status = ExitCode.FAILED
        except (KeyboardInterrupt, ExternalShutdownException) as error:
            status = ExitCode.INTERRUPTED
            stop_and_write(node, executor, error)
        except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
            if stop.received.is_set() or not rclpy.ok():  # stopped on purpose while it failed
                status = ExitCode.INTERRUPTED
                stop_and_write(node, executor, KeyboardInterrupt())
                return status
            error = error if node is None else blamed(node, error)  # its cause first (issue 28)
            _tell(f'formation_sim: {error}')
            if not isinstance(error, NAMED_ERRORS):
                with contextlib.suppress(OSError):
                    traceback.print_exc(file=sys.stderr)
            status = exit_status_of(node, error)
            stop_and_write(node, executor, error)
        finally:
            with shutdown_guard(world_class.COMMAND, lambda: status, announce=node is not None):
                release_ros(executor, [] if node is None else [node])
                executor = None  # its C++ teardown, under the guard
    return status


def stop_and_write(node: TimeKeeperNode | None, executor, error: BaseException) -> None:
    """A run stopped early after step 0 (a failure, SIGINT/SIGTERM): a final Step at the instant
    it stopped, the samples up to it and the agents' final reports, as at the horizon, so that the
    bag ends where the summary does; then the summary of what happened, and why it stopped."""
    if node is None:
        return
    node.fail(error)
    if executor is not None:
        try:
            stop_agents(node, executor)
        except Exception as problem:  # noqa: BLE001 - the original failure is what matters
            _tell(f'formation_sim: could not stop the agents: {problem}')
            stop_robots_all_the_same(node, executor)
        node.note_what_followed()
        if node.failure_info is not None and 'followed' in node.failure_info:
            _tell(f'formation_sim: {node.failure_info["message"]}')
    if not node.out_dir:
        return
    try:
        write_results(node) if node.step is not None else write_unstarted(node)
    except Exception as problem:  # noqa: BLE001 - the original failure is what matters
        _tell(f'formation_sim: could not write the partial results: {problem}')


def stop_robots_all_the_same(node: TimeKeeperNode, executor) -> None:
    """The orderly end failed (`stop_agents` raised, the final reports not collected): every robot
    its zero command from here all the same, and the world's wait for it to be acknowledged
    (`after_final_step`, bounded), so that no robot drives on after its run, whatever ended it."""
    try:
        node.world.stop_robots(why='the run could not be ended in order')
        node.world.after_final_step(executor)
    except Exception as problem:  # noqa: BLE001 - the original failure is what matters
        _tell(f'formation_sim: could not stop the robots: {problem}')


def _tell(line: str) -> None:
    """A line on stderr (the run's log), if it can still be written (the disk may be full)."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr, flush=True)
