"""Every operation of the implicit march on n x n structure matrices, in one place.

The march (kernels/march.py) and its step solvers (kernels/step_solvers.py) never index M,
C, K, Lin or a factorisation themselves: they call the functions below with a structure
backend code (MarchSettings.structure), chosen once per run in Python:

    DENSE     dense matrices, one LU of J(S) per contact state (kernels/state_solve.py)
    LOW_RANK  dense matrices, J(S) solved by the low-rank update of J(all stick)
              (kernels/state_solve.py; for structures with many more DOFs than contact
              coordinates)
    BANDED    the banded backend of slipstep.system (issue 10): M, C, K in band storage
              (sys.Mb, Cb, Kb; kl = ku = sys.kl), Lin (n, 2 b + 1) in band storage, J(S) and
              its factors (n, 3 b + 1) in banded-LU storage (kernels/banded.py), A and A^T in
              CSR (sys.A_ptr, ...); every operation O(n b) or O(nnz(A)), a factorisation
              O(n b^2). The gather/scatter functions at the end of this module are its
              products with A (the dense backends' loops stay where they were)

Contract (for a new backend, e.g. banded matrices): each function takes the backend code
first, then the CompiledSystem ``sys`` (M, C, K, A, AT) and/or the Workspace arrays it needs
(Lin, J, the StateCache of kernels/settings.py), and branches on the code, compared with the
bare names DENSE, LOW_RANK, BANDED: the code is a constant of every march kernel (a closure of
it, kernels.march.implicit_kernel), and numba prunes a branch on a constant against a global name
(not a module attribute such as ``so.BANDED``) before typing, after inlining too. The arrays are
those the runner allocated for the backend (Simulation._allocate_workspace): a backend may
store Lin, J and the factors in its own layout as long as every function below agrees on
it. Equations (kfac = 1 - alpha_f dynamic, 1 quasi-static):

    build_lin        Lin = c_m M + c_c C + c_k K            (c_* from the scheme and dt)
    sub_predictor    r0 -= M y_a + C y_v + K x              (the residual base's structure part)
    sub_lin          r  -= Lin dx                           (Newton residual)
    max_diagonal     max_i (Lin_ii + kfac diag K_D(stick)_i)  (the residual floor's scale)
    diagonal         diag(M)                                (massless DOFs; accept, local error)
    factorise        slot of J(S) = Lin + kfac A^T K(S) A, factorised (cached per state)
    stick_factor     the factor of J(all stick) as (lu, piv) arrays for solve_factor
    solve            out = J(S)^-1 r with the factorisation of a slot
    solve_factor     out = F^-1 r with a factor from stick_factor (or state_factor)
"""

import numpy as np
from numba import njit

from slipstep.kernels.banded import (
    band_combine, band_lu_solve, band_matvec_sub, csr_abs_max, csr_gather, csr_matvec,
)
from slipstep.kernels.contact import gather, scatter
from slipstep.kernels.linalg import lu_solve
from slipstep.kernels.state_solve import factorise_banded, factorise_state, solve_low_rank, state_slot

#: structure backends (MarchSettings.structure)
DENSE, LOW_RANK, BANDED = 0, 1, 2


@njit(cache=True, error_model="numpy", inline="always")
def build_lin(backend, sys, inertia, c_m, c_c, c_k, Lin):
    """Lin = c_m M + c_c C + c_k K (dynamic), Lin = K (quasi-static, inertia False)."""
    if backend == BANDED:
        if inertia:
            band_combine(c_m, sys.Mb, c_c, sys.Cb, c_k, sys.Kb, Lin)
        else:
            band_combine(0.0, sys.Mb, 0.0, sys.Cb, 1.0, sys.Kb, Lin)
        return
    M, Cd, Kst = sys.M, sys.C, sys.K
    n = Lin.shape[0]
    for i in range(n):
        for j in range(n):
            if inertia:
                Lin[i, j] = c_m * M[i, j] + c_c * Cd[i, j] + c_k * Kst[i, j]
            else:
                Lin[i, j] = Kst[i, j]


@njit(cache=True, error_model="numpy", inline="always")
def sub_predictor(backend, sys, inertia, has_damping, has_stiffness, acc_pred, vel_pred, x, r0):
    """r0 -= M acc_pred + C vel_pred + K x (the first two only with inertia, C y only with
    damping, K x only with stiffness), each product subtracted in turn, row by row (one loop:
    the same sequence of operations on each r0_i as three separate products)."""
    if backend == BANDED:
        if inertia:
            band_matvec_sub(sys.Mb, sys.kl, sys.ku, acc_pred, r0)
            if has_damping:
                band_matvec_sub(sys.Cb, sys.kl, sys.ku, vel_pred, r0)
        if has_stiffness:
            band_matvec_sub(sys.Kb, sys.kl, sys.ku, x, r0)
        return
    M, Cd, Kst = sys.M, sys.C, sys.K
    n = r0.shape[0]
    use_c = inertia and has_damping
    for i in range(n):
        ri = r0[i]
        if inertia:
            s = 0.0
            for j in range(n):
                s += M[i, j] * acc_pred[j]
            ri -= s
        if use_c:
            s = 0.0
            for j in range(n):
                s += Cd[i, j] * vel_pred[j]
            ri -= s
        if has_stiffness:
            s = 0.0
            for j in range(n):
                s += Kst[i, j] * x[j]
            ri -= s
        r0[i] = ri


@njit(cache=True, error_model="numpy", inline="always")
def sub_lin(backend, Lin, dx, r):
    """r -= Lin dx (row by row, the terms subtracted in order)."""
    if backend == BANDED:  # Lin (n, 2 b + 1) in band storage
        b = (Lin.shape[1] - 1) // 2
        band_matvec_sub(Lin, b, b, dx, r)
        return
    n = dx.shape[0]
    for i in range(n):
        s = r[i]
        for j in range(n):
            s -= Lin[i, j] * dx[j]
        r[i] = s


@njit(cache=True, error_model="numpy", inline="always")
def max_diagonal(backend, Lin, kfac, kd_stick):
    """max_i (Lin_ii + kfac kd_stick_i): the largest diagonal entry of J(all stick)."""
    kdiag = 0.0
    b = (Lin.shape[1] - 1) // 2  # BANDED: the diagonal's column of the band storage
    for i in range(Lin.shape[0]):
        kdiag = max(kdiag, (Lin[i, b] if backend == BANDED else Lin[i, i]) + kfac * kd_stick[i])
    return kdiag


@njit(cache=True, nogil=True, error_model="numpy")
def diagonal(backend, Mat):
    """A copy of diag(Mat)."""
    n = Mat.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = Mat[i, i]
    return out


@njit(cache=True, error_model="numpy", inline="always")
def factorise(backend, sys, cl, cache, Lin, J, kfac, kd_state, q, w_old, nominal, singular_rtol, counters):
    """(slot, ok): the factorisation of J(kd_state) = Lin + kfac A^T K(kd_state) A for the
    current step size, cached per (kd_state, dt state) (q, w_old: the linearisation point of a
    coupled slip; length 0 for none). ok False: J singular."""
    slot, found = state_slot(cl, cache, kd_state, nominal)
    if found:
        return slot, cache.ok[slot]
    if backend == BANDED:
        return slot, factorise_banded(slot, sys, cl, cache, Lin, kfac, kd_state, q, w_old, singular_rtol, counters)
    return slot, factorise_state(slot, backend == LOW_RANK, Lin, J, kfac, sys.A, cl, cache, kd_state, q, w_old,
                                 nominal, singular_rtol, counters)


@njit(cache=True, error_model="numpy", inline="always")
def stick_factor(backend, cache, slot):
    """(lu, piv) of J(all stick) held by ``slot`` (a slot factorised for the all-stick state):
    the state's LU (dense) or the low-rank base of that slot."""
    if backend == LOW_RANK:
        lr = cache.lr
        b = lr.slot_base[slot]
        return lr.base_lu[b], lr.base_piv[b]
    return cache.lu[slot], cache.piv[slot]


@njit(cache=True, error_model="numpy", inline="always")
def state_factor(backend, cache, slot):
    """(lu, piv) of a slot's own J(S) (dense only: in low rank a slot holds C(S), not J(S))."""
    return cache.lu[slot], cache.piv[slot]


@njit(cache=True, error_model="numpy", inline="always")
def solve_factor(backend, lu, piv, r, out):
    """out = F^-1 r for a factor (lu, piv) from stick_factor / state_factor."""
    if backend == BANDED:  # lu (n, 3 b + 1) in banded-LU storage
        b = (lu.shape[1] - 1) // 3
        band_lu_solve(lu, b, b, piv, r, out)
        return
    lu_solve(lu, piv, r, out)


@njit(cache=True, error_model="numpy", inline="always")
def solve(backend, sys, cl, cache, slot, kd_state, q, w_old, kfac, r, out):
    """out = J(kd_state)^-1 r with the factorisation of ``slot`` (from :func:`factorise`)."""
    if backend == LOW_RANK:
        solve_low_rank(slot, cache, sys.A, cl, kd_state, q, w_old, kfac, r, out)
    elif backend == BANDED:
        band_lu_solve(cache.lu[slot], sys.kl, sys.ku, cache.piv[slot], r, out)
    else:
        lu_solve(cache.lu[slot], cache.piv[slot], r, out)


@njit(cache=True, nogil=True, error_model="numpy")
def mass_diagonal(backend, sys):
    """A copy of diag(M) (zeros: massless DOFs), dense or band storage."""
    if backend == BANDED:
        n = sys.Mb.shape[0]
        out = np.empty(n)
        for i in range(n):
            out[i] = sys.Mb[i, sys.ku]
        return out
    return diagonal(backend, sys.M)


@njit(cache=True, error_model="numpy", inline="always")
def has_nonzero(backend, sys, which):
    """Any non-zero entry in C (which 1) or K (which 2)."""
    if backend == BANDED:
        return np.any(sys.Cb != 0.0) if which == 1 else np.any(sys.Kb != 0.0)
    return np.any(sys.C != 0.0) if which == 1 else np.any(sys.K != 0.0)


# ---- products with the gather map A of the banded backend (CSR) ----------------------------
# ``csr`` = csr_of(sys): the six CSR arrays of A and A^T, a small tuple the step solvers carry
# (not the whole CompiledSystem: passing it to a non-inlined solver costs microseconds a step)
@njit(cache=True, error_model="numpy", inline="always")
def csr_of(sys):
    """(A_ptr, A_idx, A_val, AT_ptr, AT_idx, AT_val) of a CompiledSystem."""
    return sys.A_ptr, sys.A_idx, sys.A_val, sys.AT_ptr, sys.AT_idx, sys.AT_val


@njit(cache=True, error_model="numpy", inline="always")
def gather_increment(csr, base, y, out):
    """out = base + A y, A in CSR (banded backend)."""
    csr_gather(csr[0], csr[1], csr[2], base, y, out)


@njit(cache=True, error_model="numpy", inline="always")
def gather_abs_max(csr, y):
    """max_r |(A y)_r|, A in CSR (banded backend)."""
    return csr_abs_max(csr[0], csr[1], csr[2], y)


@njit(cache=True, error_model="numpy", inline="always")
def scatter_force(backend, csr, A, f, out):
    """out = A^T f (A dense, or A^T in CSR for the banded backend)."""
    if backend == BANDED:
        csr_matvec(csr[3], csr[4], csr[5], f, out)
    else:
        scatter(A, f, out)


@njit(cache=True, error_model="numpy", inline="always")
def gather_state(backend, sys, x, p, q):
    """q = A x - B p + g (kernels.contact.gather; A in CSR for the banded backend)."""
    if backend != BANDED:
        gather(sys.AT, sys.B, sys.g, x, p, q)
        return
    motion_base(sys, p, q)
    csr_gather(sys.A_ptr, sys.A_idx, sys.A_val, q, x, q)


@njit(cache=True, error_model="numpy", inline="always")
def motion_base(sys, p, q):
    """q = g - B p: the contact coordinates at x = 0 (any backend; B and g are dense)."""
    B, g = sys.B, sys.g
    for r in range(q.shape[0]):
        s = g[r]
        for j in range(B.shape[1]):
            s -= B[r, j] * p[j]
        q[r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def stick_diagonal(sys):
    """diag K_D(all stick) = sum_c k_n A_v^2 + sum_d k_t A_u^2 per DOF (the residual floor's
    scale), over the non-zeros of A in CSR (held by every backend's CompiledSystem)."""
    out = np.zeros(sys.AT_ptr.shape[0] - 1)
    ptr, idx, val = sys.A_ptr, sys.A_idx, sys.A_val
    for c in range(sys.kn.shape[0]):
        nr = sys.normal_row[c]
        for k in range(ptr[nr], ptr[nr + 1]):
            out[idx[k]] += sys.kn[c] * val[k] ** 2
        for d in range(sys.first_direction[c], sys.first_direction[c] + sys.n_directions[c]):
            tr = sys.tangential_row[d]
            for k in range(ptr[tr], ptr[tr + 1]):
                out[idx[k]] += sys.kt[d] * val[k] ** 2
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def column_abs_max_banded(sys, j):
    """max_r |A_rj| (A^T in CSR)."""
    m = 0.0
    for k in range(sys.AT_ptr[j], sys.AT_ptr[j + 1]):
        m = max(m, abs(sys.AT_val[k]))
    return m
