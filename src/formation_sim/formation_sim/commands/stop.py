"""`formation stop [--domain-id N] [--timeout S]`: the emergency stop of a run, from any terminal.

It calls the run's `/formation/stop` service (std_srvs/srv/Trigger, served by the run's time keeper:
`formation_sim.runtime.nodes.operator_stop`) once, waits at most --timeout for the answer and prints it.
Exit 0 when a run acknowledged; 1 when no run answered on the domain within the timeout (or a run
refused); 2 bad input.  rclpy is imported only once the arguments are good, and nothing of the
scenario model: the command starts fast (`formation_sim.cli` builds its parser alone, `cli.ALONE`).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import socket
import sys
import time

from formation_msgs_py.exit_codes import ExitCode
from formation_msgs_py.middleware import DOMAIN_ID_MAX, domain_id_ok, use_our_fastdds_profile
from formation_msgs_py.topics import STOP_SERVICE

# Its own light pieces, not `formation_sim.commands.common`'s (which loads scipy through the
# scenario model: seconds on a loaded machine); `formation_sim.cli` builds its parser alone.  The
# same rules and words as common's DOMAIN_ID and POSITIVE (tests/formation_sim/commands/test_stop.py).

DEFAULT_TIMEOUT = 5.0  # [s] discovery of the run's time keeper on one machine takes well under a second
DISCOVERY_LOOK = 0.01  # [s] how often it looks whether the stop service is reachable yet
# [s] Once the request is out, its answer gets at least this long, past --timeout if need be: the
# run stops at once but may answer late (it looks up who asked: operator_stop.CALLER_WAIT; a loaded
# machine), and "no run answered" must not be said of a run that is stopping.
ANSWER_WAIT = 3.0


def _domain_id(text: str) -> int:
    rule = f'an integer in [0, {DOMAIN_ID_MAX}] (a ROS_DOMAIN_ID)'
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'must be {rule}, got {text!r}') from None
    if not domain_id_ok(value):
        raise argparse.ArgumentTypeError(f'must be {rule}, got {value!r}')
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'must be a finite number > 0, got {text!r}') from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'must be a finite number > 0, got {value!r}')
    return value


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'stop',
        help='emergency stop: end the run on the ROS domain now, every robot sent a zero command',
        description=f'Call the emergency stop of the run on the ROS domain ({STOP_SERVICE}, '
        'std_srvs/srv/Trigger, served by its simulator or coordinator): the run ends at once with '
        'a final Step, the coordinator sends every robot a zero command itself, and `formation run` '
        'exits 5 with extra.failure.kind = stopped_by_operator (docs/EMERGENCY_STOP.md). '
        f'`ros2 service call {STOP_SERVICE} std_srvs/srv/Trigger` does the same.',
        epilog='Discovery: this machine only (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, as `formation run` '
        'uses by default) unless the environment sets a range or --network is given. Exit status: 0 a run '
        'acknowledged (its answer printed); 1 no run answered on the domain within --timeout, or it '
        'refused; 2 bad input.',
    )
    parser.add_argument(
        '--domain-id',
        type=_domain_id,
        default=None,
        metavar='N',
        help="the run's ROS_DOMAIN_ID (default: the environment's)",
    )
    parser.add_argument(
        '--timeout',
        type=_positive,
        default=DEFAULT_TIMEOUT,
        metavar='S',
        help=f'wait at most S seconds for a run to answer once ROS is up (default {DEFAULT_TIMEOUT:g}; an '
        f'answer to a request already sent gets at least {ANSWER_WAIT:g} s)',
    )
    parser.add_argument(
        '--network',
        action='store_true',
        help='reach runs on other machines (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, as `formation run '
        '--network`)',
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    domain = args.domain_id
    if domain is None:
        text = os.environ.get('ROS_DOMAIN_ID') or '0'
        if not text.strip().isdigit() or not domain_id_ok(int(text)):
            print(
                f'formation stop: error: ROS_DOMAIN_ID={text!r} is not a ROS domain id (give --domain-id N)',
                file=sys.stderr,
            )
            return ExitCode.BAD_INPUT
        domain = int(text)
    _discovery_environment(network=args.network)
    try:
        answer = call_stop(domain_id=domain, timeout=args.timeout)
    except KeyboardInterrupt:
        return 130
    if not isinstance(answer, tuple):
        why = (
            f'the request went out to a {STOP_SERVICE} service at {answer} but no answer came: that run '
            'may be stopping, its output and summary.json say; call again to see'
            if answer
            else f'no {STOP_SERVICE} service reached; is the run on another --domain-id, or another machine: '
            '--network?'
        )
        print(
            f'formation stop: no run answered on domain {domain} within {args.timeout:g} s ({why})',
            file=sys.stderr,
        )
        return ExitCode.FAILED
    success, message = answer
    print(
        f'formation stop: {"" if success else "refused: "}{message}',
        file=sys.stdout if success else sys.stderr,
    )
    return ExitCode.OK if success else ExitCode.FAILED


def _discovery_environment(*, network: bool) -> None:
    """As a run's processes discover (`runtime.launch.plan.child_environment`): Fast DDS with the run's
    settings (announcements every 0.1 s at first: a loaded machine's participants find each other
    sooner), and this machine only unless `network` or the environment's own range."""
    os.environ['RMW_IMPLEMENTATION'] = 'rmw_fastrtps_cpp'
    use_our_fastdds_profile()  # a user's own file wins
    if network:
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SUBNET'
    else:
        os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def caller_name() -> str:
    """The node name the run's summary names as who stopped it: formation_stop_<host>_<pid>."""
    host = re.sub(r'[^A-Za-z0-9_]', '_', socket.gethostname())[:40] or 'host'
    return f'formation_stop_{host}_{os.getpid()}'


def call_stop(*, domain_id: int, timeout: float) -> tuple[bool, str] | str:
    """Call the stop service on `domain_id`: (success, message) of the run that answered; else ''
    when no service was reached within `timeout` seconds (once ROS is up: its start on a loaded
    machine is not the run's), or the time the request went out when no answer came within the
    timeout and `ANSWER_WAIT` after the request.  One call, one bounded wait (no loop of spins)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_srvs.srv import Trigger

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = None
    try:
        node = Node(caller_name(), context=context, start_parameter_services=False, enable_rosout=False)
        deadline = time.monotonic() + timeout
        client = node.create_client(Trigger, STOP_SERVICE)
        # Client.wait_for_service looks every 0.25 s: an emergency stop looks more often.
        while not client.service_is_ready():
            if time.monotonic() >= deadline:
                return ''
            time.sleep(DISCOVERY_LOOK)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        sent = time.strftime('%H:%M:%S')
        future = client.call_async(Trigger.Request())
        wait = max(deadline - time.monotonic(), ANSWER_WAIT)
        executor.spin_until_future_complete(future, timeout_sec=wait)
        response = future.result() if future.done() else None
        return sent if response is None else (bool(response.success), str(response.message))
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
