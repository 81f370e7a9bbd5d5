"""What a message's tag costs (issue 28), against decoding the same message, in one run.

    python benchmarks/tags.py [--messages 20000] [--repeats 5]

For a Status-sized array of 10 values (the size of a TriggerInfo of p = 2 too), times per message,
alternating `--repeats` times: tagging it (`Signer.tag_array`), checking its tag
(`Verifier.check_array`, each tag fresh, as on the wire), and `codec.decode_status` of the same
message (what an agent or the keeper spends on every Status anyway). Reported: the median µs per
message of each, and the tag's costs as ratios to the decode, measured in the same run (the ratios
hold on a loaded machine; the microseconds do not). docs/HOSTILE_TRAFFIC.md quotes it.
"""

from __future__ import annotations

import argparse
import functools
import statistics
import time

from formation_msgs_py.codec import decode_status, encode_status
from formation_msgs_py.lockstep import Status
from formation_msgs_py.tags import Signer, Verifier

KEY = bytes(range(32))
TOPIC = '/agent_2/status'


def _per_message(work, count: int) -> float:
    """µs per message of `work(i)` over `count` messages."""
    start = time.perf_counter()
    for i in range(count):
        work(i)
    return (time.perf_counter() - start) / count * 1e6


def measure(*, messages: int, repeats: int) -> dict[str, float]:
    """Median µs per message of tagging, checking and decoding, and the ratios to the decode."""
    msg = encode_status(
        Status(
            agent=2,
            step_index=7,
            next_time=1.25,
            info_sent=3,
            info_received=4,
            commands_sent=5,
            triggers=6,
            ready=True,
            last_planned=1.0,
        )
    )
    values = tuple(msg.data)
    times: dict[str, list[float]] = {'tag': [], 'check': [], 'decode': []}
    for _ in range(repeats):
        signer = Signer(KEY, writer='agent_2')
        labels = [signer.tag_array(TOPIC, values) for _ in range(messages)]
        verifier = Verifier(KEY)  # a fresh one: every tag is new to it, as on the wire
        tag = functools.partial(signer.tag_array, TOPIC, values)
        check = functools.partial(verifier.check_array, TOPIC, values)
        times['tag'].append(_per_message(lambda _, tag=tag: tag(), messages))
        times['check'].append(_per_message(lambda i, check=check, labels=labels: check(labels[i]), messages))
        times['decode'].append(_per_message(lambda _: decode_status(msg), messages))
    result = {name: statistics.median(series) for name, series in times.items()}
    result['tag_over_decode'] = result['tag'] / result['decode']
    result['check_over_decode'] = result['check'] / result['decode']
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--messages', type=int, default=20000, help='messages per timing (default 20000)')
    parser.add_argument('--repeats', type=int, default=5, help='alternating repeats (default 5)')
    args = parser.parse_args()
    r = measure(messages=args.messages, repeats=args.repeats)
    print('| per message of 10 values | µs (median) | / decode_status |')
    print('|---|---|---|')
    print(f'| decode_status | {r["decode"]:.1f} | 1 |')
    print(f'| tag (Signer.tag_array) | {r["tag"]:.1f} | {r["tag_over_decode"]:.2f} |')
    print(f'| check (Verifier.check_array) | {r["check"]:.1f} | {r["check_over_decode"]:.2f} |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
