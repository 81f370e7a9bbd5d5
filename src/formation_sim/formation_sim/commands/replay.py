"""`formation replay BAG`: republish a bag's topics on ROS with their original timing, and /clock."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from formation_sim.commands.common import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    add_domain_argument,
    refuse,
)


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'replay',
        help='republish a bag on ROS with its original timing (like ros2 bag play --clock)',
        description='Republish every message of a rosbag2 bag byte for byte (raw CDR) on its topic, '
        'at its recorded time scaled by --rate, and publish /clock from the bag timestamps (unless '
        "the bag recorded /clock itself). QoS: what each topic's publishers offered when it was recorded "
        "(the bag's offered_qos_profiles, as ros2 bag play does: a transient-local topic is latched for "
        'late joiners), else reliable and transient local; history keep all (reliable readers lose nothing, '
        'even with --as-fast-as-possible) or keep last --depth.',
    )
    parser.add_argument('bag', metavar='BAG', type=Path, help='bag folder (or its .mcap file)')
    parser.add_argument(
        '--rate', type=NON_NEGATIVE, default=1.0, help='speed factor (default 1; 0 = as fast as possible)'
    )
    parser.add_argument('--as-fast-as-possible', action='store_true', help='same as --rate 0')
    add_domain_argument(parser)
    parser.add_argument('--topics', nargs='+', default=None, metavar='TOPIC', help='replay only these topics')
    parser.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    parser.add_argument(
        '--depth',
        type=POSITIVE_INT,
        default=None,
        help='keep-last history of this depth instead of keep-all (may drop messages for slow readers)',
    )
    parser.add_argument(
        '--delay',
        type=NON_NEGATIVE,
        default=0.0,
        metavar='S',
        help='wait S seconds before the first message (discovery)',
    )
    parser.add_argument(
        '--wait-for-subscribers',
        type=NON_NEGATIVE_INT,
        default=0,
        metavar='K',
        help=(
            'wait until every replayed topic has K matched subscribers before starting (timeout '
            '--wait-timeout)'
        ),
    )
    parser.add_argument(
        '--wait-timeout',
        type=POSITIVE,
        default=30.0,
        metavar='S',
        help='give up waiting for subscribers after S seconds (default 30)',
    )
    parser.add_argument('--quiet', action='store_true', help='no progress')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.progress import Progress
    from formation_sim.runtime.errors import ReplayError
    from formation_sim.runtime.tools.replay import main_replay

    rate = 0.0 if args.as_fast_as_possible else args.rate
    progress = Progress(f'replaying {args.bag}', enabled=not args.quiet)
    try:
        result = main_replay(
            args.bag,
            rate=rate,
            domain_id=args.domain_id,
            topics=args.topics,
            clock=not args.no_clock,
            depth=args.depth,
            delay=args.delay,
            wait_for_subscribers=args.wait_for_subscribers,
            wait_timeout=args.wait_timeout,
            progress=progress,
        )
    except ReplayError as error:
        return refuse('replay', error)
    progress.close()
    for topic, why in result.skipped_topics.items():
        print(f'warning: {topic} not replayed: {why}', file=sys.stderr)
    if not args.quiet:
        clock = f', {result.clock_messages} /clock' if result.clock_messages else ''
        print(
            f'published {result.published} messages on {len(result.per_topic)} topics{clock} in '
            f'{result.wall_time:.2f} s',
            file=sys.stderr,
        )
    return 130 if result.interrupted else 0
