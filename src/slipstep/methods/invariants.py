"""The contact invariants every status-OK march must satisfy, checked once on the rows it wrote.

For every saved row j (step k_j, time t_j) and saved contact c with friction coefficient mu
(the contact invariants from step 1 on: row 0 holds the state the march was given, which a
shooting iteration sets freely):

* finite:        every t, x, q, f, w written is a finite number;
* rows written:  the rows hold steps 0 = k_0 < k_1 < ... (strictly increasing) at
                 non-decreasing times (an unwritten or overwritten row breaks this);
* N >= 0:        the normal force N_c = f[normal row of c] is never a tension;
* friction:      |T_d| <= mu N_c (1 + 1e-12) for every direction d of an uncoupled contact
                 (2D, quasi-3D, Jenkins), ||(T_1, T_2)|| <= mu N_c (1 + 1e-12) (the Euclidean
                 norm) for a friction-circle contact;
* slip along T:  between two rows of consecutive steps, a direction in a slip state moves its
                 slider along its force: (w_d,k - w_d,k-1) T_d,k >= 0, to a rounding floor of
                 1e-12 (|w| + L) |T| (L the system length scale, CompiledSystem.length_scale).

Why once on the outputs in Python rather than in the kernels' accept step: one function for
every kernel (implicit, quasi-static, event-driven, explicit), no kernel edited or recompiled,
and it is cheap: a dozen vectorised passes over the rows the march has already written,
about 0.13 ms plus 0.03 us per row on the paper case, 1-3 % of a whole ``slipstep.run``
(benchmarks/bench_invariants.py; a kernel-side test would save that fraction at the price of
the same test written into four kernels). What it cannot see are the steps a save plan does
not keep (``every`` > 1, given times): those rows are never written, so no result holds them.

``check_outputs(cs, out, n_rows)`` returns None or a :class:`Violation` naming the invariant,
the step, the time and the contact or direction (Simulation.march turns it into the status
``INVARIANT``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from slipstep.kernels.codes import SLIP_STATES
from slipstep.methods.sensitivity_twin import TWIN_FLAG, sensitivity_text
from slipstep.model.contact import COUPLED_SLIP_CODES

FRICTION_RTOL = 1e-12  # |T| <= mu N (1 + FRICTION_RTOL)
SLIP_FLOOR = 1e-12  # rounding floor of the slip-along-T test, relative to |w| + L


class Violation(NamedTuple):
    """The first broken invariant of a march: which, at which step and time, and where."""

    invariant: str  # "finite", "rows written", "N >= 0", "|T| <= mu N", "slip along T"
    step: int
    time: float
    where: str  # contact or direction index text
    detail: str

    def text(self) -> str:
        return (
            f"broken invariant {self.invariant} at step {self.step}, t = {self.time:.6g} s, {self.where}: {self.detail}"
        )


def check_outputs(cs, out, n_rows: int) -> Violation | None:
    """The first invariant (module docstring) broken by the first ``n_rows`` rows of the kernel
    outputs ``out`` (kernels.march.Outputs) of a march of the compiled system ``cs``, or None."""
    t, step = np.asarray(out.t[:n_rows]), np.asarray(out.step[:n_rows])
    q, f, w = np.asarray(out.q[:n_rows]), np.asarray(out.f[:n_rows]), np.asarray(out.w[:n_rows])
    state = np.asarray(out.state[:n_rows])
    for name, values in (("t", t), ("x", out.x[:n_rows]), ("q", q), ("f", f), ("w", w)):
        bad = ~np.isfinite(np.asarray(values))
        if bad.any():
            j = int(np.argmax(bad.reshape(n_rows, -1).any(axis=1)))
            return _at(step, t, j, "finite", "all values", f"{name} holds a non-finite number")
    if n_rows > 1:
        bad = (np.diff(step) <= 0) | (np.diff(t) < 0)
        if bad.any():
            j = int(np.argmax(bad)) + 1
            return _at(step, t, j, "rows written", "output row", f"step {step[j]} after step {step[j - 1]}")
    return _contact_violation(cs, out, step, t, f, w, state)


def _at(step, t, j, invariant, where, detail) -> Violation:
    return Violation(invariant, int(step[j]), float(t[j]), where, detail)


def _first(bad) -> tuple[int, int]:
    """(row, column) of the first True of a (rows, columns) mask, row-major."""
    j, k = np.unravel_index(int(np.argmax(bad)), bad.shape)
    return int(j), int(k)


def _contact_violation(cs, out, step, t, f, w, state) -> Violation | None:
    """N >= 0, the friction bound and slip along T (module docstring) of every saved contact
    and direction, vectorised over them, or None."""
    dirs = np.asarray(out.dirs)
    if dirs.size == 0:
        return None
    column = {int(r): i for i, r in enumerate(np.asarray(out.rows))}
    owner = np.asarray(cs.direction_contact)[dirs]
    contacts = np.unique(owner)
    N = f[:, [column[int(r)] for r in np.asarray(cs.normal_row)[contacts]]]
    solved = (step > 0)[:, None]  # row 0 is the given start (a shooting iterate), not a solved step
    if (solved & (N < 0)).any():
        j, k = _first(solved & (N < 0))
        return _at(step, t, j, "N >= 0", f"contact {int(contacts[k])}", f"N = {N[j, k]:.6g} N")
    T = f[:, [column[int(r)] for r in np.asarray(cs.tangential_row)[dirs]]]
    at = np.searchsorted(contacts, owner)  # the column of each direction's contact in N
    mu = np.asarray(cs.law_par)[contacts, 1]
    size = np.abs(T)  # per direction (uncoupled laws); the circle's norm over its directions
    for k in np.flatnonzero(np.isin(np.asarray(cs.law)[contacts], list(COUPLED_SLIP_CODES))):
        mine = at == k
        size[:, mine] = np.sqrt((T[:, mine] ** 2).sum(axis=1))[:, None]
    limit = (mu * N)[:, at]
    bad = solved & (size > limit * (1 + FRICTION_RTOL))
    if bad.any():
        j, k = _first(bad)
        return _at(
            step,
            t,
            j,
            "|T| <= mu N",
            f"contact {int(owner[k])}",
            f"|T| = {size[j, k]:.6g} N, mu N = {limit[j, k]:.6g} N",
        )
    if len(step) < 2:
        return None
    dw = np.diff(w, axis=0)
    slip = np.isin(state[1:], SLIP_STATES) & (np.diff(step) == 1)[:, None]
    floor = SLIP_FLOOR * (np.abs(w[1:]) + np.abs(w[:-1]) + float(cs.length_scale)) * np.abs(T[1:])
    bad = slip & (dw * T[1:] < -floor)
    if bad.any():
        j, k = _first(bad)
        return _at(
            step,
            t,
            j + 1,
            "slip along T",
            f"direction {int(dirs[k])} (contact {int(owner[k])})",
            f"slider moved {dw[j, k]:.3g} m against T = {T[j + 1, k]:.6g} N",
        )
    return None


def check_march(runner):
    """Set ``runner.status`` (a Simulation or an explicit runner after its march) to
    ``Status.INVARIANT`` when it is OK and its rows break an invariant: the failing step and time
    go where every failure's are (counters[C_FAIL_STEP], times[S_FAIL]; the result's
    ``failed_at_step``, ``failed_at_time_s``) and the violation to ``runner.broken_invariant``
    (the result's ``broken_invariant`` attr, named in ``status_message``). Returns the status."""
    from slipstep.errors import Status
    from slipstep.kernels.codes import C_FAIL_STEP, C_STEPS
    from slipstep.kernels.march import S_FAIL
    from slipstep.methods.buffers import saved_rows

    runner.broken_invariant = None
    runner.step_audit = {}  # audit_steps and tolerance_check: the result attrs of the trust flags
    if runner.status != Status.OK:
        return runner.status
    out = runner.out
    found = check_outputs(runner.compiled, out, saved_rows(out, int(out.counters[C_STEPS])))
    if found is None and hasattr(runner, "method"):
        runner.step_audit = {**audit_steps(runner), **tolerance_check(runner)}
    if found is not None:
        runner.status = Status.INVARIANT
        runner.broken_invariant = found
        out.counters[C_FAIL_STEP] = found.step
        out.times[S_FAIL] = found.time
    return runner.status


#: a step of an iterative solver whose balance residual exceeds this many tolerances of the
#: physical force scale is flagged (issue 29 item 3: Method 1's accepted state off the discrete solution)
RESIDUAL_FLAG_FACTOR = 1e4
#: the audit is skipped above this many rows x DOFs^2 (it would cost more than a few tens of ms)
AUDIT_MAX_FLOPS = 2e7


def step_residuals(runner) -> np.ndarray | None:
    """The relative balance residual of every step k >= 1 of a Newmark march (alpha_m = alpha_f = 0),
    recomputed from the rows it wrote:

        rho_k = max_i |M a_k + C v_k + K x_k + A^T f_k - f_e(t_k)|_i / F_k,
        F_k   = the largest |term|_i of the five (the physical force scale of the step)

    (the Newton tests measure the residual against the step's whole right-hand side, predictor
    terms included, and never below the floor tol L max diag J(stick): on a response far below L
    or with large predictor terms they pass at a rho far above the tolerance). None when the
    rows do not hold every DOF and contact at every step, or the structure is banded or has
    massless DOFs (the balance needs them all), or rows x DOFs^2 exceeds AUDIT_MAX_FLOPS."""
    from slipstep.kernels.codes import C_STEPS
    from slipstep.methods.buffers import saved_rows
    from slipstep.model.excitation import force_signal
    from slipstep.model.excitation import evaluate_compiled

    plan = getattr(runner, "save_plan", None)
    cs, out = runner.compiled, runner.out
    scheme = runner.options.scheme
    if plan is not None and not (plan.all_dofs and plan.all_contacts and plan.every_step):
        return None
    if cs.banded or cs.M.shape[1] != cs.M.shape[0]:  # banded or sparse backend: no dense matrices to audit with
        return None
    if scheme.alpha_m != 0.0 or scheme.alpha_f != 0.0 or getattr(runner, "massless", None) is not None:
        return None
    k = saved_rows(out, int(out.counters[C_STEPS]))
    n = cs.M.shape[0]
    if k < 2 or k * n * n > AUDIT_MAX_FLOPS:  # three dense products of (k, n) by (n, n)
        return None
    F = np.zeros((k, cs.A.shape[0]))
    F[:, np.asarray(out.rows)] = out.f[:k]
    terms = (
        out.a[:k] @ cs.M.T,
        out.v[:k] @ cs.C.T,
        out.x[:k] @ cs.K.T,
        F @ cs.A,
        -(evaluate_compiled(force_signal(cs), out.t[:k]) + cs.constant_force),
    )
    scale = np.max([np.abs(term).max(axis=1) for term in terms], axis=0)
    return (np.abs(sum(terms)).max(axis=1) / np.maximum(scale, 1e-300))[1:]


def audit_steps(runner) -> dict:
    """The per-step residual flag of an OK modified-Newton march (Methods 1 and 2): the steps whose
    :func:`step_residuals` exceed RESIDUAL_FLAG_FACTOR x tolerance, counted in the result attrs
    (``steps_above_tolerance``, ``max_step_residual``, ``first_step_above_tolerance``) with a
    warning; {} when not audited (another solver, a partial save, a failed march)."""
    import warnings

    from slipstep.errors import Status
    from slipstep.kernels.codes import MODIFIED_NEWTON, MODIFIED_NEWTON_STATE

    if runner.status != Status.OK or runner.method.quasi_static:
        return {}
    if getattr(runner.method, "solver", None) not in (MODIFIED_NEWTON, MODIFIED_NEWTON_STATE):
        return {}
    rho = step_residuals(runner)
    if rho is None:
        return {}
    tol = float(runner.options.tolerance)
    flagged = np.flatnonzero(rho > RESIDUAL_FLAG_FACTOR * tol)
    attrs = {"steps_above_tolerance": int(flagged.size), "max_step_residual": float(rho.max())}
    if flagged.size:
        first = int(flagged[0]) + 1
        attrs["first_step_above_tolerance"] = int(runner.out.step[first])
        warnings.warn(
            f"{flagged.size} of {rho.size} steps were accepted with a balance residual above "
            f"{RESIDUAL_FLAG_FACTOR:g} x tolerance of their forces (largest {rho.max():.2g}, first at "
            f"t = {float(runner.out.t[first]):.6g} s): the result may be off the discrete solution "
            "(issue 29). Check with method='full-newton' or a smaller tolerance (`slipstep run --tolerance`)",
            RuntimeWarning,
            stacklevel=3,
        )
    return attrs


#: a Newton march whose increment tolerance is above this fraction of its response range is flagged
#: (issue 29 item 3: the result may then be that far off the discrete solution, and no residual shows it)
TOLERANCE_RANGE_FLAG = 1e-8


def tolerance_over_range(runner) -> float | None:
    """The Newton increment tolerance of a march against the response it marched:

        tolerance_over_range = tol L / R,   R = max_j (max_t x_j - min_t x_j)

    with tol the ``tolerance`` option, L the system's length scale (``length_scale_m``; the
    Newton test accepts a step whose last increment is below tol L in the contact coordinates,
    kernels/step_solvers.py CV_TOL_Q) and R the largest DOF range over the saved rows (the
    denominator of study.verification.agreement_error). A step's solution may then be off the
    discrete one by about tol L, so the result by about that fraction of its range (more where
    the steps' errors accumulate, or on a system that amplifies them: measured 2.3 times it on
    tests/test_trust_flag.py's clamped oscillator). inf when nothing moved (R = 0); None when no DOF or
    fewer than two rows were saved."""
    from slipstep.kernels.codes import C_STEPS
    from slipstep.methods.buffers import saved_rows

    rows = saved_rows(runner.out, int(runner.out.counters[C_STEPS]))
    x = np.asarray(runner.out.x[:rows])
    if rows < 2 or x.ndim != 2 or x.shape[1] == 0:
        return None
    span = float(np.ptp(x, axis=0).max())
    tol_q = float(runner.options.tolerance) * float(runner.compiled.length_scale)
    return tol_q / span if span > 0.0 else math.inf


def tolerance_check(runner) -> dict:
    """The tolerance flag of an OK modified-Newton march (Methods 1 and 2): the attr
    ``tolerance_over_range`` (:func:`tolerance_over_range`) and, above TOLERANCE_RANGE_FLAG, a
    RuntimeWarning saying how far off the result may be and how to tighten; {} for another
    solver or a failed march."""
    import warnings

    from slipstep.errors import Status
    from slipstep.kernels.codes import MODIFIED_NEWTON, MODIFIED_NEWTON_STATE

    if runner.status != Status.OK or runner.method.quasi_static:
        return {}
    if getattr(runner.method, "solver", None) not in (MODIFIED_NEWTON, MODIFIED_NEWTON_STATE):
        return {}
    ratio = tolerance_over_range(runner)
    if ratio is None:
        return {}
    if ratio > TOLERANCE_RANGE_FLAG:
        tol = float(runner.options.tolerance)
        warnings.warn(tolerance_text(ratio, tol), RuntimeWarning, stacklevel=3)
    return {"tolerance_over_range": ratio}


def tolerance_text(ratio: float, tolerance: float) -> str:
    """The words of the tolerance flag (the warning, and the reason :func:`flagged` gives)."""
    tighter = tolerance * TOLERANCE_RANGE_FLAG / ratio if math.isfinite(ratio) and ratio > 0 else 0.0
    tighter = 10.0 ** math.floor(math.log10(tighter)) if tighter > 0 else 0.0  # the power of ten below
    fix = (
        f"tolerance={tighter:.0e}, `slipstep run --tolerance {tighter:.0e}` or [run] tolerance = {tighter:.0e}"
        if tighter >= 1e-15
        else "a tighter tolerance: `slipstep run --tolerance`, [run] tolerance"
    )
    return (
        f"the Newton tolerance x length scale is {ratio:.2g} of the response range (above {TOLERANCE_RANGE_FLAG:g}): "
        f"the result may differ from the discrete solution by about that fraction of the range, more where "
        f"the steps' errors accumulate. Tighten it with the tolerance option ({fix}; now {tolerance:g}) or use "
        "method='piecewise-linear' (`-m 3`), which has no Newton tolerance"
    )


def flagged(attrs) -> list[str]:
    """The reasons a status-OK result may be off its discrete solution (issue 29 item 3), from
    its attrs: steps accepted far above their tolerance (:func:`audit_steps`), a Newton tolerance
    above TOLERANCE_RANGE_FLAG of the response range (:func:`tolerance_check`), a response that
    moved by more than TWIN_FLAG of its range in the sensitivity twin (loads x (1 + 1e-10), the
    tolerance 100 times tighter: slipstep.methods.sensitivity_twin); [] when none."""
    reasons = []
    if attrs.get("steps_above_tolerance", 0) > 0:
        reasons.append(
            f"{attrs['steps_above_tolerance']} steps accepted with a balance residual above "
            f"{RESIDUAL_FLAG_FACTOR:g} x tolerance (largest {attrs.get('max_step_residual', math.nan):.2g})"
        )
    ratio = attrs.get("tolerance_over_range", 0.0)
    if ratio > TOLERANCE_RANGE_FLAG:  # NaN (not computed) is not flagged
        reasons.append(tolerance_text(float(ratio), float(attrs.get("tolerance", math.nan))))
    moved = attrs.get("twin_difference", 0.0)
    if moved > TWIN_FLAG:  # NaN (no twin result) is not flagged
        reasons.append(sensitivity_text(float(moved), float(attrs.get("tolerance", math.nan))))
    return reasons
