"""The contact laws over all contacts (physics.md 2-3): gather, scatter, the K_D assembly, and,
re-exported from :mod:`slipstep.kernels.laws` where the one dispatch on the law code is, the
loops applying each contact's row of the state table (law, piecewise_law, compatible,
compatible_law, coupled, delta_stiffness).

Every contact c has a law code (``lcode[c]``, kernels/codes.py) and a row of the law
parameter table (``lpar[c]``: k_n, mu); k_t is per tangential direction. The laws:

* LAW_UNCOUPLED (laws/uncoupled.py): the paper's 2D and quasi-3D law, one slider per
  tangential direction, |T_d| <= mu N each (a quasi-3D contact can carry sqrt(2) mu N);
  the Jenkins element is this law with a constant normal approach;
* LAW_CIRCLE (laws/circle.py): coupled 3D friction circle, |T| <= mu N as a vector norm.

Shared normal part (laws/normal.py): N = k_n v, and v <= 0 is LIFT (T = N = 0, w = u,
every direction).
In a state S with a piecewise-linear form the law is f = K(S) q + s(S, w_old) (paper Eq. 5),
assembled (paper Eq. 7) as K_D(S) = A^T K(S) A; the generalised contact force is A^T f.
A coupled slip has no such form: its K is the consistent tangent at (q, w_old), and a step
in that state is solved by Newton (kernels/march.py). The state of a contact is stored per
tangential direction (codes.STATE_NAMES).
"""

import numpy as np
from numba import njit

from slipstep.kernels import laws
from slipstep.kernels.borrow import borrowed
from slipstep.kernels.codes import LIFT, SLIP_COUPLED, SLIP_NEG, SLIP_POS, STICK  # noqa: F401  (re-exported)
from slipstep.kernels.laws import (  # noqa: F401  (re-exported: the loops over the contacts)
    compatible, compatible_law, coupled, delta_stiffness, law, piecewise_law,
)
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
def _add_outer(out, k, A, r1, r2):
    """out += k * A[r1]^T A[r2]."""
    n = A.shape[1]
    for i in range(n):
        a = k * A[r1, i]
        if a != 0.0:
            for j in range(n):
                out[i, j] += a * A[r2, j]


@njit(cache=True, nogil=True, error_model="numpy")
def contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, state, q, w_old, factor, out):
    """out += factor * K_D(S), with K_D(S) = A^T K(S) A (paper Eq. 7): the laws' local
    stiffness (laws.stiffness), at (q, w_old) for a coupled slip (q of length 0: no point,
    the stiffest tangent, used for T_min)."""
    cl = borrowed((nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old))  # no counting per contact
    nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old = cl
    for c in range(nrow.shape[0]):
        ks, ra, rb = laws.stiffness(c, nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old)
        for i in range(len(ks)):
            if ks[i] != 0.0:
                _add_outer(out, factor * ks[i], A, ra[i], rb[i])


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
