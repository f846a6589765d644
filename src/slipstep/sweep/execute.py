"""Running the cases of a sweep: one case, a batch of cases, and the two executors.

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
import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError, SolverError

STATUS_INPUT = "INPUT_ERROR"  # the case's values are not a valid case
STATUS_PRELOAD = "PRELOAD_FAILED"  # the static preload found no equilibrium
STATUS_ERROR = "ERROR"  # an unexpected exception (a bug): type and message kept
STATUS_TASK = "TASK_FAILED"  # the dask task failed on every try (workers lost): retried on resume


@dataclass(frozen=True)
class Payload:
    """What every task needs, sent once per worker: the base case, the parameters' resolved
    locations, the extra run options and the outputs."""

    base: dict
    parameters: tuple
    extra_run: dict
    outputs: dict
    base_dir: str | None = None
    reference: tuple = ()  # a mistuning sweep's tuned peaks (slipstep.sweep.run.tuned_references)


def payload_of(plan, reference=()) -> Payload:
    return Payload(plan.base, plan.parameters, plan.extra_run, plan.outputs, plan.base_dir, tuple(reference))


def run_case(payload: Payload, values) -> dict:
    """Build and run one case through the case format (apply_values, build_case, Simulation);
    returns {"status", "message", "warning", "summary", "histories", "frf", "timing"}.
    Deterministic except "timing"."""
    return guarded(lambda result: _case_format(payload, values, result))


def empty_result() -> dict:
    return {
        "status": "",
        "message": "",
        "warning": "",
        "summary": {},
        "histories": {},
        "frf": {},
        "timing": {"kernel_time_s": math.nan, "wall_time_s": math.nan},
    }


def guarded(body) -> dict:
    """The result of one case whose entries ``body(result)`` fills in: its warnings recorded,
    an exception turned into the case's status and message (a case never raises), its time
    and CPU time added."""
    start, cpu = time.perf_counter(), time.thread_time()
    result = empty_result()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            body(result)
        except InputError as exc:
            result.update(status=STATUS_INPUT, message=str(exc))
        except SolverError as exc:
            result.update(status=STATUS_PRELOAD, message=str(exc))
        except Exception as exc:  # noqa: BLE001 - a case never aborts the sweep; the message names it
            result.update(status=STATUS_ERROR, message=f"{type(exc).__name__}: {exc}")
    return _finish(result, caught, start, cpu)


def _case_format(payload: Payload, values, result: dict) -> None:
    from slipstep.methods.simulation import Simulation
    from slipstep.post.summary import summarise, timings
    from slipstep.sweep.cases import apply_values, build_case

    data = apply_values(payload.base, payload.parameters, values)
    system, run = build_case(data, payload.base_dir)
    options = _run_options(run, payload.extra_run)
    method = run.method or "newmark"
    if payload.outputs.get("time_summary", True) is False:
        result.update(_run_frf_only(payload, data, values, system, run))
        return
    sim = Simulation(system, method, **options)
    if _fast(payload, options):
        result.update(_run_fast(sim, system))
        return
    ds = sim.run()
    result["status"] = ds.attrs["status"]
    result["message"] = ds.attrs["status_message"]
    result["summary"] = summarise(ds, system)
    result["timing"] = timings(ds)
    if payload.outputs.get("histories"):
        result["histories"] = histories(ds, payload.outputs["histories"], payload.outputs["history_points"])
    if payload.outputs.get("frf"):
        result["frf"] = frf_values(system, run, payload.outputs["frf"])
        result["summary"].update(_mistuning_summary(payload, data, values, result["frf"]))


def _finish(result: dict, caught: list, start: float, cpu: float) -> dict:
    if caught:
        result["warning"] = " | ".join(dict.fromkeys(" ".join(str(w.message).split()) for w in caught))
    result["timing"]["case_time_s"] = time.perf_counter() - start
    result["timing"]["case_cpu_s"] = time.thread_time() - cpu
    return result


def _fast(payload: Payload, options: dict) -> bool:
    """The fast path (summary from the kernel's arrays, no Dataset) serves the cases that store
    only the summary of a full record: no histories, no FRF, no save option."""
    outputs = payload.outputs
    return not outputs.get("histories") and not outputs.get("frf") and "save" not in options


def _run_fast(sim, interfaces) -> dict:
    """March ``sim`` and summarise it from the kernel's arrays (post.summary.record_of and
    summarise_record: the numbers of summarise(Simulation.run()), without the Dataset and
    without the step-doubling accuracy estimate, which the summary does not hold).
    ``interfaces``: the System, or its interfaces (post.loops.interfaces_from_system)."""
    from types import SimpleNamespace

    from slipstep.methods.simulation import collapsed_step_warning
    from slipstep.post.summary import record_of, summarise_record

    wall = time.perf_counter()
    sim.march()
    rec = record_of(sim)
    collapsed_step_warning(SimpleNamespace(attrs=dict(rec.attrs)))
    return {
        "status": rec.attrs["status"],
        "message": rec.attrs["status_message"],
        "summary": summarise_record(rec, interfaces),
        "timing": {"kernel_time_s": float(sim.kernel_time), "wall_time_s": time.perf_counter() - wall},
    }


def _run_frf_only(payload: Payload, data: dict, values, system, run) -> dict:
    """An FRF-only case ([outputs] time_summary = false): the FRF and its mistuning summary; the
    status OK when every point is OK, else the most frequent other point status."""
    from collections import Counter

    wall = time.perf_counter()
    frf = frf_values(system, run, payload.outputs["frf"])
    points = [str(s) for s in np.atleast_1d(frf.get("status", np.array([], str)))]
    bad = Counter(s for s in points if s != "OK")
    status = bad.most_common(1)[0][0] if bad else "OK"
    message = f"{sum(bad.values())} of {len(points)} FRF points are not OK ({dict(bad)})" if bad else ""
    return {
        "status": status,
        "message": message,
        "summary": _mistuning_summary(payload, data, values, frf),
        "frf": frf,
        "timing": {"kernel_time_s": math.nan, "wall_time_s": time.perf_counter() - wall},
    }


def _mistuning_summary(payload: Payload, data: dict, values, frf: dict) -> dict:
    """The mistuning fields of a case (slipstep.sweep.mistuning), {} for other sweeps."""
    from slipstep.sweep.mistuning import mistuning_stats, reference_for, summary_of

    cfg = payload.outputs.get("mistuning")
    if not cfg:
        return {}
    ref = reference_for(payload.reference, payload.parameters, values)
    return {**summary_of(frf, payload.outputs["frf"], cfg, ref), **mistuning_stats(data)}


def _run_options(run, extra: dict) -> dict:
    """RunOptions from a case's [run] table and the sweep's extra options."""
    opts = {}
    if run.duration_s is not None:
        opts["duration"] = run.duration_s
    for key in ("periods", "step_ratio", "steps_per_period"):
        if getattr(run, key) is not None:
            opts[key] = getattr(run, key)
    if getattr(run, "save", None) is not None:  # [run.save]: what the march stores (as `slipstep run`)
        opts["save"] = run.save.options()
    opts.update(extra)
    return opts


def histories(ds, names, points: int) -> dict:
    """The last period of each named variable on ``points`` uniform times from t_end - T to
    t_end (post.timeline.resample_uniform: floats interpolated, states held)."""
    from slipstep.post.periodic import last_period
    from slipstep.post.timeline import resample_uniform

    try:
        lp = resample_uniform(last_period(ds), n=points)
    except InputError:
        return {}
    return {name: np.asarray(lp[name].values) for name in names if name in lp}


def frf_values(system, run, cfg: dict) -> dict:
    """The case's frequency response (slipstep.frequency.frf with the [outputs.frf] settings and
    the sweep's method), its FRF_SCHEMA variables as arrays in ascending frequency."""
    from slipstep.frequency import FRF_SCHEMA, frf

    method = run.method if run.method and run.method not in ("quasi-static", "4") else "piecewise-linear"
    hbm = {"check": cfg["check"], "adequacy": cfg["adequacy"]} if cfg["solver"] == "hbm" else {}
    ds = frf(
        system,
        cfg["frequencies_Hz"],
        solver=cfg["solver"],
        direction=cfg["direction"],
        responses=cfg["responses"],
        harmonics=tuple(cfg["harmonics"]) if isinstance(cfg["harmonics"], list) else cfg["harmonics"],
        method=method,
        tolerance=cfg["tolerance"],
        **hbm,
    )
    if "point_kind" in ds and cfg["solver"] == "hbm":  # the asked points, not the continuation's steps
        ds = ds.isel(frequency=np.flatnonzero(np.asarray(ds["point_kind"].values).astype(str) == "asked"))
    ds = ds.sortby("frequency")
    _, first = np.unique(ds["frequency"].values, return_index=True)
    if first.size != ds.sizes["frequency"]:  # a frequency met twice (a fold): its first point
        ds = ds.isel(frequency=first)
    return {name: np.asarray(ds[name].transpose(*FRF_SCHEMA[name][0]).values) for name in FRF_SCHEMA if name in ds}


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
