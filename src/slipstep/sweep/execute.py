"""Running the cases of a sweep: a batch of cases and the two executors (one case:
slipstep.sweep.case_run, re-exported here).

Both executors call the same :func:`run_batch` on the same inputs, so the serial executor
(debugging, one process) and the dask.distributed executor give bit-identical numbers.

* :class:`SerialExecutor`: the batches one after another in this process.
* :class:`DaskExecutor`: a ``LocalCluster`` on 127.0.0.1 (loopback only: nothing listens on
  the network), one single-threaded worker process per core by default, or an existing
  cluster given by its scheduler address. Each task is a batch of cases (the per-task
  overhead of dask, about a millisecond, is paid once per batch); a task lost with a killed
  worker is recomputed on another worker (``retries``), and the client, the only writer of
  the store, receives the results as the batches finish.

A case never raises: every failure (bad parameter values, a failed preload, an unexpected
exception) becomes a result with its status and message.
"""

from __future__ import annotations

import logging
import math
import os
import socket
import time
from collections.abc import Iterator


from slipstep.errors import InputError


from slipstep.sweep.case_run import (  # noqa: F401  (one case: re-exported for the executors' callers)
    STATUS_INPUT,
    STATUS_PRELOAD,
    STATUS_ERROR,
    STATUS_TASK,
    Payload,
    payload_of,
    run_case,
    empty_result,
    guarded,
    _case_format,
    _finish,
    _fast,
    _run_fast,
    _run_frf_only,
    _mistuning_summary,
    _run_options,
    histories,
    frf_values,
)


def run_batch(payload: Payload, rows) -> list[dict]:
    """Run the cases ``rows`` = [(index, hash, values), ...] on this thread's runner of the
    payload (slipstep.sweep.runner: the compiled system patched per case, or run_case); each
    result carries its index, hash, the worker's identity and the slipstep version."""
    from slipstep import __version__
    from slipstep.sweep.runner import case_runner

    worker = f"{socket.gethostname()}:{os.getpid()}"
    runner = case_runner(payload)
    out = []
    for index, digest, values in rows:
        r = runner.run(values)
        r.update(index=int(index), hash=digest, worker=worker, version=__version__)
        out.append(r)
    return out


def warm_up(payload: Payload, values) -> float:
    """Run one case and forget it: imports slipstep, loads (or compiles) the kernels of the
    sweep's method and builds this worker's runner (slipstep.sweep.runner), so the timed cases
    do not pay for it. Returns seconds."""
    from slipstep.sweep.runner import case_runner

    start = time.perf_counter()
    case_runner(payload).run(values)
    return time.perf_counter() - start


def _task_key(rows) -> str:
    """A task key from the content of the batch (the case hashes), so that a resumed sweep,
    whose batches may group other cases, never meets a stale task of the same name."""
    import hashlib

    digest = hashlib.sha256("".join(r[1] for r in rows).encode()).hexdigest()[:16]
    return f"slipstep-sweep-{rows[0][0]}-{digest}"


def task_failure(row, exc: BaseException) -> dict:
    """The result of a case whose task failed on every try (its cases are retried on resume)."""
    from slipstep import __version__

    index, digest, _ = row
    return {
        "index": int(index),
        "hash": digest,
        "status": STATUS_TASK,
        "warning": "",
        "summary": {},
        "histories": {},
        "frf": {},
        "message": f"the task failed on every try: {type(exc).__name__}: {exc}",
        "timing": {"kernel_time_s": math.nan, "wall_time_s": math.nan, "case_time_s": math.nan, "case_cpu_s": math.nan},
        "worker": "",
        "version": __version__,
    }


def default_batch_size(n_cases: int, slots: int) -> int:
    """About 10 tasks per slot (worker thread: load balance, a lost task loses little), at most
    100 cases each (a quasi-static paper case takes ~6 ms: a task lasts under a second)."""
    return max(1, min(100, math.ceil(n_cases / (10 * max(slots, 1)))))


def batches(rows: list, size: int) -> list[list]:
    return [rows[k : k + size] for k in range(0, len(rows), size)]


def machine_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        return os.cpu_count() or 1


class SerialExecutor:
    """The batches in order, in this process."""

    name = "serial"
    workers = 1
    slots = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def warm_up(self, payload: Payload, values) -> float:
        return warm_up(payload, values)

    def map(self, payload: Payload, tasks: list[list]) -> Iterator[list[dict]]:
        for rows in tasks:
            yield run_batch(payload, rows)


class DaskExecutor:
    """dask.distributed: a loopback LocalCluster of ``workers`` single-threaded processes
    (default: one per core) or the cluster of ``scheduler`` (an address such as
    tcp://10.0.0.5:8786). ``threads`` > 1 runs several cases per worker process in
    threads (the kernels release the GIL; the set-up around them does not). Python's warning
    capture is process-wide, so with threads a case's ``warning`` text may carry a warning of
    a case run beside it; the numbers are unaffected."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, workers: int | None = None, threads: int = 1, retries: int = 3):
        self.scheduler, self.n_workers, self.threads, self.retries = scheduler, workers, threads, retries
        self.cluster = self.client = None
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise InputError("workers", f"is {workers!r}", "give a whole number >= 1")
        if scheduler is not None and workers is not None:
            raise InputError("workers", "is set together with --scheduler", "size an existing cluster where it runs")
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise InputError("threads", f"is {threads!r}", "give a whole number >= 1")

    def __enter__(self):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:  # pragma: no cover
            raise InputError(
                "scheduler", "dask.distributed is not installed", "pip install 'dask[distributed]' or run with --serial"
            ) from None
        if self.scheduler is None:
            n = self.n_workers or machine_cores()
            self.cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=self.threads,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                silence_logs=logging.ERROR,
                memory_limit=0,
            )
            self.client = Client(self.cluster)
        else:
            try:
                self.client = Client(self.scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(
                    "scheduler",
                    f"{self.scheduler!r} cannot be reached ({exc})",
                    "give the address a running `dask scheduler` prints (tcp://HOST:8786)",
                ) from None
            try:
                self.client.wait_for_workers(1, timeout=30)
            except TimeoutError:
                self.client.close()
                raise InputError(
                    "scheduler",
                    f"{self.scheduler!r} has no workers (waited 30 s)",
                    f"start some: dask worker {self.scheduler}",
                ) from None
        return self

    @property
    def workers(self) -> int:
        """Worker processes of the cluster."""
        return max(1, len(self.client.scheduler_info(n_workers=-1)["workers"])) if self.client else 1

    @property
    def slots(self) -> int:
        """Cases the cluster runs at once: the threads of all its workers."""
        info = self.client.scheduler_info(n_workers=-1)["workers"] if self.client else {}
        return max(1, sum(w.get("nthreads", 1) for w in info.values()))

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        return False

    def warm_up(self, payload: Payload, values) -> float:
        """Every worker runs :func:`warm_up` (in parallel); returns the seconds it took."""
        start = time.perf_counter()
        self.client.run(warm_up, payload, values)
        return time.perf_counter() - start

    def map(self, payload: Payload, tasks: list[list]) -> Iterator[list[dict]]:
        from dask.distributed import as_completed

        if not tasks:
            return
        shared = self.client.scatter(payload, broadcast=True)
        futures = {
            self.client.submit(run_batch, shared, rows, pure=False, retries=self.retries, key=_task_key(rows)): rows
            for rows in tasks
        }
        try:
            for future in as_completed(list(futures)):
                try:
                    result = future.result()
                except Exception as exc:  # noqa: BLE001 - the task failed on every try (it killed its workers)
                    result = [task_failure(row, exc) for row in futures[future]]
                future.release()
                yield result
        finally:
            for f in futures:
                if not f.done():
                    f.cancel()
