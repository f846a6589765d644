"""The implicit time march: Newmark / HHT / generalised-alpha and quasi-static, with the
modified-Newton, full-Newton and piecewise-linear step solvers and the contact-state
adaptive step (physics.md section 4; paper 4.2, 4.3, 5, Appendices A.3, A.4, B).

Legend. x, v, a: DOF displacement, velocity, acceleration; dx = x_{n+1} - x_n (solved for,
never x_{n+1}, to keep digits); p: prescribed motion; q = A x - B p + g: local contact
displacements; f: local contact forces; w: sliders; S: contact state (per direction).

Newmark relations (beta, gamma):
    a_{n+1} = a0 dx - a2 v_n - a3 a_n,         a0 = 1/(beta dt^2), a2 = 1/(beta dt), a3 = 1/(2 beta) - 1
    v_{n+1} = a1 dx + (1 - gamma/beta) v_n + dt (1 - gamma/(2 beta)) a_n,   a1 = gamma/(beta dt)
Generalised-alpha balance (alpha_m = alpha_f = 0: Newmark; alpha_m = 0: HHT):
    M a_{n+1-am} + C v_{n+1-af} + K x_{n+1-af} + A^T f_{n+1-af} = f_e(t_{n+1-af})
with y_{n+1-a} = (1 - a) y_{n+1} + a y_n. Written as the residual in dx:
    r(dx) = r0 - Lin dx - (1 - af) A^T f(q_base + A dx)
    Lin   = (1 - am) a0 M + (1 - af) a1 C + (1 - af) K,      q_base = A x_n - B p_{n+1} + g
and the Jacobian in state S is J(S) = Lin + (1 - af) K_D(S).
Quasi-static (inertia off, paper Eq. 10): Lin = K, r0 = f_e - K x_n, J(S) = K + K_D(S).

Step solvers:
    0 modified Newton (Method 1): J(all stick) factorised once per dt, iterate on dx until
      BOTH the increment test (the error estimate theta/(1-theta) of the scaled increment on
      the contact coordinates and the DOFs, theta the larger of the last two contraction
      ratios, :func:`_newton_update`) and the force-residual test at the new iterate
      (:func:`_residual_converged`) hold; each iteration = one contact-law call + one solve.
    1 full Newton: J(S) of the current iterate's state.
    2 piecewise linear (Method 3/4): postulate S = S_n, one solve with J(S), accept if S is
      compatible at the computed q, else postulate the law's states there and re-solve.
      If the states cycle, fall back to modified Newton for that step (counted).
      A postulated state without a piecewise-linear form (a coupled slip of the friction-
      circle law) is solved by Newton on the consistent tangent (solver 1) instead.
    3 modified Newton with J(S) of the state whose T_min set the step (Method 2: the state
      at the step start, or the one a redo found; fixed step: S_n), cached per state, given
      up for J(all stick) from the dx reached when it stops contracting (theta >= 0.5).
    (4 EVENTS: not a solver of this march; kernels/events.py.)
Accuracy control (fpar RTOL > 0, RunOptions.rtol): dt = min(rule, dt_acc) for the Newton
solvers (rule: the fixed step or the contact-state step below), min(dt_acc, dt_max) for the
piecewise-linear solve; dt_acc follows the local error of each step (:func:`_local_error`),
a step above it is redone smaller (counted as a redo). Every step then factorises afresh.
Adaptive step (Method 2): dt = min(step_factor * T_min(S_n), dt_max), with
T_min = 2 pi / sqrt(max|eig(M^-1 (K + K_D(S)))|) cached per state; redo the step with the
smaller dt when the new state's limit is below the dt used (a redone step postulates the
state it found).
Every solve with J(S) goes through kernels/state_solve.py: a cached LU per (S, dt state), or
the low-rank update of J(all stick) for structures with few contact coordinates.
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.cache import find_slot
from slipstep.kernels.codes import (  # noqa: F401  (re-exported: the counters and status codes)
    C_FACTORISATIONS, C_FAIL_STEP, C_FALLBACKS, C_LAW_CALLS, C_N_VISITED, C_REDOS, C_SOLVES, C_STATE_CHANGES, C_STEPS,
    CAPACITY, N_COUNTERS, NON_FINITE, NOT_CONVERGED, OK, SINGULAR, STATE_CYCLING,
)
from slipstep.kernels.codes import (  # noqa: F401
    C_PROGRESS, C_STOP, EVENTS, FULL_NEWTON, INTERRUPTED, LAW_CIRCLE, MODIFIED_NEWTON, MODIFIED_NEWTON_STATE,
    PIECEWISE_LINEAR,
)
from slipstep.kernels.contact import compatible, contact_stiffness, coupled, gather, law, piecewise_law, scatter
from slipstep.kernels.eigen import EIG_RTOL, MAX_BASIS, MAX_RESTARTS, largest_eigenvalue_modulus
from slipstep.kernels.linalg import lu_solve
from slipstep.kernels.state_solve import LowRank, factorise_state, solve_low_rank
from slipstep.kernels.signals import evaluate_signal

THETA_GIVE_UP = 0.5  # contraction at which solver 3 leaves J(S) for J(all stick)
# float parameters
BETA, GAMMA, ALPHA_M, ALPHA_F, DT, STEP_FACTOR, DT_MAX, TOL, STATE_RTOL, SINGULAR_RTOL, T_START, T_END = range(12)
RTOL, ERR_SCALE = 12, 13  # accuracy control (rtol > 0: on; the piecewise-linear solve then keeps dt <= DT_MAX only)
N_FPAR = 14
ACC_GROWTH = 1.5  # the largest growth of the accuracy step from one step to the next
# int parameters
SOLVER, ADAPTIVE, INERTIA, MAX_ITER, MAX_STATE_ITER, MAX_REDO, FALLBACK, SIGNALS, PRELOAD, LOWRANK = range(10)
N_IPAR = 10


class Workspace(NamedTuple):
    """Scratch and carried state of a march; allocated once in Python (see methods.base)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    fe: np.ndarray  # f_e(t_n)
    gf: np.ndarray  # A^T f_n
    w: np.ndarray
    state: np.ndarray  # int8
    fe1: np.ndarray
    gf1: np.ndarray
    f1: np.ndarray
    q1: np.ndarray
    w1: np.ndarray
    state1: np.ndarray
    dx: np.ndarray
    delta: np.ndarray
    r0: np.ndarray
    r: np.ndarray
    p: np.ndarray
    qbase: np.ndarray
    Lin: np.ndarray
    J: np.ndarray
    mass_factor: np.ndarray  # L with M = L L^T (zero pivots: DOFs without mass), kernels/eigen.py
    key: np.ndarray  # int8 (2 nd): [S for K_D, S for dt]
    dt_state: np.ndarray  # int8 (nd)
    stick: np.ndarray  # int8 (nd) all STICK
    cache_keys: np.ndarray  # int8 (cap, 2 nd)
    cache_used: np.ndarray  # bool (cap)
    cache_ok: np.ndarray  # bool (cap + 1): factorisation not singular
    cache_lu: np.ndarray  # (cap + 1, n, n); slot cap is scratch
    cache_piv: np.ndarray  # int64 (cap + 1, n)
    tmin_keys: np.ndarray  # int8 (cap, nd)
    tmin_used: np.ndarray
    tmin_value: np.ndarray  # (cap,) s
    lin_dt: np.ndarray  # (1,) dt of the current Lin
    visited: np.ndarray  # int8 (max_state_iter + 1, nd): states of the last state iteration
    lr: LowRank  # the low-rank solve's arrays (placeholders in direct mode), see state_solve.py


class Outputs(NamedTuple):
    t: np.ndarray
    dt: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    q: np.ndarray
    f: np.ndarray
    w: np.ndarray
    state: np.ndarray
    solves: np.ndarray
    counters: np.ndarray
    step: np.ndarray  # int64 (rows,): the step stored in each row
    dofs: np.ndarray  # int64: the kernel DOF of each x, v, a column (methods/save.py kernel_dofs)
    rows: np.ndarray  # int64: the contact row of each q, f column
    dirs: np.ndarray  # int64: the direction of each w, state column
    plan: np.ndarray  # int64 (6,): S_CAPACITY steps, S_EVERY k; kept by _store: S_ROWS, S_LAST, S_GRID, S_NEXT
    times: np.ndarray  # (3 + G,): S_FROM window start [s], S_FAIL time of a failed step [s], G given times, +inf


# Outputs.plan and Outputs.times (the save plan of methods/save.py). S_ROWS rows kept, S_LAST the last
# kept step, S_GRID the next given time, S_NEXT the next multiple of S_EVERY: set by Python before each
# march (methods/simulation.reset_outputs: 0, -1, 0, 0; times[S_FAIL] = nan), then kept by _store.
S_CAPACITY, S_EVERY, S_ROWS, S_LAST, S_GRID, S_NEXT = range(6)
S_FROM, S_FAIL = 0, 1


@njit(cache=True, error_model="numpy", inline="always")
def newmark_coefficients(beta, gamma, dt):
    """(a0, a1, a2, a3, b1, b2) of the Newmark relations in the module docstring:
    a_{n+1} = a0 dx - a2 v_n - a3 a_n,  v_{n+1} = a1 dx + b1 v_n + b2 a_n."""
    return (1.0 / (beta * dt * dt), gamma / (beta * dt), 1.0 / (beta * dt), 1.0 / (2.0 * beta) - 1.0,
            1.0 - gamma / beta, dt * (1.0 - gamma / (2.0 * beta)))


@njit(cache=True, error_model="numpy", inline="always")
def _newton_residual(A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, Lin, kfac, r0, qbase, w, dx, q1, f1, w1, state1,
                     gf1, r, counters):
    """The contact law at q = q_base + A dx and the residual r = r0 - Lin dx - kfac A^T f."""
    n = dx.shape[0]
    for rr in range(A.shape[0]):
        s = qbase[rr]
        for j in range(n):
            s += A[rr, j] * dx[j]
        q1[rr] = s
    law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
    counters[C_LAW_CALLS] += 1
    scatter(AT, f1, gf1)
    for i in range(n):
        s = r0[i] - kfac * gf1[i]
        for j in range(n):
            s -= Lin[i, j] * dx[j]
        r[i] = s


# convergence parameters of the Newton iterations (the array ``conv``, filled per step by march):
#   conv[CV_TOL]    tol, the relative tolerance (RunOptions.tolerance)
#   conv[CV_TOL_Q]  tol * L, the absolute tolerance on the contact coordinates [m]
#   conv[CV_FLOOR]  tol * L * max diag J(stick): the residual floor [N] (a step at rest)
#   conv[CV_X + j]  tol * L / max_r |A_rj| (tol * L for a DOF no contact sees): the tolerance on DOF j
CV_TOL, CV_TOL_Q, CV_FLOOR, CV_X = 0, 1, 2, 3
#: the residual test never asks for less than this relative residual (round-off of r)
RESIDUAL_RTOL_MIN = 1e-13
#: an increment below this fraction of its scale is round-off (its contraction ratio is meaningless)
ROUNDOFF = 1e-14


@njit(cache=True, error_model="numpy", inline="always")
def _newton_update(A, dx, delta, it, prev_norm, prev_theta, conv):
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
    for rr in range(nq):
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
def _residual_converged(r, r0, gf1, kfac, conv):
    """The force-residual test at the current iterate (r = r0 - Lin dx - kfac A^T f):
        max_i |r_i| <= max(tol, RESIDUAL_RTOL_MIN) * max(F, floor)
    with F the step's force scale, the largest term of the balance over the DOFs,
    F = max_i max(|r0_i|, kfac |(A^T f)_i|, |(Lin dx)_i|), (Lin dx = r0 - kfac A^T f - r),
    and floor = tol L max diag J(stick) (conv)."""
    rmax = 0.0
    scale = conv[CV_FLOOR] / conv[CV_TOL]
    for i in range(r.shape[0]):
        c = kfac * gf1[i]
        rmax = max(rmax, abs(r[i]))
        scale = max(scale, abs(r0[i]), abs(c), abs(r0[i] - c - r[i]))
    return rmax <= max(conv[CV_TOL], RESIDUAL_RTOL_MIN) * scale


@njit(cache=True, nogil=True, error_model="numpy")
def _modified_newton(lu0, piv0, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w,
                     dx, delta, r, q1, f1, w1, state1, gf1, max_iter, conv, counters):
    """Method 1's iteration on r(dx) = r0 - Lin dx - kfac A^T f(q_base + A dx) = 0 with the
    factorised full-stick Jacobian (lu0, piv0). Converged when BOTH the increment test of
    :func:`_newton_update` (on the contact coordinates and the DOFs) and the force-residual
    test of :func:`_residual_converged` at the new iterate hold. Returns (status, solves);
    on success q1, f1, w1, state1, gf1 hold the converged step."""
    for i in range(dx.shape[0]):
        dx[i] = 0.0
    prev_norm = 0.0
    theta = 0.0
    inc_ok = False
    for it in range(max_iter + 1):
        _newton_residual(A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, Lin, kfac, r0, qbase, w, dx, q1, f1, w1,
                         state1, gf1, r, counters)
        if inc_ok and _residual_converged(r, r0, gf1, kfac, conv):
            return OK, it
        if it == max_iter:
            break
        lu_solve(lu0, piv0, r, delta)
        status, inc_ok, prev_norm, theta = _newton_update(A, dx, delta, it, prev_norm, theta, conv)
        if status != OK:
            return status, it + 1
    return NOT_CONVERGED, max_iter


@njit(cache=True, nogil=True, error_model="numpy")
def _full_newton(lowrank, Lin, J, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w,
                 dx, delta, r, q1, f1, w1, state1, gf1, stick, dt_state, key,
                 keys, used, ok_flags, lus, pivs, lr, nominal, max_iter, conv, singular_rtol, counters):
    """Newton with the Jacobian J(S) of the current iterate's state (factorised per state,
    cached); the full-stick one where J(S) is singular. The same two-part convergence test
    as :func:`_modified_newton` (increment and force residual, both)."""
    for i in range(dx.shape[0]):
        dx[i] = 0.0
    stick_slot, ok = factorise_state(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, stick, qbase, w, dt_state,
                                     stick, key, keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters)
    if not ok:
        return SINGULAR, 0
    prev_norm = 0.0
    theta = 0.0
    inc_ok = False
    for it in range(max_iter + 1):
        _newton_residual(A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, Lin, kfac, r0, qbase, w, dx, q1, f1, w1,
                         state1, gf1, r, counters)
        if inc_ok and _residual_converged(r, r0, gf1, kfac, conv):
            return OK, it
        if it == max_iter:
            break
        use, use_state = stick_slot, stick
        slot, ok = factorise_state(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, dt_state,
                                   stick, key, keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters)
        if ok:
            use, use_state = slot, state1
        if lowrank:
            solve_low_rank(use, lus, pivs, lr, A, nrow, lcode, lpar, fdir, ndir, trow, kt, use_state, q1, w, kfac, r, delta)
        else:
            lu_solve(lus[use], pivs[use], r, delta)
        status, inc_ok, prev_norm, theta = _newton_update(A, dx, delta, it, prev_norm, theta, conv)
        if status != OK:
            return status, it + 1
    return NOT_CONVERGED, max_iter


@njit(cache=True, nogil=True, error_model="numpy")
def _stick_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, stick, dt_state, key,
                         keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters):
    """(ok, lu, piv): the factorisation of J(all stick) for the current step size, held by its
    state slot (direct) or by the low-rank base (where C(stick) = I). Method 1 iterates with it
    in :func:`_modified_newton`, which takes only these two arrays so that its hot loop never
    carries the low-rank arrays (the reason it is separate from :func:`_full_newton`)."""
    nowhere = np.empty(0)  # J(stick) needs no linearisation point
    slot, ok = factorise_state(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, stick, nowhere, nowhere, dt_state, stick,
                               key, keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters)
    if lowrank:
        b = lr.slot_base[slot]
        return ok, lr.base_lu[b], lr.base_piv[b]
    return ok, lus[slot], pivs[slot]


@njit(cache=True, nogil=True, error_model="numpy")
def _guarded_newton(lu, piv, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w, dx, delta, r, q1, f1, w1, state1,
                    gf1, max_iter, conv, theta_give_up, from_zero, counters):
    """:func:`_modified_newton` (the same convergence tests) with the factorised J(S) of a
    state S (solver 3), given up as soon as it stops contracting (the contraction ratio of
    the increment >= theta_give_up): J(S) softer than the tangent of the state the step
    reaches (a slip state entering stick) can make the iteration diverge, where the stiffest
    tangent, J(all stick), cannot; that one then goes on from the dx reached (from_zero False,
    theta_give_up inf). Returns (status, solves); NOT_CONVERGED when given up."""
    if from_zero:
        for i in range(dx.shape[0]):
            dx[i] = 0.0
    prev_norm = 0.0
    theta = 0.0
    inc_ok = False
    for it in range(max_iter + 1):
        _newton_residual(A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, Lin, kfac, r0, qbase, w, dx, q1, f1, w1, state1, gf1, r, counters)
        if inc_ok and _residual_converged(r, r0, gf1, kfac, conv):
            return OK, it
        if it == max_iter:
            break
        lu_solve(lu, piv, r, delta)
        status, inc_ok, prev_norm, theta = _newton_update(A, dx, delta, it, prev_norm, theta, conv)
        if status != OK:
            return status, it + 1
        if it > 0 and theta >= theta_give_up:
            return NOT_CONVERGED, it + 1
    return NOT_CONVERGED, max_iter


@njit(cache=True, nogil=True, error_model="numpy")
def _state_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, tstate, stick, dt_state, key,
                         keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters):
    """(ok, lu, piv): the factorisation of J(S) for the modified Newton of solver 3, S the
    contact state whose T_min set the step (cached per state like the stick one). Falls back
    to J(all stick) where S has no constant tangent (coupled slip), in low-rank mode (whose
    J(S) solve is not one LU) and where J(S) is singular."""
    if not lowrank and not coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, tstate):
        nowhere = np.empty(0)
        slot, ok = factorise_state(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, tstate, nowhere, nowhere, dt_state,
                                   stick, key, keys, used, ok_flags, lus, pivs, lr, nominal, singular_rtol, counters)
        if ok:
            return ok, lus[slot], pivs[slot]
    return _stick_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, stick, dt_state, key, keys, used, ok_flags,
                                lus, pivs, lr, nominal, singular_rtol, counters)


@njit(cache=True, nogil=True, error_model="numpy")
def _local_error(M, A, dx, v, a, a0, a2, a3, dt, beta, err_tol):
    """Accuracy control: the local displacement error of a Newmark step (Zienkiewicz & Xie
    1991), e_j = dt^2 |beta - 1/6| (a_{n+1} - a_n)_j, a_{n+1} = a0 dx - a2 v_n - a3 a_n; for a
    massless DOF (M_jj = 0, methods/massless.py: a quasi-static path) the error of its linear
    interpolation in time, e_j = |dx_j - v_j dt| / 8 (dt^2/8 of its second derivative).
    Measured on the contact coordinates (A e; on the DOFs without contacts) against
    err_tol = rtol L. Returns max |e| / err_tol (> 1: reject the step). The step that
    follows is dt (0.9 / err)^(1/3), within [0.2, ACC_GROWTH] dt (the local error is O(dt^3))."""
    n = dx.shape[0]
    c = dt * dt * max(abs(beta - 1.0 / 6.0), 1.0 / 12.0)
    e = np.empty(n)
    for j in range(n):
        if M[j, j] != 0.0:
            e[j] = c * (a0 * dx[j] - a2 * v[j] - a3 * a[j] - a[j])
        else:
            e[j] = (dx[j] - v[j] * dt) / 8.0
    err = 0.0
    if A.shape[0] == 0:
        for j in range(n):
            err = max(err, abs(e[j]))
    else:
        for rr in range(A.shape[0]):
            s = 0.0
            for j in range(n):
                s += A[rr, j] * e[j]
            err = max(err, abs(s))
    return err / err_tol


@njit(cache=True, nogil=True, error_model="numpy")
def _stick_diagonal(A, nrow, kn, fdir, ndir, trow, kt):
    """diag K_D(all stick) = sum_c k_n A_v^2 + sum_d k_t A_u^2 per DOF (the residual floor's scale)."""
    n = A.shape[1]
    out = np.zeros(n)
    for c in range(kn.shape[0]):
        for i in range(n):
            out[i] += kn[c] * A[nrow[c], i] ** 2
        for d in range(fdir[c], fdir[c] + ndir[c]):
            for i in range(n):
                out[i] += kt[d] * A[trow[d], i] ** 2
    return out


@njit(cache=True, error_model="numpy", inline="always")
def _sub_matvec(Mat, y, out):
    """out -= Mat y."""
    for i in range(out.shape[0]):
        s = 0.0
        for j in range(y.shape[0]):
            s += Mat[i, j] * y[j]
        out[i] -= s


@njit(cache=True, error_model="numpy", inline="always")
def _accept_contacts(w, state, w1, state1):
    """Take the step's sliders and states; True if any state changed."""
    changed = False
    for d in range(w.shape[0]):
        w[d] = w1[d]
        if state[d] != state1[d]:
            changed = True
        state[d] = state1[d]
    return changed


@njit(cache=True, error_model="numpy", inline="always")
def _same(s1, s2):
    for d in range(s1.shape[0]):
        if s1[d] != s2[d]:
            return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state, tkeys, tused, tvalue,
                      step_factor, dt_max):
    """dt limit of a state: step_factor * T_min(S), capped at dt_max; T_min cached per state,
    T_min = 2 pi / sqrt(max |eig(M^-1 (K + K_D(S)))|) (paper Eq. 8), the largest |eigenvalue| alone
    to EIG_RTOL (kernels/eigen.py; mass_factor: L with M = L L^T)."""
    slot, found = find_slot(tkeys, tused, state)
    if not found:
        Keff = Kst.copy()
        contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, state, np.empty(0), np.empty(0), 1.0, Keff)
        wmax2 = largest_eigenvalue_modulus(Keff, mass_factor, EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
        tvalue[slot] = 2.0 * np.pi / np.sqrt(wmax2) if wmax2 > 0.0 else np.inf
    return min(step_factor * tvalue[slot], dt_max)


@njit(cache=True, nogil=True, error_model="numpy")
def march(sys, fpar, ipar, ws, out, q0, f0):
    """March from t_start to t_end, writing step k into out[k] (k = 0: the initial state,
    whose local q0 and f0 are given). Returns the status; out.counters[C_STEPS] steps done.

    Preload mode (ipar[PRELOAD] = N > 0): N quasi-static increments at t = 0 with the
    constant loads scaled by k/N and p = 0 (set INERTIA = 0 and SIGNALS = 0)."""
    # ---- unpack once: the loop below only touches local arrays ----
    M = sys.M
    Cd = sys.C
    Kst = sys.K
    A = sys.A
    AT = sys.AT
    B = sys.B
    g = sys.g
    nrow = sys.normal_row
    kn = sys.kn
    lcode = sys.law
    lpar = sys.law_par
    fdir = sys.first_direction
    ndir = sys.n_directions
    trow = sys.tangential_row
    kt = sys.kt
    f_const = sys.constant_force
    length_scale = sys.length_scale
    x, v, a, fe, gf, w, state = ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w, ws.state
    fe1, gf1, f1, q1, w1, state1 = ws.fe1, ws.gf1, ws.f1, ws.q1, ws.w1, ws.state1
    dx, delta, r0, r, p, qbase = ws.dx, ws.delta, ws.r0, ws.r, ws.p, ws.qbase
    Lin, J, mass_factor, key, dt_state, stick = ws.Lin, ws.J, ws.mass_factor, ws.key, ws.dt_state, ws.stick
    keys, used, ok_flags, lus, pivs = ws.cache_keys, ws.cache_used, ws.cache_ok, ws.cache_lu, ws.cache_piv
    tkeys, tused, tvalue, visited = ws.tmin_keys, ws.tmin_used, ws.tmin_value, ws.visited
    lr = ws.lr
    lowrank = ipar[LOWRANK] == 1
    counters = out.counters
    n = x.shape[0]
    nq = A.shape[0]
    nd = state.shape[0]
    beta, gamma, am, af = fpar[BETA], fpar[GAMMA], fpar[ALPHA_M], fpar[ALPHA_F]
    conv = np.empty(CV_X + n)  # the Newton convergence tolerances (see CV_TOL)
    conv[CV_TOL] = fpar[TOL]
    conv[CV_TOL_Q] = fpar[TOL] * length_scale
    kd_stick = _stick_diagonal(A, nrow, kn, fdir, ndir, trow, kt)
    for i in range(n):  # DOF j's length: L over its largest gather entry (a rotation: L / lever arm)
        amax = 0.0
        for rr in range(nq):
            amax = max(amax, abs(A[rr, i]))
        conv[CV_X + i] = fpar[TOL] * (length_scale / amax if amax > 0.0 else length_scale)
    state_rtol = fpar[STATE_RTOL]
    singular_rtol = fpar[SINGULAR_RTOL]
    solver = ipar[SOLVER]
    adaptive = ipar[ADAPTIVE] == 1 and ipar[PRELOAD] == 0
    inertia = ipar[INERTIA] == 1
    signals = ipar[SIGNALS] == 1
    n_preload = ipar[PRELOAD]
    max_iter, max_state_iter, max_redo, fallback = ipar[MAX_ITER], ipar[MAX_STATE_ITER], ipar[MAX_REDO], ipar[FALLBACK]
    kfac = (1.0 - af) if inertia else 1.0
    has_damping = np.any(Cd != 0.0)
    has_circle = np.any(lcode == LAW_CIRCLE)
    has_stiffness = np.any(Kst != 0.0)
    acc_pred = np.empty(n)
    vel_pred = np.empty(n)
    cap = out.plan[S_CAPACITY]
    # ---- initial point ----
    t = fpar[T_START]
    t_end = fpar[T_END]
    o_q, o_f, o_rows = out.q, out.f, out.rows
    row = _store(x, v, a, w, state, out, 0, t, 0.0, 0)
    for ii in range(o_rows.shape[0]):
        o_q[row, ii] = q0[o_rows[ii]]
        o_f[row, ii] = f0[o_rows[ii]]
    for d in range(nd):
        dt_state[d] = 0
    tiny = 1e-12 * (t_end - t + 1e-300)
    status = OK
    k = 0
    last_slot = -1  # cache slot of the last piecewise-linear factorisation (fast path)
    stick_dt = np.nan  # step size of the current full-stick factorisation (lu0, piv0), Method 1
    tan_dt = np.nan  # step size and state of the current J(S) factorisation (luS, pivS), solver 3
    tan_state = np.full(nd, -1, np.int8)
    okS = False
    luS = lus[0]
    pivS = pivs[0]
    ok0 = False
    lu0 = lus[0]
    piv0 = pivs[0]
    dt_state_limit = 0.0  # step limit of dt_state (adaptive)
    a0 = c1 = a2 = a3 = b1 = b2 = 0.0  # Newmark coefficients of the current dt
    ws.lin_dt[0] = np.nan
    accuracy = fpar[RTOL] > 0.0 and n_preload == 0 and inertia
    err_tol = fpar[RTOL] * fpar[ERR_SCALE]
    dt_acc = fpar[DT]  # the accuracy step, adapted after every step (accuracy control)
    dt_next = dt_acc
    while (n_preload > 0 and k < n_preload) or (n_preload == 0 and t < t_end - tiny):
        if counters[C_STOP] != 0:  # stop request from another thread (Ctrl-C): keep the k steps done
            status = INTERRUPTED
            counters[C_FAIL_STEP] = k
            break
        if k >= cap or out.plan[S_ROWS] + 2 > out.t.shape[0]:  # out of steps or of output rows
            status = CAPACITY
            break
        # ---- step size (fixed, or by contact state) ----
        if n_preload > 0:
            dt_nominal = 1.0
        elif adaptive:
            if k == 0 or not _same(state, dt_state):
                for d in range(nd):
                    dt_state[d] = state[d]
                dt_state_limit = _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state,
                                                   tkeys, tused, tvalue, fpar[STEP_FACTOR], fpar[DT_MAX])
            dt_nominal = dt_state_limit
        else:
            dt_nominal = fpar[DT]
        if accuracy:  # the step of the local error estimate, never beyond the convergence / stability rule
            dt_nominal = min(dt_acc, fpar[DT_MAX]) if solver == PIECEWISE_LINEAR else min(dt_nominal, dt_acc)
        dt = dt_nominal
        if n_preload == 0 and t + dt > t_end - tiny:
            dt = t_end - t
        nominal = abs(dt - dt_nominal) <= 1e-12 * dt_nominal and not accuracy
        load_factor = (k + 1.0) / n_preload if n_preload > 0 else 1.0
        solves = 0
        for attempt in range(max_redo + 1):
            t1 = t + dt if n_preload == 0 else t
            # ---- Newmark coefficients and Lin = (1-am) a0 M + (1-af) a1 C + (1-af) K (per dt) ----
            if ws.lin_dt[0] != dt:
                a0, c1, a2, a3, b1, b2 = newmark_coefficients(beta, gamma, dt)
                last_slot = -1
                for i in range(n):
                    for j in range(n):
                        if inertia:
                            Lin[i, j] = (1.0 - am) * a0 * M[i, j] + (1.0 - af) * c1 * Cd[i, j] + (1.0 - af) * Kst[i, j]
                        else:
                            Lin[i, j] = Kst[i, j]
                ws.lin_dt[0] = dt
                kdiag = 0.0
                for i in range(n):
                    kdiag = max(kdiag, Lin[i, i] + kfac * kd_stick[i])
                conv[CV_FLOOR] = fpar[TOL] * length_scale * kdiag
            # ---- loads, motion, q_base, r0 (the dx-independent part of the residual) ----
            if signals:
                evaluate_signal(t1, sys.force_frequency, sys.force_sin, sys.force_cos, sys.force_table_time,
                                sys.force_table_value, sys.force_ramp, fe1)
                evaluate_signal(t1, sys.motion_frequency, sys.motion_sin, sys.motion_cos, sys.motion_table_time,
                                sys.motion_table_value, sys.motion_ramp, p)
            else:
                for i in range(n):
                    fe1[i] = 0.0
                for i in range(p.shape[0]):
                    p[i] = 0.0
            for i in range(n):
                fe1[i] += load_factor * f_const[i]
            gather(A, B, g, x, p, qbase)
            for i in range(n):
                r0[i] = (1.0 - af) * fe1[i] + af * (fe[i] - gf[i]) if inertia else fe1[i]
            if inertia:
                # predictor parts of a_{n+1-am} and v_{n+1-af} (the dx terms are in Lin)
                for j in range(n):
                    acc_pred[j] = (1.0 - am) * (-a2 * v[j] - a3 * a[j]) + am * a[j]
                    vel_pred[j] = (1.0 - af) * (b1 * v[j] + b2 * a[j]) + af * v[j]
                _sub_matvec(M, acc_pred, r0)
                if has_damping:
                    _sub_matvec(Cd, vel_pred, r0)
            if has_stiffness:
                _sub_matvec(Kst, x, r0)
            # ---- the step solver ----
            status = STATE_CYCLING
            if solver == PIECEWISE_LINEAR:
                if attempt == 0:  # postulate S_{n+1} = S_n; a redone step keeps the state it found
                    for d in range(nd):
                        state1[d] = state[d]
                counters[C_N_VISITED] = 0
                for it in range(max_state_iter):
                    for d in range(nd):
                        visited[it, d] = state1[d]
                    counters[C_N_VISITED] = it + 1
                    if has_circle and coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, state1):  # no linear form: Newton on the consistent tangent
                        status, more = _full_newton(lowrank, Lin, J, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w, dx,
                                                    delta, r, q1, f1, w1, state1, gf1, stick, dt_state, key, keys,
                                                    used, ok_flags, lus, pivs, lr, nominal, max_iter, conv,
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
                        slot, ok = last_slot, ok_flags[last_slot]
                    else:
                        slot, ok = factorise_state(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt,
                                                   state1, qbase, w, dt_state, stick, key, keys, used, ok_flags, lus, pivs,
                                                   lr, nominal, singular_rtol, counters)
                        last_slot = slot if nominal else -1
                    if not ok:
                        status = SINGULAR
                        break
                    piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, qbase, w, f1, w1)
                    scatter(AT, f1, gf1)
                    for i in range(n):
                        r[i] = r0[i] - kfac * gf1[i]
                    if lowrank:
                        solve_low_rank(slot, lus, pivs, lr, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, kfac,
                                       r, dx)
                    else:
                        lu_solve(lus[slot], pivs[slot], r, dx)
                    solves += 1
                    finite = True
                    for i in range(n):
                        if not np.isfinite(dx[i]):
                            finite = False
                    if not finite:
                        status = NON_FINITE
                        break
                    for rr in range(nq):
                        s = qbase[rr]
                        for j in range(n):
                            s += A[rr, j] * dx[j]
                        q1[rr] = s
                    if compatible(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, state_rtol, length_scale):
                        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, f1, w1)
                        scatter(AT, f1, gf1)
                        status = OK
                        break
                    law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
                    counters[C_LAW_CALLS] += 1
                if status != OK and status != NON_FINITE and fallback == 1:
                    counters[C_FALLBACKS] += 1
                    pl_status = status
                    ok0, lu0, piv0 = _stick_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt,
                                                          stick, dt_state, key, keys, used, ok_flags, lus, pivs, lr,
                                                          nominal, singular_rtol, counters)
                    more = 0
                    if ok0:
                        status, more = _modified_newton(lu0, piv0, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow,
                                                        kt, r0, qbase, w, dx, delta, r, q1, f1, w1, state1, gf1,
                                                        max_iter, conv, counters)
                    solves += more
                    if status != OK:
                        status = pl_status  # the more telling reason: singular state or cycling
            else:
                if solver == FULL_NEWTON:
                    status, more = _full_newton(lowrank, Lin, J, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0,
                                                qbase, w, dx, delta, r, q1, f1, w1, state1, gf1, stick, dt_state, key,
                                                keys, used, ok_flags, lus, pivs, lr, nominal, max_iter, conv,
                                                singular_rtol, counters)
                elif solver == MODIFIED_NEWTON_STATE:  # the tangent of the state that set the step
                    tstate = dt_state if adaptive else state
                    if not (nominal and dt == tan_dt and _same(tstate, tan_state)):
                        okS, luS, pivS = _state_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, tstate, stick,
                                                              dt_state, key, keys, used, ok_flags, lus, pivs, lr,
                                                              nominal, singular_rtol, counters)
                        tan_dt = dt if nominal else np.nan
                        for d in range(nd):
                            tan_state[d] = tstate[d]
                    stick_dt = np.nan
                    status, more = SINGULAR, 0
                    if okS:
                        status, more = _guarded_newton(luS, pivS, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w, dx,
                                                       delta, r, q1, f1, w1, state1, gf1, max_iter, conv,
                                                       THETA_GIVE_UP, True, counters)
                    if status != OK:  # J(S) too soft for the state the step reached: the stick tangent
                        counters[C_FALLBACKS] += 1
                        restart = status != NOT_CONVERGED  # else go on from the dx reached
                        solves += more
                        ok0, lu0, piv0 = _stick_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow, kt, stick, dt_state,
                                                              key, keys, used, ok_flags, lus, pivs, lr, nominal,
                                                              singular_rtol, counters)
                        status, more = SINGULAR, 0
                        if ok0:
                            status, more = _guarded_newton(lu0, piv0, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, r0, qbase, w, dx,
                                                           delta, r, q1, f1, w1, state1, gf1, max_iter, conv,
                                                           np.inf, restart, counters)
                else:
                    if dt != stick_dt or not nominal:  # the stick factorisation of this step size
                        ok0, lu0, piv0 = _stick_factorisation(lowrank, Lin, J, kfac, A, nrow, lcode, lpar, fdir, ndir, trow,
                                                              kt, stick, dt_state, key, keys, used, ok_flags, lus,
                                                              pivs, lr, nominal, singular_rtol, counters)
                        stick_dt = dt if nominal else np.nan
                    if ok0:
                        status, more = _modified_newton(lu0, piv0, Lin, kfac, A, AT, nrow, lcode, lpar, fdir, ndir, trow,
                                                        kt, r0, qbase, w, dx, delta, r, q1, f1, w1, state1, gf1,
                                                        max_iter, conv, counters)
                    else:
                        status, more = SINGULAR, 0
                solves += more
            if accuracy and status == OK:
                err = _local_error(M, A, dx, v, a, a0, a2, a3, dt, beta, err_tol)
                if err > 1.0 and attempt < max_redo:  # reject: redo with the step the estimate asks for
                    counters[C_REDOS] += 1
                    dt = dt * max(0.2, 0.9 * err ** (-1.0 / 3.0))
                    continue
                dt_next = dt * min(ACC_GROWTH, max(0.2, 0.9 * err ** (-1.0 / 3.0))) if err > 0.0 else ACC_GROWTH * dt
            if status != OK or not adaptive or attempt == max_redo:
                break
            # ---- redo rule (paper 4.2): the new state needs a smaller step ----
            if _same(state1, dt_state):
                break
            limit = _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state1,
                                      tkeys, tused, tvalue, fpar[STEP_FACTOR], fpar[DT_MAX])
            if limit >= dt * (1.0 - 1e-9):
                break
            counters[C_REDOS] += 1
            for d in range(nd):
                dt_state[d] = state1[d]
            dt_state_limit = limit
            dt = limit
            nominal = True
        counters[C_SOLVES] += solves
        if accuracy and status == OK:
            dt_acc = dt_next
        if status != OK:
            counters[C_FAIL_STEP] = k + 1
            out.times[S_FAIL] = t + dt if n_preload == 0 else t
            break
        # ---- accept: x_{n+1} = x_n + dx and the Newmark relations ----
        for i in range(n):
            if inertia and M[i, i] != 0.0:
                a_new = a0 * dx[i] - a2 * v[i] - a3 * a[i]
                v[i] = c1 * dx[i] + b1 * v[i] + b2 * a[i]
                a[i] = a_new
            elif inertia:  # a massless DOF in a dynamic march (methods/massless.py): v = dx/dt, a = 0
                v[i] = dx[i] / dt
                a[i] = 0.0
            x[i] += dx[i]
            fe[i] = fe1[i]
            gf[i] = gf1[i]
        if _accept_contacts(w, state, w1, state1):
            counters[C_STATE_CHANGES] += 1
        if n_preload == 0:
            t += dt
        k += 1
        row = _store(x, v, a, w, state, out, k, t, dt, solves)
        counters[C_PROGRESS] = k
        for ii in range(o_rows.shape[0]):
            o_q[row, ii] = q1[o_rows[ii]]
            o_f[row, ii] = f1[o_rows[ii]]
    counters[C_STEPS] = k
    return status


@njit(cache=True, error_model="numpy", inline="always")
def _store(x, v, a, w, state, out, k, t, dt, solves):
    """Write the carried state of step k (time t) into the pending row out.plan[S_ROWS] (the
    saved DOFs and directions) and keep it, or leave it pending (overwritten by the next step),
    by the save plan (methods/save.py): every S_EVERY-th step from the window start
    times[S_FROM] (the pending step before the window is kept with its first step), or, with
    given times, the two step ends around each given time (one given time passed per step: a
    step holding several keeps the following pairs too, at most two rows per given time).
    Returns the row written."""
    # branch-free (a branch here costs 0.2 us per step: numba then keeps the loop's array refcounts)
    plan, times = out.plan, out.times
    given = np.int64(times.shape[0] > 3)  # given times (the last entry is an +inf sentinel)
    g = plan[S_GRID]
    cross = np.int64(times[2 + g] <= t)  # step k reached given time g: keep it and step k - 1
    plan[S_GRID] = g + cross
    inside = np.int64(t >= times[S_FROM])
    hit = np.int64(k == plan[S_NEXT])  # a multiple of S_EVERY
    plan[S_NEXT] += hit * plan[S_EVERY]
    first = inside * np.int64(plan[S_LAST] < 0)  # the first step of the window (nothing kept yet)
    keep = given * cross + (1 - given) * inside * (hit | first)
    prev = np.int64(k > 0) * np.int64(plan[S_LAST] != k - 1) * (given * cross + (1 - given) * first)
    j = plan[S_ROWS] + prev  # the pending row holds step k - 1: kept with step k when prev
    plan[S_LAST] = keep * k + (1 - keep) * plan[S_LAST]
    plan[S_ROWS] = j + keep
    out.step[j] = k
    out.t[j] = t
    out.dt[j] = dt
    out.solves[j] = solves
    o_x, o_v, o_a, dofs = out.x, out.v, out.a, out.dofs
    for ii in range(dofs.shape[0]):
        i = dofs[ii]
        o_x[j, ii] = x[i]
        o_v[j, ii] = v[i]
        o_a[j, ii] = a[i]
    o_w, o_state, dirs = out.w, out.state, out.dirs
    for ii in range(dirs.shape[0]):
        d = dirs[ii]
        o_w[j, ii] = w[d]
        o_state[j, ii] = state[d]
    return j
