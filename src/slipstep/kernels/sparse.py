"""The condensed sparse backend (issue 26): the implicit march of the piecewise-linear
methods on a sparse structure, the contact problem solved in contact space.

Per step size the Python side (methods/sparse.py) factorises the structure's step matrix
with the full-stick contact stiffness,

    Lin0 = Lin + kfac A^T K(stick) A,      Lin = c_m M + c_c C + c_k K  (dynamic), K (quasi-static)

by a sparse LU (scipy's SuperLU) in an order that eliminates the DOFs the contacts see (the
set B, nb of them) last: P^T Lin0 P = L U with P the order ``perm``, L unit lower and U upper
triangular (CSC). Then, with F = L_BB^-1 A_B^T (nb x nq) and G0 = A Lin0^-1 A^T = A_B U_BB^-1 F
(nq x nq), the step's linear system in the contact state S,

    J(S) dx = r0 - kfac A^T b_S,      J(S) = Lin0 + kfac A^T dK(S) A,   dK(S) = K(S) - K(stick)

(b_S = K(S) q_base + s(S, w_n), the law of the postulate at q_base), is condensed on the
contact coordinates. The total force h = b_S + dK(S) A dx gives

    Lin0 dx = r0 - kfac A^T h,                 A dx = u0 - kfac G0 h,   u0 = A Lin0^-1 r0,
    (I + kfac dK_R G0[:, R]) h_R = b_R + dK_R t,   h_j = b_j (j not in R),   t = u0 - kfac G0 h|_(not R)

where R is the rows of dK(S) that are not zero (the slipping and lifted directions, the
normals of lifted contacts): an m x m system, m the rows that left stick, factorised once per
state (dense LU, cached per state). u0 needs the forward solve of r0 and the backward solve of
the trailing (B) block only; the accepted step's DOFs come from the same forward solve with
its B part corrected, w_B -= kfac F h, and one full backward solve: one sparse solve per step.

The march (:func:`sparse_march`) is kernels/march.py's march for the piecewise-linear solver
at a fixed step (and its preload mode), with these solves in place of the dense ones; a step
shorter than the nominal one (the end of a run that is not a whole number of steps) uses the
second factorisation ``ws.last``, prepared by the Python side for that step size.
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.banded import csr_gather, csr_matvec
from slipstep.kernels.borrow import borrowed
from slipstep.kernels.cache import find_slot
from slipstep.kernels.codes import (
    C_FACTORISATIONS, C_FAIL_STEP, C_FALLBACKS, C_LAW_CALLS, C_N_VISITED, C_PROGRESS, C_SOLVES, C_STATE_CHANGES, C_STEPS, C_STOP,
    CAPACITY, INTERRUPTED, NON_FINITE, NOT_CONVERGED, OK, P_KN, SINGULAR, STATE_CYCLING,
)
from slipstep.kernels.contact import compatible_law, law, piecewise_law
from slipstep.kernels import laws
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.march import (
    S_CAPACITY, S_FAIL, S_ROWS, _accept, _accept_contacts, _loads_and_motions, _store, newmark_coefficients,
)
from slipstep.kernels.settings import contact_table
from slipstep.kernels.step_solvers import ROUNDOFF
from slipstep.kernels.lean_compiler import LeanCompiler


class SparseFactor(NamedTuple):
    """The factorisation of Lin0 for one step size (module docstring); arrays only."""

    key: np.ndarray  # (3,): dt [s], inertia (1.0 / 0.0), kfac of the factorisation
    perm: np.ndarray  # int64 (n): position i of the factorisation holds DOF perm[i]
    L_ptr: np.ndarray  # int64 (n + 1) CSC of L, sorted: the unit diagonal first in each column
    L_idx: np.ndarray  # int32
    L_val: np.ndarray
    U_ptr: np.ndarray  # int64 (n + 1) CSC of U, sorted: the diagonal last in each column
    U_idx: np.ndarray  # int32
    U_val: np.ndarray
    U_diag: np.ndarray  # (n) the diagonal of U
    UBB: np.ndarray  # (nb, nb) the trailing block of U (dense, upper)
    F: np.ndarray  # (nb, nq) L_BB^-1 A_B^T
    G0: np.ndarray  # (nq, nq) A Lin0^-1 A^T
    AB: np.ndarray  # (nq, nb) A on the trailing block


class SparseWorkspace(NamedTuple):
    """The carried state, scratch and caches of :func:`sparse_march` (methods/sparse.py
    allocates it). The state cache holds, per contact state S of the current factorisation
    (``owner``: its key), the rows R of dK(S) that are not zero (``rows``, ``m``), their
    entries (dK_rr on the row itself, dK_rc at column ``kcol``, -1 for none) and the LU of
    I + kfac dK_R G0[:, R]; slot cap is scratch (a step of the ``last`` factorisation)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    fe: np.ndarray
    gf: np.ndarray
    w: np.ndarray
    state: np.ndarray  # int8
    fe1: np.ndarray
    gf1: np.ndarray
    f1: np.ndarray
    q1: np.ndarray
    w1: np.ndarray
    state1: np.ndarray
    dx: np.ndarray
    r0: np.ndarray
    p: np.ndarray
    qbase: np.ndarray
    fwd: np.ndarray  # (n) the forward solve L^-1 r0 (factorisation order)
    zb: np.ndarray  # (nb) scratch of the trailing block
    u0: np.ndarray  # (nq) A Lin0^-1 r0
    h: np.ndarray  # (nq) the condensed force h
    t: np.ndarray  # (nq) scratch
    rhs: np.ndarray  # (nq) scratch
    sol: np.ndarray  # (nq) scratch
    mdiag: np.ndarray  # (n) diag M
    M_ptr: np.ndarray  # CSR of M, C, K (int64 pointers, int32 indices)
    M_idx: np.ndarray
    M_val: np.ndarray
    C_ptr: np.ndarray
    C_idx: np.ndarray
    C_val: np.ndarray
    K_ptr: np.ndarray
    K_idx: np.ndarray
    K_val: np.ndarray
    main: SparseFactor  # the factorisation of the nominal step
    last: SparseFactor  # the factorisation of a shorter last step (main itself when there is none)
    owner: np.ndarray  # (3,) the key of the factorisation the state cache belongs to
    keys: np.ndarray  # int8 (cap, nd)
    used: np.ndarray  # bool (cap)
    ok: np.ndarray  # bool (cap + 1)
    m: np.ndarray  # int64 (cap + 1)
    rows: np.ndarray  # int64 (cap + 1, nq)
    kdiag: np.ndarray  # (cap + 1, nq)
    kcol: np.ndarray  # int64 (cap + 1, nq)
    koff: np.ndarray  # (cap + 1, nq)
    lu: np.ndarray  # (cap + 1, nq, nq)
    piv: np.ndarray  # int64 (cap + 1, nq)
    lin_dt: np.ndarray  # (1,)
    visited: np.ndarray  # int8 (max_state_iter + 1, nd)


# ---- sparse triangular solves (CSC, as SuperLU's own) ---------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def forward_solve(ptr, idx, val, x, start):
    """x <- L^-1 x over the columns start..n-1 (L unit lower triangular in sorted CSC, its
    diagonal the first entry of each column): for each column j, x_i -= L_ij x_j below it."""
    n = x.shape[0]
    for j in range(start, n):
        xj = x[j]
        if xj != 0.0:
            for k in range(ptr[j] + 1, ptr[j + 1]):
                x[idx[k]] -= val[k] * xj


@njit(cache=True, nogil=True, error_model="numpy")
def backward_solve(ptr, idx, val, diag, x):
    """x <- U^-1 x (U upper triangular in sorted CSC, its diagonal ``diag`` the last entry of
    each column)."""
    for j in range(x.shape[0] - 1, -1, -1):
        xj = x[j] / diag[j]
        x[j] = xj
        if xj != 0.0:
            for k in range(ptr[j], ptr[j + 1] - 1):
                x[idx[k]] -= val[k] * xj


@njit(cache=True, nogil=True, error_model="numpy")
def dense_upper_solve(U, x):
    """x <- U^-1 x, U dense upper triangular."""
    nb = x.shape[0]
    for j in range(nb - 1, -1, -1):
        xj = x[j] / U[j, j]
        x[j] = xj
        for i in range(j):
            x[i] -= U[i, j] * xj


@njit(cache=True, nogil=True, error_model="numpy")
def csr_sub(ptr, idx, val, y, out):
    """out -= X y, X in CSR."""
    for r in range(out.shape[0]):
        s = 0.0
        for k in range(ptr[r], ptr[r + 1]):
            s += val[k] * y[idx[k]]
        out[r] -= s


# ---- the contact-space step ------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def free_solution(fac, r0, fwd, zb, u0):
    """fwd = L^-1 P^T r0 (the forward solve, kept for the recovery) and u0 = A Lin0^-1 r0
    (the backward solve on the trailing block alone: A sees only B)."""
    n = r0.shape[0]
    perm = fac.perm
    for i in range(n):
        fwd[i] = r0[perm[i]]
    forward_solve(fac.L_ptr, fac.L_idx, fac.L_val, fwd, 0)
    nb = zb.shape[0]
    off = n - nb
    for i in range(nb):
        zb[i] = fwd[off + i]
    dense_upper_solve(fac.UBB, zb)
    AB = fac.AB
    for r in range(u0.shape[0]):
        s = 0.0
        for i in range(nb):
            s += AB[r, i] * zb[i]
        u0[r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def recover_dofs(fac, kfac, h, fwd, dx):
    """dx = Lin0^-1 (r0 - kfac A^T h): the forward solve of r0 with its B part corrected by
    -kfac F h, then the full backward solve, back in the DOF order."""
    n = dx.shape[0]
    F = fac.F
    nb = F.shape[0]
    off = n - nb
    for i in range(nb):
        s = 0.0
        for r in range(h.shape[0]):
            s += F[i, r] * h[r]
        fwd[off + i] -= kfac * s
    backward_solve(fac.U_ptr, fac.U_idx, fac.U_val, fac.U_diag, fwd)
    perm = fac.perm
    for i in range(n):
        dx[perm[i]] = fwd[i]


@njit(cache=True, nogil=True, error_model="numpy")
def _delta_rows(cl, state, rows, kdiag, kcol, koff):
    """The rows R of dK(S) = K(S) - K(stick) that are not zero, with their entries
    (kernels.laws.delta_rows). Returns m."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    return laws.delta_rows(nrow, lpar, fdir, ndir, trow, kt, state, rows, kdiag, kcol, koff)


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def factorise_state(fac, cl, ws, slot, state, kfac, singular_rtol):
    """Rows R of dK(S) into ``slot`` and the LU of C_R = I + kfac dK_R G0[:, R] (m x m).
    Returns ok (False: C_R, hence J(S), singular)."""
    rows, kdiag, kcol, koff = ws.rows[slot], ws.kdiag[slot], ws.kcol[slot], ws.koff[slot]
    m = _delta_rows(cl, state, rows, kdiag, kcol, koff)
    ws.m[slot] = m
    if m == 0:
        ws.ok[slot] = True
        return True
    G0 = fac.G0
    Cm = ws.lu[slot, :m, :m]
    for i in range(m):
        ri, c2 = rows[i], kcol[i]
        for j in range(m):
            rj = rows[j]
            s = kdiag[i] * G0[ri, rj]
            if c2 >= 0:
                s += koff[i] * G0[c2, rj]
            Cm[i, j] = kfac * s + (1.0 if i == j else 0.0)
    ok = lu_factor(Cm, Cm, ws.piv[slot, :m], singular_rtol)
    ws.ok[slot] = ok
    return ok


@njit(cache=True, nogil=True, error_model="numpy")
def condensed_solve(fac, ws, slot, kfac, b, u0, qbase, h, q1):
    """h (module docstring) of the state in ``slot`` for the law b = b_S at q_base, and
    q1 = q_base + u0 - kfac G0 h (the contact coordinates at the end of the step)."""
    nq = b.shape[0]
    m = ws.m[slot]
    rows, kdiag, kcol, koff = ws.rows[slot], ws.kdiag[slot], ws.kcol[slot], ws.koff[slot]
    G0 = fac.G0
    t, rhs, sol = ws.t, ws.rhs, ws.sol
    for r in range(nq):
        h[r] = b[r]
    for i in range(m):
        h[rows[i]] = 0.0
    for r in range(nq):  # t = u0 - kfac G0 h (h without the rows R)
        s = 0.0
        for j in range(nq):
            s += G0[r, j] * h[j]
        t[r] = u0[r] - kfac * s
    if m > 0:
        for i in range(m):
            s = kdiag[i] * t[rows[i]]
            if kcol[i] >= 0:
                s += koff[i] * t[kcol[i]]
            rhs[i] = b[rows[i]] + s
        lu_solve(ws.lu[slot, :m, :m], ws.piv[slot, :m], rhs[:m], sol[:m])
        for i in range(m):
            h[rows[i]] = sol[i]
        for r in range(nq):  # t -= kfac G0[:, R] h_R
            s = 0.0
            for i in range(m):
                s += G0[r, rows[i]] * sol[i]
            t[r] -= kfac * s
    for r in range(nq):
        q1[r] = qbase[r] + t[r]


@njit(cache=True, nogil=True, error_model="numpy")
def _state_slot(ws, state, scratch):
    """(slot, found) of a contact state in the state cache (scratch: slot cap, never found)."""
    if scratch:
        return ws.used.shape[0], False
    return find_slot(ws.keys, ws.used, state)


@njit(cache=True, nogil=True, error_model="numpy")
def sparse_piecewise_linear_step(sys, cl, ws, fac, scratch, kfac, attempt, max_state_iter, state_rtol,
                                 singular_rtol, fallback, max_iter, tol, counters):
    """Solver 2 (Methods 3, 2+3) in contact space: postulate S = S_n (a redone step keeps the
    state it found), solve the condensed step of S (module docstring), accept if S is
    compatible at q1, else postulate the law's states there; the accepted step keeps the law
    at q1 (kernels/step_solvers.py, as the dense solve). Then dx by one backward solve.
    If the states cycle (max_state_iter postulates) or J(S) is singular, :func:`contact_fallback`
    (fallback: counted). Returns (status, solves)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    state, state1, visited = ws.state, ws.state1, ws.visited
    qbase, w, q1, f1, w1, h = ws.qbase, ws.w, ws.q1, ws.f1, ws.w1, ws.h
    nd = state.shape[0]
    if attempt == 0:
        for d in range(nd):
            state1[d] = state[d]
    free_solution(fac, ws.r0, ws.fwd, ws.zb, ws.u0)
    counters[C_N_VISITED] = 0
    status = STATE_CYCLING
    solves = 0
    for it in range(max_state_iter):
        for d in range(nd):
            visited[it, d] = state1[d]
        counters[C_N_VISITED] = it + 1
        slot, found = _state_slot(ws, state1, scratch)
        if found:
            ok = ws.ok[slot]
        else:
            ok = factorise_state(fac, cl, ws, slot, state1, kfac, singular_rtol)
            counters[C_FACTORISATIONS] += 1
        if not ok:
            status = SINGULAR
            break
        for rr in range(q1.shape[0]):  # the law of the postulate at q_base
            q1[rr] = qbase[rr]
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, f1, w1)
        condensed_solve(fac, ws, slot, kfac, f1, ws.u0, qbase, h, q1)
        solves += 1
        finite = True
        for rr in range(q1.shape[0]):
            if not np.isfinite(q1[rr]):
                finite = False
        if not finite:
            status = NON_FINITE
            break
        if compatible_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state1, q1, w, state_rtol, sys.length_scale, f1,
                          w1):
            law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
            status = OK
            break
        law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
        counters[C_LAW_CALLS] += 1
    if status != OK and status != NON_FINITE and fallback:  # the postulates cycled: modified Newton
        fb_status, more = contact_fallback(sys, cl, ws, fac, kfac, max_iter, tol, counters)
        solves += more
        if fb_status == OK:
            status = OK
    if status == OK:
        recover_dofs(fac, kfac, h, ws.fwd, ws.dx)
        csr_matvec(sys.AT_ptr, sys.AT_idx, sys.AT_val, f1, ws.gf1)
        for i in range(ws.dx.shape[0]):
            if not np.isfinite(ws.dx[i]):
                status = NON_FINITE
                break
    return status, solves


@njit(cache=True, nogil=True, error_model="numpy")
def contact_fallback(sys, cl, ws, fac, kfac, max_iter, tol, counters):
    """The fallback of the piecewise-linear solve when its postulates cycle (as the dense
    step_solvers.stick_fallback): modified Newton with J(all stick) = Lin0 from dx = 0, in
    contact space. With Lin = Lin0 - kfac A^T K(stick) A its iterates are
        dx_(k+1) = Lin0^-1 (r0 - kfac A^T h_k),   h_k = f(q_k) - K(stick) (q_k - q_base),
        q_(k+1) = q_base + u0 - kfac G0 h_k
    (f the nonlinear law), stopped by the increment test of step_solvers.newton_update on the
    contact coordinates (tol L; the DOFs and the force residual are not tested here: the
    condensed iteration has no DOF iterate). Returns (status, solves)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    qbase, w, q1, f1, w1, state1, h, t = ws.qbase, ws.w, ws.q1, ws.f1, ws.w1, ws.state1, ws.h, ws.t
    u0, G0 = ws.u0, fac.G0
    nq = q1.shape[0]
    counters[C_FALLBACKS] += 1
    tol_q = tol * sys.length_scale
    for r in range(nq):
        q1[r] = qbase[r]
    prev_norm = 0.0
    prev_theta = 0.0
    for it in range(max_iter):
        law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
        counters[C_LAW_CALLS] += 1
        for r in range(nq):
            h[r] = f1[r]
        for c in range(nrow.shape[0]):  # h = f - K(stick) (q - q_base)
            nr = nrow[c]
            h[nr] -= lpar[c, P_KN] * (q1[nr] - qbase[nr])
            for d in range(fdir[c], fdir[c] + ndir[c]):
                tr = trow[d]
                h[tr] -= kt[d] * (q1[tr] - qbase[tr])
        eta = 0.0
        for r in range(nq):
            s = 0.0
            for j in range(nq):
                s += G0[r, j] * h[j]
            t[r] = qbase[r] + u0[r] - kfac * s
            eta = max(eta, abs(t[r] - q1[r]) / tol_q)
            if not np.isfinite(t[r]):
                return NON_FINITE, it + 1
        for r in range(nq):
            q1[r] = t[r]
        if it == 0:
            converged = eta <= 1.0
            theta = 0.0
        else:
            theta_k = eta / prev_norm if prev_norm > 0.0 else 0.0
            theta = max(theta_k, prev_theta) if it >= 2 else theta_k
            converged = eta * tol <= ROUNDOFF or (theta < 1.0 and eta * theta / (1.0 - theta) <= 1.0)
            theta = theta_k
        prev_norm, prev_theta = eta, theta
        if converged:
            law(nrow, lcode, lpar, fdir, ndir, trow, kt, q1, w, f1, w1, state1)
            return OK, it + 1
    return NOT_CONVERGED, max_iter


# ---- the march -------------------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def _residual_base(ws, inertia, has_damping, am, af, a2, a3, b1, b2, acc_pred, vel_pred):
    """r0 = (1 - af) f_e(t_{n+1}) + af (f_e(t_n) - A^T f_n) - M acc_pred - C vel_pred - K x_n
    (kernels/march.py _residual_base; quasi-static r0 = f_e(t_{n+1}) - K x_n), M, C, K in CSR."""
    x, v, a, fe, gf, fe1, r0 = ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.fe1, ws.r0
    n = x.shape[0]
    for i in range(n):
        r0[i] = (1.0 - af) * fe1[i] + af * (fe[i] - gf[i]) if inertia else fe1[i]
    if inertia:
        for j in range(n):
            acc_pred[j] = (1.0 - am) * (-a2 * v[j] - a3 * a[j]) + am * a[j]
            vel_pred[j] = (1.0 - af) * (b1 * v[j] + b2 * a[j]) + af * v[j]
        csr_sub(ws.M_ptr, ws.M_idx, ws.M_val, acc_pred, r0)
        if has_damping:
            csr_sub(ws.C_ptr, ws.C_idx, ws.C_val, vel_pred, r0)
    csr_sub(ws.K_ptr, ws.K_idx, ws.K_val, x, r0)


@njit(cache=True, nogil=True, error_model="numpy")
def _gather_state(sys, x, p, q):
    """q = A x - B p + g, A in CSR."""
    B, g = sys.B, sys.g
    for r in range(q.shape[0]):
        s = g[r]
        for j in range(B.shape[1]):
            s -= B[r, j] * p[j]
        q[r] = s
    csr_gather(sys.A_ptr, sys.A_idx, sys.A_val, q, x, q)


@njit(cache=True, nogil=True, error_model="numpy")
def _same_key(a, b):
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def nominal_step(st):
    """The nominal step of a march: st.dt, or for the adaptive step (Method 2+3, whose factor
    the sparse backend takes infinite: methods/sparse.py check_adaptive) its cap st.dt_max, as
    kernels/march.py's min(step_factor T_min(S), dt_max)."""
    return st.dt_max if st.adaptive else st.dt


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def sparse_march(sys, st, ws, out, q0, f0):
    """kernels/march.py's march (fixed step, piecewise-linear solver; preload mode st.preload
    = N > 0: N quasi-static increments of the constant loads) with the condensed sparse
    solves (module docstring). Returns the status; out.counters[C_STEPS] steps done.
    A nominal step uses ws.main; a shorter one ws.last, which must hold its step size (else
    SINGULAR: the Python side prepares it, methods/sparse.py)."""
    # one statement each (kernels/march.py)
    sys = borrowed(sys)
    ws = borrowed(ws)
    out = borrowed(out)
    q0 = borrowed(q0)
    f0 = borrowed(f0)
    cl = contact_table(sys)
    counters = out.counters
    n = ws.x.shape[0]
    am, af = st.alpha_m, st.alpha_f
    n_preload = st.preload
    inertia = st.inertia
    signals = st.signals
    kfac = (1.0 - af) if inertia else 1.0
    has_damping = ws.C_val.shape[0] > 0 and np.any(ws.C_val != 0.0)
    if not _same_key(ws.owner, ws.main.key):  # the state cache belongs to another factorisation
        for s in range(ws.used.shape[0]):
            ws.used[s] = False
        for i in range(3):
            ws.owner[i] = ws.main.key[i]
    own_pred = np.empty((2, n))
    acc_pred, vel_pred = own_pred[0], own_pred[1]
    cap = out.plan[S_CAPACITY]
    t = st.t_start
    t_end = st.t_end
    o_q, o_f, o_rows = out.q, out.f, out.rows
    row = _store(ws.x, ws.v, ws.a, ws.w, ws.state, out, 0, t, 0.0, 0)
    for ii in range(o_rows.shape[0]):
        o_q[row, ii] = q0[o_rows[ii]]
        o_f[row, ii] = f0[o_rows[ii]]
    tiny = 1e-12 * (t_end - t + 1e-300)
    status = OK
    k = 0
    a0 = c1 = a2 = a3 = b1 = b2 = 0.0
    ws.lin_dt[0] = np.nan
    basis = np.zeros((4, sys.force_frequency.shape[0] + sys.motion_frequency.shape[0]))
    clock = np.zeros(4)
    clock[0], clock[1], clock[2], clock[3] = t, np.nan, 0.0, np.nan
    while (n_preload > 0 and k < n_preload) or (n_preload == 0 and t < t_end - tiny):
        if counters[C_STOP] != 0:
            status = INTERRUPTED
            counters[C_FAIL_STEP] = k
            break
        if k >= cap or out.plan[S_ROWS] + 2 > out.t.shape[0]:
            status = CAPACITY
            break
        dt_nominal = 1.0 if n_preload > 0 else nominal_step(st)
        dt = dt_nominal
        if n_preload == 0 and t + dt > t_end - tiny:
            dt = t_end - t
        nominal = abs(dt - dt_nominal) <= 1e-12 * dt_nominal
        fac = ws.main if nominal else ws.last
        if not nominal and abs(fac.key[0] - dt) > 1e-12 * dt:
            status = SINGULAR  # no factorisation of this step size (the Python side prepares it)
            counters[C_FAIL_STEP] = k + 1
            out.times[S_FAIL] = t + dt
            break
        load_factor = (k + 1.0) / n_preload if n_preload > 0 else 1.0
        t1 = t + dt if n_preload == 0 else t
        if ws.lin_dt[0] != dt:
            a0, c1, a2, a3, b1, b2 = newmark_coefficients(st.beta, st.gamma, dt)
            ws.lin_dt[0] = dt
        _loads_and_motions(sys, t1, signals, load_factor, basis, clock, ws.fe1, ws.p)
        _gather_state(sys, ws.x, ws.p, ws.qbase)
        _residual_base(ws, inertia, has_damping, am, af, a2, a3, b1, b2, acc_pred, vel_pred)
        status, solves = sparse_piecewise_linear_step(sys, cl, ws, fac, not nominal, kfac, 0, st.max_state_iter,
                                                      st.state_rtol, st.singular_rtol, st.fallback, st.max_iter,
                                                      st.tol, counters)
        counters[C_SOLVES] += solves
        if status != OK:
            counters[C_FAIL_STEP] = k + 1
            out.times[S_FAIL] = t + dt if n_preload == 0 else t
            break
        _accept(ws.mdiag, inertia, a0, c1, a2, a3, b1, b2, dt, ws.dx, ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.fe1, ws.gf1)
        if _accept_contacts(ws.w, ws.state, ws.w1, ws.state1):
            counters[C_STATE_CHANGES] += 1
        if n_preload == 0:
            t += dt
        k += 1
        row = _store(ws.x, ws.v, ws.a, ws.w, ws.state, out, k, t, dt, solves)
        counters[C_PROGRESS] = k
        for ii in range(o_rows.shape[0]):
            o_q[row, ii] = ws.q1[o_rows[ii]]
            o_f[row, ii] = ws.f1[o_rows[ii]]
    counters[C_STEPS] = k
    return status


@njit(cache=True, nogil=True, error_model="numpy")
def last_step(t_start, t_end, dt):
    """The size of the last step :func:`sparse_march` takes from t_start to t_end with the
    step dt (its own loop and rounding: the Python side factorises that step size)."""
    t = t_start
    tiny = 1e-12 * (t_end - t + 1e-300)
    last = dt
    while t < t_end - tiny:
        step = dt
        if t + step > t_end - tiny:
            step = t_end - t
        last = step
        t += step
    return last
