"""The `formation_agent` command: one process running one or more agent nodes.

```
formation_agent --ros-args -r __ns:=/agent_2 --params-file team.yaml --params-file robot.yaml
formation_agent --ros-args --params-file agents.params.yaml -p agent_id:=2  # /agent_2 from its id
formation_agent --agents 1,2,3 --ros-args --params-file agents.params.yaml  # packed (`formation run`)
formation_agent --help                                                      # options and the parameter table
```

A node started without `--agents` takes its namespace from the ROS arguments (`-r __ns:=/agent_<i>`)
or, without one, from its `agent_id` (`-p agent_id:=i`, or a parameter file's ``/**`` section).

Exit statuses: 0 the run ended (final Step); 1 the agent failed (a stale pose, a protocol
violation, an error it names); 2 bad parameters (every problem named, nothing started); 3 a peer
was lost (the simulator or coordinator); 130 SIGINT/SIGTERM.  Whichever it is, every node sends
its zero command and its final report before the process exits (`FormationAgentNode.leave`).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from typing import NoReturn

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from formation_agent.core.errors import PoseError
from formation_agent.ros.config import AGENT_PARAMETERS, agent_help
from formation_agent.ros.errors import (
    FaultInjectionError,
    ParameterError,
    PeerLostError,
    PredictionError,
    StaleStateError,
)
from formation_agent.ros.node import DELIVERY_TIMEOUT, NODE_NAME, FormationAgentNode
from formation_agent.ros.parameters import read_parameters
from formation_agent.ros.process import (
    EXECUTORS,
    StopSignals,
    exit_process,
    make_executor,
    release_ros,
    shutdown_guard,
)
from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.middleware import use_our_fastdds_profile
from formation_msgs_py.topics import agent_namespace

SPIN_PERIOD = 0.1
"""Seconds of events the process's loop dispatches, at most, between its looks at the stop signals
(SIGINT/SIGTERM are acted on within it) and at failures raised outside the executor's reach."""

SIGNAL_DELIVERY_TIMEOUT = 1.0
"""Seconds the nodes of a process stopped by SIGINT/SIGTERM wait, at most, for their last messages
(the zero command first) to be acknowledged: a stopped agent exits within 2 s, acknowledged or
not (DELIVERY_TIMEOUT for every other way out)."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='formation_agent',
        description='Run formation agent nodes (one per agent; several share an executor with --agents).',
        epilog='Parameters come from ROS arguments, e.g. --ros-args --params-file agents.yaml, keyed by node '
        'name /agent_<i>/formation_agent (or /** for every node).\n\n' + agent_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        '--executor',
        choices=EXECUTORS,
        default='events',
        help=(
            'rclpy executor: events (rclpy.experimental.EventsExecutor, default) or single '
            '(SingleThreadedExecutor)'
        ),
    )
    parser.add_argument(
        '--agents',
        help='comma-separated agent ids to run in this process, each in namespace /agent_<i> '
        '(default: one node whose namespace and parameters come from the ROS arguments: -r __ns:=/agent_<i>, '
        'or -p agent_id:=i)',
    )
    return parser


def _namespace_from_agent_id() -> str | None:
    """/agent_<i> for a node the ROS arguments put in no namespace but give an agent_id
    (`-p agent_id:=i`, or a parameter file's ``/**`` section); None otherwise (the arguments decide)."""
    probe = rclpy.create_node(NODE_NAME, start_parameter_services=False, enable_rosout=False)
    try:
        if probe.get_namespace() != '/':
            return None  # -r __ns:=... chose it
        values, _ = read_parameters(probe, [spec for spec in AGENT_PARAMETERS if spec.name == 'agent_id'])
        return agent_namespace(values['agent_id']) if 'agent_id' in values else None
    finally:
        probe.destroy_node()


def _build_nodes(options: argparse.Namespace, ros_arguments: Sequence[str]) -> list[FormationAgentNode]:
    if not options.agents:
        named = any('__ns:=' in argument for argument in ros_arguments)  # -r __ns:=/agent_<i> decides
        return [FormationAgentNode(namespace=None if named else _namespace_from_agent_id())]
    ids = [int(text) for text in options.agents.split(',') if text.strip()]
    packed = len(ids) > 1
    # Packed (large teams): no per-node parameter, type description and /rosout endpoints, which
    # every process of the run would discover (~5 of ~20 endpoints an agent node has); the log
    # still goes to the process's own output.
    services = (
        [] if not packed else [Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, Parameter.Type.BOOL, False)]
    )
    return [
        FormationAgentNode(
            namespace=agent_namespace(agent_id),
            start_parameter_services=not packed,
            enable_rosout=not packed,
            parameter_overrides=[Parameter('agent_id', Parameter.Type.INTEGER, agent_id), *services],
        )
        for agent_id in ids
    ]


def _missing_id_hint(error: Exception, options: argparse.Namespace) -> str:
    """Why a node without --agents and without a namespace found no agent_id, and what to do."""
    missing = any(
        problem.startswith("parameter 'agent_id' (int) is required")
        for problem in getattr(error, 'problems', ())
    )
    if not missing or options.agents:
        return ''
    return (
        '. A parameter file keyed by node name, as agents.params.yaml is, gives '
        '/agent_<i>/formation_agent its parameters: name the agent with --agents i, '
        '-r __ns:=/agent_<i> or -p agent_id:=i'
    )


def main(args: Sequence[str] | None = None) -> int:
    argv = list(args if args is not None else sys.argv)
    # --help and bad options end here, before ROS starts (exit 0 / 2, no traceback).
    options = _parser().parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    use_our_fastdds_profile()  # before the participant: a stopped robot's zero is repaired in 0.1 s
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    nodes: list[FormationAgentNode] = []
    executor = None
    status = 0
    failure: str | None = None
    with StopSignals() as stop:
        try:
            began = time.monotonic()
            nodes = _build_nodes(options, argv)
            if len(nodes) > 1:  # how long a packed process takes to be up (large teams)
                nodes[0].get_logger().info(
                    f'{len(nodes)} agent nodes created in {time.monotonic() - began:.1f} s '
                    f'(agents {options.agents})'
                )
            executor = make_executor(options.executor)
            for node in nodes:
                executor.add_node(node)
            # SPIN_PERIOD of events per look at the stop signals and the nodes' failures (a
            # spin_once per event cost more, issue 19); a node that finishes or fails ends it.
            # rclpy's Python executor keeps a done callback on the future per call: one event
            # per look there.
            batched = options.executor == 'events'
            while not all(node.finished for node in nodes):
                if batched:
                    waiting = next(node for node in nodes if not node.finished)
                    executor.spin_until_future_complete(waiting.settled, timeout_sec=SPIN_PERIOD)
                else:
                    executor.spin_once(timeout_sec=SPIN_PERIOD)
                stop.check()
                for node in nodes:
                    node.check()
        except (KeyboardInterrupt, ExternalShutdownException):
            status, failure = 130, 'stopped by a signal'
        except (
            ParameterError,
            FaultInjectionError,
        ) as error:  # bad input: every problem named, nothing started
            print(f'formation_agent: {error}{_missing_id_hint(error, options)}', file=sys.stderr, flush=True)
            status = ExitCode.BAD_INPUT
        except PeerLostError as error:
            print(f'formation_agent: {error}', file=sys.stderr, flush=True)
            status, failure = ExitCode.LOST, str(error)
        except (
            PoseError,
            StaleStateError,
            PredictionError,
        ) as error:  # poses, a freeze or double precision: said in full
            print(f'formation_agent: {error}', file=sys.stderr, flush=True)
            status, failure = 1, str(error)
        except Exception as error:  # noqa: BLE001 - named on the first line, traced below for the log
            if stop.received.is_set() or not rclpy.ok():  # stopped on purpose while it failed
                status, failure = 130, 'stopped by a signal'
            else:
                print(f'formation_agent: {error}', file=sys.stderr, flush=True)
                traceback.print_exc(file=sys.stderr)
                status, failure = 1, str(error)
        finally:
            deadline = _delivery_deadline(
                stop, interrupted=status == 130
            )  # one for every node of the process
            for node in nodes:
                with contextlib.suppress(Exception):  # best effort: the others must still stop
                    node.leave(failure=failure, deadline=deadline)
            with shutdown_guard('formation_agent', lambda: status, announce=bool(nodes)):
                release_ros(executor, nodes)
                executor = None  # its C++ teardown, under the guard
    return status


def _delivery_deadline(stop: StopSignals, *, interrupted: bool) -> Callable[[], float]:
    """Until when (time.monotonic()) the nodes of a leaving process wait for their last messages to
    be acknowledged: DELIVERY_TIMEOUT from now, SIGNAL_DELIVERY_TIMEOUT if a stop signal made them
    leave or comes while they wait (`formation run` stops the agents once the run's end is
    recorded; a reader that died with its process never acknowledges, and is matched until DDS
    drops it)."""
    began = time.monotonic()
    patience = SIGNAL_DELIVERY_TIMEOUT if interrupted else DELIVERY_TIMEOUT

    def deadline() -> float:
        if stop.received_at is None:
            return began + patience
        return min(began + patience, max(began, stop.received_at) + SIGNAL_DELIVERY_TIMEOUT)

    return deadline


def entry_point() -> NoReturn:
    """The `formation_agent` console script: `main()`, then `exit_process` (a plain entry point's
    `sys.exit(main())` would run the interpreter's finalization and C++ static destructors after
    rclpy's shutdown)."""
    exit_process(main())


if __name__ == '__main__':
    entry_point()
