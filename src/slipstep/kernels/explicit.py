"""Explicit time marches: central difference and classical Runge-Kutta 4 (paper App. A.1),
with the contact law of :mod:`slipstep.kernels.contact` and the contact-state adaptive step.

Legend as in :mod:`slipstep.kernels.march`: x, v, a DOF displacement, velocity, acceleration;
p prescribed motion; q = A x - B p + g; f local contact forces; w sliders; S contact state.
Equation of motion (paper Eq. 1):  M a = f_e(t) - C v - K x - A^T f(q(x, t), w_old).

Central difference (Newmark beta = 0, gamma = 1/2, velocity form valid for a variable dt):
    x_{n+1} = x_n + dt v_n + dt^2/2 a_n
    f_{n+1}, w_{n+1}, S_{n+1} = law(q(x_{n+1}, t_{n+1}), w_n)
    (M + dt/2 C) a_{n+1} = f_e(t_{n+1}) - K x_{n+1} - A^T f_{n+1} - C (v_n + dt/2 a_n)
    v_{n+1} = v_n + dt/2 (a_n + a_{n+1})
With C = 0 this is x_{n+1} - 2 x_n + x_{n-1} = dt^2 a_n. Stable for omega_max dt <= 2.
One linear solve (with the factorised M + dt/2 C) and one law call per step.

Runge-Kutta 4 on the first-order form y = [x, v], y' = F(t, y) = [v, M^-1 (f_e - C v - K x - A^T f)]:
    k1 = F(t, y_n), k2 = F(t + dt/2, y_n + dt/2 k1), k3 = F(t + dt/2, y_n + dt/2 k2),
    k4 = F(t + dt, y_n + dt k3),   y_{n+1} = y_n + dt/6 (k1 + 2 k2 + 2 k3 + k4)
Every stage evaluates the law with the slider w_n of the last accepted step; the sliders
and states are updated once, by the law at q(x_{n+1}), when the step is accepted.
k1 is a_n of the previous step (first same as last: the force of the law at q_{n+1} with
w_{n+1} equals the one with w_n, by construction of the slider update), so a step costs
3 stage solves + 1 solve for a_{n+1} = 4 solves with the factorised M, and 4 law calls.

Adaptive step (paper 4.2 with the scheme's own stability limit): dt = step_factor * T_min(S_n),
T_min = 2 pi / sqrt(max |eig(M^-1 (K + K_D(S)))|) cached per state; the step is redone with
the smaller limit when the state reached at its end has a shorter one (as in march.py).
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.cache import find_slot
from slipstep.kernels.contact import add_contact_stiffness, contact_law, generalised_force, local_displacement
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.march import (
    C_FACTORISATIONS, C_FAIL_STEP, C_LAW_CALLS, C_REDOS, C_SOLVES, C_STATE_CHANGES, C_STEPS,
    CAPACITY, NON_FINITE, OK, SINGULAR,
)
from slipstep.kernels.signals import force_at, motion_at

# float parameters
DT, STEP_FACTOR, DT_MAX, T_START, T_END, SINGULAR_RTOL, DIVERGENCE = range(7)
N_FPAR = 7
# int parameters
KIND, ADAPTIVE, MAX_REDO = range(3)
N_IPAR = 3
CENTRAL_DIFFERENCE, RK4 = 0, 1


class ExplicitWorkspace(NamedTuple):
    """Carried state and scratch of an explicit march (allocated once in Python)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    w: np.ndarray
    state: np.ndarray  # int8 (nd)
    x1: np.ndarray
    v1: np.ndarray
    a1: np.ndarray
    q1: np.ndarray
    f1: np.ndarray
    w1: np.ndarray
    state1: np.ndarray  # int8 (nd)
    gf: np.ndarray  # A^T f scratch
    fe: np.ndarray  # f_e scratch
    p: np.ndarray  # prescribed motion scratch
    rhs: np.ndarray
    xs: np.ndarray  # RK4 stage displacement
    vs: np.ndarray  # RK4 stage velocity
    kx: np.ndarray  # (4, n) RK4 stage slopes of x
    kv: np.ndarray  # (4, n) RK4 stage slopes of v
    fs: np.ndarray  # stage local forces (discarded)
    ws_: np.ndarray  # stage sliders (discarded)
    ss: np.ndarray  # stage states (discarded), int8
    lu: np.ndarray  # (n, n) factorised M (RK4) or M + dt/2 C (central difference)
    piv: np.ndarray  # int64 (n)
    lu_dt: np.ndarray  # (1,) dt of the current factorisation (nan: none)
    Minv: np.ndarray
    tmin_keys: np.ndarray  # int8 (cap, nd)
    tmin_used: np.ndarray  # bool (cap)
    tmin_value: np.ndarray  # (cap,) s


@njit(cache=True, error_model="numpy")
def explicit_step_limit(sys, fpar, ws, state):
    """dt limit of a state: step_factor * T_min(S), capped at dt_max; T_min cached per state."""
    slot, found = find_slot(ws.tmin_keys, ws.tmin_used, state)
    if not found:
        n = ws.x.shape[0]
        Keff = sys.K.copy()
        add_contact_stiffness(sys, state, 1.0, Keff)
        D = np.dot(ws.Minv, Keff).astype(np.complex128)
        ev = np.linalg.eigvals(D)
        wmax2 = 0.0
        for i in range(n):
            if abs(ev[i]) > wmax2:
                wmax2 = abs(ev[i])
        ws.tmin_value[slot] = 2.0 * np.pi / np.sqrt(wmax2) if wmax2 > 0.0 else np.inf
    return min(fpar[STEP_FACTOR] * ws.tmin_value[slot], fpar[DT_MAX])


@njit(cache=True, error_model="numpy")
def _factor(sys, fpar, ipar, ws, dt, counters):
    """Factorise M (RK4) or M + dt/2 C (central difference) if not done for this dt."""
    if ipar[KIND] == RK4:
        if ws.lu_dt[0] == ws.lu_dt[0]:  # not nan: M already factorised
            return True
        c = 0.0
    else:
        if ws.lu_dt[0] == dt:
            return True
        c = 0.5 * dt
    n = ws.x.shape[0]
    Meff = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            Meff[i, j] = sys.M[i, j] + c * sys.C[i, j]
    ok = lu_factor(Meff, ws.lu, ws.piv, fpar[SINGULAR_RTOL])
    counters[C_FACTORISATIONS] += 1
    ws.lu_dt[0] = dt
    return ok


@njit(cache=True, error_model="numpy")
def _accel(sys, ws, t, x, v, w_old, f, w_new, state, q, out):
    """out = M^-1 (f_e(t) - C v - K x - A^T f(q(x, t), w_old)); also fills q, f, w_new, state."""
    n = x.shape[0]
    motion_at(sys, t, ws.p)
    force_at(sys, t, 1.0, ws.fe)
    local_displacement(sys, x, ws.p, q)
    contact_law(sys, q, w_old, f, w_new, state)
    generalised_force(sys, f, ws.gf)
    for i in range(n):
        s = ws.fe[i] - ws.gf[i]
        for j in range(n):
            s -= sys.C[i, j] * v[j] + sys.K[i, j] * x[j]
        ws.rhs[i] = s
    lu_solve(ws.lu, ws.piv, ws.rhs, out)


@njit(cache=True, error_model="numpy")
def _central_difference_step(sys, fpar, ws, t1, dt, counters):
    """One central-difference step into the '1' fields. Returns the number of solves."""
    n = ws.x.shape[0]
    h = 0.5 * dt
    for i in range(n):
        ws.x1[i] = ws.x[i] + dt * ws.v[i] + h * dt * ws.a[i]
        ws.vs[i] = ws.v[i] + h * ws.a[i]  # predicted velocity v_n + dt/2 a_n
    motion_at(sys, t1, ws.p)
    force_at(sys, t1, 1.0, ws.fe)
    local_displacement(sys, ws.x1, ws.p, ws.q1)
    contact_law(sys, ws.q1, ws.w, ws.f1, ws.w1, ws.state1)
    counters[C_LAW_CALLS] += 1
    generalised_force(sys, ws.f1, ws.gf)
    for i in range(n):
        s = ws.fe[i] - ws.gf[i]
        for j in range(n):
            s -= sys.K[i, j] * ws.x1[j] + sys.C[i, j] * ws.vs[j]
        ws.rhs[i] = s
    lu_solve(ws.lu, ws.piv, ws.rhs, ws.a1)
    for i in range(n):
        ws.v1[i] = ws.vs[i] + h * ws.a1[i]
    return 1


@njit(cache=True, error_model="numpy")
def _rk4_step(sys, fpar, ws, t, dt, counters):
    """One classical RK4 step on [x, v] into the '1' fields (stages use w_n). Returns solves."""
    n = ws.x.shape[0]
    for i in range(n):
        ws.kx[0, i] = ws.v[i]
        ws.kv[0, i] = ws.a[i]
    cs = (0.5, 0.5, 1.0)
    for s in range(1, 4):
        c = cs[s - 1]
        for i in range(n):
            ws.xs[i] = ws.x[i] + c * dt * ws.kx[s - 1, i]
            ws.vs[i] = ws.v[i] + c * dt * ws.kv[s - 1, i]
        _accel(sys, ws, t + c * dt, ws.xs, ws.vs, ws.w, ws.fs, ws.ws_, ws.ss, ws.q1, ws.kv[s])
        counters[C_LAW_CALLS] += 1
        for i in range(n):
            ws.kx[s, i] = ws.vs[i]
    for i in range(n):
        ws.x1[i] = ws.x[i] + dt / 6.0 * (ws.kx[0, i] + 2.0 * ws.kx[1, i] + 2.0 * ws.kx[2, i] + ws.kx[3, i])
        ws.v1[i] = ws.v[i] + dt / 6.0 * (ws.kv[0, i] + 2.0 * ws.kv[1, i] + 2.0 * ws.kv[2, i] + ws.kv[3, i])
    # accepted-step law: forces, sliders and states at q_{n+1}; a_{n+1} (k1 of the next step)
    _accel(sys, ws, t + dt, ws.x1, ws.v1, ws.w, ws.f1, ws.w1, ws.state1, ws.q1, ws.a1)
    counters[C_LAW_CALLS] += 1
    return 4


@njit(cache=True, error_model="numpy")
def _step(sys, fpar, ipar, ws, t, dt, counters):
    """One step of the chosen scheme from t to t + dt. Returns (status, solves)."""
    if not _factor(sys, fpar, ipar, ws, dt, counters):
        return SINGULAR, 0
    if ipar[KIND] == RK4:
        solves = _rk4_step(sys, fpar, ws, t, dt, counters)
    else:
        solves = _central_difference_step(sys, fpar, ws, t + dt, dt, counters)
    counters[C_SOLVES] += solves
    bound = fpar[DIVERGENCE]
    for i in range(ws.x1.shape[0]):
        if not (np.isfinite(ws.x1[i]) and np.isfinite(ws.v1[i]) and np.isfinite(ws.a1[i])):
            return NON_FINITE, solves
    for r in range(ws.q1.shape[0]):
        if not abs(ws.q1[r]) <= bound:
            return NON_FINITE, solves
    return OK, solves


@njit(cache=True, error_model="numpy")
def _store(ws, out, k, t, dt, solves):
    out.t[k] = t
    out.dt[k] = dt
    out.solves[k] = solves
    for i in range(ws.x.shape[0]):
        out.x[k, i] = ws.x[i]
        out.v[k, i] = ws.v[i]
        out.a[k, i] = ws.a[i]
    for d in range(ws.w.shape[0]):
        out.w[k, d] = ws.w[d]
        out.state[k, d] = ws.state[d]


@njit(cache=True, error_model="numpy")
def _accept(ws):
    changed = False
    for i in range(ws.x.shape[0]):
        ws.x[i] = ws.x1[i]
        ws.v[i] = ws.v1[i]
        ws.a[i] = ws.a1[i]
    for d in range(ws.w.shape[0]):
        ws.w[d] = ws.w1[d]
        if ws.state[d] != ws.state1[d]:
            changed = True
        ws.state[d] = ws.state1[d]
    return changed


@njit(cache=True, error_model="numpy")
def explicit_march(sys, fpar, ipar, ws, out, q0, f0):
    """March from t_start to t_end writing step k into out[k] (k = 0: the initial state with
    local q0, f0), same layout and counters as :func:`slipstep.kernels.march.march`.
    Returns the status; out.counters[C_STEPS] steps done."""
    counters = out.counters
    cap = out.t.shape[0] - 1
    for r in range(q0.shape[0]):
        out.q[0, r] = q0[r]
        out.f[0, r] = f0[r]
    t = fpar[T_START]
    t_end = fpar[T_END]
    _store(ws, out, 0, t, 0.0, 0)
    k = 0
    adaptive = ipar[ADAPTIVE] == 1
    tiny = 1e-12 * (t_end - t + 1e-300)
    status = OK
    while t < t_end - tiny:
        if k >= cap:
            status = CAPACITY
            break
        if adaptive:
            dt = explicit_step_limit(sys, fpar, ws, ws.state)
        else:
            dt = fpar[DT]
        if t + dt > t_end - tiny:
            dt = t_end - t
        status, solves = _step(sys, fpar, ipar, ws, t, dt, counters)
        if adaptive and status == OK:
            for redo in range(ipar[MAX_REDO]):
                limit = explicit_step_limit(sys, fpar, ws, ws.state1)
                if limit >= dt * (1.0 - 1e-9):
                    break
                counters[C_REDOS] += 1
                dt = limit
                status, more = _step(sys, fpar, ipar, ws, t, dt, counters)
                solves += more
                if status != OK:
                    break
        if status != OK:
            counters[C_FAIL_STEP] = k + 1
            out.t[k + 1] = t + dt
            break
        if _accept(ws):
            counters[C_STATE_CHANGES] += 1
        t += dt
        k += 1
        _store(ws, out, k, t, dt, solves)
        for r in range(ws.q1.shape[0]):
            out.q[k, r] = ws.q1[r]
            out.f[k, r] = ws.f1[r]
    counters[C_STEPS] = k
    return status
