"""Run a command; print one JSON line with its wall time, peak resident memory and exit status.

    python benchmarks/peak_rss.py LOG -- COMMAND [ARGUMENT ...]

The memory is the kernel's `ru_maxrss` of the command's process (`os.wait4`), measured from this
small process and not from the benchmark itself: a child's ru_maxrss starts at the resident memory
of the parent it was forked from (the copied address space counts until exec), so a benchmark
holding a few hundred MiB would show them as every command's floor. Here the floor is this
process's own ~10 MiB. The command's output goes to LOG.
"""

from __future__ import annotations

import json
import os
import sys
import time


def main() -> int:
    log, separator, command = sys.argv[1], sys.argv[2], sys.argv[3:]
    if separator != '--' or not command:
        print(__doc__, file=sys.stderr)
        return 2
    with open(log, 'wb') as sink:
        started = time.perf_counter()
        pid = os.fork()
        if pid == 0:  # the command, with its output in LOG
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            try:
                os.execvp(command[0], command)  # noqa: S606 - the measured command, exec'd in the forked child
            finally:
                os._exit(127)
        _, status, usage = os.wait4(pid, 0)
        wall = time.perf_counter() - started
    print(
        json.dumps(
            {
                'wall_s': wall,
                'peak_rss_mib': usage.ru_maxrss / 1024,
                'exit': os.waitstatus_to_exitcode(status),
            }
        )
    )
    return 0


if __name__ == '__main__':
    sys.exit(main())
