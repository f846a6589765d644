"""BLAS threads for small dense problems: the one rule shared by shooting, harmonic balance and
the exact event-driven march.

Multi-threaded BLAS on matrices of a few hundred rows is 10-30x slower on a loaded machine than
one thread (measured: the `ring` case's exact march 14 s against 0.8 s; a harmonic-balance
Newton iteration of the blade pair) and gains little on an idle one, so below SMALL_SIZE
unknowns these problems run on one BLAS thread.
"""

from __future__ import annotations

import contextlib
import functools

SMALL_SIZE = 2000  # unknowns below which BLAS runs on one thread

_CONTROLLER = None


def one_blas_thread(size: int = 0):
    """A context limiting BLAS to one thread for a dense problem of ``size`` unknowns below
    SMALL_SIZE (a null context above it). The library scan is done once per process."""
    global _CONTROLLER
    if size >= SMALL_SIZE:
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1, user_api="blas")


def on_one_blas_thread(size_of):
    """Decorator: the function runs within ``one_blas_thread(size_of(*args, **kwargs))``, the
    problem size computed from its own arguments."""

    def decorate(fn):
        @functools.wraps(fn)
        def wrapped(*args, **kwargs):
            with one_blas_thread(size_of(*args, **kwargs)):
                return fn(*args, **kwargs)

        return wrapped

    return decorate
