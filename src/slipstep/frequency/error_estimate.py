"""The error of each FRF point of the time-domain solvers (march, shoot): step doubling on
the converged periodic orbit.

With E_h an energy per cycle of the steady state at the step h and E_{h/r} that of the orbit
re-solved from it with the step divided by r (r = 2: the steps per period doubled), the
trapezoidal rule's order p = 2 gives E_h = E + c h^p, so the error of the finer solution is
(Richardson)

    err(E_{h/r}) = |E_h - E_{h/r}| / (r^p - 1)                 (r = 2: |E_h - E_{h/2}| / 3)

and the point's ``error_estimate`` is the larger of the two relative errors

    max( err(D) / max(|D_{h/r}|, 1e-4 |W_{h/r}|),  err(W) / |W_{h/r}| )

with D the friction energy per cycle (all contacts) and W the excitation work per cycle (a
point whose contacts dissipate almost nothing, or a system without contacts, is judged by
W). The re-solve starts on the coarse orbit, so it costs a few periods (a Newton iteration
or two for shooting).

**The returned point is the finer solution**, the one the estimate is about. When the
estimate exceeds ``REFINE_SHARE * rtol`` (a margin for the estimate's own error: on the
Jenkins check of benchmarks/bench_frf_accuracy.py it is 0.5 to 2.5 times the true error) the
step is halved again from the finer orbit (``max_refinements`` times at most); a point still
above ``rtol`` keeps its status (the orbit did converge), gets a ``status_message`` and the
FRF one summary :class:`FrfAccuracyWarning`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

ORDER = 2  # the trapezoidal rule (Newmark average acceleration, the quasi-static path)
DISSIPATION_FLOOR = 1e-4  # friction energy compared with at least this share of the excitation work
REFINE_SHARE = 0.5  # the step is refined while the estimate exceeds this share of rtol
MIN_REDUCTION = 0.5  # ... and while each halving divides it by 2 at least (h^2: by 4)
METHOD_TEXT = (
    "step doubling on the converged orbit: |E_h - E_h/2| / |E_h/2| / 3 (trapezoidal rule, order 2), "
    "E the friction energy and the excitation work per cycle (the larger); the point is the h/2 solution"
)


class FrfAccuracyWarning(UserWarning):
    """Some FRF points' error estimate stays above rtol (see slipstep.frequency.error_estimate)."""


def check_accuracy_options(rtol, max_refinements) -> None:
    from slipstep.errors import InputError

    if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not (0 < rtol < 1):
        raise InputError(
            "rtol", f"is {rtol!r}", "give the relative error allowed per point, between 0 and 1 (e.g. 1e-2)"
        )
    if isinstance(max_refinements, bool) or not isinstance(max_refinements, int) or max_refinements < 0:
        raise InputError("max_refinements", f"is {max_refinements!r}", "give a whole number >= 0 (e.g. 3)")


def relative_error(coarse: dict, fine: dict, ratio: float) -> float:
    """The estimate of the module docstring from the point values (frequency.response.point_values)
    of the coarse and the fine solution, the fine one having ``ratio`` times the steps."""
    factor = ratio**ORDER - 1.0
    d_c, d_f = float(coarse["energy_per_cycle"].sum()), float(fine["energy_per_cycle"].sum())
    w_c, w_f = float(coarse["excitation_work"]), float(fine["excitation_work"])
    if not all(math.isfinite(v) for v in (d_c, d_f, w_c, w_f)) or factor <= 0:
        return math.nan
    scale_w = abs(w_f)
    scale_d = max(abs(d_f), DISSIPATION_FLOOR * scale_w)
    e_w = abs(w_c - w_f) / factor / scale_w if scale_w > 0 else 0.0
    e_d = abs(d_c - d_f) / factor / scale_d if scale_d > 0 else 0.0
    return max(e_w, e_d)


def steps_of(steady) -> int:
    """Time steps of the steady state's period."""
    return int(steady.period.attrs["steps"])


def halved_step_options(options: dict, steady) -> dict:
    """The steady-state options with the step of ``steady``'s period halved: twice its steps per
    period (``min_steps_per_period``; ``steps_per_period`` for the quasi-static method; a given
    fixed ``dt`` halved)."""
    steps = 2 * steps_of(steady)
    out = dict(options)
    out["min_steps_per_period"] = steps
    if steady.period.attrs.get("quasi_static"):
        out["steps_per_period"] = steps
    if out.get("dt") is not None:
        out["dt"] = 0.5 * float(out["dt"])
    return out


def _with_history(fine, first):
    """``fine`` carrying the point's orbit history as shooting's FRF predictor needs it: the
    previous point's orbit (from the first solve of this point), then this point's fine orbit
    (a re-solve at the same frequency would otherwise leave two entries at one frequency)."""
    history = getattr(first, "orbit_history", ())
    if not history or not getattr(fine, "orbit_history", ()):
        return fine
    return dataclasses.replace(fine, orbit_history=(*history[:-1], fine.orbit_history[-1]))


@dataclass
class PointResult:
    """The returned steady state of a point with its error (module docstring)."""

    steady: object
    values: dict
    error_estimate: float
    refinements: int
    periods: int
    message: str


def refine(
    solve: Callable, system, steady, values_of: Callable, options: dict, rtol: float, max_refinements: int
) -> PointResult:
    """Step doubling from the converged ``steady`` (module docstring): ``solve(system, initial=...,
    **options)`` re-solves, ``values_of(steady)`` gives a point's values. Returns the finer
    solution with its estimate; when a re-solve does not converge, the last converged solution
    with the estimate of the last pair (NaN without one) and a message saying so."""
    coarse, cv = steady, values_of(steady)
    periods = steady.periods
    best = PointResult(coarse, cv, math.nan, 0, periods, "")
    opts = dict(options)
    for level in range(max_refinements + 1):
        opts = halved_step_options(opts, coarse)
        fine = solve(system, initial=coarse, **opts)
        periods += fine.periods
        if fine.status != "OK":
            best.periods = periods
            best.message = (
                f"the solve with {opts['min_steps_per_period']} steps per period ({fine.status}: {fine.message}) "
                f"did not converge: the point is the {steps_of(coarse)}-step solution"
                + ("" if math.isnan(best.error_estimate) else ", its error estimate from the pair before")
                + ("" if level else ", without an error estimate")
            )
            return best
        fine = _with_history(fine, steady)
        fv = values_of(fine)
        estimate = relative_error(cv, fv, steps_of(fine) / steps_of(coarse))
        previous = best.error_estimate
        best = PointResult(fine, fv, estimate, level, periods, "")
        if not estimate > REFINE_SHARE * rtol:
            return best
        if level > 0 and not estimate < MIN_REDUCTION * previous:  # not falling as h^2: stop refining
            best.message = (
                f"error estimate {estimate:.2g} at {steps_of(fine)} steps per period did not fall with the step "
                f"({previous:.2g} before): not the trapezoidal rule's h^2 error (an orbit of a family that "
                "sliders stuck over the whole period leave free, or a response not smooth in the step)"
                + (f"; above rtol {rtol:g}" if estimate > rtol else "")
            )
            return best
        coarse, cv = fine, fv
    if not best.error_estimate > rtol:
        return best
    best.message = (
        f"error estimate {best.error_estimate:.2g} above rtol {rtol:g} at {steps_of(best.steady)} steps per "
        f"period ({best.refinements} refinement(s) of the step, the cap): give min_steps_per_period of "
        f"{4 * steps_of(best.steady)} or more, or raise rtol"
    )
    return best
