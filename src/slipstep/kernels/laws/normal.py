"""The normal part every law shares (physics.md 2-3), for one contact with normal row nr and
tangential directions d0 .. d0 + nd - 1 (rows trow[d]):

    v >  0   in contact   N = k_n v, the friction limit mu N, the law's tangential states
    v <= 0   LIFT         T = N = 0 and every slider follows, w = u (every direction)

so K(LIFT) = 0 and K(LIFT) - K(stick) is -k_n on v and -k_t on each u. Its margins in time
(kernels/events.py): v >= 0 in contact, -v >= 0 lifted off; a lifted contact that touches
again re-enters in the law's contact state with w = u.
"""

from numba import njit

from slipstep.kernels.codes import LIFT


@njit(cache=True, error_model="numpy", inline="always")
def lift_off(nr, d0, nd, trow, q, f, w_new):
    """The LIFT row of the law: f = 0 on the contact's rows, w_new = u."""
    f[nr] = 0.0
    for d in range(d0, d0 + nd):
        f[trow[d]] = 0.0
        w_new[d] = q[trow[d]]


@njit(cache=True, error_model="numpy", inline="always")
def lift_state(d0, nd, state):
    """Every direction of the contact lifted off."""
    for d in range(d0, d0 + nd):
        state[d] = LIFT


@njit(cache=True, error_model="numpy", inline="always")
def lift_delta(nr, d0, nd, trow, kn, kt, kfac, y, out):
    """out = kfac (K(LIFT) - K(stick)) y on the contact's rows: -k_n on v, -k_t on each u."""
    out[nr] = -kfac * kn * y[nr]
    for d in range(d0, d0 + nd):
        out[trow[d]] = -kfac * kt[d] * y[trow[d]]


@njit(cache=True, error_model="numpy", inline="always")
def lift_delta_rows(nr, d0, nd, trow, kn, kt, rows, kdiag, kcol, koff, m):
    """The rows of K(LIFT) - K(stick) (diagonal entry, no off-diagonal: kcol -1) from slot m:
    each u, then v. Returns the next slot."""
    for d in range(d0, d0 + nd):
        rows[m], kdiag[m], kcol[m], koff[m] = trow[d], -kt[d], -1, 0.0
        m += 1
    rows[m], kdiag[m], kcol[m], koff[m] = nr, -kn, -1, 0.0
    return m + 1
