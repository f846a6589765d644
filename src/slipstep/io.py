"""Crash-safe file output: every file slipstep writes goes through :func:`atomic_path`.

    with atomic_path(target) as tmp:      # tmp: a unique temporary name in target's directory
        write_something(tmp)              # any writer that takes a path
    # on success: tmp is fsynced and renamed over target (atomic on POSIX);
    # on any exception (including KeyboardInterrupt): tmp is removed, target is untouched.

The previous file therefore survives a crash, a full disk or an interrupt during the write,
and two concurrent writers never interleave their bytes (the last rename wins whole).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike):
    """Yield a temporary path beside ``target``; on success fsync it and rename it onto
    ``target``, on failure remove it and re-raise. The directory must exist."""
    target = Path(target)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        with contextlib.suppress(OSError):  # make the rename itself durable
            dir_fd = os.open(target.parent, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
