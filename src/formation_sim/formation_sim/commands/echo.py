"""`formation echo TOPIC`: print a live topic's messages readably (formation payloads decoded)."""

from __future__ import annotations

import argparse
import sys

from formation_sim.commands.common import (
    NON_NEGATIVE,
    POSITIVE,
    POSITIVE_INT,
    add_domain_argument,
    inspection_node,
    refuse,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'echo',
        help='print the messages of a live topic (formation layouts decoded)',
        description='Like `ros2 topic echo`, for machines without ros2cli: TriggerInfo, Step, Status '
        'and WorldState (Float64MultiArray layouts of docs/MESSAGES.md) are decoded into their '
        'fields; every other type is printed field by field. Messages are separated by ---.',
    )
    parser.add_argument(
        'topic',
        metavar='TOPIC',
        help=(
            "the topic's name, e.g. /formation/step or /agent_1/trigger_info/to_2 (`formation topics` lists "
            'them)'
        ),
    )
    add_domain_argument(parser)
    parser.add_argument('--count', type=POSITIVE_INT, default=None, metavar='K', help='exit after K messages')
    parser.add_argument(
        '--timeout',
        type=POSITIVE,
        default=None,
        metavar='S',
        help='exit 1 if fewer than --count messages (or none) came within S seconds',
    )
    parser.add_argument(
        '--wait',
        type=NON_NEGATIVE,
        default=10.0,
        metavar='S',
        help='wait up to S seconds for a publisher of TOPIC (default 10)',
    )
    parser.add_argument('--raw', action='store_true', help='do not decode formation layouts')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    if not args.topic.startswith('/'):
        args.topic = f'/{args.topic}'  # relative names resolve in the root namespace, as in ros2 topic echo
    try:
        validate_full_topic_name(args.topic)
    except InvalidTopicNameException as error:
        return refuse('echo', f'argument TOPIC: {error}')
    try:
        with inspection_node('echo', args.domain_id) as node:
            return _echo(node, args)
    except KeyboardInterrupt:
        return 130


def _echo(node, args: argparse.Namespace) -> int:
    """Print the messages of args.topic until --count of them came (0) or --timeout passed (1)."""
    import time

    from rclpy.executors import SingleThreadedExecutor

    from formation_sim.bag.errors import UnknownMessageTypeError
    from formation_sim.runtime.errors import InspectError
    from formation_sim.runtime.nodes.recorder import import_message_class
    from formation_sim.runtime.tools.graph import echo_qos, format_message, to_yaml, wait_for_topic

    try:
        msgtype = wait_for_topic(node, args.topic, timeout=args.wait)
        msg_class = import_message_class(msgtype)
    except (InspectError, UnknownMessageTypeError) as error:
        print(f'formation echo: error: {error}', file=sys.stderr)
        return 1
    received = 0

    def show(msg) -> None:
        nonlocal received
        received += 1
        text = to_yaml(msg) if args.raw else format_message(args.topic, msgtype, msg)
        sys.stdout.write(text + '---\n')
        sys.stdout.flush()

    node.create_subscription(msg_class, args.topic, show, echo_qos(node, args.topic))
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = None if args.timeout is None else time.monotonic() + args.timeout
    while args.count is None or received < args.count:
        if deadline is not None and time.monotonic() > deadline:
            print(
                f'formation echo: {received} message(s) on {args.topic} within {args.timeout} s',
                file=sys.stderr,
            )
            return 1
        executor.spin_once(timeout_sec=0.1)
    return 0
