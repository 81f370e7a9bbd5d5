"""`formation recover BAG`: make the bag of a recorder that died (SIGKILL, power loss) readable."""

from __future__ import annotations

import argparse
from pathlib import Path

from formation_sim.commands.common import refuse


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        'recover',
        help='rebuild a bag whose recorder died (no metadata.yaml, MCAP file cut short)',
        description='Recover a rosbag2 bag (MCAP) whose recorder was killed or whose file was damaged: '
        'every message in an intact MCAP chunk is kept (the recorder flushes every 0.5 s; each chunk '
        'is checked against its checksum), each chunk dropped is named, a cut-short or damaged file is '
        'rewritten complete with the original kept beside it as <name>.mcap.damaged, and '
        'metadata.yaml is rebuilt (an unreadable one kept as metadata.yaml.damaged). A healthy bag '
        '(one that opens as it is, every checksum matching) is left alone. `formation run` '
        'does this by itself when its recorder dies.',
    )
    parser.add_argument('bag', metavar='BAG', type=Path, help='bag directory (holding one .mcap file)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from formation_sim.bag.errors import BagRecoveryError
    from formation_sim.bag.recovery import reindex

    bag: Path = args.bag
    if not bag.is_dir():
        return refuse('recover', f'{bag} is not a directory (give the bag directory)')
    try:
        recovery = reindex(bag)
    except BagRecoveryError as error:
        return refuse('recover', error)
    if recovery.healthy:
        print(
            f'{bag}: healthy (metadata.yaml and a complete MCAP file, {recovery.message_count} '
            'messages); left as it is'
        )
        return 0
    if recovery.rewritten:
        print(
            f'{bag}: recovered {recovery.message_count} messages into {recovery.mcap_path.name}; '
            f'the damaged or cut-short original is kept as {recovery.damaged_copy.name}'
        )
        for what in recovery.dropped:
            print(f'  dropped: {what}')
    else:
        print(f'{bag}: the MCAP file was complete; metadata.yaml rebuilt ({recovery.message_count} messages)')
    for topic, count in sorted(recovery.message_counts.items()):
        print(f'  {count:8d}  {topic}')
    return 0
