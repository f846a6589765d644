"""The paper's spring-slider law (physics.md 2-3), per tangential direction: 2D, quasi-3D
uncoupled, and the Jenkins element (a constant normal approach v = g, hence constant
N = k_n g). In contact (v > 0, N = k_n v, limit mu N), with the trial force
T* = k_t (u - w_old):

    |T*| <= mu N                STICK   T = T*,               w = w_old
    T* >  mu N                  SLIP+   T = +mu N,            w = u - T / k_t
    T* < -mu N                  SLIP-   T = -mu N,            w = u - T / k_t

(v <= 0: LIFT, T = N = 0, w = u.) Each direction is bounded on its own, |T_d| <= mu N: a
quasi-3D contact slipping in both directions carries |T| = sqrt(2) mu N. In a fixed state
the law is linear (paper Eq. 5): f = K(S) q + s(S, w_old), K(STICK) = diag(k_t, k_n),
s = (-k_t w_old, 0); K(SLIP+/-) = [[0, +/-mu k_n], [0, k_n]], s = 0; K(LIFT) = 0. The slider
moves with q as w = w_old (stick), w = u -/+ mu k_n v / k_t (slip+/-), w = u (LIFT).

In time (kernels/events.py, the continuous form of :func:`compatible`), a state holds while
its margins stay >= 0: stick mu k_n v -/+ k_t (u - w) (one per side, crossing into slip+/-),
slip+/- +/- dw/dt (the slider keeps moving; crossing into stick).
"""

from numba import njit

from slipstep.kernels.codes import SLIP_NEG, SLIP_POS, STICK


@njit(cache=True, error_model="numpy", inline="always")
def law(kt, limit, u, w_old):
    """(T, w_new, state) of one direction in contact (module docstring table)."""
    trial = kt * (u - w_old)
    if abs(trial) <= limit:
        return trial, w_old, STICK
    if trial > 0.0:
        return limit, u - limit / kt, SLIP_POS
    return -limit, u + limit / kt, SLIP_NEG


@njit(cache=True, error_model="numpy", inline="always")
def linear(kt, limit, state, u, w_old):
    """(T, w_new) = K(S) q + s(S, w_old) of one direction in the postulated state S."""
    if state == STICK:
        return kt * (u - w_old), w_old
    T = limit if state == SLIP_POS else -limit
    return T, u - T / kt


@njit(cache=True, error_model="numpy", inline="always")
def compatible(kt, limit, state, u, w_old, tol_t):
    """Does the postulated state of one direction hold (friction test within tol_t)?"""
    trial = kt * (u - w_old)
    if state == STICK:
        return abs(trial) <= limit + tol_t
    if state == SLIP_POS:
        return trial >= limit - tol_t
    return trial <= -limit + tol_t


@njit(cache=True, error_model="numpy", inline="always")
def tangent(kt, mu_kn, state):
    """(dT/du, dT/dv) of one direction in state S (constant in each state)."""
    if state == STICK:
        return kt, 0.0
    if state == SLIP_POS:
        return 0.0, mu_kn
    return 0.0, -mu_kn


@njit(cache=True, error_model="numpy", inline="always")
def slider_derivative(kt, mu_kn, state):
    """(a, s) of the slider's derivative dw = a dq_t - s dq_n in state S at fixed w_old (the
    shooting sensitivity's rows, the slip margins of the events): stick a = s = 0 (with
    dT/dw_old = -k_t); slip+/- a = 1, s = +/-mu k_n / k_t; LIFT a = 1, s = 0."""
    if state == STICK:
        return 0.0, 0.0
    if state == SLIP_POS:
        return 1.0, mu_kn / kt
    if state == SLIP_NEG:
        return 1.0, -mu_kn / kt
    return 1.0, 0.0


@njit(cache=True, error_model="numpy", inline="always")
def stick_margin(kt, mu_kn, side):
    """(a, b, crossed): the stick margin a v - b (u - w) >= 0 of one side (side 0: T* <= mu N,
    side 1: T* >= -mu N) and the state entered where it crosses zero."""
    if side == 0:
        return mu_kn, kt, SLIP_POS
    return mu_kn, -kt, SLIP_NEG

