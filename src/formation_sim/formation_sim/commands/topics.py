"""`formation topics`: live topics with types, publisher/subscriber counts and node names (no ros2cli
needed)."""

from __future__ import annotations

import argparse
import sys

from formation_sim.commands.common import NON_NEGATIVE, add_domain_argument, inspection_node


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'topics',
        help='list live ROS topics with types, publisher/subscriber counts and nodes',
        description='Like `ros2 topic list -v` / `ros2 topic info -v`, for machines without ros2cli: '
        'waits for discovery, then lists every topic with its type(s), the number of publishers and '
        'subscribers, and (--verbose) the nodes behind them.',
    )
    add_domain_argument(parser)
    parser.add_argument(
        '--wait',
        type=NON_NEGATIVE,
        default=3.0,
        metavar='S',
        help='discovery time at most S seconds (default 3; stops earlier once the graph is stable)',
    )
    parser.add_argument(
        '--verbose', '-v', action='store_true', help='also list the node of every publisher and subscriber'
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.runtime.tools.graph import discover_topics, format_topics

    try:
        with inspection_node('topics', args.domain_id) as node:
            topics = discover_topics(node, wait=args.wait)
    except KeyboardInterrupt:
        return 130
    sys.stdout.write(format_topics(topics, verbose=args.verbose))
    return 0
