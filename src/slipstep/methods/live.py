"""Interruptible, observable kernel calls.

The march kernels are compiled ``nogil``: :func:`call_kernel` runs one in a worker thread
while the main thread waits on it. Ctrl-C (KeyboardInterrupt in the main thread) sets the
kernel's stop flag ``counters[C_STOP]``; the kernel stops at the start of its next step and
returns ``INTERRUPTED`` with every step done before kept, and the run continues as for any
early stop (partial Dataset). A second Ctrl-C while waiting for the kernel aborts. The same
loop draws a rich progress bar (simulated time, steps, rate, time left) from the live counter
``counters[C_PROGRESS]`` and the output times when asked to, once the run has lasted
``PROGRESS_AFTER_S``.

:func:`deferred_interrupt` protects a short critical section (saving the result): the first
Ctrl-C is noted and the section completes; a second one aborts it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time

from slipstep.kernels.codes import C_PROGRESS, C_STOP

THREAD_MIN_POINTS = 2_000  # runs with fewer output points are called directly (about a millisecond)
PROGRESS_AFTER_S = 1.0
POLL_S = 0.1


def in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def call_kernel(kernel, args, counters, times, t_end: float, points: int, progress: bool = False):
    """Run ``kernel(*args)``; return (status code, kernel time [s]). Threaded (interruptible,
    with progress) in the main thread when the run has at least THREAD_MIN_POINTS output points
    or ``progress`` is asked; directly otherwise."""
    if not in_main_thread() or (points < THREAD_MIN_POINTS and not progress):
        start = time.perf_counter()
        status = kernel(*args)
        return status, time.perf_counter() - start
    result: dict = {}
    done = threading.Event()  # not Thread.is_alive: an interrupted join() can leave it wrong (CPython)

    def work():
        start = time.perf_counter()
        try:
            result["status"] = kernel(*args)
        except BaseException as exc:  # re-raised in the calling thread
            result["error"] = exc
        finally:
            result["time"] = time.perf_counter() - start
            done.set()

    worker = threading.Thread(target=work, name="slipstep-march", daemon=True)
    bar = _Progress(counters, times, t_end) if progress else None
    worker.start()
    try:
        try:
            _wait(done, bar)
        except KeyboardInterrupt:
            counters[C_STOP] = 1  # the kernel stops at its next step
            if bar is not None:
                bar.note("stopping at the current step (Ctrl-C again to abort)")
            _wait(done, bar)  # a second KeyboardInterrupt propagates: abort
    finally:
        if bar is not None:
            bar.close()
    if "error" in result:
        raise result["error"]
    return result["status"], result["time"]


def _wait(done: threading.Event, bar) -> None:
    started = time.monotonic()
    while not done.wait(POLL_S):
        if bar is not None and time.monotonic() - started >= PROGRESS_AFTER_S:
            bar.update()


class _Progress:
    """A rich progress bar on stderr: simulated time against the end time, steps, rate, time left."""

    def __init__(self, counters, times, t_end: float):
        self.counters, self.times, self.t_end = counters, times, t_end
        self.progress = None
        self.task = None

    def _start(self):
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self.progress = Progress(
            TextColumn("march"),
            BarColumn(),
            TextColumn("t = {task.fields[t]} of {task.fields[t_end]}"),
            TextColumn("{task.fields[steps]} steps"),
            TextColumn("{task.fields[rate]} steps/s"),
            TimeElapsedColumn(),
            TextColumn("left"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
            refresh_per_second=5,
        )
        self.progress.start()
        self.task = self.progress.add_task(
            "march", total=self.t_end, t="0 s", t_end=_seconds(self.t_end), steps=0, rate="-"
        )
        self.started, self.steps0 = time.monotonic(), int(self.counters[C_PROGRESS])

    def update(self):
        if self.progress is None:
            self._start()
        k = int(self.counters[C_PROGRESS])
        t = float(self.times[min(k, self.times.shape[0] - 1)])
        elapsed = max(time.monotonic() - self.started, 1e-9)
        rate = (k - self.steps0) / elapsed
        self.progress.update(
            self.task, completed=min(t, self.t_end), t=_seconds(t), steps=f"{k:,}", rate=f"{rate:,.0f}"
        )

    def note(self, text: str):
        if self.progress is not None:
            self.progress.console.print(text, markup=False, highlight=False)

    def close(self):
        if self.progress is not None:
            self.progress.stop()


def _seconds(t: float) -> str:
    return f"{t * 1e3:.4g} ms" if abs(t) < 1 else f"{t:.4g} s"


@contextlib.contextmanager
def deferred_interrupt(on_first=None, armed: bool = False):
    """Within the block the first SIGINT calls ``on_first()`` and is otherwise ignored; the
    second raises KeyboardInterrupt. ``armed=True`` (an interrupt was already received): the
    first one raises. Outside the main thread this does nothing."""
    if not in_main_thread():
        yield
        return
    count = [1 if armed else 0]

    def handler(signum, frame):
        count[0] += 1
        if count[0] >= 2:
            raise KeyboardInterrupt
        if on_first is not None:
            on_first()

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
