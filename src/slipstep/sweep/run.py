"""The sweep driver: plan, store, executor, incremental writes, resume.

    report = run_sweep("examples/amplitude_sweep.toml", "amp.zarr")             # local dask cluster
    report = run_sweep(spec, "amp.zarr", executor=SerialExecutor())             # one process
    report = run_sweep(spec, "amp.zarr", executor=DaskExecutor("tcp://host:8786"))

The client is the only writer of the store: finished batches are buffered and flushed every
``flush_seconds`` (default 5 s: a flush costs ~50 ms plus ~0.1 ms per case, so the client
stays a few per cent of a core) and at the end and on Ctrl-C, so a killed client loses at most the
cases of the last ``flush_seconds``, and a rerun of the same call computes only the cases
the store does not hold yet.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from slipstep.errors import InputError
from slipstep.sweep.cases import Plan, make_plan
from slipstep.sweep.execute import DaskExecutor, batches, default_batch_size, payload_of
from slipstep.sweep.spec import SweepSpec, load_spec
from slipstep.sweep.store import SweepStore


def plan_of(spec: SweepSpec | str | Path) -> Plan:
    return make_plan(spec if isinstance(spec, SweepSpec) else load_spec(spec))


def labels_of(plan: Plan) -> dict:
    """Names along the model's dimensions (the parameters change values, not the model's
    topology), from the probe case: the base case with the keys it does not hold (defaults)
    set to their parameter's first value. A probe that is not a valid case is an error of the
    spec (a misspelt key, an invalid base case); invalid values of single cases are not: they
    are recorded as those cases' INPUT_ERROR."""
    from slipstep.post.loops import interfaces_from_system
    from slipstep.sweep.cases import build_case, probe_case

    try:
        system, run = build_case(probe_case(plan), plan.base_dir, source="the base case of the sweep")
    except InputError as exc:
        raise InputError(exc.field, f"{exc.problem} (base case of the sweep)", exc.fix) from None
    _check_run(run, plan.extra_run)
    return {
        "interface": list(interfaces_from_system(system)),
        "contact": list(system.contact_names),
        "direction": list(system.direction_names()),
        "dof": list(system.structure.dof_names),
        "motion": list(system.motion_names),
    }


def _check_run(run, extra: dict) -> None:
    """The method and run options, checked once (not once per case); errors name run.<key>."""
    from slipstep.methods.registry import get_method
    from slipstep.methods.simulation import RunOptions
    from slipstep.sweep.execute import _run_options

    try:
        get_method(run.method or "newmark")
    except InputError as exc:
        raise InputError("[run] method", exc.problem, exc.fix) from None
    try:
        RunOptions(**_run_options(run, extra)).validated()
    except InputError as exc:
        raise InputError(f"[run] {exc.field}", exc.problem, exc.fix) from None


def run_sweep(
    spec: SweepSpec | str | Path,
    store: str | Path,
    *,
    executor=None,
    batch_size: int | None = None,
    overwrite: bool = False,
    progress: Callable[[dict], None] | None = None,
    flush_seconds: float = 5.0,
) -> dict:
    """Compute every case of ``spec`` missing from ``store`` (created if needed) and return a
    report: cases, computed, skipped (already stored), missing (still not in the store: lost
    tasks, computed by a rerun), status_counts, failed, elapsed_s (the cases only), startup_s
    (cluster start and one warm-up case per worker, which loads the kernels), cases_per_s,
    mean_kernel_time_s, mean_case_time_s, mean_case_cpu_s (CPU of the case in its worker thread),
    overhead_per_case_s (case time outside the kernel),
    batch_size, workers, executor. ``progress`` is called with the running counts after each
    batch. The executor (default: a local dask cluster) is not started when nothing is missing."""
    plan = plan_of(spec)
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1):
        raise InputError("batch_size", f"is {batch_size!r}", "give a whole number >= 1")
    sweep_store = SweepStore.open_or_create(store, plan, labels_of(plan), overwrite=overwrite)
    done = sweep_store.done()
    rows = [(int(i), plan.hashes[i], plan.values[i].tolist()) for i in np.flatnonzero(~done)]
    state = {
        "total": plan.n_cases,
        "skipped": int(done.sum()),
        "computed": 0,
        "failed": 0,
        "todo": len(rows),
        "elapsed_s": 0.0,
    }
    counts: Counter = Counter()
    times: list[tuple[float, float]] = []
    size, workers, startup, elapsed, name = 0, 0, 0.0, 0.0, getattr(executor, "name", "dask")
    if rows:
        executor = executor if executor is not None else DaskExecutor()
        started = time.perf_counter()
        reference = _mistuning_reference(plan, sweep_store)
        with executor as ex:
            payload = payload_of(plan, reference)
            ex.warm_up(payload, rows[0][2])
            start = time.perf_counter()
            startup = start - started
            size = batch_size or plan.spec.batch_size or default_batch_size(len(rows), ex.slots)
            if progress is not None:
                progress(dict(state))
            results = ex.map(payload, batches(rows, size))
            _collect(results, sweep_store, state, counts, times, start, flush_seconds, progress)
            elapsed, workers, name = time.perf_counter() - start, ex.workers, ex.name
    k, c, u = (np.array([t[i] for t in times], float) for i in (0, 1, 2))
    return {
        "store": str(store),
        "cases": plan.n_cases,
        "computed": state["computed"],
        "skipped": state["skipped"],
        "missing": int((~sweep_store.done()).sum()),
        "status_counts": dict(counts),
        "failed": state["failed"],
        "elapsed_s": elapsed,
        "startup_s": startup,
        "cases_per_s": state["computed"] / elapsed if elapsed > 0 else float("nan"),
        "mean_kernel_time_s": float(np.nanmean(k)) if np.isfinite(k).any() else float("nan"),
        "mean_case_time_s": float(np.nanmean(c)) if np.isfinite(c).any() else float("nan"),
        "mean_case_cpu_s": float(np.nanmean(u)) if np.isfinite(u).any() else float("nan"),
        "overhead_per_case_s": float(np.nanmean(c - np.nan_to_num(k))) if np.isfinite(c).any() else float("nan"),
        "batch_size": size,
        "workers": workers,
        "executor": name,
    }


def _mistuning_reference(plan: Plan, store: SweepStore) -> list[dict]:
    """The tuned peaks of a mistuning sweep (:func:`tuned_references`), computed
    by the client once per sweep and kept in the store's attrs (``mistuning_reference``: a
    resumed sweep reads them; ``mistuning_responses``: the blade DOFs); [] for other sweeps."""
    import json

    if "mistuning" not in plan.outputs:
        return []
    stored = store.group.attrs.get("mistuning_reference")
    if stored:
        return json.loads(stored)
    from slipstep.sweep.execute import frf_values

    reference = tuned_references(plan, frf_values)
    store.group.attrs["mistuning_reference"] = json.dumps(reference)
    store.group.attrs["mistuning_responses"] = list(plan.outputs["mistuning"]["responses"])
    store.consolidate()
    return reference


def tuned_references(plan, frf_values) -> list[dict]:
    """The tuned assembly's peaks, once per combination of the non-mistuning parameters:
    [{"values": [...], "<peak field>": A_peak, its frequency and blade fields, ...}] (the linear
    limits' peaks refined off the grid as the cases': slipstep.sweep.mistuning.case_peaks).
    ``frf_values(system, run, cfg)`` computes the FRF arrays (slipstep.sweep.execute.frf_values). A tuned case that cannot be built or solved
    is an error of the sweep (its amplification factors would have no reference)."""
    from slipstep.sweep.cases import apply_values, build_case
    from slipstep.sweep.mistuning import apply_mistuning, case_peaks, reference_key, summary_of

    m = next(p.mistuning for p in plan.parameters if p.mistuning is not None)
    seen: dict[tuple, int] = {}
    for i, row in enumerate(plan.values):
        seen.setdefault(reference_key(plan.parameters, row), i)
    out = []
    for key, i in seen.items():
        data = apply_values(plan.base, plan.parameters, plan.values[i])
        apply_mistuning(data, m, 0.0, 0)
        try:
            system, run = build_case(data, plan.base_dir, source="the tuned case of the sweep")
        except InputError as exc:
            raise InputError(exc.field, f"{exc.problem} (the tuned case of the sweep)", exc.fix) from None
        frf = frf_values(system, run, plan.outputs["frf"])
        cfg = plan.outputs["frf"]
        p = case_peaks(system, frf, cfg, plan.outputs["mistuning"]["responses"])
        entry = {"values": list(key), **summary_of(p, None)}
        entry = {k: v for k, v in entry.items() if not k.endswith("amplification_factor")}
        out.append(entry)
    return out


def _collect(
    results, store: SweepStore, state: dict, counts: Counter, times: list, start: float, flush_seconds: float, progress
) -> None:
    """Receive the batches as they finish, flush them to the store every ``flush_seconds`` and
    once more at the end, on Ctrl-C or on any error (nothing received is lost)."""
    from slipstep import __version__

    buffer: list[dict] = []
    last_flush = time.perf_counter()
    try:
        for batch in results:
            for r in batch:
                if r["version"] != __version__:
                    raise InputError(
                        "scheduler",
                        f"a worker runs slipstep {r['version']}, this client {__version__}",
                        "install the same slipstep version on every worker",
                    )
                counts[r["status"]] += 1
                times.append((r["timing"]["kernel_time_s"], r["timing"]["case_time_s"], r["timing"]["case_cpu_s"]))
            buffer.extend(batch)
            state["computed"] += len(batch)
            state["failed"] = sum(v for k, v in counts.items() if k != "OK")
            state["elapsed_s"] = time.perf_counter() - start
            if time.perf_counter() - last_flush >= flush_seconds:
                store.write(buffer)
                buffer, last_flush = [], time.perf_counter()
            if progress is not None:
                progress(dict(state))
    finally:
        store.write(buffer)
