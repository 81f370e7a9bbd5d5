"""`formation topics`: live topics with types, publisher/subscriber counts and node names (no ros2cli needed)."""

from __future__ import annotations

import argparse
import sys


def add_domain_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--domain-id', type=int, default=None, metavar='N', help="ROS_DOMAIN_ID (default: the environment's)")


def check_domain(command: str, domain_id: int | None) -> bool:
    if domain_id is not None and not 0 <= domain_id <= 232:
        print(f'formation {command}: error: --domain-id must lie in [0, 232], got {domain_id}', file=sys.stderr)
        return False
    return True


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'topics',
        help='list live ROS topics with types, publisher/subscriber counts and nodes',
        description='Like `ros2 topic list -v` / `ros2 topic info -v`, for machines without ros2cli: '
        'waits for discovery, then lists every topic with its type(s), the number of publishers and '
        'subscribers, and (--verbose) the nodes behind them.',
    )
    add_domain_argument(parser)
    parser.add_argument('--wait', type=float, default=3.0, metavar='S', help='discovery time at most S seconds (default 3; stops earlier once the graph is stable)')
    parser.add_argument('--verbose', '-v', action='store_true', help='also list the node of every publisher and subscriber')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not check_domain('topics', args.domain_id):
        return 2
    import os

    import rclpy
    from rclpy.node import Node

    from formation_sim.ros_inspect import discover_topics, format_topics

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = None
    try:
        node = Node(f'formation_topics_{os.getpid()}', context=context, start_parameter_services=False, enable_rosout=False)
        topics = discover_topics(node, wait=args.wait)
    except KeyboardInterrupt:
        return 130
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    sys.stdout.write(format_topics(topics, verbose=args.verbose))
    return 0
