"""Side-by-side comparison of the paper's methods on one case (paper Section 6, Figs. 5 and 8).

For each method the same System is marched with the same options. The table reports:

* kernel wall time (:func:`time_kernels`, run in a fresh process that loads the kernels
  compiled here from the cache, :func:`fresh_process_times`): every method's kernel is
  warmed first (called through its compiled entry point twice), then the
  ``repeats`` timed calls of :meth:`Simulation.march` are interleaved across the methods (in
  a rotating order, garbage collection off), so that load from other processes and the
  machine's state hit every method alike; the median, the minimum, the ratios of both to
  Method 1's, and the spread of the samples, interquartile range / median;
* counts: steps, linear solves, mean solves per step, the share of steps that needed a
  single solve, state changes (raw over the run, and over the last period);
* accuracy against Method 1 (``newmark``) over the LAST period: the largest difference of
  the translational DOF displacements [um] and of the contact forces (tangential and
  normal) as a percentage of CF = |constant_force| [N]. Results on another time grid
  (adaptive, quasi-static) are linearly interpolated onto Method 1's grid. The same
  differences are also given after a zero-phase low-pass filter that removes the damper's
  ringing at its internal frequencies (paper 5.1): :func:`slipstep.post.filtering.lowpass`
  (zero-phase Butterworth) on a uniform grid of Method 1's step, with the cut-off that
  :func:`slipstep.post.filtering.choose_cutoff` picks between the excitation harmonics and the
  lowest internal frequency of the states Method 1 visits (it warns when they are too close).

Writers: :func:`write_csv`, :func:`write_json`, :func:`plot_time_ratios` (Figure 8) and
:func:`plot_solves_histogram` (Figure 5).
"""

from __future__ import annotations

import csv
import gc
import io
import json
import math
import multiprocessing
import os
import queue
import signal
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from statistics import median

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.output.io import plain_text_figures, save_figure, write_text
from slipstep.methods.registry import COMPARE_METHODS, PAPER_METHODS, get_method
from slipstep.methods.simulation import Simulation
from slipstep.post.filtering import (
    choose_cutoff,
    excitation_frequencies,
    lowest_internal_frequency,
    lowpass,
    samples_per_period,
    visited_states,
)
from slipstep.model.system import System

REFERENCE = "newmark"

#: Columns of the comparison table, in order (all keys of a row).
COLUMNS = (
    "method",
    "paper_method",
    "status",
    "steps",
    "solves",
    "mean_solves_per_step",
    "single_solve_share",
    "state_changes",
    "state_changes_last_period",
    "kernel_time_s",
    "time_ratio",
    "kernel_time_min_s",
    "time_ratio_min",
    "time_spread",
    "dt_min_s",
    "dt_max_s",
    "max_disp_diff_um",
    "max_force_diff_pct_cf",
    "max_disp_diff_filtered_um",
    "max_force_diff_filtered_pct_cf",
)


def time_kernels(sims: dict, repeats: int, warmups: int = 2) -> dict[str, list[float]]:
    """Kernel times [s] of ``repeats`` calls of ``march()`` per runner in ``sims`` (name ->
    runner): all runners warmed ``warmups`` times first, then the timed calls interleaved
    (round r starts at runner r mod len, so no runner always follows the same one), with
    garbage collection off."""
    names = list(sims)
    for _ in range(warmups):
        for name in names:
            sims[name].march()
    samples: dict[str, list[float]] = {name: [] for name in names}
    enabled = gc.isenabled()
    gc.disable()
    try:
        for r in range(repeats):
            k = r % len(names)
            for name in names[k:] + names[:k]:
                sims[name].march()
                samples[name].append(sims[name].kernel_time)
    finally:
        if enabled:
            gc.enable()
    return samples


def fresh_process_times(system: System, names: list[str], periods: float, repeats: int, options: dict):
    """(samples, "a fresh process") from :func:`time_kernels` run in a new Python process that
    loads the kernels this process compiled from numba's cache, or (None, the reason) if that
    process could not be started or failed.

    Why: in the process that has just compiled the kernels, the same compiled code runs 5-20 %
    slower, unevenly across the methods (measured on the paper case: the event-driven method
    0.053-0.061 of Method 1 there against 0.045-0.048 in a process that loaded them from the
    cache; Method 4 0.180-0.188 against 0.164-0.177). It is an effect of where the compiler
    left code and data in memory, not of the kernels, and it made the first run of a fresh
    install disagree with every later run."""
    try:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            samples = pool.submit(_times_of_new_runners, system, names, periods, repeats, options).result()
    except Exception as exc:  # noqa: BLE001  (any failure: time in this process instead, and say why)
        return None, f"a fresh process failed: {type(exc).__name__}: {exc}"
    return samples, "a fresh process"


@dataclass
class CompilingHelper:
    """The process of :func:`compile_ahead` and what it has said so far: the method it marches
    now (``progress``: a queue of ("start" | "done", method name))."""

    process: multiprocessing.process.BaseProcess
    progress: object
    marching: str | None = None

    def wait_for(self, name: str, timeout: float = 600.0) -> None:
        """If the helper is marching ``name`` now, wait until it is done (the kernel then in
        numba's cache, loaded here): compiling it in this process too would only take its time
        twice. Returns at once for a method the helper is not marching, and when the helper
        ends or ``timeout`` [s] passes."""
        self._read(wait=0.0)
        deadline = time.monotonic() + timeout
        while self.marching == name and self.process.is_alive() and time.monotonic() < deadline:
            self._read(wait=1.0)

    def _read(self, wait: float) -> None:
        """Take the helper's messages: the first within ``wait`` [s] (none: do not wait), then
        those already there."""
        try:
            while True:
                kind, name = self.progress.get(timeout=wait) if wait > 0 else self.progress.get_nowait()
                self.marching = name if kind == "start" else None
                wait = 0.0
        except (queue.Empty, OSError, ValueError):
            pass

    def stop(self) -> None:
        """Terminate the helper (its work is done or no longer needed) and wait for it."""
        self.process.terminate()
        self.process.join(timeout=10)


def compile_ahead(system: System, names: list[str], options: dict) -> CompilingHelper | None:
    """Start a process that marches ``names`` briefly, in that order, so that numba compiles their
    kernels into its on-disk cache while this process compiles the others; return it (the caller
    stops it when it needs it no more), or None on a machine with one CPU.

    compare() builds every runner first (each one's static preload marches the implicit kernel:
    compiled here, then cached), then starts this helper on the methods in reverse order while it
    runs them in order: the last method's kernel (on the paper case the event-driven march) is
    compiled by the helper while this process compiles the first ones' and the quasi-static
    march, and this process loads it from the cache when it gets there, after waiting for the
    helper if it is still at it (:meth:`CompilingHelper.wait_for`). Nothing but numba's cache
    is shared: a kernel both processes compile is compiled twice (numba writes its cache files
    atomically), and the results are this process's alone. With the lean compiler, on an empty
    cache on two cores, ``slipstep compare paper`` took 132 s of wall time against 208 s before
    both changes (docs/measured.md, "Compile time")."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if cpus < 2:
        return None
    context = multiprocessing.get_context("spawn")
    progress = context.Queue()
    process = context.Process(
        target=_march_briefly, args=(system, names, options, progress), name="slipstep-compile-ahead", daemon=True
    )
    process.start()
    return CompilingHelper(process, progress)


def _march_briefly(system: System, names: list[str], options: dict, progress) -> None:
    """:func:`compile_ahead`'s body: a few steps of each method (their kernels compiled and cached),
    each between a ("start", name) and a ("done", name) on ``progress``; silent: Ctrl-C is the
    caller's (it terminates this process), warnings are the caller's runs'."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warnings.simplefilter("ignore")
    for name in names:
        progress.put(("start", name))
        try:
            Simulation(system, name, **{**options, "periods": 0.05}).run()
        except Exception:  # noqa: BLE001  (a warm-up only: this process's failures are the caller's to find)
            pass
        finally:
            progress.put(("done", name))


def _times_of_new_runners(system: System, names: list[str], periods: float, repeats: int, options: dict) -> dict:
    """:func:`time_kernels` on new runners of ``names`` (the body of the fresh process)."""
    sims = {name: Simulation(system, name, periods=periods, **options) for name in names}
    for sim in sims.values():
        sim.run()
    return time_kernels(sims, repeats)


def compare(
    system: System,
    methods=COMPARE_METHODS,
    periods: float = 3,
    repeats: int = 21,
    cutoff_Hz: float | None = None,
    datasets: dict | None = None,
    fresh_process: bool = True,
    **options,
) -> list[dict]:
    """Run ``methods`` on ``system`` and return one row (dict, keys :data:`COLUMNS` plus
    ``force_scale_N``, ``filter_cutoff_Hz`` and ``timed_in``) per method, Method 1 first.

    ``cutoff_Hz``: low-pass cut-off (default: chosen by slipstep.post.filtering.choose_cutoff).
    ``datasets``: if a dict is given it receives the result Dataset of every method.
    ``fresh_process``: time the kernels in a fresh process (:func:`fresh_process_times`), else
    in this one. ``options``: further :class:`~slipstep.methods.options.RunOptions` for every
    method. Each row's ``timed_in`` says where the kernels were timed.
    """
    names = _method_names(methods)
    options = {**options, "step_rule": "t-min"}  # the paper's rule: Methods 1 and 3 march the same steps
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise InputError("repeats", f"is {repeats!r}", "give a whole number >= 1")
    if cutoff_Hz is not None and not (
        isinstance(cutoff_Hz, (int, float)) and math.isfinite(cutoff_Hz) and cutoff_Hz > 0
    ):
        raise InputError("cutoff_Hz", f"is {cutoff_Hz!r}", "give a frequency > 0 [Hz], or None to choose it")
    sims = {name: Simulation(system, name, periods=periods, **options) for name in names}
    helper = compile_ahead(system, names[::-1], options) if fresh_process else None
    results = {}
    try:
        for name, sim in sims.items():
            if helper is not None:
                helper.wait_for(name)
            results[name] = sim.run()  # the results (and the first, compiling call)
    finally:
        if helper is not None:
            helper.stop()
    times, timed_in = fresh_process_times(system, names, periods, repeats, options) if fresh_process else (None, "")
    if times is None:
        times, timed_in = time_kernels(sims, repeats), "this process" + (f" ({timed_in})" if timed_in else "")
    if datasets is not None:
        datasets.update(results)
    ref = results[REFERENCE]
    force_scale = _force_scale(system, ref)
    cutoff = _cutoff(system, ref) if cutoff_Hz is None else float(cutoff_Hz)
    filtered_ref = _lowpass_dataset(ref, ref, cutoff)
    rows = []
    for name in names:
        ds = results[name]
        rows.append(_row(ds, ref, filtered_ref, times[name], times[REFERENCE], force_scale, cutoff))
        rows[-1]["timed_in"] = timed_in
    return rows


def _method_names(methods) -> list[str]:
    if isinstance(methods, str):
        methods = [m for m in methods.split(",") if m.strip()]
    names = []
    for m in methods:
        name = get_method(m).name
        if name not in names:
            names.append(name)
    if not names:
        raise InputError("methods", "is empty", f"give method names, e.g. {','.join(PAPER_METHODS)}")
    if REFERENCE in names:
        names.remove(REFERENCE)
    return [REFERENCE] + names  # the reference (Method 1) always runs, first


def _force_scale(system: System, ref: xr.Dataset) -> float:
    """CF = |constant force| [N]; without a constant load, the largest reference contact force."""
    f0 = system.excitation.constant_force
    cf = float(np.linalg.norm(f0)) if f0 is not None else 0.0
    if cf > 0:
        return cf
    peak = max(
        float(np.abs(ref.tangential_force.values).max(initial=0.0)),
        float(np.abs(ref.normal_force.values).max(initial=0.0)),
    )
    return peak if peak > 0 else 1.0


def _cutoff(system: System, ref: xr.Dataset) -> float:
    """The automatic cut-off of the paper's filter (slipstep.post.filtering), kept below the
    Nyquist frequency of Method 1's grid; FilterWarning when the ringing cannot be separated."""
    period = float(ref.attrs["period_s"]) if "period_s" in ref.attrs else float(ref.attrs["t_end_s"])
    excitation = max(excitation_frequencies(system), default=1.0 / period)
    internal = lowest_internal_frequency(system, visited_states(ref))
    return min(choose_cutoff(excitation, internal).cutoff_Hz, 0.4 / float(ref.attrs["dt_s"]))


def _last_period(ref: xr.Dataset) -> np.ndarray:
    t = ref.time.values
    period = float(ref.attrs.get("period_s", t[-1]))
    return t >= t[-1] - period * (1 + 1e-9)


def _on_grid(ds: xr.Dataset, name: str, t: np.ndarray) -> np.ndarray:
    """Variable ``name`` (time, k) linearly interpolated onto times ``t`` -> (len(t), k)."""
    tt, values = ds.time.values, np.asarray(ds[name].values, float)
    return np.column_stack([np.interp(t, tt, values[:, j]) for j in range(values.shape[1])])


def _translational(ds: xr.Dataset) -> np.ndarray:
    units = np.asarray(ds.dof_unit.values).astype(str)
    return units == "m"


def _differences(a: dict, b: dict, mask: np.ndarray, force_scale: float) -> tuple[float, float]:
    disp = np.abs(a["displacement"][mask] - b["displacement"][mask])
    force = np.concatenate([np.abs(a[k][mask] - b[k][mask]).ravel() for k in ("tangential_force", "normal_force")])
    return float(disp.max(initial=0.0)) * 1e6, float(force.max(initial=0.0)) / force_scale * 100.0


def _signals(ds: xr.Dataset, t: np.ndarray, translational: np.ndarray) -> dict:
    out = {k: _on_grid(ds, k, t) for k in ("displacement", "tangential_force", "normal_force")}
    out["displacement"] = out["displacement"][:, translational]
    return out


def _uniform_grid(ref: xr.Dataset) -> np.ndarray:
    t = ref.time.values
    dt = float(ref.attrs["dt_s"])
    n = max(int(round((t[-1] - t[0]) / dt)), 1)
    return np.linspace(t[0], t[-1], n + 1)


def _lowpass_dataset(ds: xr.Dataset, ref: xr.Dataset, cutoff: float) -> dict:
    """The compared signals of ``ds`` resampled on the reference's uniform grid and low-pass filtered."""
    grid = _uniform_grid(ref)
    sig = _signals(ds, grid, _translational(ref))
    dt = grid[1] - grid[0]
    per = samples_per_period(grid, ref.attrs.get("period_s"))
    out = {k: lowpass(v, dt, cutoff, period_samples=per) for k, v in sig.items()}
    out["time"] = grid
    return out


def _row(ds, ref, filtered_ref, samples, ref_samples, force_scale, cutoff) -> dict:
    a = ds.attrs
    kernel_time, ref_time = median(samples), median(ref_samples)
    fastest, ref_fastest = min(samples), min(ref_samples)
    solves = ds.solves.values[1:]
    steps = int(a["steps"])
    last = _last_period(ref)
    t_ref = ref.time.values
    trans = _translational(ref)
    d_um, f_pct = _differences(_signals(ds, t_ref, trans), _signals(ref, t_ref, trans), last, force_scale)
    filt = _lowpass_dataset(ds, ref, cutoff)
    fd_um, ff_pct = _differences(filt, filtered_ref, _grid_last(filt["time"], ref), force_scale)
    states = ds.contact_state.values
    changed = np.any(states[1:] != states[:-1], axis=1)
    t = ds.time.values
    period = float(a.get("period_s", t[-1]))
    in_last = t[1:] > t[-1] - period * (1 + 1e-9)
    steps_dt = ds.step_size.values[1:]
    return {
        "method": a["method"],
        "paper_method": a["paper_method"],
        "status": a["status"],
        "steps": steps,
        "solves": int(a["solves"]),
        "mean_solves_per_step": float(a["mean_solves_per_step"]),
        "single_solve_share": float(np.mean(solves == 1)) if solves.size else math.nan,
        "state_changes": int(a["state_changes"]),
        "state_changes_last_period": int(np.count_nonzero(changed & in_last)),
        "kernel_time_s": float(kernel_time),
        "time_ratio": float(kernel_time / ref_time) if ref_time > 0 else math.nan,
        "kernel_time_min_s": float(fastest),
        "time_ratio_min": float(fastest / ref_fastest) if ref_fastest > 0 else math.nan,
        "time_spread": float(np.subtract(*np.percentile(samples, [75, 25])) / kernel_time)
        if kernel_time > 0
        else math.nan,
        "dt_min_s": float(steps_dt.min()) if steps_dt.size else math.nan,
        "dt_max_s": float(steps_dt.max()) if steps_dt.size else math.nan,
        "max_disp_diff_um": d_um,
        "max_force_diff_pct_cf": f_pct,
        "max_disp_diff_filtered_um": fd_um,
        "max_force_diff_filtered_pct_cf": ff_pct,
        "force_scale_N": force_scale,
        "filter_cutoff_Hz": cutoff,
    }


def _grid_last(grid: np.ndarray, ref: xr.Dataset) -> np.ndarray:
    period = float(ref.attrs.get("period_s", grid[-1]))
    return grid >= grid[-1] - period * (1 + 1e-9)


# -- writers ------------------------------------------------------------------------------------


def write_csv(rows: list[dict], path) -> Path:
    """The table as CSV (one line per method, header = keys of the first row)."""
    path = Path(path)
    buffer = io.StringIO(newline="")
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    return write_text(path, buffer.getvalue())


def write_json(rows: list[dict], path) -> Path:
    """The table as a JSON list of objects."""
    return write_text(Path(path), json.dumps(rows, indent=2, default=_jsonable) + "\n")


def _jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {value!r}")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_time_ratios(rows: list[dict], path, title: str = "") -> Path:
    """Figure 8 of the paper: kernel CPU time of each method relative to Method 1, the paper's
    stated ratios (Method.paper_time_ratio) marked beside the measured ones."""
    plt = _pyplot()
    labels = [f"{r['paper_method']}\n{r['method']}" for r in rows]
    ratios = [r["time_ratio"] for r in rows]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(rows)), 4.2))
    bars = ax.bar(range(len(rows)), ratios, color="tab:blue")
    for bar, r in zip(bars, rows):
        ax.annotate(
            f"{r['time_ratio']:.3g}\n({r['kernel_time_s'] * 1e3:.3g} ms)",
            (bar.get_x() + bar.get_width() / 2, bar.get_height()),
            ha="center",
            va="bottom",
            fontsize=8,
        )
    stated = {i: get_method(r["method"]).paper_time_ratio for i, r in enumerate(rows)}
    stated = {i: p for i, p in stated.items() if p is not None and rows[i]["method"] != REFERENCE}
    for k, (i, (wording, value)) in enumerate(stated.items()):  # the paper's ratios beside ours
        ax.hlines(value, i - 0.45, i + 0.45, color="tab:orange", lw=2.5, label="paper (Fig. 8)" if k == 0 else None)
        labels[i] += f"\npaper: {'< ' if wording == 'below' else 'about '}{value:g}"
    if stated:
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xticks(range(len(rows)), labels, fontsize=8)
    ax.set_ylabel("kernel time / Method 1 kernel time [-]")
    ax.set_ylim(0, max(1.0, max(ratios)) * 1.25)
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_title(title or "Computational time relative to standard Newmark (paper Fig. 8)")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_solves_histogram(datasets: dict, path, methods=(REFERENCE, "piecewise-linear")) -> Path:
    """Figure 5 of the paper: histograms of linear solves (iterations) per time step."""
    plt = _pyplot()
    shown = [m for m in methods if m in datasets]
    fig, axes = plt.subplots(1, max(len(shown), 1), figsize=(5.0 * max(len(shown), 1), 3.8), squeeze=False)
    for ax, name in zip(axes[0], shown):
        ds = datasets[name]
        solves = ds.solves.values[1:]
        edges = np.arange(0.5, max(int(solves.max(initial=1)), 1) + 1.5)
        ax.hist(solves, bins=edges, color="tab:orange", edgecolor="black")
        ax.set_xlabel("linear solves (iterations) per time step [-]")
        ax.set_ylabel("number of time steps [-]")
        ax.set_title(f"{ds.attrs['paper_method']} ({name}): mean {solves.mean():.2f}", fontsize=10)
    fig.suptitle("Iterations per time step (paper Fig. 5)")
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    return Path(path)


@plain_text_figures
def write_outputs(rows: list[dict], datasets: dict, output_dir, title: str = "") -> dict[str, Path]:
    """Write comparison.csv, comparison.json, fig8_time_ratios.png and fig5_iterations.png."""
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    return {
        "csv": write_csv(rows, out / "comparison.csv"),
        "json": write_json(rows, out / "comparison.json"),
        "fig8": plot_time_ratios(rows, out / "fig8_time_ratios.png", title),
        "fig5": plot_solves_histogram(datasets, out / "fig5_iterations.png"),
    }
