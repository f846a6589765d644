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
period: P and R are formed (one solve with J(S)) only when S or dt changes, and each step
costs two matrix products (BLAS). Only the sliders asked for carry rows: a slider that stays
stuck over the whole period keeps w_d fixed, so its row is the unit vector and its column
only matters if w_d is an unknown (shooting fixes it: a neutral direction). Steps that fell
back to Newton converged to the same equations in their final state, so the same formulas
hold.
"""

import numpy as np
from numba import njit

from slipstep.kernels.codes import P_KN, P_MU
from slipstep.kernels.contact import LIFT, SLIP_POS, STICK, contact_stiffness
from slipstep.kernels.march import newmark_coefficients


@njit(cache=True, nogil=True, error_model="numpy")
def period_sensitivity(
    M, Cd, Kst, A, nrow, lcode, lpar, fdir, ndir, trow, kt, beta, gamma, inertia, dts, states, n_steps, wrow, Z
):
    """Propagate Z (rows x | v | a | w of the sliders d with wrow[d] >= 0, at row 3 n + wrow[d];
    columns: the unknowns) through steps 1..n_steps with step sizes dts[k] and accepted states
    states[k], in place (module docstring). A slider with wrow[d] < 0 must stay stuck over the
    steps (its w is then constant and carries no row)."""
    kn = lpar[:, P_KN]
    mu = lpar[:, P_MU]
    n = M.shape[0]
    nd = kt.shape[0]
    nz, m = Z.shape
    iv, ia, iw = n, 2 * n, 3 * n
    na = nz - iw
    massless = np.zeros(n, np.bool_)
    for i in range(n):
        massless[i] = M[i, i] == 0.0
    owner = np.zeros(nd, np.int64)
    for c in range(nrow.shape[0]):
        for d in range(fdir[c], fdir[c] + ndir[c]):
            owner[d] = c
    G = np.zeros((n, nz))  # [-(K + K_D) | a2 M - b1 C | a3 M - b2 C | H]
    P = np.zeros((n, nz))
    R = np.zeros((max(na, 1), n))
    moving = np.zeros(max(na, 1), np.int64)
    n_moving = 0
    ddx = np.zeros((n, m))
    dw = np.zeros((max(na, 1), m))
    prev_state = np.full(nd, -1, np.int8)
    prev_dt = -1.0
    a0 = c1 = a2 = a3 = b1 = b2 = 0.0
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
            contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, S, np.empty(0), np.empty(0), 1.0, J)
            G[:, :] = 0.0
            G[:, 0:n] = -J
            if inertia:
                G[:, 0:n] += a0 * M + c1 * Cd
                G[:, iv:ia] = a2 * M - b1 * Cd
                G[:, ia:iw] = a3 * M - b2 * Cd
            n_moving = 0
            for d in range(nd):
                j = wrow[d]
                if j < 0:
                    continue
                tr = trow[d]
                if S[d] == STICK:
                    for i in range(n):
                        G[i, iw + j] = kt[d] * A[tr, i]
                    continue
                c = owner[d]
                s = 0.0 if S[d] == LIFT else (mu[c] * kn[c] / kt[d] if S[d] == SLIP_POS else -mu[c] * kn[c] / kt[d])
                nr = nrow[c]
                for i in range(n):
                    R[n_moving, i] = A[tr, i] - s * A[nr, i]
                moving[n_moving] = iw + j
                n_moving += 1
            P[:, :] = np.linalg.solve(J, G)
            prev_dt = dt
            for d in range(nd):
                prev_state[d] = S[d]
        np.dot(P, Z, ddx)
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
        for i in range(n):
            for j in range(m):
                Z[i, j] += ddx[i, j]
        if n_moving > 0:
            np.dot(R[:n_moving], Z[0:n], dw[:n_moving])
            for r in range(n_moving):
                for j in range(m):
                    Z[moving[r], j] = dw[r, j]
