"""Memory estimate of a march, checked before any array is allocated.

A march stores one output point per saved step (kernels.march.Outputs; what is saved:
slipstep.methods.save, the ``save`` option):

    bytes per point = 8 (t) + 8 (dt) + 8 (solves) + 8 (step) + 3 * 8 n (x, v, a) + 2 * 8 nq (q, f) + 9 nd (w, state)

with n the saved DOFs, nq the saved local contact coordinates and nd the saved tangential
directions; the points are the saved steps (slipstep.methods.save.rows_needed), not the steps. The result Dataset
copies the stored points once and the evaluated prescribed motion adds 8 m per point, so the
peak of a run and its save is about ``PEAK_FACTOR`` times the output buffer (measured:
``benchmarks/bench_memory.py``), plus the workspace (the per-state factorisation cache).
A run whose estimate exceeds the limit (default: ``DEFAULT_FRACTION`` of the available memory,
or ``RunOptions.max_memory`` / ``--max-memory``) is refused with an InputError.
"""

from __future__ import annotations

import math
import re

from slipstep.errors import InputError
from slipstep.output.io import DEFAULT_FRACTION, available_memory, memory_limit  # noqa: F401 (re-exported)

PEAK_FACTOR = 3.0  # run + Dataset + save over the output buffer: 2.5 measured (benchmarks/bench_memory.py)


def point_bytes(n: int, nq: int, nd: int, m: int = 0) -> int:
    """Bytes of one stored output point (see the module docstring); m motion components
    are evaluated for the Dataset."""
    return 32 + 24 * n + 16 * nq + 9 * nd + 8 * m


def run_bytes(points: int, n: int, nq: int, nd: int, m: int, workspace: int) -> float:
    """Peak memory estimate [bytes] of a march of ``points`` output points and its Dataset."""
    return PEAK_FACTOR * points * point_bytes(n, nq, nd, m) + workspace


def check(
    points: int, n: int, nq: int, nd: int, m: int, workspace: int, max_memory: float | None, field: str, fixes: str
) -> float:
    """Raise InputError(field) when the estimate exceeds the limit; return the estimate."""
    from slipstep.output.io import format_bytes

    need = run_bytes(points, n, nq, nd, m, workspace)
    limit = memory_limit(max_memory)
    if need > limit:
        source = (
            "max_memory"
            if max_memory is not None
            else f"{DEFAULT_FRACTION:.0%} of the {format_bytes(available_memory())} available"
        )
        raise InputError(
            field,
            f"needs {points:.3g} output points x {point_bytes(n, nq, nd, m)} B = about "
            f"{format_bytes(need)} of memory with the result Dataset, more than the limit "
            f"{format_bytes(limit)} ({source})",
            f"{fixes}, or raise the limit (max_memory; command line: --max-memory, e.g. 16GB)",
        )
    return need


_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]{1,3})?)\s*([kKmMgGtT]?)(i?)[bB]?\s*$")


def parse_size(field: str, text) -> float:
    """'4GB', '500 MB', '2.5G', '1e9' -> bytes (powers of 1024 for the suffixes)."""
    if isinstance(text, bool):
        raise InputError(field, f"is {text!r}", "give a size such as 4GB or 500MB")
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        match = _SIZE.match(str(text))
        if not match:
            raise InputError(field, f"{str(text)!r} is not a size", "give a size such as 4GB, 500MB or 2e9 (bytes)")
        value = float(match.group(1)) * 1024 ** " KMGT".index(match.group(2).upper() or " ")
    if not math.isfinite(value) or value <= 0:
        raise InputError(field, f"is {text!r}", "give a positive size such as 4GB")
    return value
