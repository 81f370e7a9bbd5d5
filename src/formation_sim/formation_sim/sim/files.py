"""Writing result files so that a reader never sees half of one (ROS-free).

A file written in place and interrupted (a full disk, a kill) is left empty or cut short, and
whoever reads it next fails on it or, worse, believes it.  `write_atomically` writes a temporary
file beside the target and renames it over the target only once it is complete: the target is
then either the new file or what it was before, and the temporary is removed whatever happens.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO


def staging_path(path: Path) -> Path:
    """The temporary beside `path` that `write_atomically` writes first (`<name>.tmp`)."""
    return path.with_name(f'{path.name}.tmp')


def write_atomically(path: str | Path, content: str | bytes | Callable[[BinaryIO], None]) -> Path:
    """Write `content` (text as UTF-8, bytes, or a function writing into a binary file) to `path`.

    Raises OSError naming `path` (e.g. "[Errno 28] No space left on device: 'run/summary.json'").
    """
    path = Path(path)
    staging = staging_path(path)
    try:
        with staging.open('wb') as handle:
            if callable(content):
                content(handle)
            else:
                handle.write(content.encode('utf-8') if isinstance(content, str) else content)
            handle.flush()
            os.fsync(handle.fileno())  # a full disk may only tell at the flush to the device
        staging.replace(path)
    except OSError as error:
        staging.unlink(missing_ok=True)
        raise OSError(error.errno, error.strerror, str(path)) from error
    except BaseException:
        staging.unlink(missing_ok=True)
        raise
    return path
