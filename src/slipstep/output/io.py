"""Crash-safe file output: every file slipstep writes goes through :func:`atomic_path`.

    with atomic_path(target) as tmp:      # tmp: a unique temporary name in target's directory
        write_something(tmp)              # any writer that takes a path
    # on success: tmp is fsynced and renamed over target (atomic on POSIX);
    # on any exception (including KeyboardInterrupt): tmp is removed, target is untouched.

The previous file therefore survives a crash, a full disk or an interrupt during the write,
and two concurrent writers never interleave their bytes (each writes its own temporary file,
the last rename wins whole). A temporary file left by a killed process (SIGKILL, power loss)
is named ``.<target>.<pid>.<random>.tmp`` and removed by the next write of the same target once
its process is gone. Failures of the environment (disk full, read-only file system, no
permission) raise :class:`~slipstep.errors.OutputError` naming the path; the helpers
:func:`write_text`, :func:`write_bytes` and :func:`save_figure` cover the common writers.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import math
import os
import shutil
import tempfile
from pathlib import Path

from slipstep.errors import OutputError

#: the share of the available memory one run may take (slipstep.methods.memory)
DEFAULT_FRACTION = 0.5

_UMASK = os.umask(0)
os.umask(_UMASK)

_OS_PROBLEMS = {  # errno -> (problem, fix)
    errno.ENOSPC: ("no space left on the device (disk full)", "free disk space or write elsewhere"),
    errno.EDQUOT: ("the disk quota is exceeded", "free disk space or write elsewhere"),
    errno.EFBIG: (
        "the file exceeds the file size limit (ulimit -f) or the file system's largest file",
        "raise the limit or write a smaller result",
    ),
    errno.EROFS: ("the file system is read-only", "write to a writable directory"),
    errno.EACCES: ("permission denied", "write to a directory you may write to"),
    errno.EPERM: ("operation not permitted", "write to a directory you may write to"),
    errno.EISDIR: ("is a directory", "give a file name, not a directory"),
    errno.ENOENT: ("the directory does not exist", "create it first or give an existing directory"),
    errno.ENOTDIR: ("a part of the path is not a directory", "give a path inside a directory"),
    errno.ENAMETOOLONG: ("the file name is too long", "give a shorter name"),
    errno.EIO: ("an input/output error of the device", "check the disk"),
}


def output_error(path, exc: OSError) -> OutputError:
    """The :class:`OutputError` of an ``OSError`` met while writing ``path``."""
    problem, fix = _OS_PROBLEMS.get(
        exc.errno, (exc.strerror or str(exc) or type(exc).__name__, "check the path and the disk")
    )
    return OutputError(path, f"cannot be written: {problem}", fix)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def remove_stale_temporaries(target: Path) -> None:
    """Remove ``.<name>.<pid>.*.tmp`` files beside ``target`` whose process no longer exists."""
    prefix = f".{target.name}."
    with contextlib.suppress(OSError):
        for entry in os.scandir(target.parent):
            name = entry.name
            if not (name.startswith(prefix) and name.endswith(".tmp")):
                continue
            pid = name[len(prefix) :].split(".", 1)[0]
            if pid.isdigit() and int(pid) != os.getpid() and not _pid_alive(int(pid)):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike):
    """Yield a temporary path beside ``target``; on success fsync it and rename it onto
    ``target``, on failure remove it and re-raise (an ``OSError`` as :class:`OutputError`).
    The directory must exist. The file gets the mode a new file would get (umask), or the
    mode of the file it replaces."""
    target = Path(target)
    if target.is_dir():
        raise OutputError(target, "is a directory", "give a file name, not a directory")
    remove_stale_temporaries(target)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise output_error(target, exc) from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        try:
            mode = os.stat(target).st_mode & 0o7777
        except OSError:
            mode = 0o666 & ~_UMASK
        os.chmod(tmp, mode)
        os.replace(tmp, target)
        with contextlib.suppress(OSError):  # make the rename itself durable
            dir_fd = os.open(target.parent, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):
            raise output_error(target, exc) from None
        raise


def free_space(path) -> float:
    """Bytes that may still be written beside ``path``: the free space of its file system,
    capped by the file size limit of the process (ulimit -f); inf if unknown."""
    free = math.inf
    with contextlib.suppress(OSError):
        free = shutil.disk_usage(Path(path).parent).free
    with contextlib.suppress(ImportError, OSError, ValueError):
        import resource

        soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        if soft != resource.RLIM_INFINITY:
            free = min(free, soft)
    return free


def ensure_space(path, nbytes: float) -> float:
    """Refuse (OutputError) before writing about ``nbytes`` to ``path`` when its file system
    has less free space or the file size limit is lower, so that a full disk is reported
    before any byte is written; return the space left [bytes]."""
    free = free_space(path)
    if nbytes > free:
        with contextlib.suppress(OSError):
            if free < shutil.disk_usage(Path(path).parent).free:
                raise OutputError(
                    path,
                    f"cannot be written: it needs about {format_bytes(nbytes)}, more than the "
                    f"file size limit (ulimit -f) of {format_bytes(free)}",
                    "raise the limit or write a smaller result",
                )
        raise OutputError(
            path,
            f"cannot be written: no space left on the device: it needs about "
            f"{format_bytes(nbytes)} and the disk has {format_bytes(free)} free",
            "free disk space or write elsewhere",
        )
    return free


def format_bytes(n: float) -> str:
    """1536 -> '1.5 KB' (powers of 1024)."""
    n = float(n)
    for unit in ("B", "KB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1024 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PB"  # pragma: no cover


def write_text(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding=encoding)
    return path


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def plain_text_figures(func):
    """Decorator: the figures ``func`` makes draw every text as written, not as mathtext, so that a
    name such as ``P$\\frac$1`` from a case file is a label, not a formula that fails to parse
    (matplotlib's rcParams are restored afterwards)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        import matplotlib

        with matplotlib.rc_context({"text.parse_math": False}):
            return func(*args, **kwargs)

    return wrapper


def save_figure(fig, path, **savefig_kwargs) -> Path:
    """``fig.savefig`` to ``path`` atomically (the format from the file suffix, PNG by default)."""
    path = Path(path)
    fmt = savefig_kwargs.pop("format", None) or (path.suffix.lstrip(".").lower() or "png")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **savefig_kwargs)
    return path


def available_memory() -> int:
    """Memory this process may still use [bytes]: MemAvailable of /proc/meminfo, capped by a
    cgroup (container) limit; the physical memory where /proc is absent."""
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 8 * 1024**3
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        try:
            with open(limit_file) as fh:
                text = fh.read().strip()
            if text == "max":
                continue
            with open(usage_file) as fh:
                used = int(fh.read().strip())
            avail = min(avail, max(int(text) - used, 0))
        except (OSError, ValueError):
            continue
    return int(avail)


def memory_limit(max_memory: float | None = None) -> float:
    """The limit [bytes] of one run: ``max_memory`` if given, else DEFAULT_FRACTION of the
    available memory."""
    return float(max_memory) if max_memory is not None else DEFAULT_FRACTION * available_memory()
