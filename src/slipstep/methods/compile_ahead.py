"""The out-of-line kernels of a march compiled in a second process while this one types the march
(issue 25, item 8: a first result within a minute on an empty numba cache).

numba compiles a march kernel in one thread: typing the march compiles, one after the other,
every out-of-line kernel it calls (on the paper case about 40 s of the 80 s of ``slipstep run
paper`` on an empty cache: the T_min eigenvalue routines, full Newton, the factorisations, the
stick fallback), then lowers the march itself. On a machine with two CPUs the second one idles.
:func:`start` gives it those callees: it starts ``python -m slipstep.methods.compile_ahead``,
which compiles them, with the argument types of their call sites (the kernel module's lists,
e.g. :func:`slipstep.kernels.march.implicit_callees`): first the few the march's typing meets
soon after it starts, then the others in the reverse of the order in which the typing meets
them, then the kernels the caller needs after the march.
numba writes each into its on-disk cache (atomically), and this process's typing loads from
there every callee the helper compiled before it got there; the two meet in the middle. On the
paper case this process still types and lowers the march itself (about 25 s) and compiles the
rest of T_min's routines and one or two step solvers. Nothing else is shared, the results are
this process's alone, and a callee both reach is compiled twice (no harm but the time).

Only where it pays: within :func:`enabled` (every command of the command line), the
first march of a kernel in the process, the march not in numba's cache, two CPUs or more; the
helper is stopped when the march it served has been compiled (:func:`stop`).
"""

from __future__ import annotations

import contextlib
import os
import pickle
import pkgutil
import signal
import subprocess
import sys

#: the kernel of a method (registry Method.kernel) -> the function that lists the out-of-line kernels
#: its typing compiles, ``callees(backend, sys, ws) -> (first, rest)``, lists of ("module:name", argument types)
CALLEES = {"slipstep.kernels.march:implicit_kernel": "slipstep.kernels.march:implicit_callees"}

_enabled = False
_started: set = set()  # (kernel, backend) whose callees a helper compiled or was given in this process
_helper: subprocess.Popen | None = None


@contextlib.contextmanager
def enabled():
    """Compile ahead within this block (a command of the command line), and stop the helper at its end."""
    global _enabled
    before, _enabled = _enabled, True
    try:
        yield
    finally:
        _enabled = before
        stop()


def start(kernel: str, dispatcher, arguments: tuple, then: tuple = ()) -> None:
    """Start the helper on the callees of ``dispatcher`` (the numba kernel of the registry's
    ``kernel`` for one backend) before its first call on ``arguments`` (sys, settings, ws, out,
    q0, f0), where it pays (module docstring); ``then``: ("module:name", argument types) of the
    kernels the caller needs after the march, compiled by the helper after the callees (module
    docstring: the order)."""
    global _helper
    if not _enabled or kernel not in CALLEES:
        return
    backend = arguments[1].structure
    if (kernel, backend) in _started or _cpus() < 2:
        return
    _started.add((kernel, backend))
    from numba import typeof  # here: the command line enters enabled() before it needs numba

    from slipstep.kernels.arguments import FIELDS, KernelArgumentsType

    sys_, settings, ws, out, q0, f0 = arguments
    march_types = (
        KernelArgumentsType([(name, typeof(v)) for name, v in zip(FIELDS, (sys_, ws, out, q0, f0))]),
        typeof(settings),
    )
    if in_disk_cache(dispatcher, march_types):
        return
    first, rest = pkgutil.resolve_name(CALLEES[kernel])(backend, sys_, ws)
    if not first + rest:
        return
    stop()
    _helper = subprocess.Popen(
        [sys.executable, "-m", "slipstep.methods.compile_ahead"],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    with contextlib.suppress(OSError):
        _helper.stdin.write(pickle.dumps(first + rest[::-1] + list(then)))
        _helper.stdin.close()


def stop() -> None:
    """Stop the helper (its work is done or no longer needed); numba's cache files are written
    atomically, so a compile cut short leaves nothing behind."""
    global _helper
    helper, _helper = _helper, None
    if helper is not None and helper.poll() is None:
        helper.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            helper.wait(timeout=5)


def in_disk_cache(dispatcher, argument_types: tuple) -> bool:
    """Is the compiled kernel for these argument types in numba's on-disk cache? (numba's cache
    index, read as its own ``load_overload`` reads it; False when that cannot be told.)"""
    try:
        cache = dispatcher._cache
        key = cache._index_key(tuple(argument_types), dispatcher.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # noqa: BLE001  (numba internals: unknown means compile ahead)
        return False


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _compile(callees: list) -> None:
    """The helper's body: compile each ("module:name", argument types) in order; a failure is
    left to the march's own typing to meet (and report)."""
    for path, argument_types in callees:
        with contextlib.suppress(Exception):
            pkgutil.resolve_name(path).compile(tuple(argument_types))


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's, which stops this process
    _compile(pickle.load(sys.stdin.buffer))
