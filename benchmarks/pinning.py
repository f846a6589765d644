"""Pin a benchmark process to one CPU, so that its kernel times are not a mix of two modes.

On this project's machine kind (2 shared vCPUs), a process the scheduler moves between the CPUs
times the adaptive methods in two modes per process: Method 2 on the paper case at 100 Hz took
550-690 us per period in some processes and 900-1,010 us in others, with the same source tree
(also the tree before a change), so an old-against-new comparison of two unpinned processes could
show a 1.5-1.9x "regression" that is not in the code. Pinned to either CPU (``taskset -c 0`` or
``-c 1``), six processes out of six took the fast mode (measured 2026-12-06, session 37). Child
processes inherit the affinity.
"""

from __future__ import annotations

import os


def pin_to_one_cpu(enabled: bool = True) -> str:
    """Restrict this process (and its children) to the last CPU it may run on; return a line
    that says what was done (for the benchmark's header)."""
    if not enabled:
        return "not pinned (--no-pin): times may mix two modes on a shared machine"
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity on this platform)"
    allowed = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {allowed[-1]})
    return f"pinned to CPU {allowed[-1]} (benchmarks/pinning.py; --no-pin to let it move)"
