"""One case of a sweep: its payload, the case-format path (:func:`run_case`), the fast path
from the kernel's arrays, the FRF-only path, and the guard that turns every failure into a
result with its status and message (a case never raises). The per-worker runner
(slipstep.sweep.runner) and the executors (slipstep.sweep.execute) stand on it.
"""

from __future__ import annotations

import math
import time
import warnings
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
        result["summary"].update(_mistuning_summary(payload, data, values, system, result["frf"]))


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
        "summary": _mistuning_summary(payload, data, values, system, frf),
        "frf": frf,
        "timing": {"kernel_time_s": math.nan, "wall_time_s": time.perf_counter() - wall},
    }


def _mistuning_summary(payload: Payload, data: dict, values, system, frf: dict) -> dict:
    """The mistuning fields of a case (slipstep.sweep.mistuning), {} for other sweeps."""
    from slipstep.sweep.mistuning import case_peaks, mistuning_stats, reference_for, summary_of

    cfg = payload.outputs.get("mistuning")
    if not cfg:
        return {}
    ref = reference_for(payload.reference, payload.parameters, values)
    p = case_peaks(system, frf, payload.outputs["frf"], cfg["responses"])
    return {**summary_of(p, ref), **mistuning_stats(data)}


def _run_options(run, extra: dict) -> dict:
    """RunOptions from a case's [run] table and the sweep's extra options."""
    opts = {}
    if run.duration_s is not None:
        opts["duration"] = run.duration_s
    for key in ("periods", "step_ratio", "steps_per_period", "step_rule", "tolerance"):
        if getattr(run, key, None) is not None:
            opts[key] = getattr(run, key)
    if getattr(run, "save", None) is not None:  # [run.save]: what the march stores (as `slipstep run`)
        opts["save"] = run.save.options()
    opts.update(extra)
    opts.setdefault("sensitivity_check", False)  # a sweep has its own checks: no perturbed twin per case
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
