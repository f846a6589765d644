"""Coupled 3D friction: a friction circle with variable normal load and lift-off.

One slider w = (w1, w2) in the tangent plane of a 3-row contact (u1, u2, v), isotropic
tangential stiffness k_t (the same for both directions), N = k_n v and the trial force
T* = k_t (u - w_old) (a 2-vector). Radial return (the closest point on the circle, which
for isotropic k_t is also the maximum-dissipation one), in contact (v > 0):

    |T*| <= mu N         STICK         T = T*,                  w = w_old
    |T*| >  mu N         SLIP_COUPLED  T = mu N T* / |T*|,      w = u - T / k_t

(v <= 0: LIFT, T = N = 0, w = u), so |T| <= mu N as a Euclidean norm, and the slip increment
w - w_old = (|T*| - mu N) e / k_t (e = T*/|T*|) is along T: the force -T the contact puts on
the structure opposes the slip rate, and the dissipation T . dw = mu N |dw| >= 0.

LIFT and STICK are linear (K(STICK) = diag(k_t, k_t, k_n), s = (-k_t w_old, 0)); a coupled
slip is not: its direction e moves with q. Its consistent tangent (d f / d q at fixed w_old):

    dT/du = mu N k_t / |T*| (I - e e^T),   dT/dv = mu k_n e,   dN/dv = k_n,   dN/du = 0

Without a point (the T_min estimate) a coupled slip takes the stick tangent, the stiffest.
|T*| is computed with hypot (no underflow of the squares).
"""

import math

from numba import njit

from slipstep.kernels.codes import SLIP_COUPLED, STICK


@njit(cache=True, error_model="numpy", inline="always")
def law(kt, limit, u1, u2, w1, w2):
    """(T1, T2, w1_new, w2_new, state): the radial return (module docstring table)."""
    t1 = kt * (u1 - w1)
    t2 = kt * (u2 - w2)
    norm = math.hypot(t1, t2)
    if norm <= limit:
        return t1, t2, w1, w2, STICK
    s = limit / norm
    return s * t1, s * t2, u1 - s * t1 / kt, u2 - s * t2 / kt, SLIP_COUPLED


@njit(cache=True, error_model="numpy", inline="always")
def linear(kt, limit, state, u1, u2, w1, w2):
    """(T1, T2, w1_new, w2_new) in the postulated state: linear in STICK; in a coupled slip
    the radial-return force itself, T = mu N T*/|T*| (no linear form)."""
    t1 = kt * (u1 - w1)
    t2 = kt * (u2 - w2)
    if state == STICK:
        return t1, t2, w1, w2
    norm = math.hypot(t1, t2)
    s = limit / norm if norm > 0.0 else 0.0
    return s * t1, s * t2, u1 - s * t1 / kt, u2 - s * t2 / kt


@njit(cache=True, error_model="numpy", inline="always")
def compatible(kt, limit, state, u1, u2, w1, w2, tol_t):
    """Does the state hold? The stick test on the norm, |T*| <= mu N + tol_t."""
    norm = math.hypot(kt * (u1 - w1), kt * (u2 - w2))
    if state == STICK:
        return norm <= limit + tol_t
    return norm >= limit - tol_t


@njit(cache=True, error_model="numpy", inline="always")
def tangent(kt, mu_kn, limit, state, at_point, u1, u2, w1, w2):
    """(dT1/du1, dT1/du2, dT2/du1, dT2/du2, dT1/dv, dT2/dv) in state S: the stick stiffness, or
    the consistent tangent of a coupled slip at (u, w_old) (at_point False: the stick one)."""
    if state == STICK or not at_point:
        return kt, 0.0, 0.0, kt, 0.0, 0.0
    t1 = kt * (u1 - w1)
    t2 = kt * (u2 - w2)
    norm = math.hypot(t1, t2)
    if norm == 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    e1, e2 = t1 / norm, t2 / norm
    g = limit * kt / norm
    return g * (1.0 - e1 * e1), -g * e1 * e2, -g * e2 * e1, g * (1.0 - e2 * e2), mu_kn * e1, mu_kn * e2
