"""The step solvers of the implicit march (kernels/march.py): each solves one step's residual

    r(dx) = r0 - Lin dx - kfac A^T f(q_base + A dx, w_n) = 0

for dx (module docstring of kernels/march.py for r0, Lin, q_base, kfac), and leaves in the
StepVectors ``sv`` (kernels/settings.py) the converged q1, f1, w1, state1 and gf1 = A^T f1
(the piecewise-linear solver only where kfac != 1: A^T f_{n+1} enters the next step's residual
base through alpha_f alone, so a quasi-static or Newmark march never reads it).
Every structure-matrix operation goes through kernels/structure_ops.py (``backend``).

    0 MODIFIED_NEWTON        :func:`stick_tangent_step` (Method 1)
    1 FULL_NEWTON            :func:`full_newton`
    2 PIECEWISE_LINEAR       :func:`piecewise_linear_step` (Methods 3, 4), with its fallback
    3 MODIFIED_NEWTON_STATE  :func:`state_tangent_step` (Method 2)

Each returns (status, solves) (and the factorisations it holds across steps, where it
keeps them: the per-step fast paths).

One body per algorithm for every backend: ``backend`` is a compile-time constant wherever these
run (the march kernels are closures of it, kernels.march.implicit_kernel), so numba prunes the other
backends' branches of the inlined helpers before typing. The solvers compiled out of line
(:func:`modified_newton`, :func:`full_newton`, the factorisations, :func:`stick_fallback`, the
banded piecewise-linear step) are closures of the backend too, one kernel per backend
(:func:`per_backend`): numba does not prune on a literal argument, only on a constant of the IR.
"""

import numpy as np
from numba import njit

from slipstep.kernels.codes import C_FALLBACKS, C_LAW_CALLS, C_N_VISITED, NON_FINITE, NOT_CONVERGED, OK, SINGULAR
from slipstep.kernels.codes import STATE_CYCLING
from slipstep.kernels.contact import compatible_law, coupled, gather_columns, law, piecewise_law
from slipstep.kernels import structure_ops as so
from slipstep.kernels.structure_ops import BANDED, DENSE, LOW_RANK
from slipstep.kernels.lean_compiler import LeanCompiler

THETA_GIVE_UP = 0.5  # contraction at which solver 3 leaves J(S) for J(all stick)
# convergence parameters of the Newton iterations (the array ``conv``, filled per step by march):
#   conv[CV_TOL]    tol, the relative tolerance (RunOptions.tolerance)
#   conv[CV_TOL_Q]  tol * L, the absolute tolerance on the contact coordinates [m]
#   conv[CV_FLOOR]  tol * L * max diag (K + K_D(stick)): the residual floor [N] (a step at rest; no inertia)
#   conv[CV_X + j]  tol * L / max_r |A_rj| (tol * L for a DOF no contact sees): the tolerance on DOF j
CV_TOL, CV_TOL_Q, CV_FLOOR, CV_X = 0, 1, 2, 3
#: the residual test never asks for less than this relative residual (round-off of r)
RESIDUAL_RTOL_MIN = 1e-13
#: an increment below this fraction of its scale is round-off (its contraction ratio is meaningless)
ROUNDOFF = 1e-14


def per_backend(factory):
    """(factory(DENSE), factory(LOW_RANK), factory(BANDED)): the out-of-line kernels of one
    function, one per structure backend (closures of the backend code, cached on disk per code;
    numba compiles one only when a march of its backend calls it)."""
    return factory(DENSE), factory(LOW_RANK), factory(BANDED)


@njit(cache=True, error_model="numpy", inline="always")
def local_coordinates(backend, csr, AT, qbase, dx, q):
    """q = q_base + A dx (AT: the transpose of A, dense; A in CSR for the banded backend:
    structure_ops.gather_increment)."""
    if backend == BANDED:
        so.gather_increment(csr, qbase, dx, q)
        return
    gather_columns(AT, qbase, dx, q)


@njit(cache=True, error_model="numpy", inline="always")
def newton_residual(backend, csr, A, AT, cl, Lin, kfac, sv, counters):
    """The contact law at q = q_base + A dx and the residual r = r0 - kfac A^T f - Lin dx."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    local_coordinates(backend, csr, AT, sv.qbase, sv.dx, sv.q1)
    law(nrow, lcode, lpar, fdir, ndir, trow, kt, sv.q1, sv.w, sv.f1, sv.w1, sv.state1)
    counters[C_LAW_CALLS] += 1
    so.scatter_force(backend, csr, A, sv.f1, sv.gf1)
    r, r0, gf1 = sv.r, sv.r0, sv.gf1
    for i in range(r.shape[0]):
        r[i] = r0[i] - kfac * gf1[i]
    so.sub_lin(backend, Lin, sv.dx, r)


@njit(cache=True, error_model="numpy", inline="always")
def newton_update(backend, csr, A, dx, delta, it, prev_norm, prev_theta, conv):
    """dx += delta; returns (status, increment_converged, norm, theta).

    The scaled increment eta = max(max_r |(A delta)_r| / tol_q, max_j |delta_j| / tol_x,j)
    (contact coordinates and DOFs, conv), its contraction theta_k = eta_k / eta_{k-1} and
    the robust contraction theta = max(theta_k, theta_{k-1}) (slow or irregular contraction
    cannot hide behind one lucky ratio). The increment test, the error estimate of a
    linearly converging iteration (Hairer & Wanner IV.8; Deuflhard's natural monotonicity):
        theta < 1  and  eta theta / (1 - theta) <= 1
    The first increment has no theta yet: eta <= 1 itself (then the residual decides). An
    increment below ROUNDOFF of its scale (L or |x_j|: about 50 machine epsilons) is round-off, whose ratios
    say nothing about contraction: accepted as converged."""
    n = dx.shape[0]
    nq = A.shape[0]
    for i in range(n):
        dx[i] += delta[i]
        if not np.isfinite(dx[i]):
            return NON_FINITE, False, 0.0, 0.0
    eta = 0.0
    tol_q = conv[CV_TOL_Q]
    if backend == BANDED:  # max_r |(A delta)_r| with A in CSR
        eta = so.gather_abs_max(csr, delta) / tol_q
    for rr in range(nq if backend != BANDED else 0):
        s = 0.0
        for j in range(n):
            s += A[rr, j] * delta[j]
        eta = max(eta, abs(s) / tol_q)
    for i in range(n):
        eta = max(eta, abs(delta[i]) / conv[CV_X + i])
    if it == 0:
        return OK, eta <= 1.0, eta, 0.0
    theta_k = eta / prev_norm if prev_norm > 0.0 else 0.0
    theta = max(theta_k, prev_theta) if it >= 2 else theta_k
    converged = eta * conv[CV_TOL] <= ROUNDOFF or (theta < 1.0 and eta * theta / (1.0 - theta) <= 1.0)
    return OK, converged, eta, theta_k


@njit(cache=True, error_model="numpy", inline="always")
def residual_converged(sv, kfac, conv):
    """The force-residual test at the current iterate (r = r0 - Lin dx - kfac A^T f):
        max_i |r_i| <= max(tol, RESIDUAL_RTOL_MIN) * max(F, floor)
    with F the step's force scale, the largest term of the balance over the DOFs,
    F = max_i max(|r0_i|, kfac |(A^T f)_i|, |(Lin dx)_i|), (Lin dx = r0 - kfac A^T f - r),
    and floor = tol L max diag (K + K_D(stick)) (conv: the stiffness forces of a displacement L;
    the inertia term a0 M of J(stick) is left out, it let steps off by 1e-8 of the forces pass)."""
    r, r0, gf1 = sv.r, sv.r0, sv.gf1
    rmax = 0.0
    scale = conv[CV_FLOOR] / conv[CV_TOL]
    for i in range(r.shape[0]):
        c = kfac * gf1[i]
        rmax = max(rmax, abs(r[i]))
        scale = max(scale, abs(r0[i]), abs(c), abs(r0[i] - c - r[i]))
    return rmax <= max(conv[CV_TOL], RESIDUAL_RTOL_MIN) * scale


@njit(cache=True, error_model="numpy", inline="always")
def modified_newton(backend, lu, piv, Lin, kfac, csr, A, AT, cl, sv, max_iter, conv, theta_give_up, from_zero, counters):
    """The modified Newton iteration of :func:`_modified_newton_kernel` for the backend (A in CSR,
    ``csr`` = structure_ops.csr_of, for the banded one; the dense and low-rank backends share
    one). ``bool(from_zero)``: a plain bool, so that a literal True at a call site does not
    compile a second specialisation of the callee (benchmarks/bench_compile.py)."""
    if backend == BANDED:
        return _modified_newton_banded(lu, piv, Lin, kfac, csr, A, AT, cl, sv, max_iter, conv, theta_give_up,
                                       bool(from_zero), counters)
    return _modified_newton_dense(lu, piv, Lin, kfac, (), A, AT, cl, sv, max_iter, conv, theta_give_up,
                                  bool(from_zero), counters)


def _modified_newton_kernel(backend):
    """:func:`modified_newton` of one structure backend, compiled out of line (once per backend,
    shared by the marches): the backend a constant of the closure, so that numba prunes the
    other backends' branches of the inlined helpers before typing (kernels.march.implicit_kernel)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def modified_newton(lu, piv, Lin, kfac, csr, A, AT, cl, sv, max_iter, conv, theta_give_up, from_zero,
                        counters):
        """Iterate dx += F^-1 r(dx) with one factorised Jacobian F = (lu, piv) (Method 1: J(all
        stick); solver 3: J(S) of a state), from dx = 0 (from_zero) or from the dx reached.
        Converged when BOTH the increment test of :func:`newton_update` (on the contact
        coordinates and the DOFs) and the force-residual test of :func:`residual_converged` at
        the new iterate hold; given up (NOT_CONVERGED) as soon as the contraction ratio of the
        increment reaches theta_give_up (inf: never). Returns (status, solves); on success the
        StepVectors hold the converged step. Takes the two factor arrays only, so that its hot
        loop never carries the low-rank arrays."""
        dx, delta, r = sv.dx, sv.delta, sv.r
        if from_zero:
            for i in range(dx.shape[0]):
                dx[i] = 0.0
        prev_norm = 0.0
        theta = 0.0
        inc_ok = False
        for it in range(max_iter + 1):
            newton_residual(backend, csr, A, AT, cl, Lin, kfac, sv, counters)
            if inc_ok and residual_converged(sv, kfac, conv):
                return OK, it
            if it == max_iter:
                break
            so.solve_factor(backend, lu, piv, r, delta)
            status, inc_ok, prev_norm, theta = newton_update(backend, csr, A, dx, delta, it, prev_norm, theta, conv)
            if status != OK:
                return status, it + 1
            if it > 0 and theta >= theta_give_up:
                return NOT_CONVERGED, it + 1
        return NOT_CONVERGED, max_iter

    return modified_newton


_modified_newton_dense, _modified_newton_banded = _modified_newton_kernel(DENSE), _modified_newton_kernel(BANDED)


@njit(cache=True, error_model="numpy", inline="always")
def full_newton(backend, sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, counters):
    """:func:`_full_newton_kernel` of the backend."""
    if backend == BANDED:
        return _full_newton_banded(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, counters)
    if backend == LOW_RANK:
        return _full_newton_low_rank(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol,
                                     counters)
    return _full_newton_dense(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, counters)


def _full_newton_kernel(backend):
    """:func:`full_newton` of one structure backend (out of line, its backend a constant:
    :func:`_modified_newton_kernel`)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def full_newton(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, counters):
        """Newton with the Jacobian J(S) of the current iterate's state S (factorised per state,
        cached; the consistent tangent at the iterate for a coupled slip), the full-stick one
        where J(S) is singular: dx += J(S)^-1 r(dx). The same two-part convergence test as
        :func:`modified_newton` (increment and force residual, both)."""
        A, AT = sys.A, sys.AT
        csr = so.csr_of(sys)  # once per step: a tuple of arrays per iteration costs their reference counts
        dx, delta, r, q1, w, state1 = sv.dx, sv.delta, sv.r, sv.q1, sv.w, sv.state1
        stick = cache.stick
        for i in range(dx.shape[0]):
            dx[i] = 0.0
        stick_slot, ok = so.factorise(backend, sys, cl, cache, Lin, J, kfac, stick, sv.qbase, w, nominal, singular_rtol,
                                      counters)
        if not ok:
            return SINGULAR, 0
        prev_norm = 0.0
        theta = 0.0
        inc_ok = False
        for it in range(max_iter + 1):
            newton_residual(backend, csr, A, AT, cl, Lin, kfac, sv, counters)
            if inc_ok and residual_converged(sv, kfac, conv):
                return OK, it
            if it == max_iter:
                break
            use, use_state = stick_slot, stick
            slot, ok = so.factorise(backend, sys, cl, cache, Lin, J, kfac, state1, q1, w, nominal, singular_rtol, counters)
            if ok:
                use, use_state = slot, state1
            so.solve(backend, sys, cl, cache, use, use_state, q1, w, kfac, r, delta)
            status, inc_ok, prev_norm, theta = newton_update(backend, csr, A, dx, delta, it, prev_norm, theta, conv)
            if status != OK:
                return status, it + 1
        return NOT_CONVERGED, max_iter

    return full_newton


_full_newton_dense, _full_newton_low_rank, _full_newton_banded = per_backend(_full_newton_kernel)


@njit(cache=True, error_model="numpy", inline="always")
def stick_factorisation(backend, sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters):
    """:func:`_factorisation_kernels` of the backend: (ok, lu, piv) of J(all stick)."""
    if backend == BANDED:
        return _stick_factorisation_banded(sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)
    if backend == LOW_RANK:
        return _stick_factorisation_low_rank(sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)
    return _stick_factorisation_dense(sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)


@njit(cache=True, error_model="numpy", inline="always")
def state_factorisation(backend, sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol, counters):
    """:func:`_factorisation_kernels` of the backend: (ok, lu, piv) of J(S), S = tstate."""
    if backend == BANDED:
        return _state_factorisation_banded(sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol, counters)
    if backend == LOW_RANK:
        return _state_factorisation_low_rank(sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol, counters)
    return _state_factorisation_dense(sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol, counters)


def _factorisation_kernels(backend):
    """(stick_factorisation, state_factorisation) of one structure backend (out of line, its
    backend a constant: :func:`_modified_newton_kernel`)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def stick_kernel(sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters):
        """(ok, lu, piv): the factorisation of J(all stick) = Lin + kfac A^T K(stick) A for the
        current step size, held by its state slot (direct) or by the low-rank base (where
        C(stick) = I), for :func:`modified_newton`."""
        nowhere = np.empty(0)  # J(stick) needs no linearisation point
        slot, ok = so.factorise(backend, sys, cl, cache, Lin, J, kfac, cache.stick, nowhere, nowhere, nominal,
                                singular_rtol, counters)
        lu, piv = so.stick_factor(backend, cache, slot)
        return ok, lu, piv

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def state_kernel(sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol, counters):
        """(ok, lu, piv): the factorisation of J(S) = Lin + kfac A^T K(S) A for the modified Newton
        of solver 3, S the contact state whose T_min set the step (cached per state like the
        stick one). Falls back to J(all stick) where S has no constant tangent (coupled slip), in
        low-rank mode (whose J(S) solve is not one LU) and where J(S) is singular."""
        nrow, lcode, lpar, fdir, ndir, trow, kt = cl
        if backend != LOW_RANK and not coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, tstate):
            nowhere = np.empty(0)
            slot, ok = so.factorise(backend, sys, cl, cache, Lin, J, kfac, tstate, nowhere, nowhere, nominal,
                                    singular_rtol, counters)
            if ok:
                lu, piv = so.state_factor(backend, cache, slot)
                return ok, lu, piv
        return stick_factorisation(backend, sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)

    return stick_kernel, state_kernel


_dense_factorisations, _low_rank_factorisations, _banded_factorisations = per_backend(_factorisation_kernels)
_stick_factorisation_dense, _state_factorisation_dense = _dense_factorisations
_stick_factorisation_low_rank, _state_factorisation_low_rank = _low_rank_factorisations
_stick_factorisation_banded, _state_factorisation_banded = _banded_factorisations


@njit(cache=True, error_model="numpy", inline="always")
def stick_tangent_step(backend, sys, cl, cache, Lin, J, kfac, sv, dt, nominal, max_iter, conv, singular_rtol,
                       counters, ok0, lu0, piv0, stick_dt):
    """Solver 0 (Method 1): modified Newton with J(all stick), factorised once per step size
    (kept across steps while dt is the nominal one: stick_dt). Returns (status, solves, ok0,
    lu0, piv0, stick_dt), the last four the factorisation held for the next step."""
    if dt != stick_dt or not nominal:
        ok0, lu0, piv0 = stick_factorisation(backend, sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)
        stick_dt = dt if nominal else np.nan
    if ok0:
        status, more = modified_newton(backend, lu0, piv0, Lin, kfac, so.csr_of(sys), sys.A, sys.AT, cl, sv, max_iter, conv, np.inf,
                                       True, counters)
    else:
        status, more = SINGULAR, 0
    return status, more, ok0, lu0, piv0, stick_dt


@njit(cache=True, error_model="numpy", inline="always")
def state_tangent_step(backend, sys, cl, cache, Lin, J, kfac, sv, tstate, dt, nominal, max_iter, conv,
                       singular_rtol, counters, okS, luS, pivS, tan_dt, tan_state):
    """Solver 3 (Method 2): modified Newton with J(S) of the state S = tstate whose T_min set
    the step (kept across steps while S and the nominal dt stay: tan_dt, tan_state), given up
    for J(all stick) from the dx reached when it stops contracting (theta >= THETA_GIVE_UP;
    from dx = 0 after a failure of another kind). Returns (status, solves, okS, luS, pivS,
    tan_dt), the last four the J(S) factorisation held for the next step."""
    nd = tstate.shape[0]
    same = nominal and dt == tan_dt
    if same:
        for d in range(nd):
            if tstate[d] != tan_state[d]:
                same = False
                break
    if not same:
        okS, luS, pivS = state_factorisation(backend, sys, cl, cache, Lin, J, kfac, tstate, nominal, singular_rtol,
                                             counters)
        tan_dt = dt if nominal else np.nan
        for d in range(nd):
            tan_state[d] = tstate[d]
    A, AT = sys.A, sys.AT
    status, more = SINGULAR, 0
    if okS:
        status, more = modified_newton(backend, luS, pivS, Lin, kfac, so.csr_of(sys), A, AT, cl, sv, max_iter, conv, THETA_GIVE_UP,
                                       True, counters)
    solves = 0
    if status != OK:  # J(S) too soft for the state the step reached: the stick tangent
        counters[C_FALLBACKS] += 1
        restart = status != NOT_CONVERGED  # else go on from the dx reached
        solves += more
        ok0, lu0, piv0 = stick_factorisation(backend, sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)
        status, more = SINGULAR, 0
        if ok0:
            status, more = modified_newton(backend, lu0, piv0, Lin, kfac, so.csr_of(sys), A, AT, cl, sv, max_iter, conv, np.inf,
                                           restart, counters)
    return status, solves + more, okS, luS, pivS, tan_dt


@njit(cache=True, error_model="numpy", inline="always")
def stick_fallback(backend, sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, pl_status,
                   counters):
    """:func:`_stick_fallback_kernel` of the backend."""
    if backend == BANDED:
        return _stick_fallback_banded(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol,
                                      pl_status, counters)
    if backend == LOW_RANK:
        return _stick_fallback_low_rank(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol,
                                        pl_status, counters)
    return _stick_fallback_dense(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, pl_status,
                                 counters)


def _stick_fallback_kernel(backend):
    """:func:`stick_fallback` of one structure backend (out of line, its backend a constant:
    :func:`_modified_newton_kernel`)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def stick_fallback(sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol, pl_status, counters):
        """The fallback of :func:`piecewise_linear_step` when its postulates cycle or J(S) is
        singular (pl_status): modified Newton with J(all stick) from dx = 0 (counted in
        C_FALLBACKS). Returns (status, solves); status pl_status (the more telling reason) when
        Newton fails too."""
        counters[C_FALLBACKS] += 1
        ok0, lu0, piv0 = stick_factorisation(backend, sys, cl, cache, Lin, J, kfac, nominal, singular_rtol, counters)
        if not ok0:
            return pl_status, 0
        status, solves = modified_newton(backend, lu0, piv0, Lin, kfac, so.csr_of(sys), sys.A, sys.AT, cl, sv, max_iter,
                                         conv, np.inf, True, counters)
        return (OK if status == OK else pl_status), solves

    return stick_fallback


_stick_fallback_dense, _stick_fallback_low_rank, _stick_fallback_banded = per_backend(_stick_fallback_kernel)


@njit(cache=True, error_model="numpy", inline="always")
def piecewise_linear_step(backend, sys, cl, cache, Lin, J, kfac, sv, state, visited, attempt, nominal, last_slot,
                          has_circle, max_state_iter, fallback, max_iter, conv, state_rtol, singular_rtol,
                          length_scale, counters):
    """Solver 2 (Methods 3, 4): :func:`_piecewise_linear_step`, inlined for the dense backends, a
    plain call for the banded one (:func:`_piecewise_linear_step_banded`: compiled once and
    shared by the implicit and quasi-static marches instead of inside each, docs/measured.md,
    "Compile time"; ``np.int64(attempt)``, ``np.int64(last_slot)``: one specialisation, the
    quasi-static march's literal 0 and a literal -1 would compile others)."""
    if backend == BANDED:
        return _piecewise_linear_step_banded(sys, cl, cache, Lin, J, kfac, sv, state, visited, np.int64(attempt),
                                             nominal, np.int64(last_slot), has_circle, max_state_iter, fallback,
                                             max_iter, conv, state_rtol, singular_rtol, length_scale, counters)
    return _piecewise_linear_step(backend, sys, cl, cache, Lin, J, kfac, sv, state, visited, attempt, nominal,
                                  last_slot, has_circle, max_state_iter, fallback, max_iter, conv, state_rtol,
                                  singular_rtol, length_scale, counters)


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def _piecewise_linear_step_banded(sys, cl, cache, Lin, J, kfac, sv, state, visited, attempt, nominal, last_slot,
                                  has_circle, max_state_iter, fallback, max_iter, conv, state_rtol, singular_rtol,
                                  length_scale, counters):
    """:func:`_piecewise_linear_step` of the banded backend (A in CSR), out of line."""
    return _piecewise_linear_step(BANDED, sys, cl, cache, Lin, J, kfac, sv, state, visited, attempt, nominal,
                                  last_slot, has_circle, max_state_iter, fallback, max_iter, conv, state_rtol,
                                  singular_rtol, length_scale, counters)


@njit(cache=True, error_model="numpy", inline="always")
def _piecewise_linear_step(backend, sys, cl, cache, Lin, J, kfac, sv, state, visited, attempt, nominal, last_slot,
                           has_circle, max_state_iter, fallback, max_iter, conv, state_rtol, singular_rtol,
                           length_scale, counters):
    """Solver 2 (Methods 3, 4): postulate S = S_n (a redone step keeps the state it found),
    solve the linear step J(S) dx = r0 - kfac A^T s(S, w_n) - kfac A^T K(S) q_base (the law
    f = K(S) q + s(S, w_n) of the postulate), accept if S is compatible at q = q_base + A dx,
    else postulate the law's states there and re-solve. The accepted step keeps the law at q
    (f, w and S of kernels.contact.law, not of the postulate): a postulate accepted within the
    tolerance across a stick/slip or contact boundary takes the law's side of it, so that
    |T| <= mu N, N >= 0 and slip along T hold exactly (issue 29), the residual then off by at
    most the tolerance. A postulated coupled slip (no linear
    form) is solved by :func:`full_newton` instead. If the states cycle (max_state_iter
    postulates), modified Newton with J(all stick) for that step (fallback, counted).
    last_slot: the cache slot of the last factorisation, reused without a look-up while the
    step is nominal. Returns (status, solves, last_slot)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    A, AT = sys.A, sys.AT
    nd = state.shape[0]
    n = sv.dx.shape[0]
    dx, r, r0, qbase, w, q1, f1, w1, state1, gf1 = sv.dx, sv.r, sv.r0, sv.qbase, sv.w, sv.q1, sv.f1, sv.w1, \
        sv.state1, sv.gf1
    keys, dt_state = cache.keys, cache.dt_state
    status = STATE_CYCLING
    solves = 0
    if attempt == 0:  # postulate S_{n+1} = S_n; a redone step keeps the state it found
        for d in range(nd):
            state1[d] = state[d]
    counters[C_N_VISITED] = 0
    for it in range(max_state_iter):
        for d in range(nd):
            visited[it, d] = state1[d]
        counters[C_N_VISITED] = it + 1
        if has_circle and coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, state1):  # no linear form: Newton
            status, more = full_newton(backend, sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv,
                                       singular_rtol, counters)
            solves += more
            break
        same = nominal and last_slot >= 0
        if same:
            for d in range(nd):
                if keys[last_slot, d] != state1[d] or keys[last_slot, nd + d] != dt_state[d]:
                    same = False
                    break
        if same:
            slot, ok = last_slot, cache.ok[last_slot]
        else:
            slot, ok = so.factorise(backend, sys, cl, cache, Lin, J, kfac, state1, qbase, w, nominal, singular_rtol,
                                    counters)
            last_slot = slot if nominal else -1
        if not ok:
            status = SINGULAR
            break
        for rr in range(q1.shape[0]):  # the law at q_base (in q1: one call site of the law with q1)
            q1[rr] = qbase[rr]
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, f1, w1)
        so.scatter_force(backend, so.csr_of(sys), A, f1, gf1)
        for i in range(n):
            r[i] = r0[i] - kfac * gf1[i]
        so.solve(backend, sys, cl, cache, slot, state1, q1, w, kfac, r, dx)
        solves += 1
        finite = True
        for i in range(n):
            if not np.isfinite(dx[i]):
                finite = False
        if not finite:
            status = NON_FINITE
            break
        local_coordinates(backend, so.csr_of(sys), AT, qbase, dx, q1)
        if compatible_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, state_rtol, length_scale, f1, w1):
            law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)  # the law's f, w, S at q1 (exact_law)
            if kfac != 1.0:  # A^T f1 for the next residual base (alpha_f != 0; module docstring)
                so.scatter_force(backend, so.csr_of(sys), A, f1, gf1)  # f1, w1: the law at q1
            status = OK
            break
        law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
        counters[C_LAW_CALLS] += 1
    if status != OK and status != NON_FINITE and fallback:
        status, more = stick_fallback(backend, sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv, singular_rtol,
                                      status, counters)
        solves += more
    return status, solves, last_slot
