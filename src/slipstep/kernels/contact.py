"""The contact laws over all contacts: gather, scatter, and the laws of
:mod:`slipstep.kernels.laws` dispatched on each contact's law code (physics.md 2-3).

Every contact c has a law code (``lcode[c]``, kernels/codes.py) and a row of the law
parameter table (``lpar[c]``: k_n, mu); k_t is per tangential direction. The laws:

* LAW_UNCOUPLED (laws/uncoupled.py): the paper's 2D and quasi-3D law, one slider per
  tangential direction, |T_d| <= mu N each (a quasi-3D contact can carry sqrt(2) mu N);
  the Jenkins element is this law with a constant normal approach;
* LAW_CIRCLE (laws/circle.py): coupled 3D friction circle, |T| <= mu N as a vector norm.

Shared normal part: N = k_n v, and v <= 0 is LIFT (T = N = 0, w = u, every direction).
In a state S with a piecewise-linear form the law is f = K(S) q + s(S, w_old) (paper Eq. 5),
assembled (paper Eq. 7) as K_D(S) = A^T K(S) A; the generalised contact force is A^T f.
A coupled slip has no such form: its K is the consistent tangent at (q, w_old), and a step
in that state is solved by Newton (kernels/march.py). The state of a contact is stored per
tangential direction (codes.STATE_NAMES).
"""

import numpy as np
from numba import njit

from slipstep.kernels.codes import (  # noqa: F401  (re-exported: the state codes)
    LAW_CIRCLE, LIFT, P_KN, P_MU, SLIP_COUPLED, SLIP_NEG, SLIP_POS, STICK,
)
from slipstep.kernels.laws import circle, uncoupled
from slipstep.kernels.settings import contact_table

# ---- explicit-array cores (the hot path: small argument lists, no tuples) ------------------
# Contact table arguments, in this order everywhere:
#   nrow (nc) normal row of each contact in q, lcode (nc) law code, lpar (nc, N_LAW_PAR) law
#   parameters (k_n, mu), fdir (nc) first direction, ndir (nc) number of directions,
#   trow (nd) tangential row of each direction in q, kt (nd).


# The dense products with A below run column by column of the result's source (axpy form):
# the inner loop has no reduction, so it vectorises without fastmath, and each entry is still
# summed in the order of the row-by-row dot product (bit-identical to it); a zero x_j or f_r
# is skipped. 3-4x faster than the dot products for a 400 x 31 gather (benchmark in the
# closing note of issue 24), the many-contact case.


@njit(cache=True, error_model="numpy", inline="always")
def gather_columns(AT, base, x, q):
    """q = base + A x (AT: the contiguous transpose of A), column by column of A."""
    for r in range(AT.shape[1]):
        q[r] = base[r]
    for j in range(AT.shape[0]):
        xj = x[j]
        if xj != 0.0:
            for r in range(AT.shape[1]):
                q[r] += AT[j, r] * xj


@njit(cache=True, error_model="numpy", inline="always")
def gather(AT, B, g, x, p, q):
    """q = A x - B p + g (AT: the contiguous transpose of A)."""
    gather_columns(AT, g, x, q)
    for r in range(AT.shape[1]):
        s = q[r]
        for j in range(B.shape[1]):
            s -= B[r, j] * p[j]
        q[r] = s


@njit(cache=True, error_model="numpy", inline="always")
def scatter(A, f, out):
    """out = A^T f: the contact force on the DOFs as it enters the left-hand side, row by row
    of A."""
    for j in range(A.shape[1]):
        out[j] = 0.0
    for r in range(A.shape[0]):
        fr = f[r]
        if fr != 0.0:
            for j in range(A.shape[1]):
                out[j] += A[r, j] * fr


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_law(trow, kt, d0, limit, q, w_old, f, w_new, state):
    """laws/circle.py law for the contact whose first direction is d0 (limit = mu N)."""
    r1, r2 = trow[d0], trow[d0 + 1]
    f[r1], f[r2], w_new[d0], w_new[d0 + 1], s = circle.law(kt[d0], limit, q[r1], q[r2], w_old[d0], w_old[d0 + 1])
    state[d0] = s
    state[d0 + 1] = s


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new):
    """laws/circle.py linear for the contact whose first direction is d0."""
    r1, r2 = trow[d0], trow[d0 + 1]
    f[r1], f[r2], w_new[d0], w_new[d0 + 1] = circle.linear(kt[d0], limit, state[d0], q[r1], q[r2], w_old[d0],
                                                           w_old[d0 + 1])


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_compatible(trow, kt, d0, limit, state, q, w_old, tol_t):
    """laws/circle.py compatible for the contact whose first direction is d0."""
    return circle.compatible(kt[d0], limit, state[d0], q[trow[d0]], q[trow[d0 + 1]], w_old[d0], w_old[d0 + 1], tol_t)


@njit(cache=True, error_model="numpy", inline="always")
def law(nrow, lcode, lpar, fdir, ndir, trow, kt, q, w_old, f, w_new, state):
    """The nonlinear law (return mapping): forces f (local, like q), new sliders and states
    from q and w_old."""
    for c in range(nrow.shape[0]):
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
        N = lpar[c, P_KN] * v
        f[nr] = N
        limit = lpar[c, P_MU] * N
        if lcode[c] == LAW_CIRCLE:  # (out of line: keeps the paper's law compact where it is inlined)
            _circle_law(trow, kt, d0, limit, q, w_old, f, w_new, state)
        else:
            for d in range(d0, d0 + ndir[c]):
                tr = trow[d]
                f[tr], w_new[d], state[d] = uncoupled.law(kt[d], limit, q[tr], w_old[d])


@njit(cache=True, error_model="numpy", inline="always")
def piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, f, w_new):
    """The law in a postulated state S: f = K(S) q + s(S, w_old) where S is linear."""
    for c in range(nrow.shape[0]):
        nr = nrow[c]
        d0 = fdir[c]
        if state[d0] == LIFT:
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]] = 0.0
                w_new[d] = q[trow[d]]
            continue
        N = lpar[c, P_KN] * q[nr]
        f[nr] = N
        limit = lpar[c, P_MU] * N
        if lcode[c] == LAW_CIRCLE:
            _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new)
        else:
            for d in range(d0, d0 + ndir[c]):
                tr = trow[d]
                f[tr], w_new[d] = uncoupled.linear(kt[d], limit, state[d], q[tr], w_old[d])


@njit(cache=True, error_model="numpy", inline="always")
def compatible(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, rtol, length_scale):
    """Does the postulated state satisfy its row of the state table at q (within tolerance)?

    Tolerances: rtol * L on v (L the system length scale) and rtol * (mu k_n |v| + k_t L)
    on the friction test, so that a point on a stick/slip or contact boundary is accepted.
    """
    tol_v = rtol * length_scale
    for c in range(nrow.shape[0]):
        v = q[nrow[c]]
        d0 = fdir[c]
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            continue
        if v < -tol_v:
            return False
        limit = lpar[c, P_MU] * lpar[c, P_KN] * v
        if lcode[c] == LAW_CIRCLE:
            if not _circle_compatible(trow, kt, d0, limit, state, q, w_old, rtol * (abs(limit) + kt[d0] * length_scale)):
                return False
            continue
        for d in range(d0, d0 + ndir[c]):
            tol_t = rtol * (abs(limit) + kt[d] * length_scale)
            if not uncoupled.compatible(kt[d], limit, state[d], q[trow[d]], w_old[d], tol_t):
                return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def compatible_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, rtol, length_scale, f, w_new):
    """:func:`compatible` and, when the postulated state holds, :func:`piecewise_law` at q in
    the same pass over the contacts (the piecewise-linear step's accept test). Returns the
    compatibility; f and w_new are meaningful only when it is True."""
    tol_v = rtol * length_scale
    for c in range(nrow.shape[0]):
        nr = nrow[c]
        v = q[nr]
        d0 = fdir[c]
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]] = 0.0
                w_new[d] = q[trow[d]]
            continue
        if v < -tol_v:
            return False
        N = lpar[c, P_KN] * v
        limit = lpar[c, P_MU] * N
        f[nr] = N
        if lcode[c] == LAW_CIRCLE:
            climit = lpar[c, P_MU] * lpar[c, P_KN] * v
            if not _circle_compatible(trow, kt, d0, climit, state, q, w_old, rtol * (abs(climit) + kt[d0] * length_scale)):
                return False
            _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new)
            continue
        climit = lpar[c, P_MU] * lpar[c, P_KN] * v
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            tol_t = rtol * (abs(climit) + kt[d] * length_scale)
            if not uncoupled.compatible(kt[d], climit, state[d], q[tr], w_old[d], tol_t):
                return False
            f[tr], w_new[d] = uncoupled.linear(kt[d], limit, state[d], q[tr], w_old[d])
    return True


@njit(cache=True, error_model="numpy", inline="always")
def coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, state):
    """True if some contact is in a state without a piecewise-linear form (coupled slip)."""
    for c in range(nrow.shape[0]):
        if state[fdir[c]] == SLIP_COUPLED:
            return True
    return False


@njit(cache=True, nogil=True, error_model="numpy")
def _add_outer(out, k, A, r1, r2):
    """out += k * A[r1]^T A[r2]."""
    n = A.shape[1]
    for i in range(n):
        a = k * A[r1, i]
        if a != 0.0:
            for j in range(n):
                out[i, j] += a * A[r2, j]


@njit(cache=True, error_model="numpy", inline="always")
def _circle_tangent(nrow, lpar, fdir, trow, kt, c, state, q, w_old):
    """The six tangential entries of a friction-circle contact's K(S) (laws/circle.py), at
    (q, w_old), or without a point (q of length 0) the stick ones."""
    d0 = fdir[c]
    mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
    if q.shape[0] == 0:
        return circle.tangent(kt[d0], mu_kn, 0.0, state[d0], False, 0.0, 0.0, 0.0, 0.0)
    return circle.tangent(kt[d0], mu_kn, mu_kn * q[nrow[c]], state[d0], True, q[trow[d0]], q[trow[d0 + 1]],
                          w_old[d0], w_old[d0 + 1])


@njit(cache=True, nogil=True, error_model="numpy")
def contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, state, q, w_old, factor, out):
    """out += factor * K_D(S), with K_D(S) = A^T K(S) A (paper Eq. 7): the laws' local
    stiffness (laws/*.tangent), at (q, w_old) for a coupled slip (q of length 0: no point,
    the stiffest tangent, used for T_min)."""
    for c in range(nrow.shape[0]):
        d0 = fdir[c]
        if state[d0] == LIFT:
            continue
        nr = nrow[c]
        kn = lpar[c, P_KN]
        _add_outer(out, factor * kn, A, nr, nr)
        if lcode[c] == LAW_CIRCLE:
            r1, r2 = trow[d0], trow[d0 + 1]
            k11, k12, k21, k22, k1v, k2v = _circle_tangent(nrow, lpar, fdir, trow, kt, c, state, q, w_old)
            for k, ra, rb in ((k11, r1, r1), (k12, r1, r2), (k21, r2, r1), (k22, r2, r2), (k1v, r1, nr),
                              (k2v, r2, nr)):
                if k != 0.0:
                    _add_outer(out, factor * k, A, ra, rb)
            continue
        mu_kn = lpar[c, P_MU] * kn
        for d in range(d0, d0 + ndir[c]):
            kuu, kuv = uncoupled.tangent(kt[d], mu_kn, state[d])
            if kuu != 0.0:
                _add_outer(out, factor * kuu, A, trow[d], trow[d])
            if kuv != 0.0:
                _add_outer(out, factor * kuv, A, trow[d], nr)


@njit(cache=True, error_model="numpy", inline="always")
def delta_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, kfac, y, out):
    """out = kfac (K(S) - K(stick)) y, local (the low-rank update of kernels/state_solve.py):
    lift-off: -k_t on u, -k_n on v; slip: the slip tangent minus k_t on u; stick: 0."""
    for r in range(out.shape[0]):
        out[r] = 0.0
    for c in range(nrow.shape[0]):
        d0 = fdir[c]
        nr = nrow[c]
        if state[d0] == LIFT:
            out[nr] = -kfac * lpar[c, P_KN] * y[nr]
            for d in range(d0, d0 + ndir[c]):
                out[trow[d]] = -kfac * kt[d] * y[trow[d]]
            continue
        if lcode[c] == LAW_CIRCLE:
            if state[d0] == STICK:
                continue
            r1, r2 = trow[d0], trow[d0 + 1]
            k11, k12, k21, k22, k1v, k2v = _circle_tangent(nrow, lpar, fdir, trow, kt, c, state, q, w_old)
            out[r1] = kfac * ((k11 - kt[d0]) * y[r1] + k12 * y[r2] + k1v * y[nr])
            out[r2] = kfac * (k21 * y[r1] + (k22 - kt[d0]) * y[r2] + k2v * y[nr])
            continue
        mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
        for d in range(d0, d0 + ndir[c]):
            if state[d] != STICK:
                kuu, kuv = uncoupled.tangent(kt[d], mu_kn, state[d])
                out[trow[d]] = kfac * (kuv * y[nr] + (kuu - kt[d]) * y[trow[d]])


# ---- convenience wrappers taking the CompiledSystem (Python, tests, cold paths) --------------


@njit(cache=True, nogil=True, error_model="numpy")
def local_displacement(sys, x, p, q):
    """q = A x - B p + g (A dense, or in CSR for the banded backend of slipstep.system)."""
    if not sys.banded:
        gather(sys.AT, sys.B, sys.g, x, p, q)
        return
    for r in range(q.shape[0]):
        s = sys.g[r]
        for j in range(sys.B.shape[1]):
            s -= sys.B[r, j] * p[j]
        for k in range(sys.A_ptr[r], sys.A_ptr[r + 1]):
            s += sys.A_val[k] * x[sys.A_idx[k]]
        q[r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def contact_law(sys, q, w_old, f, w_new, state):
    """The nonlinear law (see :func:`law`)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    law(nrow, lcode, lpar, fdir, ndir, trow, kt, q, w_old, f, w_new, state)


@njit(cache=True, nogil=True, error_model="numpy")
def linear_law(sys, state, q, w_old, f, w_new):
    """The piecewise-linear law (see :func:`piecewise_law`)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, f, w_new)


@njit(cache=True, nogil=True, error_model="numpy")
def is_compatible(sys, state, q, w_old, rtol):
    """The compatibility check (see :func:`compatible`)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    return compatible(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, rtol, sys.length_scale)


@njit(cache=True, nogil=True, error_model="numpy")
def add_contact_stiffness(sys, state, factor, out):
    """out += factor * K_D(S) without a point (coupled slip: the stick tangent), for T_min."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, sys.A, state, np.empty(0), np.empty(0), factor, out)


@njit(cache=True, nogil=True, error_model="numpy")
def add_tangent_stiffness(sys, state, q, w_old, factor, out):
    """out += factor * A^T K(S; q, w_old) A: the consistent tangent of state S at (q, w_old)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, sys.A, state, q, w_old, factor, out)


@njit(cache=True, nogil=True, error_model="numpy")
def generalised_force(sys, f, out):
    """out = A^T f (A^T dense, or in CSR for the banded backend)."""
    if not sys.banded:
        scatter(sys.A, f, out)
        return
    for j in range(out.shape[0]):
        s = 0.0
        for k in range(sys.AT_ptr[j], sys.AT_ptr[j + 1]):
            s += sys.AT_val[k] * f[sys.AT_idx[k]]
        out[j] = s
