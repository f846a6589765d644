"""The spring-slider contact law and its piecewise-linear form (physics.md sections 2-3).

Per contact c with normal approach v and per tangential direction d with displacement u,
slider w_old (the converged value of the previous step) and trial force T* = k_t (u - w_old):

    v <= 0                      LIFT    T = N = 0,            w = u
    |T*| <= mu k_n v            STICK   T = T*, N = k_n v,    w = w_old
    T* >  mu k_n v              SLIP+   T = +mu k_n v,        w = u - T / k_t
    T* < -mu k_n v              SLIP-   T = -mu k_n v,        w = u - T / k_t

In a fixed state S the law is linear (paper Eq. 5): f = K(S) q + s(S, w_old) with
K(STICK) = diag(k_t, k_n), s = (-k_t w_old, 0); K(SLIP+/-) = [[0, +/-mu k_n], [0, k_n]].
Assembled (paper Eq. 7): K_D(S) = A^T K(S) A, and the generalised contact force is A^T f.
The state of a contact is stored per tangential direction (LIFT is shared by both
directions of a quasi-3D contact).
"""

import numpy as np
from numba import njit

LIFT = 0
STICK = 1
SLIP_POS = 2
SLIP_NEG = 3


@njit(cache=True)
def local_displacement(sys, x, p, q):
    """q = A x - B p + g."""
    A = sys.A
    B = sys.B
    for r in range(A.shape[0]):
        s = sys.g[r]
        for j in range(A.shape[1]):
            s += A[r, j] * x[j]
        for j in range(B.shape[1]):
            s -= B[r, j] * p[j]
        q[r] = s


@njit(cache=True)
def contact_law(sys, q, w_old, f, w_new, state):
    """The nonlinear law: forces f (local, like q), new sliders and states from q and w_old."""
    for c in range(sys.kn.shape[0]):
        nr = sys.normal_row[c]
        v = q[nr]
        d0 = sys.first_direction[c]
        nd = sys.n_directions[c]
        if v <= 0.0:
            f[nr] = 0.0
            for d in range(d0, d0 + nd):
                tr = sys.tangential_row[d]
                f[tr] = 0.0
                w_new[d] = q[tr]
                state[d] = LIFT
            continue
        N = sys.kn[c] * v
        f[nr] = N
        limit = sys.mu[c] * N
        for d in range(d0, d0 + nd):
            tr = sys.tangential_row[d]
            kt = sys.kt[d]
            trial = kt * (q[tr] - w_old[d])
            if abs(trial) <= limit:
                f[tr] = trial
                w_new[d] = w_old[d]
                state[d] = STICK
            elif trial > 0.0:
                f[tr] = limit
                w_new[d] = q[tr] - limit / kt
                state[d] = SLIP_POS
            else:
                f[tr] = -limit
                w_new[d] = q[tr] + limit / kt
                state[d] = SLIP_NEG


@njit(cache=True)
def linear_law(sys, state, q, w_old, f, w_new):
    """The piecewise-linear law f = K(S) q + s(S, w_old) for a postulated state S."""
    for c in range(sys.kn.shape[0]):
        nr = sys.normal_row[c]
        d0 = sys.first_direction[c]
        nd = sys.n_directions[c]
        if state[d0] == LIFT:
            f[nr] = 0.0
            for d in range(d0, d0 + nd):
                tr = sys.tangential_row[d]
                f[tr] = 0.0
                w_new[d] = q[tr]
            continue
        N = sys.kn[c] * q[nr]
        f[nr] = N
        for d in range(d0, d0 + nd):
            tr = sys.tangential_row[d]
            kt = sys.kt[d]
            s = state[d]
            if s == STICK:
                f[tr] = kt * (q[tr] - w_old[d])
                w_new[d] = w_old[d]
            else:
                T = sys.mu[c] * N if s == SLIP_POS else -sys.mu[c] * N
                f[tr] = T
                w_new[d] = q[tr] - T / kt


@njit(cache=True)
def is_compatible(sys, state, q, w_old, rtol):
    """Does the postulated state satisfy its row of the state table at q (within tolerance)?

    Tolerances: rtol * L on v (L the system length scale) and rtol * (mu k_n |v| + k_t L)
    on the friction test, so that a point on a stick/slip or contact boundary is accepted.
    """
    L = sys.length_scale
    for c in range(sys.kn.shape[0]):
        v = q[sys.normal_row[c]]
        d0 = sys.first_direction[c]
        nd = sys.n_directions[c]
        tol_v = rtol * L
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            continue
        if v < -tol_v:
            return False
        limit = sys.mu[c] * sys.kn[c] * v
        for d in range(d0, d0 + nd):
            kt = sys.kt[d]
            trial = kt * (q[sys.tangential_row[d]] - w_old[d])
            tol_t = rtol * (abs(limit) + kt * L)
            s = state[d]
            if s == STICK:
                if abs(trial) > limit + tol_t:
                    return False
            elif s == SLIP_POS:
                if trial < limit - tol_t:
                    return False
            else:
                if trial > -limit + tol_t:
                    return False
    return True


@njit(cache=True)
def add_contact_stiffness(sys, state, factor, out):
    """out += factor * K_D(S), with K_D(S) = A^T K(S) A (paper Eq. 7)."""
    A = sys.A
    n = A.shape[1]
    for c in range(sys.kn.shape[0]):
        d0 = sys.first_direction[c]
        if state[d0] == LIFT:
            continue
        nr = sys.normal_row[c]
        kn = factor * sys.kn[c]
        for i in range(n):
            a = kn * A[nr, i]
            if a != 0.0:
                for j in range(n):
                    out[i, j] += a * A[nr, j]
        for d in range(d0, d0 + sys.n_directions[c]):
            tr = sys.tangential_row[d]
            s = state[d]
            if s == STICK:
                k = factor * sys.kt[d]
                col = tr
            elif s == SLIP_POS:
                k = factor * sys.mu[c] * sys.kn[c]
                col = nr
            else:
                k = -factor * sys.mu[c] * sys.kn[c]
                col = nr
            for i in range(n):
                a = k * A[tr, i]
                if a != 0.0:
                    for j in range(n):
                        out[i, j] += a * A[col, j]


@njit(cache=True)
def generalised_force(sys, f, out):
    """out = A^T f: the contact force on the DOFs as it enters the left-hand side."""
    A = sys.A
    for j in range(A.shape[1]):
        out[j] = 0.0
    for r in range(A.shape[0]):
        fr = f[r]
        if fr != 0.0:
            for j in range(A.shape[1]):
                out[j] += A[r, j] * fr


@njit(cache=True)
def fill_state(sys, value, state):
    for d in range(state.shape[0]):
        state[d] = value
