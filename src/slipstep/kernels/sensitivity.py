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
each line gives the step's sensitivity. With K_D(S) = A^T K(S) A the contact stiffness of
J(S) (kernels/contact.py) and H(S) the columns k_t A_t^T of the stuck directions (df_b/dw =
-k_t there), the derivative of the step's increment is

    d(dx) = P(dt, S) [dX; dV; dA; dW],   P = J(S)^-1 [-(K + K_D(S)) | a2 M - b1 C | a3 M - b2 C | H(S)]

(quasi-static: P = J(S)^-1 [-(K + K_D(S)) | 0 | 0 | H(S)]), and a slider that slips or lifts
off follows dw_{n+1} = R_d(S) dX_{n+1}, R_d = A_t - s mu k_n / k_t A_n (slip in direction s),
A_t (lift-off); a stuck slider keeps dw. The kernel carries the derivative matrix Z of
(x, v, a, w) with respect to the unknowns through the recorded sequence of (dt, S) of the
period: P is formed (one solve with J(S)) and the stuck sliders' term H(S) dW summed only when
S or dt changes, each step costs one matrix product (BLAS), and a moving slider's row R_d dX
is formed only when it sticks again and at the end (:func:`period_sensitivity`). Only the
sliders asked for carry rows: a slider that stays stuck over the whole period keeps w_d
fixed, so its row is the unit vector and its column only matters if w_d is an unknown
(shooting fixes it: a neutral direction). Steps that fell back to Newton converged to the
same equations in their final state, so the same formulas hold.
"""

import numpy as np
from numba import njit

from slipstep.kernels.codes import P_KN, P_MU
from slipstep.kernels.contact import STICK, contact_stiffness
from slipstep.kernels.laws import uncoupled
from slipstep.kernels.linalg import lu_factor, lu_solve_rows
from slipstep.kernels.march import newmark_coefficients
from slipstep.kernels.lean_compiler import LeanCompiler


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def period_sensitivity(
    M, Cd, Kst, A, nrow, lcode, lpar, fdir, ndir, trow, kt, beta, gamma, inertia, dts, states, n_steps, wrow,
    singular_rtol, Z
):
    """Propagate Z (rows x | v | a | w of the sliders d with wrow[d] >= 0, at row 3 n + wrow[d];
    columns: the unknowns) through steps 1..n_steps with step sizes dts[k] and accepted states
    states[k], in place (module docstring). A slider with wrow[d] < 0 must stay stuck over the
    steps (its w is then constant and carries no row). Returns False (Z unfinished) if a J(S)
    has a pivot below singular_rtol max|J| (kernels/linalg.lu_factor).

    The sliders act on the structure through the contact DOFs c (those A gathers, nc of them)
    only, so per (dt, S) the kernel forms P_s = J^-1 [G_x | G_v | G_a] (n x 3 n), with
    J^-1 G_x = J^-1 (a0 M + a1 C) - I, and Q = (J^-1)[:, c] (n x nc): J updated by the K_D of
    the contacts whose state changed (built afresh when dt changes), one factorisation and one
    solve with the right-hand sides [a0 M + a1 C | G_v | G_a | E_c], fixed while dt is.
    A step costs

        d(dx) = P_s Z_xva + Q h,   h = sum over the stuck sliders d of k_t A_t[d, c]^T Z_w[d]

    where h and Q h change only with (dt, S): a stuck slider keeps its row of Z_w, so h is
    updated by the sliders that stick or leave stick. A moving slider's row is w = R_d(S) X,
    R_d = A_t[d] - s A_n[d] (:func:`_slider_row`), needed only when it sticks again and at the
    period's end, so it is formed then, from the X of the last step it moved in. Per step
    n 3 n m multiply-adds for m unknowns; per change of (dt, S) the factorisation, the solve
    (n^2 (3 n + nc)) and n nc m."""
    kn = lpar[:, P_KN]
    mu = lpar[:, P_MU]
    n = M.shape[0]
    nd = kt.shape[0]
    m = Z.shape[1]
    iv, ia, iw = n, 2 * n, 3 * n
    massless = np.zeros(n, np.bool_)
    for i in range(n):
        massless[i] = M[i, i] == 0.0
    owner = np.zeros(nd, np.int64)
    for c in range(nrow.shape[0]):
        for d in range(fdir[c], fdir[c] + ndir[c]):
            owner[d] = c
    position = np.full(n, -1, np.int64)  # the contact DOFs: position[i] = their index in c, or -1
    nc = 0
    for i in range(n):
        for r in range(A.shape[0]):
            if A[r, i] != 0.0:
                position[i] = nc
                nc += 1
                break
    rhs = np.zeros((n, iw + nc))  # [a0 M + a1 C | a2 M - b1 C | a3 M - b2 C | E_c] (quasi-static: [0 | 0 | 0 | E_c])
    for i in range(n):
        if position[i] >= 0:
            rhs[i, iw + position[i]] = 1.0
    sol = np.zeros((n, iw + nc))
    J = np.zeros((n, n))
    lu = np.zeros((n, n))
    piv = np.zeros(n, np.int64)
    Ps = np.zeros((n, iw))
    Q = np.zeros((n, nc))
    hz = np.zeros((nc, m))
    qhz = np.zeros((n, m))
    ddx = np.zeros((n, m))
    stuck = np.zeros(nd, np.bool_)  # the slider's k_t A_t^T Z_w is in h
    moving = np.zeros(nd, np.bool_)  # the slider's w followed X in the last step (slip or lift-off)
    slope = np.zeros(nd)  # its s in R_d = A_t - s A_n
    prev_state = np.full(nd, -1, np.int8)
    prev_dt = -1.0
    nowhere = np.empty(0)  # no linearisation point (the laws' piecewise-constant tangents)
    a0 = c1 = a2 = a3 = b1 = b2 = 0.0
    for k in range(1, n_steps + 1):
        dt = dts[k]
        S = states[k]
        new_state = False
        for d in range(nd):
            if S[d] != prev_state[d]:
                new_state = True
        if dt != prev_dt and inertia:
            a0, c1, a2, a3, b1, b2 = newmark_coefficients(beta, gamma, dt)
            for i in range(n):
                for j in range(n):
                    rhs[i, j] = a0 * M[i, j] + c1 * Cd[i, j]
                    rhs[i, iv + j] = a2 * M[i, j] - b1 * Cd[i, j]
                    rhs[i, ia + j] = a3 * M[i, j] - b2 * Cd[i, j]
        if dt != prev_dt:
            for i in range(n):
                for j in range(n):
                    J[i, j] = Kst[i, j] + rhs[i, j]
            contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, S, nowhere, nowhere, 1.0, J)
        elif new_state:  # J(S) = J(S_prev) + K_D of the contacts that changed, S against S_prev
            for c in range(nrow.shape[0]):
                for d in range(fdir[c], fdir[c] + ndir[c]):
                    if S[d] != prev_state[d]:
                        one = slice(c, c + 1)
                        table = (nrow[one], lcode[one], lpar[one], fdir[one], ndir[one], trow, kt, A)
                        contact_stiffness(*table, prev_state, nowhere, nowhere, -1.0, J)
                        contact_stiffness(*table, S, nowhere, nowhere, 1.0, J)
                        break
        if new_state or dt != prev_dt:
            if not lu_factor(J, lu, piv, singular_rtol):
                return False
            sol[:, :] = rhs
            lu_solve_rows(lu, piv, sol)
            for i in range(n):
                for j in range(iw):
                    Ps[i, j] = sol[i, j]
                Ps[i, i] -= 1.0
                for j in range(nc):
                    Q[i, j] = sol[i, iw + j]
        if new_state:
            for d in range(nd):
                j = wrow[d]
                if j < 0:
                    continue
                if S[d] == STICK:  # df_b/dw = -k_t: dr = +k_t A_t^T dw
                    if not stuck[d]:
                        if moving[d]:  # it moved up to the last step: its w = R_d X there
                            _slider_row(Z, iw + j, A, trow[d], nrow[owner[d]], slope[d])
                            moving[d] = False
                        _add_stuck_slider(hz, position, A, trow[d], kt[d], Z[iw + j])
                        stuck[d] = True
                    continue
                if stuck[d]:
                    _add_stuck_slider(hz, position, A, trow[d], -kt[d], Z[iw + j])
                    stuck[d] = False
                c = owner[d]
                moving[d] = True
                slope[d] = uncoupled.slider_derivative(kt[d], mu[c] * kn[c], S[d])[1]  # dw = dq_t - slope dq_n
        if new_state or dt != prev_dt:
            np.dot(Q, hz, qhz)
            prev_dt = dt
            for d in range(nd):
                prev_state[d] = S[d]
        np.dot(Ps, Z[0:iw], ddx)
        for i in range(n):
            zx, zv, za, dxi, hi = Z[i], Z[iv + i], Z[ia + i], ddx[i], qhz[i]
            if not inertia:
                for j in range(m):
                    zx[j] += dxi[j] + hi[j]
            elif massless[i]:  # a massless DOF in a dynamic march: v = dx/dt, a = 0
                for j in range(m):
                    d_x = dxi[j] + hi[j]
                    zx[j] += d_x
                    zv[j] = d_x / dt
                    za[j] = 0.0
            else:
                for j in range(m):
                    d_x = dxi[j] + hi[j]
                    vj, aj = zv[j], za[j]
                    zx[j] += d_x
                    za[j] = a0 * d_x - a2 * vj - a3 * aj
                    zv[j] = c1 * d_x + b1 * vj + b2 * aj
    for d in range(nd):  # the sliders still moving at the end: w = R_d X of the last step
        if moving[d]:
            _slider_row(Z, iw + wrow[d], A, trow[d], nrow[owner[d]], slope[d])
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _add_stuck_slider(hz, position, A, tr, k, zw):
    """h += k A_t[c]^T zw: a stuck slider's force on the contact DOFs (k = k_t), or its removal
    (k = -k_t) when it leaves stick; zw its row of Z_w."""
    for i in range(A.shape[1]):
        h = k * A[tr, i]
        if h != 0.0:
            p = position[i]
            for col in range(zw.shape[0]):
                hz[p, col] += h * zw[col]


@njit(cache=True, error_model="numpy", inline="always")
def _slider_row(Z, row, A, tr, nr, s):
    """Z[row] = R_d Z_x, R_d = A[tr] - s A[nr]: the w of a slider that slips (s = +/- mu k_n / k_t)
    or lifts off (s = 0) follows its contact point, dw = dq_t - s dq_n."""
    m = Z.shape[1]
    for col in range(m):
        Z[row, col] = 0.0
    for i in range(A.shape[1]):
        r = A[tr, i] - s * A[nr, i]
        if r != 0.0:
            for col in range(m):
                Z[row, col] += r * Z[i, col]
