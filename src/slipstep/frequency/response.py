"""Frequency response by steady states: step through the frequencies, each point's steady
state starting from the previous point's, upward, downward or both (to show jumps). :func:`frf`
is the one entry point of every solver (march, shoot, harmonic balance, and "auto":
slipstep.frequency.choice); the CLI calls it.

Per point (excitation retuned to the frequency, slipstep.model.retune): the steady state
(``solver`` "march": slipstep.steady.march_to_steady, "shoot": slipstep.steady.shoot), re-solved
from the converged orbit with half the step for its error estimate (and refined while the
estimate exceeds ``rtol``: slipstep.frequency.error_estimate; the point is the finer solution),
its harmonics 0..H per response DOF (slipstep.frequency.harmonics), the friction energy per
cycle per contact and the energy balance over the period (slipstep.post.energy):

    W_exc = int f_e . dx - int f . B dp,   D_visc = int (C v) . dx,   D_fric = sum_d int T_d dw_d
    energy_balance_residual = (W_exc - D_visc - D_fric) / |W_exc|

(zero for an exactly periodic orbit of a piecewise-linear Newmark march, up to the change
over the period), and the two linear limits in the frequency domain (slipstep.steady.linear).
"""

from __future__ import annotations

import dataclasses
import math
import pkgutil
import time
import warnings
from collections.abc import Callable

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.frequency.hbm_seed import HbmSeeder
from slipstep.frequency.choice import DEFAULT_METHOD, choose
from slipstep.output.frf_dataset import concat_sweeps, empty_frf, finalise
from slipstep.frequency.error_estimate import (
    METHOD_TEXT,
    FrfAccuracyWarning,
    check_accuracy_options,
    refine,
    steps_of,
)
from slipstep.model.frequency_grid import check_frequencies, parse_frequencies  # noqa: F401  (re-exported)
from slipstep.frequency.harmonics import amplitudes_phases, fourier_coefficients
from slipstep.steady.linear import linear_limits
from slipstep.model.retune import retune
from slipstep.output.frf_schema import FRF_SOLVERS, TEXT_VARIABLES
from slipstep.model.excitation import CompiledSignal, evaluate_compiled
from slipstep.steady.marching import STEADY_STEPS_PER_PERIOD, STEP_OPTIONS
from slipstep.steady.state import SteadyState
from slipstep.model.system import System

STEADY_SOLVERS: dict[str, Callable[..., SteadyState]] = {
    name: pkgutil.resolve_name(s.runs) for name, s in FRF_SOLVERS.items() if s.steady
}
"""Steady-state solvers of :func:`frf` (FRF_SOLVERS' steady ones, march_to_steady and shoot of
slipstep.steady): name -> f(system, initial=..., tolerance=..., ...)."""

SOLVERS = tuple(FRF_SOLVERS)
"""The ``solver`` values of :func:`frf` (output.frf_schema.FRF_SOLVERS; auto: slipstep.frequency.choice)."""
DEFAULT_RTOL = 1e-2  # relative error of the energy per cycle allowed per point
DEFAULT_MAX_REFINEMENTS = 3  # step halvings beyond the first step doubling


def period_energies(ds: xr.Dataset, cs) -> tuple[float, float, np.ndarray]:
    """(W_exc, D_visc, D_fric per direction) [J] over the stored period of ``ds``: the
    trapezoid rules of slipstep.post.energy (the same discrete sums, without the Dataset)."""
    t = ds["time"].values
    x = ds["displacement"].values
    fe = np.asarray(cs.constant_force, float)[None, :] + evaluate_compiled(
        CompiledSignal(
            cs.force_frequency, cs.force_sin, cs.force_cos, cs.force_table_time, cs.force_table_value, cs.force_ramp
        ),
        t,
    )
    dx = np.diff(x, axis=0)
    work = float((0.5 * (fe[1:] + fe[:-1]) * dx).sum())
    if cs.B.shape[1]:
        f = np.zeros((t.size, cs.A.shape[0]))
        f[:, np.asarray(cs.tangential_row)] = ds["tangential_force"].values
        f[:, np.asarray(cs.normal_row)] = ds["normal_force"].values
        fB = f @ cs.B
        work -= float((0.5 * (fB[1:] + fB[:-1]) * np.diff(ds["prescribed_motion"].values, axis=0)).sum())
    visc = 0.0
    if "velocity" in ds:
        cv = ds["velocity"].values @ cs.C.T
        visc = float((0.5 * (cv[1:] + cv[:-1]) * dx).sum())
    T = ds["tangential_force"].values
    fric = (0.5 * (T[1:] + T[:-1]) * np.diff(ds["slider"].values, axis=0)).sum(axis=0)
    return work, visc, fric


def point_values(steady: SteadyState, system: System, responses, n_harmonics: int) -> dict:
    """The FRF quantities of one steady state (see the module docstring)."""
    ds = steady.period
    cs = system.compile_dense("the frequency response")
    T = system.period
    y = ds["displacement"].values[:, [list(ds["dof"].values).index(r) for r in responses]]
    A, phase = amplitudes_phases(fourier_coefficients(ds["time"].values, y, T, n_harmonics))
    work, visc, per_dir = period_energies(ds, cs)
    owner = np.asarray(cs.direction_contact)
    per_contact = np.array([per_dir[owner == c].sum() for c in range(len(system.contacts))])
    scale = max(abs(work), 1e-300)
    return {
        "amplitude": 0.5 * np.ptp(y, axis=0),
        "harmonic_amplitude": A,
        "harmonic_phase": phase,
        "energy_per_cycle": per_contact,
        "excitation_work": work,
        "viscous_dissipation": visc,
        "energy_balance_residual": (work - visc - per_contact.sum()) / scale,
        "periods_to_steady": steady.periods,
        "steady_change": steady.change,
        "floquet_multiplier_max": (
            float(np.abs(steady.floquet_multipliers).max(initial=0.0))
            if steady.floquet_multipliers is not None
            else math.nan
        ),
        "status": steady.status,
    }


def sweep(
    system: System,
    frequencies: np.ndarray,
    *,
    solver: str = "march",
    responses=None,
    n_harmonics: int = 5,
    initial=None,
    progress=None,
    rtol: float = DEFAULT_RTOL,
    max_refinements: int = DEFAULT_MAX_REFINEMENTS,
    retry_steps: int | None = None,
    hbm_start: bool = True,
    **options,
) -> tuple[xr.Dataset, SteadyState | None]:
    """One sweep through ``frequencies`` in the given order; returns (Dataset, last steady state).
    Each converged point is refined by step doubling (slipstep.frequency.error_estimate); with
    ``retry_steps``, a point whose steady state did not converge is solved once more from the
    same start with that many steps per period (its periods counted in both). hbm_start (solver
    "shoot"): before that retry, a point not converged is shot from the harmonic balance solution
    continued from the previous frequency, with the retry's steps (slipstep.frequency.hbm_seed: an
    unstable orbit, on which marching never settles; a failed solve costs up to max_periods)."""
    if solver not in STEADY_SOLVERS:
        raise InputError("solver", f"is {solver!r}", f"use one of {sorted(SOLVERS)}")
    names = list(system.structure.dof_names)
    responses = names if responses is None else list(responses)
    unknown = [r for r in responses if r not in names]
    if unknown:
        raise InputError("responses", f"{unknown} are not DOFs of the system", f"use names from {names}")
    units = [system.structure.dof_units[names.index(r)] for r in responses]
    ds = empty_frf(frequencies, responses, units, system.contact_names, n_harmonics)
    columns = {name: ds[name].values.copy() for name in ds.data_vars}  # filled in NumPy, wrapped at the end
    steady_solver = STEADY_SOLVERS[solver]
    prev = initial
    last = None
    seeder = HbmSeeder(system) if hbm_start and solver == "shoot" else None
    for i, f in enumerate(frequencies):
        start = time.perf_counter()
        system_f = retune(system, float(f))
        try:
            solve = steady_solver
            if seeder is not None:
                solve = _WithHbmStart(steady_solver, seeder, float(frequencies[i - 1]) if i else None, float(f))
            # with a harmonic balance start to try, a failed Newton is not marched (up to max_periods)
            first = options if seeder is None else {**options, "march_fallback": False}
            steady = steady_solver(system_f, initial=prev, **first)
            steps = {} if retry_steps is None else {"steps_per_period": retry_steps}
            if steady.status != "OK" and seeder is not None:
                steady = solve(system_f, failed=steady, **{**options, **steps})
            if steady.status != "OK" and retry_steps is not None:
                retry = steady_solver(system_f, initial=prev, **{**options, **steps})
                steady = dataclasses.replace(retry, periods=steady.periods + retry.periods)
            if steady.status != "OK":
                steady = dataclasses.replace(steady, message=steady.message + turning_point_hint(prev))
            values = _point(solve, system_f, steady, responses, n_harmonics, options, rtol, max_refinements)
        except KeyboardInterrupt:  # keep the points done; the rest are marked
            columns["status"][i:] = "INTERRUPTED"
            ds.attrs["interrupted"] = 1
            break
        steady = values.pop("steady")
        values["point_time"] = time.perf_counter() - start
        values["solve_start"] = "harmonic balance" if getattr(solve, "used", False) else "previous orbit"
        for name, value in values.items():
            columns[name][i] = value
        prev = steady if steady.status in ("OK", "NOT_STEADY") else None
        last = steady
        if progress is not None:
            progress(i + 1, len(frequencies), float(f), steady)
    for name, values in columns.items():
        ds[name].values = values
    ds.attrs.update(method=last.method if last is not None else "", solver=solver)
    return ds, last


class _WithHbmStart:
    """``steady_solver`` that, when a solve does not converge (or given the ``failed`` one), shoots
    again from the harmonic balance start at ``f`` [Hz] continued from ``f_previous``
    (HbmSeeder.start); the periods of both attempts are counted, the message keeps the first
    attempt's status, and ``used`` says whether a start was taken from the balance. Its own first
    attempt (the error estimate's re-solves) is not marched after a failed Newton (march_fallback
    False: up to max_periods, on an orbit marching may never settle on); when the balance then
    gives no start, that attempt is made again with the marching fallback."""

    def __init__(self, steady_solver, seeder, f_previous, f):
        self.steady_solver, self.seeder, self.f_previous, self.f = steady_solver, seeder, f_previous, f
        self.used = False

    def __call__(self, system_f, initial=None, failed=None, **options):
        own_attempt = failed is None  # made here without marching (below), not given by the caller
        if own_attempt:  # a failed Newton is not marched (up to max_periods): the balance start follows
            failed = self.steady_solver(system_f, initial=initial, **{**options, "march_fallback": False})
            if failed.status == "OK":
                return failed
        start, text = self.seeder.start(self.f_previous, self.f)
        if start is None and own_attempt:  # no balance start after all: the solve with its marching fallback
            failed = self.steady_solver(system_f, initial=initial, **options)
            if failed.status == "OK":
                return failed
        if start is None:
            return dataclasses.replace(failed, message=f"{failed.message}; {text}")
        self.used = True
        again = self.steady_solver(system_f, initial=start, **options)
        periods = failed.periods + again.periods
        if again.status != "OK":
            return dataclasses.replace(failed, periods=periods, message=f"{failed.message}; {text}: {again.message}")
        note = f"{text} after {failed.status} from the previous orbit ({failed.message})"
        return dataclasses.replace(again, periods=periods, message=f"{again.message}; {note}")


def turning_point_hint(previous) -> str:
    """A sentence for a point that did not converge after a point whose orbit was unstable
    (largest Floquet multiplier modulus above 1): the branch of the previous point may end at a
    turning point before this frequency, which a solver stepping in frequency cannot pass and a
    continuation in arc length (harmonic balance) can; "" otherwise."""
    multipliers = getattr(previous, "floquet_multipliers", None)
    if multipliers is None or not len(multipliers) or not np.abs(multipliers).max() > 1.0:
        return ""
    return (
        f"; the previous point's orbit was unstable (largest |Floquet multiplier| {np.abs(multipliers).max():.3g}): "
        "its branch may end at a turning point before this frequency, which stepping in frequency cannot pass "
        "(solver='hbm' follows the response through turning points)"
    )


def _point(solve, system_f, steady, responses, n_harmonics, options, rtol, max_refinements) -> dict:
    """The FRF values of one point from its first steady state: refined by step doubling when it
    converged (slipstep.frequency.error_estimate), else as it ended, with the solver's message."""
    if steady.status != "OK" or rtol is None:  # no estimate; the step of a period that was marched is recorded
        if steady.status == "OK":  # rtol None: the point as solved, without the step doubling
            values = point_values(steady, system_f, responses, n_harmonics)
            values.update(
                steady=steady, steps_per_period=steps_of(steady), time_step=system_f.period / steps_of(steady)
            )
            return values
        if steady.status == "NOT_STEADY":
            values = point_values(steady, system_f, responses, n_harmonics)
            values.update(steps_per_period=steps_of(steady), time_step=system_f.period / steps_of(steady))
        else:
            values = {"status": steady.status, "periods_to_steady": steady.periods}
        values.update(steady=steady, status_message=steady.message)
        return values
    result = refine(
        solve,
        system_f,
        steady,
        lambda s: point_values(s, system_f, responses, n_harmonics),
        options,
        rtol,
        max_refinements,
    )
    steps = steps_of(result.steady)
    return {
        **result.values,
        "steady": result.steady,
        "periods_to_steady": result.periods,
        "error_estimate": result.error_estimate,
        "steps_per_period": steps,
        "time_step": system_f.period / steps,
        "step_refinements": result.refinements,
        "status_message": result.message,
    }


HBM_ONLY_OPTIONS = (
    "samples",
    "check",
    "check_frequencies",
    "check_options",
    "continuation",
    "adequacy",
    "auto_harmonics",
    "max_harmonics",
    "tol",
    "max_df",
    "level",
    "asked_only",
)
"""Options of :func:`frf` that only harmonic balance takes (slipstep.hbm.frf)."""


def frf(
    system: System,
    frequencies,
    *,
    solver: str = "auto",
    direction: str = "up",
    responses=None,
    harmonics=5,
    method=None,
    tolerance: float = 1e-6,
    rtol: float = DEFAULT_RTOL,
    max_refinements: int = DEFAULT_MAX_REFINEMENTS,
    linear: bool = True,
    progress=None,
    **options,
) -> xr.Dataset:
    """Frequency response of ``system`` at ``frequencies`` [Hz] (see the module docstring): the
    one entry point of every solver.

    solver: "auto" (slipstep.frequency.choice: shooting, the method chosen when none is given),
    "march" or "shoot" (STEADY_SOLVERS) or "hbm" (harmonic balance, slipstep.hbm.frf: harmonics
    is then the retained set, an int H or a set such as (1, 3, 5); its options samples, check,
    check_frequencies, continuation, auto_harmonics, ... pass through). direction: "up", "down"
    or "both" (two sweeps concatenated along ``sweep``, the down sweep starting from the up
    sweep's last state; harmonic balance follows the branch once, "both" gives "up"); responses:
    DOF names (default all); harmonics: H of the reported harmonics (march, shoot); method
    (default piecewise-linear; auto: chosen), tolerance and the other options go to the
    steady-state solver (max_periods, min_steps_per_period, initial, RunOptions ...).
    rtol: the relative error of the energy per cycle allowed per point (error_estimate: step
    doubling for march and shoot, refined up to ``max_refinements`` times; the truncation
    estimate for hbm; None: march and shoot points as solved, no step doubling, no estimate); a point above it keeps its status, gets a status_message, and one
    FrfAccuracyWarning (hbm: HarmonicAdequacyWarning) is issued. progress(done, total,
    frequency, steady) is called after every point (hbm: every continuation step, steady None).
    hbm_start (solver "shoot", default True): a point that does not converge is shot once more
    from the harmonic balance solution continued from the previous frequency (:func:`sweep`;
    the point's ``solve_start`` says so).
    method "events" (solver "shoot" only): the reference FRF of exact periodic orbits
    (slipstep.frequency.exact; options of steady/exact_orbit.periodic_orbit).
    Returns a Dataset in the layout of FRF_SCHEMA, the frequencies asked, ascending per up sweep
    and descending per down sweep. Ctrl-C during a point keeps the points done (the others get
    status INTERRUPTED, attribute interrupted = 1)."""
    if solver not in SOLVERS:
        raise InputError("solver", f"is {solver!r}", f"use one of {', '.join(SOLVERS)}")
    if direction not in ("up", "down", "both"):
        raise InputError("direction", f"is {direction!r}", "use 'up', 'down' or 'both'")
    check_accuracy_options(DEFAULT_RTOL if rtol is None and solver != "hbm" else rtol, max_refinements)
    f = np.sort(check_frequencies(frequencies))
    reason = ""
    if method == "events":  # the reference FRF: exact periodic orbits (slipstep.frequency.exact)
        if solver not in ("shoot", "auto"):
            raise InputError("method", f"'events' is a method of solver 'shoot', not {solver!r}", "use solver='shoot'")
        from slipstep.frequency.exact import TOLERANCE, exact_frf_dataset

        steady = min(tolerance, TOLERANCE)
        return exact_frf_dataset(system, f, direction, responses, harmonics, steady, linear, progress, **options)
    if solver == "auto":
        choice = choose(system, method)
        solver, method, reason = choice.solver, choice.method, choice.reason
    if solver == "hbm":
        out = _hbm(system, f, direction, responses, harmonics, method, tolerance, rtol, progress, options)
    else:
        hbm_only = sorted(set(options) & set(HBM_ONLY_OPTIONS))
        if hbm_only:
            raise InputError(
                hbm_only[0], f"is an option of solver 'hbm', not of {solver!r}", "drop it or use solver='hbm'"
            )
        if isinstance(harmonics, bool) or not isinstance(harmonics, (int, np.integer)) or harmonics < 0:
            raise InputError("harmonics", f"is {harmonics!r}", "give the highest harmonic number H >= 0 (e.g. 5)")
        method = DEFAULT_METHOD if method is None else method
        if rtol is not None and not any(options.get(k) is not None for k in (*STEP_OPTIONS, "steps_per_period")):
            # the point is solved at T / (N/2) and returned at T / N after the step doubling: the
            # steady step N of slipstep.steady for the price of about one solve at N; a point that
            # does not converge at N/2 is solved again at N
            options = {
                **options,
                "steps_per_period": STEADY_STEPS_PER_PERIOD // 2,
                "retry_steps": STEADY_STEPS_PER_PERIOD,
            }
        out = _steady_frf(
            system,
            f,
            solver,
            direction,
            responses,
            harmonics,
            method,
            tolerance,
            rtol,
            max_refinements,
            linear,
            progress,
            options,
        )
        _accuracy_warning(out, rtol)
    out.attrs.update(
        solver_reason=reason,
        error_estimate_method=HBM_ERROR_METHOD if solver == "hbm" else (METHOD_TEXT if rtol is not None else "none"),
    )
    if rtol is not None:
        out.attrs["rtol"] = rtol
    return finalise(out)


def _steady_frf(
    system,
    f,
    solver,
    direction,
    responses,
    harmonics,
    method,
    tolerance,
    rtol,
    max_refinements,
    linear,
    progress,
    options,
) -> xr.Dataset:
    """The FRF by steady states per point (march, shoot), both linear limits added."""
    initial = options.pop("initial", None)
    common = dict(
        solver=solver,
        responses=responses,
        n_harmonics=harmonics,
        method=method,
        tolerance=tolerance,
        progress=progress,
        rtol=rtol,
        max_refinements=max_refinements,
        **options,
    )
    sweeps = []
    last = initial
    for name in ("up", "down") if direction == "both" else (direction,):
        grid = f if name == "up" else f[::-1]
        ds, steady = sweep(system, grid, initial=last, **common)
        ds.attrs["sweep"] = name
        sweeps.append(ds)
        if ds.attrs.get("interrupted"):  # Ctrl-C: no further sweep; the points done are returned
            if direction == "both" and name == "up":
                down = ds.copy(deep=True)
                down["status"].values[:] = "INTERRUPTED"
                for var in down.data_vars:
                    if var != "status":
                        down[var].values[:] = "" if var in TEXT_VARIABLES else np.nan
                down.attrs["sweep"] = "down"
                sweeps.append(down)
            break
        last = steady if steady is not None and steady.status in ("OK", "NOT_STEADY") else None
    out = sweeps[0] if len(sweeps) == 1 else concat_sweeps(*sweeps)
    if linear:
        lim = linear_limits(system, out["frequency"].values, list(out["response"].values))
        for name in ("linear_free_amplitude", "linear_stuck_amplitude"):
            attrs = out[name].attrs
            out[name] = (("frequency", "response"), lim[name].values, attrs)
    from slipstep import __version__

    out.attrs.update(
        case=system.name,
        steady_tolerance=tolerance,
        slipstep_version=__version__,
        method=out.attrs.get("method", ""),
        solver=solver,
    )
    return out


HBM_ERROR_METHOD = "harmonic truncation estimate (slipstep.hbm.adequacy): the change with more harmonics"


def _hbm(system, f, direction, responses, harmonics, method, tolerance, rtol, progress, options) -> xr.Dataset:
    """Harmonic balance over the grid (slipstep.hbm.frf), its truncation estimate as each point's
    error_estimate and its AFT samples as steps_per_period; progress per continuation step."""
    from slipstep.hbm import frf as hbm_frf

    if direction == "both":
        warnings.warn(
            "harmonic balance follows the whole branch by continuation (turning points included): "
            "direction 'both' gives the same curve as 'up'",
            stacklevel=3,
        )
    grid = f[::-1] if direction == "down" else f
    check = {
        "method": DEFAULT_METHOD if method is None else method,
        "tolerance": tolerance,
        "max_periods": options.pop("max_periods", 200),
    }
    if options.get("min_steps_per_period"):
        check["steps_per_period"] = options.pop("min_steps_per_period")
    options.pop("min_steps_per_period", None)
    check.update(options.pop("check_options", None) or {})
    unknown = sorted(set(options) - set(HBM_ONLY_OPTIONS))
    if unknown:
        raise InputError(unknown[0], "is not an option of solver 'hbm'", f"use {', '.join(HBM_ONLY_OPTIONS)}")
    span = grid[-1] - grid[0]

    def step(point):
        at = point.omega / (2 * np.pi)
        done = grid.size if span == 0 else round(grid.size * min(max((at - grid[0]) / span, 0.0), 1.0))
        progress(done, grid.size, at, None)

    ds = hbm_frf(
        system,
        grid,
        harmonics=harmonics,
        responses=responses,
        progress=step if progress is not None else None,
        check_options=check,
        adequacy_tolerance=rtol,
        **options,
    )
    est = ds["harmonic_truncation_estimate"].values
    ds["error_estimate"].values[:] = est
    ds["steps_per_period"].values[:] = ds.attrs["samples"]
    message = ds["status_message"].values.astype(object)
    for i in np.flatnonzero(est > rtol):
        message[i] = f"harmonic truncation estimate {est[i]:.2g} above rtol {rtol:g}: raise the harmonics"
    ds["status_message"] = (ds["status_message"].dims, message, ds["status_message"].attrs)
    return ds


def _accuracy_warning(ds: xr.Dataset, rtol: float) -> None:
    """One FrfAccuracyWarning for the points whose error estimate stays above rtol."""
    if rtol is None:
        return
    est = np.asarray(ds["error_estimate"].values, float).ravel()
    above = np.flatnonzero(est > rtol)
    if above.size:
        freqs = np.broadcast_to(ds["frequency"].values, ds["error_estimate"].shape).ravel()
        warnings.warn(
            f"{above.size} FRF point(s) have an error estimate above rtol {rtol:g} after the step refinements "
            f"(largest {est[above].max():.2g} at {freqs[above[np.argmax(est[above])]]:.6g} Hz; see status_message): "
            "give a larger min_steps_per_period or max_refinements, or raise rtol",
            FrfAccuracyWarning,
            stacklevel=3,
        )
