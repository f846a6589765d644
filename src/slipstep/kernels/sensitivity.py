"""Sensitivity of a marched period to its initial state: the Jacobian of the discrete
one-period map of the piecewise-linear Newmark / quasi-static march (shooting).

Once the contact state S of a step is known, the step is linear in the previous state
(kernels/march.py, Newmark with alpha_m = alpha_f = 0):

    q_b  = A x_n - B p_{n+1} + g
    f_b  = K(S) q_b + s(S, w_n)          (piecewise law at q_b: stick T = k_t (u - w_n),
                                          slip T = +/- mu k_n v, N = k_n v, lift-off 0)
    r    = f_e - M (-a2 v_n - a3 a_n) - C (b1 v_n + b2 a_n) - K x_n - A^T f_b
    dx   = J(S)^-1 r,   J(S) = a0 M + a1 C + K + K_D(S)
    x_{n+1} = x_n + dx,   a_{n+1} = a0 dx - a2 v_n - a3 a_n,   v_{n+1} = a1 dx + b1 v_n + b2 a_n
    w_{n+1} = w_n (stick),  u_{n+1} - T_{n+1} / k_t (slip),  u_{n+1} (lift-off)

(quasi-static: r = f_e - K x_n - A^T f_b, J(S) = K + K_D(S), no v, a; a DOF without mass
in a dynamic march, methods/massless.py: v_{n+1} = dx / dt, a_{n+1} = 0). Differentiating
each line gives the step's sensitivity; the kernel carries the derivative matrix Z of
(x, v, a, w) with respect to the unknowns through the recorded sequence of (dt, S) of the
period, re-inverting J(S) only when S or dt changes. Steps that fell back to Newton
converged to the same equations in their final state, so the same formulas hold.
"""

import numpy as np
from numba import njit

from slipstep.kernels.codes import P_KN, P_MU
from slipstep.kernels.contact import LIFT, SLIP_POS, STICK, contact_stiffness
from slipstep.kernels.march import newmark_coefficients


@njit(cache=True, error_model="numpy", inline="always")
def _sparse_rows(A):
    """CSR of A (the contact gathers are sparse: a few DOFs per local coordinate)."""
    nq, n = A.shape
    count = 0
    for r in range(nq):
        for j in range(n):
            if A[r, j] != 0.0:
                count += 1
    ptr = np.zeros(nq + 1, np.int64)
    col = np.zeros(count, np.int64)
    val = np.zeros(count)
    k = 0
    for r in range(nq):
        for j in range(n):
            if A[r, j] != 0.0:
                col[k] = j
                val[k] = A[r, j]
                k += 1
        ptr[r + 1] = k
    return ptr, col, val


@njit(cache=True, error_model="numpy", inline="always")
def _gather_rows(ptr, col, val, X, out, add):
    """out = A X (add: out += A X), A in CSR."""
    m = X.shape[1]
    for r in range(ptr.shape[0] - 1):
        if not add:
            for j in range(m):
                out[r, j] = 0.0
        for k in range(ptr[r], ptr[r + 1]):
            c, v = col[k], val[k]
            for j in range(m):
                out[r, j] += v * X[c, j]


@njit(cache=True, nogil=True, error_model="numpy")
def period_sensitivity(M, Cd, Kst, A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, beta, gamma, inertia,
                       dts, states, n_steps, Z):
    """Propagate Z (rows x | v | a | w: 3 n + nd, columns: the unknowns) through steps
    1..n_steps with step sizes dts[k] and accepted states states[k] (in place)."""
    kn = lpar[:, P_KN]
    mu = lpar[:, P_MU]
    n = M.shape[0]
    nq = A.shape[0]
    nd = kt.shape[0]
    m = Z.shape[1]
    ix, iv, ia, iw = 0, n, 2 * n, 3 * n
    ptr, col, val = _sparse_rows(A)
    massless = np.zeros(n, np.bool_)
    for i in range(n):
        massless[i] = M[i, i] == 0.0
    Jinv = np.zeros((n, n))
    # r's dependence on (x, v, a): dr = G [dx; dv; da] - A^T df_b, G = [-K | a2 M - b1 C | a3 M - b2 C]
    G = np.zeros((n, 3 * n)) if inertia else np.zeros((n, n))
    prev_state = np.full(nd, -1, np.int8)
    prev_dt = -1.0
    a0 = c1 = a2 = a3 = b1 = b2 = 0.0
    dqb = np.zeros((nq, m))
    dfb = np.zeros((nq, m))
    dq1 = np.zeros((nq, m))
    for k in range(1, n_steps + 1):
        dt = dts[k]
        S = states[k]
        changed = dt != prev_dt
        for d in range(nd):
            if S[d] != prev_state[d]:
                changed = True
        if changed:
            J = Kst.copy()
            if inertia:
                a0, c1, a2, a3, b1, b2 = newmark_coefficients(beta, gamma, dt)
                J += a0 * M + c1 * Cd
            if dt != prev_dt:
                G[:, 0:n] = -Kst
                if inertia:
                    G[:, n:2 * n] = a2 * M - b1 * Cd
                    G[:, 2 * n:3 * n] = a3 * M - b2 * Cd
            contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, S, np.empty(0), np.empty(0), 1.0, J)
            Jinv = np.ascontiguousarray(np.linalg.inv(J))
            prev_dt = dt
            for d in range(nd):
                prev_state[d] = S[d]
        dX = Z[ix:ix + n]
        dW = Z[iw:iw + nd]
        _gather_rows(ptr, col, val, dX, dqb, False)
        dfb[:, :] = 0.0
        for c in range(kn.shape[0]):
            d0 = fdir[c]
            if S[d0] == LIFT:
                continue
            nr = nrow[c]
            for j in range(m):
                dfb[nr, j] = kn[c] * dqb[nr, j]
            for d in range(d0, d0 + ndir[c]):
                tr = trow[d]
                for j in range(m):
                    if S[d] == STICK:
                        dfb[tr, j] = kt[d] * (dqb[tr, j] - dW[d, j])
                    elif S[d] == SLIP_POS:
                        dfb[tr, j] = mu[c] * kn[c] * dqb[nr, j]
                    else:
                        dfb[tr, j] = -mu[c] * kn[c] * dqb[nr, j]
        dr = G @ Z[0:3 * n] if inertia else G @ dX
        for r in range(nq):  # dr -= A^T dfb
            for kk in range(ptr[r], ptr[r + 1]):
                c_, v_ = col[kk], val[kk]
                for j in range(m):
                    dr[c_, j] -= v_ * dfb[r, j]
        ddx = Jinv @ dr
        if inertia:
            for i in range(n):
                for j in range(m):
                    if massless[i]:  # a massless DOF in a dynamic march: v = dx/dt, a = 0
                        Z[iv + i, j] = ddx[i, j] / dt
                        Z[ia + i, j] = 0.0
                    else:
                        vi, ai = Z[iv + i, j], Z[ia + i, j]
                        Z[ia + i, j] = a0 * ddx[i, j] - a2 * vi - a3 * ai
                        Z[iv + i, j] = c1 * ddx[i, j] + b1 * vi + b2 * ai
        Z[ix:ix + n] += ddx
        if nq == 0:
            continue
        dq1[:, :] = dqb
        _gather_rows(ptr, col, val, ddx, dq1, True)
        for c in range(kn.shape[0]):
            d0 = fdir[c]
            nr = nrow[c]
            for d in range(d0, d0 + ndir[c]):
                tr = trow[d]
                s = S[d]
                if s == STICK:
                    continue
                for j in range(m):
                    if s == LIFT:
                        Z[iw + d, j] = dq1[tr, j]
                    elif s == SLIP_POS:
                        Z[iw + d, j] = dq1[tr, j] - mu[c] * kn[c] * dq1[nr, j] / kt[d]
                    else:
                        Z[iw + d, j] = dq1[tr, j] + mu[c] * kn[c] * dq1[nr, j] / kt[d]
