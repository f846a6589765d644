"""The normal part every law shares (physics.md 2-3), for one contact with normal row nr and
tangential directions d0 .. d0 + nd - 1 (rows trow[d]):

    v >  0   in contact   N = k_n v, the friction limit mu N, the law's tangential states
    v <= 0   LIFT         T = N = 0 and every slider follows, w = u (every direction)

so K(LIFT) = 0 and K(LIFT) - K(stick) is -k_n on v and -k_t on each u. Its margins in time
(kernels/events.py): v >= 0 in contact, -v >= 0 lifted off; a lifted contact that touches
again re-enters in the law's contact state with w = u.

Scalar functions, like the laws' (the contact loops of laws/__init__.py call them).
"""

from numba import njit

from slipstep.kernels.codes import LIFT


@njit(cache=True, error_model="numpy", inline="always")
def lift_off(u):
    """(T, w, state) of one direction of a lifted contact (its N = 0)."""
    return 0.0, u, LIFT


@njit(cache=True, error_model="numpy", inline="always")
def lift_delta(k):
    """The entry of K(LIFT) - K(stick) on a row of stick stiffness k (k_n on v, k_t on u):
    -k, on the diagonal only."""
    return -k
