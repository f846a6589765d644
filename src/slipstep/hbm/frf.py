"""Frequency (and excitation-level) responses by harmonic balance, in the FRF layout.

    ds = slipstep.hbm.frf(system, np.linspace(150, 450, 61), harmonics=(1, 3, 5))

follows the periodic response from the first to the last frequency by pseudo-arclength
continuation (:mod:`slipstep.hbm.continuation`: turning points and both sides of a jump are
followed; the points are where the continuation put them, in the order computed, so the
``frequency`` coordinate may go back and forth), or, with ``continuation=False``, solves at
exactly the given frequencies, each from the previous solution. The result is laid out as
``slipstep.output.frf_schema.FRF_SCHEMA`` (the marched and shot FRFs overlay on it), plus a
non-dimension coordinate ``excitation_level`` on ``frequency``. Each point carries the
harmonic-adequacy estimate (:mod:`slipstep.hbm.adequacy`) and, at the peak and at chosen
frequencies, the time-marching cross-check (:mod:`slipstep.hbm.crosscheck`).
"""

from __future__ import annotations

import json
import math
import time
import warnings

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.hbm.adequacy import (
    Adequacy,
    HarmonicAdequacyWarning,
    extended_set,
    force_content,
)
from slipstep.hbm.continuation import Branch, solve_point, trace
from slipstep.hbm.crosscheck import (
    hbm_initial_state,
    relative_differences,
    steady_reference,
)
from slipstep.hbm.energy import (
    contact_energy,
    excitation_work,
    half_peak_to_peak,
    viscous_dissipation,
)
from slipstep.model.frequency_grid import check_frequencies as valid_frequencies
from slipstep.output.frf_schema import FRF_SCHEMA
from slipstep.hbm.residual import HarmonicBalance
from slipstep.methods.blas import one_blas_thread
from slipstep.model.system import System


def response_indices(system: System, responses) -> np.ndarray:
    """DOF indices of the reported responses: the given names, or every DOF (up to 50), or the
    forced DOFs of a larger model."""
    names = list(system.structure.dof_names)
    if responses is None:
        if len(names) <= 50 or system.excitation.force is None:
            return np.arange(len(names))
        amp = np.abs(np.array([h.amplitude for h in system.excitation.force.harmonics])).sum(axis=0)
        return np.flatnonzero(amp > 0)
    if isinstance(responses, str):
        responses = [responses]
    out = []
    for r in responses:
        if r not in names:
            raise InputError(
                "responses", f"{r!r} is not a DOF name", f"use one of {names[:10]}{' ...' if len(names) > 10 else ''}"
            )
        out.append(names.index(r))
    return np.array(out, dtype=np.int64)


def _sequential(hb, parameter, values, fixed, progress):
    branch = Branch()
    Z = None
    for v in values:
        w, lv = (v, fixed) if parameter == "omega" else (fixed, v)
        t0 = time.perf_counter()
        pt = solve_point(hb, w, lv, Z) if parameter == "omega" else hb.solve(w, lv, Z)
        pt.wall_time = time.perf_counter() - t0
        pt.kind = "asked"
        branch.points.append(pt)
        branch.steps += 1
        if progress:
            progress(pt)
        if pt.converged:
            Z = pt.Y
        else:
            branch.status, branch.message = "NOT_CONVERGED", f"Newton did not converge at {parameter} = {v:.6g}"
    return branch


def monotone_runs(values) -> list[list[float]]:
    """The asked values split where the sweep turns: consecutive runs share their end points
    (340, 360, 350 -> [340, 360], [360, 350])."""
    v = [float(x) for x in values]
    if len(v) < 2:
        return [v]
    runs, cur = [], [v[0], v[1]]
    for x in v[2:]:
        if (x - cur[-1]) * (cur[-1] - cur[-2]) > 0:
            cur.append(x)
        else:
            runs.append(cur)
            cur = [cur[-1], x]
    return [*runs, cur]


def _continued(hb, parameter, values, fixed, progress, tol, max_dp):
    """Pseudo-arclength through the asked values, run by monotone run, each from the end of
    the previous one (whose shared first point is not repeated)."""
    branch, Y = Branch(), None
    for i, run in enumerate(monotone_runs(values)):
        span = abs(run[-1] - run[0])
        dp = max_dp if max_dp is not None else span / max(len(run) - 1, 1)
        part = trace(
            hb, parameter, run[0], run[-1], fixed, asked=run[1:-1], max_dp=dp, tol=tol, progress=progress, Z0=Y
        )
        branch.points += part.points[1:] if i else part.points
        branch.steps += part.steps
        branch.failed_correctors += part.failed_correctors
        branch.turning_points += part.turning_points
        if part.status != "OK" or part.message != "completed":
            branch.status = part.status if part.status != "OK" else branch.status
            branch.message = part.message if branch.message == "completed" else f"{branch.message}; {part.message}"
        last = next((p for p in reversed(part.points) if p.converged), None)
        Y = None if last is None else last.Y
    return branch


def _solve_branch(
    system, parameter, values, fixed, harmonics, samples, continuation, progress, tol, max_dp, condense="auto"
):
    hb = HarmonicBalance(system, harmonics, samples, condense=condense)
    if continuation and len(values) > 1 and hb.nq:
        branch = _continued(hb, parameter, values, fixed, progress, tol, max_dp)
    else:  # one point, no continuation asked, or no contacts (a linear system: nothing to follow)
        branch = _sequential(hb, parameter, values, fixed, progress)
    return hb, branch


def _response(system, parameter, values, fixed, **options):
    """Solve, estimate, cross-check and lay out (BLAS on one thread: small dense systems)."""
    with one_blas_thread():
        return _response_body(system, parameter, values, fixed, **options)


def _response_body(
    system,
    parameter,
    values,
    fixed,
    *,
    harmonics,
    samples,
    responses,
    continuation,
    check,
    check_at,
    check_options,
    adequacy,
    adequacy_tolerance,
    auto_harmonics,
    max_harmonics,
    progress,
    tol,
    max_dp,
    sweep,
    condense="auto",
    asked_only=False,
):
    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    resp = response_indices(system, responses)
    if check not in (True, False, "auto", "peak", "none", "all"):
        raise InputError("check", f"is {check!r}", "use 'auto' (the default), 'peak', 'all' or 'none'")
    check, check_skipped = resolved_check(system, check)
    start = time.perf_counter()
    callback = (lambda pt: progress(pt)) if progress else None
    hb, branch = _solve_branch(
        system, parameter, values, fixed, harmonics, samples, continuation, callback, tol, max_dp, condense
    )
    if asked_only:
        branch.points = [p for p in branch.points if p.kind == "asked"]
    estimates = np.full(len(branch.points), np.nan)
    if adequacy:
        ad = Adequacy(hb, resp)
        estimates = np.array(
            [ad.estimate(p) if p.converged and p.kind != "continuation" else np.nan for p in branch.points]
        )  # at the asked and turning points
        worst = float(np.max(estimates[~np.isnan(estimates)])) if np.any(~np.isnan(estimates)) else 0.0
        if worst > adequacy_tolerance and auto_harmonics and int(extended_set(hb.h).max()) <= max_harmonics:
            return _response_body(
                system,
                parameter,
                values,
                fixed,
                harmonics=extended_set(hb.h)[1:],
                samples=None,
                responses=responses,
                continuation=continuation,
                check=check,
                check_at=check_at,
                check_options=check_options,
                adequacy=adequacy,
                adequacy_tolerance=adequacy_tolerance,
                auto_harmonics=auto_harmonics,
                max_harmonics=max_harmonics,
                progress=progress,
                tol=tol,
                max_dp=max_dp,
                sweep=sweep,
                condense=condense,
                asked_only=asked_only,
            )
        if worst > adequacy_tolerance:
            i = int(np.nanargmax(estimates))
            where = f"{branch.points[i].omega / (2 * np.pi):.6g} Hz, level {branch.points[i].level:.3g}"
            change = (
                "the balance with more harmonics has no solution near it (an internal resonance or a "
                "strongly non-smooth response within the added harmonics)"
                if np.isinf(worst)
                else f"the response would change by about {worst:.2%} with more harmonics"
            )
            warnings.warn(
                f"harmonic balance with harmonics {[int(v) for v in hb.h[1:]]}: at {where} {change}, above the "
                f"tolerance {adequacy_tolerance:.2%}; raise the harmonics (e.g. harmonics="
                f"{int(extended_set(hb.h).max())}) or pass auto_harmonics=True (the time-marching cross-check "
                "tells the actual error)",
                HarmonicAdequacyWarning,
                stacklevel=5,
            )
    solve_time = time.perf_counter() - start
    ds = _dataset(hb, branch, resp, estimates, parameter, fixed)
    ds.attrs.update(
        {"sweep": sweep, "solve_time_s": solve_time, "time_per_point_s": solve_time / max(len(branch.points), 1)}
    )
    if check in (True, "peak", "all") and len(branch.points):
        _cross_check(ds, hb, branch, resp, check, check_at, check_options or {})
    elif check_skipped:
        ds.attrs["check_skipped"] = check_skipped
    ds.attrs["wall_time_s"] = time.perf_counter() - start
    return ds


def frf(
    system: System,
    frequencies,
    *,
    harmonics=5,
    samples: int | None = None,
    level: float = 1.0,
    responses=None,
    continuation: bool = True,
    check="auto",
    check_frequencies=(),
    check_options=None,
    adequacy: bool = True,
    adequacy_tolerance: float = 0.01,
    auto_harmonics: bool = False,
    max_harmonics: int = 127,
    progress=None,
    tol: float = 1e-10,
    max_df: float | None = None,
    asked_only: bool = False,
    condense: str = "auto",
) -> xr.Dataset:
    """Frequency response of ``system`` by harmonic balance over ``frequencies`` [Hz].

    harmonics: int H (0..H) or a set such as (1, 3, 5); samples: AFT samples per period.
    level: scale of the harmonic excitation. responses: DOF names reported (default all).
    continuation: pseudo-arclength from the first to the last frequency (step capped at the
    grid spacing or ``max_df`` Hz), else Newton at each given frequency. check: 'peak' (the
    FRF peak and ``check_frequencies``), 'all' or 'none': the time-marching cross-check; 'auto'
    (default): 'peak', or 'none' where a time-domain steady state costs minutes (attr check_skipped),
    options ``check_options`` (method, tolerance, max_periods, steps_per_period, start_from_hbm:
    march from the HBM state at t = 0 (default) rather than the static preload, run options).
    adequacy / adequacy_tolerance / auto_harmonics: the harmonic-adequacy estimate, its warning
    threshold, and whether to raise H (up to ``max_harmonics``) and recompute instead of warning.
    progress: a callable called with each solved point (slipstep.hbm.Point).
    Every asked frequency is returned (``point_kind`` "asked"), in the asked order; the
    continuation's own points between them are "continuation" (or "turning" where the branch
    turns back); ``asked_only``: return the asked points only. condense: the unknowns of the
    balance, "auto" (default), "dofs" or "contacts" (slipstep.hbm.linear.choose_gather)."""
    f = valid_frequencies(frequencies)
    fund = system.excitation.fundamental_frequency if isinstance(system, System) else None
    if isinstance(system, System) and fund is None:
        raise InputError("excitation", "has no harmonic force or motion", "give [[force]] or [[motion]] harmonics")
    level = _positive_level(level)
    sweep = "down" if f.size > 1 and f[-1] < f[0] else "up"
    ds = _response(
        system,
        "omega",
        2 * np.pi * f,
        level,
        harmonics=harmonics,
        samples=samples,
        responses=responses,
        continuation=continuation,
        check=check,
        check_at=2 * np.pi * np.atleast_1d(check_frequencies),
        check_options=check_options,
        adequacy=adequacy,
        adequacy_tolerance=adequacy_tolerance,
        auto_harmonics=auto_harmonics,
        max_harmonics=max_harmonics,
        progress=progress,
        tol=tol,
        max_dp=None if max_df is None else 2 * np.pi * max_df,
        sweep=sweep,
        condense=condense,
        asked_only=bool(asked_only),
    )
    asked = ds["point_kind"].values == "asked"
    if asked.sum() == f.size:  # the asked values exactly as given (not 2 pi f / 2 pi)
        freq = ds["frequency"].values.copy()
        freq[asked] = f
        ds = ds.assign_coords(frequency=("frequency", freq, ds["frequency"].attrs))
    return ds


def level_response(system: System, frequency_hz: float, levels, **options) -> xr.Dataset:
    """Response at one frequency against the excitation level (continuation over lambda from
    levels[0] to levels[-1]); the same layout, with ``excitation_level`` varying along the
    ``frequency`` dimension (whose values are then all ``frequency_hz``). Options as :func:`frf`
    (``check_frequencies`` becomes ``check_levels``)."""
    lv = np.atleast_1d(np.asarray(levels, dtype=float))
    if lv.ndim != 1 or lv.size == 0 or not np.all(np.isfinite(lv)) or np.any(lv < 0):
        raise InputError("levels", f"is {levels!r}", "give one or more excitation levels >= 0 (1: as given)")
    valid_frequencies([frequency_hz])
    check_levels = np.atleast_1d(options.pop("check_levels", ()))
    opts = {
        "harmonics": 5,
        "samples": None,
        "responses": None,
        "continuation": True,
        "check": "auto",
        "check_options": None,
        "adequacy": True,
        "adequacy_tolerance": 0.01,
        "auto_harmonics": False,
        "max_harmonics": 127,
        "progress": None,
        "tol": 1e-10,
        "max_dp": None,
        "condense": "auto",
        "asked_only": False,
    }
    unknown = set(options) - set(opts)
    if unknown:
        raise InputError("options", f"unknown option(s) {sorted(unknown)}", f"use only {sorted(opts)}")
    opts.update(options)
    return _response(
        system,
        "level",
        lv,
        2 * np.pi * float(frequency_hz),
        check_at=check_levels,
        sweep="up" if lv[-1] >= lv[0] else "down",
        **opts,
    )


def _positive_level(level) -> float:
    try:
        v = float(level)
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v) or v < 0:
        raise InputError("level", f"is {level!r}", "give an excitation scale factor >= 0 (1: as given)")
    return v


# ---- the Dataset -----------------------------------------------------------------------------


def _linear_limits(system, freq, level, names) -> tuple[np.ndarray, np.ndarray]:
    """Both linear limits at the points' frequencies (slipstep.frequency.linear_limits), scaled by
    the points' excitation levels; NaN where a limit is singular."""
    from slipstep.steady.linear import linear_limits

    try:
        lim = linear_limits(system, freq, names)
    except np.linalg.LinAlgError:
        nan = np.full((freq.size, len(names)), np.nan)
        return nan, nan
    return (level[:, None] * lim["linear_free_amplitude"].values, level[:, None] * lim["linear_stuck_amplitude"].values)


def _dataset(hb: HarmonicBalance, branch: Branch, resp: np.ndarray, estimates, parameter, fixed) -> xr.Dataset:
    """The FRF Dataset (slipstep.output.frf_dataset.empty_frf: the one layout) of a branch."""
    from slipstep import __version__
    from slipstep.output.frf_dataset import empty_frf, finalise

    system, pts = hb.system, branch.points
    names = [system.structure.dof_names[i] for i in resp]
    units = [system.structure.dof_units[i] for i in resp]
    freq = np.array([p.omega for p in pts]) / (2 * np.pi)
    level = np.array([p.level for p in pts])
    attrs = {
        "title": f"slipstep frequency response: {system.name}, harmonic balance",
        "case": system.name,
        "solver": "hbm",
        "method": "",
        "harmonics": [int(x) for x in hb.h],
        "samples": int(hb.basis.samples),
        "continuation": parameter if len(pts) > 1 else "none",
        "continuation_status": branch.status,
        "continuation_message": branch.message,
        "continuation_steps": branch.steps,
        "failed_correctors": branch.failed_correctors,
        "turning_points": branch.turning_points,
        "newton_iterations": int(sum(p.iterations for p in pts)),
        "max_harmonic_truncation_estimate": (
            float(np.max(estimates[~np.isnan(estimates)])) if np.any(~np.isnan(estimates)) else math.nan
        ),
        "max_force_content_outside": float(max((force_content(hb, p) for p in pts), default=0.0)),
        "steady_tolerance": math.nan,
        "slipstep_version": __version__,
    }
    ds = empty_frf(freq, names, units, list(system.contact_names), int(hb.h.max()), attrs)
    ds = ds.assign_coords(
        excitation_level=("frequency", level, {"units": "1", "long_name": "scale of the harmonic excitation"})
    )
    v = {name: ds[name].values for name in ds.data_vars}
    for i, p in enumerate(pts):
        X = p.X[:, resp]
        v["amplitude"][i] = half_peak_to_peak(hb.h, X)
        amp = np.abs(X)
        amp[0] = X[0].real
        v["harmonic_amplitude"][i, hb.h] = amp
        ph = np.angle(X)
        ph[0] = 0.0
        v["harmonic_phase"][i, hb.h] = ph
        v["energy_per_cycle"][i] = contact_energy(hb, p.Z, p.F)
        W, Dv = excitation_work(hb, p), viscous_dissipation(hb, p)
        v["excitation_work"][i], v["viscous_dissipation"][i] = W, Dv
        if "energy_balance_residual" in v and W != 0:
            v["energy_balance_residual"][i] = (W - Dv - v["energy_per_cycle"][i].sum()) / W
        if "point_time" in v:
            v["point_time"][i] = p.wall_time
        v["status"][i] = "OK" if p.converged and (p.aft_periods > 0 or hb.nq == 0) else "NOT_CONVERGED"
    v["harmonic_truncation_estimate"][:] = estimates
    v["linear_free_amplitude"][:], v["linear_stuck_amplitude"][:] = _linear_limits(system, freq, level, names)
    ds = finalise(ds)
    units, long_name = FRF_SCHEMA["point_kind"][1:]
    ds["point_kind"] = (
        "frequency",
        np.array([p.kind for p in pts], dtype=str),
        {"units": units, "long_name": long_name},
    )
    return ds


def _check_indices(ds, branch, parameter_values, check, check_at) -> list[int]:
    pts = branch.points
    ok = [i for i, p in enumerate(pts) if p.converged]
    if not ok:
        return []
    if check == "all":
        return ok
    amp = ds["amplitude"].values.max(axis=1)
    idx = [ok[int(np.nanargmax(amp[ok]))]]
    for v in np.atleast_1d(check_at):
        j = ok[int(np.argmin(np.abs(parameter_values[ok] - v)))]
        if j not in idx:
            idx.append(j)
    return idx


def resolved_check(system, check) -> tuple:
    """The cross-check asked, with ``"auto"`` resolved: ``"peak"`` unless a time-domain steady state
    of the system costs minutes (slipstep.steady.cost.time_domain_cost: a sparse structure
    above DENSE_MAX_N DOFs, or a large dense one with many sliders), where the harmonic-truncation
    estimate is the point's error instead. Returns (check, why it was skipped)."""
    if check != "auto":
        return check, ""
    from slipstep.steady.cost import time_domain_cost

    _, costly = time_domain_cost(system)
    if costly:
        return "none", (
            f"no time-marching cross-check: {costly}; each point's error is the harmonic-truncation "
            "estimate (pass check='peak' to march the peak anyway)"
        )
    return "peak", ""


def _cross_check(ds, hb, branch, resp, check, check_at, options):
    param = (
        np.array([p.omega for p in branch.points])
        if ds.attrs["continuation"] != "level"
        else np.array([p.level for p in branch.points])
    )
    if ds.attrs["continuation"] == "none" and len(branch.points) == 1:
        param = np.array([p.omega for p in branch.points])
    idx = _check_indices(ds, branch, param, check, check_at)
    opts = dict(options)
    start_from_hbm = bool(opts.pop("start_from_hbm", True))
    summary = []
    for i in idx:
        p = branch.points[i]
        f_hz = p.omega / (2 * np.pi)
        if start_from_hbm:
            hb.linear.at(p.omega, p.level)
            hb.aft.evaluate(p.Z, False)
            opts["initial"] = hbm_initial_state(hb, p)
        ref = steady_reference(hb.system, f_hz, p.level, resp, **opts)
        a, e = relative_differences(
            ds["amplitude"].values[i], ds["energy_per_cycle"].values[i], ref, float(ds["excitation_work"].values[i])
        )
        ds["check_amplitude_rel_diff"].values[i] = a
        ds["check_energy_rel_diff"].values[i] = e
        ds["periods_to_steady"].values[i] = np.nan
        summary.append(
            {
                "index": i,
                "frequency_Hz": f_hz,
                "level": p.level,
                "amplitude_rel_diff": a,
                "energy_rel_diff": e,
                "march_amplitude": float(ref.amplitude.max()),
                "march_energy_J": float(ref.energy.sum()),
                "march_periods": ref.periods,
                "march_status": ref.status,
            }
        )
        ds.attrs["method"] = ref.method
    ds.attrs["steady_tolerance"] = float(opts.get("tolerance", 1e-6))
    ds.attrs["check_points"] = len(summary)
    ds.attrs["check_summary"] = json.dumps(summary)
