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

from numba import njit

LIFT = 0
STICK = 1
SLIP_POS = 2
SLIP_NEG = 3



# ---- explicit-array cores (the hot path: small argument lists, no tuples) ------------------
# Contact table arguments, in this order everywhere:
#   nrow (nc) normal row of each contact in q, kn (nc), mu (nc), fdir (nc) first direction,
#   ndir (nc) number of directions, trow (nd) tangential row of each direction in q, kt (nd).


@njit(cache=True, error_model="numpy", inline="always")
def gather(A, B, g, x, p, q):
    """q = A x - B p + g."""
    for r in range(A.shape[0]):
        s = g[r]
        for j in range(A.shape[1]):
            s += A[r, j] * x[j]
        for j in range(B.shape[1]):
            s -= B[r, j] * p[j]
        q[r] = s


@njit(cache=True, error_model="numpy", inline="always")
def scatter(AT, f, out):
    """out = A^T f (AT: the contiguous transpose of A): the contact force on the DOFs as it
    enters the left-hand side. One dot product per DOF, accumulated in a register."""
    for j in range(AT.shape[0]):
        s = 0.0
        for r in range(AT.shape[1]):
            s += AT[j, r] * f[r]
        out[j] = s


@njit(cache=True, error_model="numpy", inline="always")
def law(nrow, kn, mu, fdir, ndir, trow, kt, q, w_old, f, w_new, state):
    """The nonlinear law: forces f (local, like q), new sliders and states from q and w_old."""
    for c in range(kn.shape[0]):
        nr = nrow[c]
        v = q[nr]
        d0 = fdir[c]
        if v <= 0.0:
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]] = 0.0
                w_new[d] = q[trow[d]]
                state[d] = LIFT
            continue
        N = kn[c] * v
        f[nr] = N
        limit = mu[c] * N
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            trial = kt[d] * (q[tr] - w_old[d])
            if abs(trial) <= limit:
                f[tr] = trial
                w_new[d] = w_old[d]
                state[d] = STICK
            elif trial > 0.0:
                f[tr] = limit
                w_new[d] = q[tr] - limit / kt[d]
                state[d] = SLIP_POS
            else:
                f[tr] = -limit
                w_new[d] = q[tr] + limit / kt[d]
                state[d] = SLIP_NEG


@njit(cache=True, error_model="numpy", inline="always")
def piecewise_law(nrow, kn, mu, fdir, ndir, trow, kt, state, q, w_old, f, w_new):
    """The piecewise-linear law f = K(S) q + s(S, w_old) for a postulated state S."""
    for c in range(kn.shape[0]):
        nr = nrow[c]
        d0 = fdir[c]
        if state[d0] == LIFT:
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]] = 0.0
                w_new[d] = q[trow[d]]
            continue
        N = kn[c] * q[nr]
        f[nr] = N
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            s = state[d]
            if s == STICK:
                f[tr] = kt[d] * (q[tr] - w_old[d])
                w_new[d] = w_old[d]
            else:
                T = mu[c] * N if s == SLIP_POS else -mu[c] * N
                f[tr] = T
                w_new[d] = q[tr] - T / kt[d]


@njit(cache=True, error_model="numpy", inline="always")
def compatible(nrow, kn, mu, fdir, ndir, trow, kt, state, q, w_old, rtol, length_scale):
    """Does the postulated state satisfy its row of the state table at q (within tolerance)?

    Tolerances: rtol * L on v (L the system length scale) and rtol * (mu k_n |v| + k_t L)
    on the friction test, so that a point on a stick/slip or contact boundary is accepted.
    """
    tol_v = rtol * length_scale
    for c in range(kn.shape[0]):
        v = q[nrow[c]]
        d0 = fdir[c]
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            continue
        if v < -tol_v:
            return False
        limit = mu[c] * kn[c] * v
        for d in range(d0, d0 + ndir[c]):
            trial = kt[d] * (q[trow[d]] - w_old[d])
            tol_t = rtol * (abs(limit) + kt[d] * length_scale)
            s = state[d]
            if s == STICK:
                if abs(trial) > limit + tol_t:
                    return False
            elif s == SLIP_POS:
                if trial < limit - tol_t:
                    return False
            elif trial > -limit + tol_t:
                return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _add_outer(out, k, A, r1, r2):
    """out += k * A[r1]^T A[r2]."""
    n = A.shape[1]
    for i in range(n):
        a = k * A[r1, i]
        if a != 0.0:
            for j in range(n):
                out[i, j] += a * A[r2, j]


@njit(cache=True, nogil=True, error_model="numpy")
def contact_stiffness(nrow, kn, mu, fdir, ndir, trow, kt, A, state, factor, out):
    """out += factor * K_D(S), with K_D(S) = A^T K(S) A (paper Eq. 7)."""
    for c in range(kn.shape[0]):
        d0 = fdir[c]
        if state[d0] == LIFT:
            continue
        nr = nrow[c]
        _add_outer(out, factor * kn[c], A, nr, nr)
        for d in range(d0, d0 + ndir[c]):
            s = state[d]
            if s == STICK:
                _add_outer(out, factor * kt[d], A, trow[d], trow[d])
            elif s == SLIP_POS:
                _add_outer(out, factor * mu[c] * kn[c], A, trow[d], nr)
            else:
                _add_outer(out, -factor * mu[c] * kn[c], A, trow[d], nr)


# ---- convenience wrappers taking the CompiledSystem (Python, tests, cold paths) --------------


@njit(cache=True, nogil=True, error_model="numpy")
def local_displacement(sys, x, p, q):
    """q = A x - B p + g."""
    gather(sys.A, sys.B, sys.g, x, p, q)


@njit(cache=True, nogil=True, error_model="numpy")
def contact_law(sys, q, w_old, f, w_new, state):
    """The nonlinear law (see :func:`law`)."""
    law(sys.normal_row, sys.kn, sys.mu, sys.first_direction, sys.n_directions, sys.tangential_row, sys.kt,
        q, w_old, f, w_new, state)


@njit(cache=True, nogil=True, error_model="numpy")
def linear_law(sys, state, q, w_old, f, w_new):
    """The piecewise-linear law (see :func:`piecewise_law`)."""
    piecewise_law(sys.normal_row, sys.kn, sys.mu, sys.first_direction, sys.n_directions, sys.tangential_row, sys.kt,
                  state, q, w_old, f, w_new)


@njit(cache=True, nogil=True, error_model="numpy")
def is_compatible(sys, state, q, w_old, rtol):
    """The compatibility check (see :func:`compatible`)."""
    return compatible(sys.normal_row, sys.kn, sys.mu, sys.first_direction, sys.n_directions, sys.tangential_row,
                      sys.kt, state, q, w_old, rtol, sys.length_scale)


@njit(cache=True, nogil=True, error_model="numpy")
def add_contact_stiffness(sys, state, factor, out):
    """out += factor * K_D(S) (see :func:`contact_stiffness`)."""
    contact_stiffness(sys.normal_row, sys.kn, sys.mu, sys.first_direction, sys.n_directions, sys.tangential_row,
                      sys.kt, sys.A, state, factor, out)


@njit(cache=True, nogil=True, error_model="numpy")
def generalised_force(sys, f, out):
    """out = A^T f."""
    scatter(sys.AT, f, out)
