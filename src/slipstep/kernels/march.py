"""The implicit time march: Newmark / HHT / generalised-alpha and quasi-static, with the
modified-Newton, full-Newton and piecewise-linear step solvers and the contact-state
adaptive step (physics.md section 4; paper 4.2, 4.3, 5, Appendices A.3, A.4, B).

Legend. x, v, a: DOF displacement, velocity, acceleration; dx = x_{n+1} - x_n (solved for,
never x_{n+1}, to keep digits); p: prescribed motion; q = A x - B p + g: local contact
displacements; f: local contact forces; w: sliders; S: contact state (per direction).

Newmark relations (beta, gamma):
    a_{n+1} = a0 dx - a2 v_n - a3 a_n,         a0 = 1/(beta dt^2), a2 = 1/(beta dt), a3 = 1/(2 beta) - 1
    v_{n+1} = a1 dx + (1 - gamma/beta) v_n + dt (1 - gamma/(2 beta)) a_n,   a1 = gamma/(beta dt)
Generalised-alpha balance (alpha_m = alpha_f = 0: Newmark; alpha_m = 0: HHT):
    M a_{n+1-am} + C v_{n+1-af} + K x_{n+1-af} + A^T f_{n+1-af} = f_e(t_{n+1-af})
with y_{n+1-a} = (1 - a) y_{n+1} + a y_n. Written as the residual in dx:
    r(dx) = r0 - Lin dx - (1 - af) A^T f(q_base + A dx)
    Lin   = (1 - am) a0 M + (1 - af) a1 C + (1 - af) K,      q_base = A x_n - B p_{n+1} + g
and the Jacobian in state S is J(S) = Lin + (1 - af) K_D(S).
Quasi-static (inertia off, paper Eq. 10): Lin = K, r0 = f_e - K x_n, J(S) = K + K_D(S).

Step solvers:
    0 modified Newton (Method 1): J(all stick) factorised once per dt, iterate on dx until
      max |A delta| <= tol * L; each iteration = one contact-law call + one solve.
    1 full Newton: J(S) of the current iterate's state.
    2 piecewise linear (Method 3/4): postulate S = S_n, one solve with J(S), accept if S is
      compatible at the computed q, else postulate the law's states there and re-solve.
      If the states cycle, fall back to modified Newton for that step (counted).
Adaptive step (Method 2): dt = step_factor * T_min(S_n), T_min = 2 pi / sqrt(max|eig(M^-1 (K + K_D(S)))|);
redo the step with the smaller dt when the new state's limit is below the dt used.
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.cache import find_slot
from slipstep.kernels.contact import (
    STICK, add_contact_stiffness, contact_law, generalised_force, is_compatible,
    linear_law, local_displacement,
)
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.signals import force_at, motion_at

# float parameters
BETA, GAMMA, ALPHA_M, ALPHA_F, DT, STEP_FACTOR, DT_MAX, TOL, STATE_RTOL, SINGULAR_RTOL, T_START, T_END = range(12)
N_FPAR = 12
# int parameters
SOLVER, ADAPTIVE, INERTIA, MAX_ITER, MAX_STATE_ITER, MAX_REDO, FALLBACK, SIGNALS = range(8)
N_IPAR = 8
MODIFIED_NEWTON, FULL_NEWTON, PIECEWISE_LINEAR = 0, 1, 2
# counters
C_STEPS, C_SOLVES, C_FACTORISATIONS, C_LAW_CALLS, C_REDOS, C_FALLBACKS, C_STATE_CHANGES, C_FAIL_STEP, C_N_VISITED = range(9)
N_COUNTERS = 9
# status (mirrors slipstep.errors.Status)
OK, NOT_CONVERGED, STATE_CYCLING, SINGULAR, CAPACITY, NON_FINITE = 0, 1, 2, 3, 4, 5


class Workspace(NamedTuple):
    """Scratch and carried state of a march; allocated once in Python (see methods.base)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    fe: np.ndarray  # f_e(t_n)
    gf: np.ndarray  # A^T f_n
    w: np.ndarray
    state: np.ndarray  # int8
    x1: np.ndarray
    v1: np.ndarray
    a1: np.ndarray
    fe1: np.ndarray
    gf1: np.ndarray
    f1: np.ndarray
    q1: np.ndarray
    w1: np.ndarray
    state1: np.ndarray
    dx: np.ndarray
    delta: np.ndarray
    r0: np.ndarray
    r: np.ndarray
    p: np.ndarray
    qbase: np.ndarray
    Adelta: np.ndarray
    Lin: np.ndarray
    J: np.ndarray
    Minv: np.ndarray
    key: np.ndarray  # int8 (2 nd): [S for K_D, S for dt]
    dt_state: np.ndarray  # int8 (nd)
    stick: np.ndarray  # int8 (nd) all STICK
    cache_keys: np.ndarray  # int8 (cap, 2 nd)
    cache_used: np.ndarray  # bool (cap)
    cache_ok: np.ndarray  # bool (cap + 1): factorisation not singular
    cache_lu: np.ndarray  # (cap + 1, n, n); slot cap is scratch
    cache_piv: np.ndarray  # int64 (cap + 1, n)
    tmin_keys: np.ndarray  # int8 (cap, nd)
    tmin_used: np.ndarray
    tmin_value: np.ndarray  # (cap,) s
    lin_dt: np.ndarray  # (1,) dt of the current Lin
    visited: np.ndarray  # int8 (max_state_iter + 1, nd): states of the last state iteration


class Outputs(NamedTuple):
    t: np.ndarray
    dt: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    q: np.ndarray
    f: np.ndarray
    w: np.ndarray
    state: np.ndarray
    solves: np.ndarray
    counters: np.ndarray


@njit(cache=True)
def _newmark_coefficients(fpar, dt):
    beta = fpar[BETA]
    gamma = fpar[GAMMA]
    a0 = 1.0 / (beta * dt * dt)
    a1 = gamma / (beta * dt)
    a2 = 1.0 / (beta * dt)
    a3 = 1.0 / (2.0 * beta) - 1.0
    b1 = 1.0 - gamma / beta
    b2 = dt * (1.0 - gamma / (2.0 * beta))
    return a0, a1, a2, a3, b1, b2


@njit(cache=True)
def _build_lin(sys, fpar, ipar, ws, dt):
    """Lin = (1-am) a0 M + (1-af) a1 C + (1-af) K  (inertia on), or K (quasi-static)."""
    n = ws.x.shape[0]
    if ipar[INERTIA] == 1:
        a0, a1, a2, a3, b1, b2 = _newmark_coefficients(fpar, dt)
        cm = (1.0 - fpar[ALPHA_M]) * a0
        cc = (1.0 - fpar[ALPHA_F]) * a1
        ck = 1.0 - fpar[ALPHA_F]
        for i in range(n):
            for j in range(n):
                ws.Lin[i, j] = cm * sys.M[i, j] + cc * sys.C[i, j] + ck * sys.K[i, j]
    else:
        for i in range(n):
            for j in range(n):
                ws.Lin[i, j] = sys.K[i, j]
    ws.lin_dt[0] = dt


@njit(cache=True)
def _factor(sys, fpar, ipar, ws, kd_state, nominal, counters):
    """Slot of the factorised J(kd_state) = Lin + (1-af) K_D(kd_state) for the current dt.

    Cached per key (kd_state, dt_state); a non-nominal dt (the last, shortened step)
    uses the scratch slot. Returns (slot, ok)."""
    nd = kd_state.shape[0]
    for d in range(nd):
        ws.key[d] = kd_state[d]
        ws.key[nd + d] = ws.dt_state[d]
    cap = ws.cache_used.shape[0]
    if nominal:
        slot, found = find_slot(ws.cache_keys, ws.cache_used, ws.key)
        if found:
            return slot, ws.cache_ok[slot]
    else:
        slot = cap
    n = ws.x.shape[0]
    for i in range(n):
        for j in range(n):
            ws.J[i, j] = ws.Lin[i, j]
    kfac = (1.0 - fpar[ALPHA_F]) if ipar[INERTIA] == 1 else 1.0
    add_contact_stiffness(sys, kd_state, kfac, ws.J)
    ok = lu_factor(ws.J, ws.cache_lu[slot], ws.cache_piv[slot], fpar[SINGULAR_RTOL])
    ws.cache_ok[slot] = ok
    counters[C_FACTORISATIONS] += 1
    return slot, ok


@njit(cache=True)
def _residual_base(sys, fpar, ipar, ws, t1, dt, load_factor):
    """f_e(t_{n+1}), p(t_{n+1}), q_base and r0 (the part of the residual independent of dx)."""
    n = ws.x.shape[0]
    if ipar[SIGNALS] == 1:
        force_at(sys, t1, load_factor, ws.fe1)
        motion_at(sys, t1, ws.p)
    else:
        for i in range(n):
            ws.fe1[i] = load_factor * sys.constant_force[i]
        for i in range(ws.p.shape[0]):
            ws.p[i] = 0.0
    local_displacement(sys, ws.x, ws.p, ws.qbase)
    am = fpar[ALPHA_M]
    af = fpar[ALPHA_F]
    if ipar[INERTIA] == 1:
        a0, a1, a2, a3, b1, b2 = _newmark_coefficients(fpar, dt)
        for i in range(n):
            s = (1.0 - af) * ws.fe1[i] + af * ws.fe[i] - ws.gf[i] * af
            for j in range(n):
                acc = (1.0 - am) * (-a2 * ws.v[j] - a3 * ws.a[j]) + am * ws.a[j]
                vel = (1.0 - af) * (b1 * ws.v[j] + b2 * ws.a[j]) + af * ws.v[j]
                s -= sys.M[i, j] * acc + sys.C[i, j] * vel + sys.K[i, j] * ws.x[j]
            ws.r0[i] = s
    else:
        for i in range(n):
            s = ws.fe1[i]
            for j in range(n):
                s -= sys.K[i, j] * ws.x[j]
            ws.r0[i] = s


@njit(cache=True)
def _update_q(sys, ws):
    """q1 = q_base + A dx."""
    A = sys.A
    for r in range(A.shape[0]):
        s = ws.qbase[r]
        for j in range(A.shape[1]):
            s += A[r, j] * ws.dx[j]
        ws.q1[r] = s


@njit(cache=True)
def _increment_small(sys, fpar, ws):
    """Convergence on the increment: max |A delta| <= tol * L (max |delta| without contacts)."""
    A = sys.A
    L = fpar[TOL] * sys.length_scale
    if A.shape[0] == 0:
        for j in range(ws.delta.shape[0]):
            if abs(ws.delta[j]) > L:
                return False
        return True
    for r in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[r, j] * ws.delta[j]
        if abs(s) > L:
            return False
    return True


@njit(cache=True)
def _newton(sys, fpar, ipar, ws, nominal, full, counters):
    """Modified (J of all stick) or full (J of the current state) Newton on dx. Returns (status, solves)."""
    n = ws.x.shape[0]
    af = fpar[ALPHA_F] if ipar[INERTIA] == 1 else 0.0
    for i in range(n):
        ws.dx[i] = 0.0
    solves = 0
    slot, ok = _factor(sys, fpar, ipar, ws, ws.stick, nominal, counters)
    if not ok:
        return SINGULAR, solves
    for it in range(ipar[MAX_ITER]):
        _update_q(sys, ws)
        contact_law(sys, ws.q1, ws.w, ws.f1, ws.w1, ws.state1)
        counters[C_LAW_CALLS] += 1
        generalised_force(sys, ws.f1, ws.gf1)
        for i in range(n):
            s = ws.r0[i] - (1.0 - af) * ws.gf1[i]
            for j in range(n):
                s -= ws.Lin[i, j] * ws.dx[j]
            ws.r[i] = s
        use = slot
        if full:
            s2, ok2 = _factor(sys, fpar, ipar, ws, ws.state1, nominal, counters)
            if ok2:
                use = s2
        lu_solve(ws.cache_lu[use], ws.cache_piv[use], ws.r, ws.delta)
        solves += 1
        for i in range(n):
            ws.dx[i] += ws.delta[i]
            if not np.isfinite(ws.dx[i]):
                return NON_FINITE, solves
        if _increment_small(sys, fpar, ws):
            _update_q(sys, ws)
            contact_law(sys, ws.q1, ws.w, ws.f1, ws.w1, ws.state1)
            counters[C_LAW_CALLS] += 1
            return OK, solves
    return NOT_CONVERGED, solves


@njit(cache=True)
def _piecewise_linear(sys, fpar, ipar, ws, nominal, counters):
    """Postulate S = S_n, solve the linear step, check compatibility, re-solve on a
    transition (paper Appendix A.4 / B). Returns (status, solves)."""
    n = ws.x.shape[0]
    nd = ws.state.shape[0]
    af = fpar[ALPHA_F] if ipar[INERTIA] == 1 else 0.0
    for d in range(nd):
        ws.state1[d] = ws.state[d]
    solves = 0
    counters[C_N_VISITED] = 0
    for it in range(ipar[MAX_STATE_ITER]):
        for d in range(nd):
            ws.visited[it, d] = ws.state1[d]
        counters[C_N_VISITED] = it + 1
        slot, ok = _factor(sys, fpar, ipar, ws, ws.state1, nominal, counters)
        if not ok:
            return SINGULAR, solves
        linear_law(sys, ws.state1, ws.qbase, ws.w, ws.f1, ws.w1)
        generalised_force(sys, ws.f1, ws.gf1)
        for i in range(n):
            ws.r[i] = ws.r0[i] - (1.0 - af) * ws.gf1[i]
        lu_solve(ws.cache_lu[slot], ws.cache_piv[slot], ws.r, ws.dx)
        solves += 1
        for i in range(n):
            if not np.isfinite(ws.dx[i]):
                return NON_FINITE, solves
        _update_q(sys, ws)
        if is_compatible(sys, ws.state1, ws.q1, ws.w, fpar[STATE_RTOL]):
            linear_law(sys, ws.state1, ws.q1, ws.w, ws.f1, ws.w1)
            return OK, solves
        contact_law(sys, ws.q1, ws.w, ws.f1, ws.w1, ws.state1)
        counters[C_LAW_CALLS] += 1
    return STATE_CYCLING, solves


@njit(cache=True)
def solve_step(sys, fpar, ipar, ws, t1, dt, load_factor, nominal, counters):
    """Solve one step from (x, v, a, w, S)_n to t1 into the '1' fields. Returns (status, solves)."""
    if ws.lin_dt[0] != dt:
        _build_lin(sys, fpar, ipar, ws, dt)
    _residual_base(sys, fpar, ipar, ws, t1, dt, load_factor)
    solver = ipar[SOLVER]
    if solver == PIECEWISE_LINEAR:
        status, solves = _piecewise_linear(sys, fpar, ipar, ws, nominal, counters)
        if status != OK and status != NON_FINITE and ipar[FALLBACK] == 1:
            counters[C_FALLBACKS] += 1
            status, more = _newton(sys, fpar, ipar, ws, nominal, False, counters)
            solves += more
    else:
        status, solves = _newton(sys, fpar, ipar, ws, nominal, solver == FULL_NEWTON, counters)
    counters[C_SOLVES] += solves
    if status != OK:
        return status, solves
    n = ws.x.shape[0]
    generalised_force(sys, ws.f1, ws.gf1)
    if ipar[INERTIA] == 1:
        a0, a1, a2, a3, b1, b2 = _newmark_coefficients(fpar, dt)
        for i in range(n):
            ws.x1[i] = ws.x[i] + ws.dx[i]
            ws.a1[i] = a0 * ws.dx[i] - a2 * ws.v[i] - a3 * ws.a[i]
            ws.v1[i] = a1 * ws.dx[i] + b1 * ws.v[i] + b2 * ws.a[i]
    else:
        for i in range(n):
            ws.x1[i] = ws.x[i] + ws.dx[i]
            ws.v1[i] = 0.0
            ws.a1[i] = 0.0
    return OK, solves


@njit(cache=True)
def state_step_limit(sys, fpar, ws, state):
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


@njit(cache=True)
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


@njit(cache=True)
def _accept(ws):
    """Copy the '1' fields (step n+1) onto the carried state; return True if S changed."""
    changed = False
    for i in range(ws.x.shape[0]):
        ws.x[i] = ws.x1[i]
        ws.v[i] = ws.v1[i]
        ws.a[i] = ws.a1[i]
        ws.fe[i] = ws.fe1[i]
        ws.gf[i] = ws.gf1[i]
    for d in range(ws.w.shape[0]):
        ws.w[d] = ws.w1[d]
        if ws.state[d] != ws.state1[d]:
            changed = True
        ws.state[d] = ws.state1[d]
    return changed


@njit(cache=True)
def march(sys, fpar, ipar, ws, out, q0, f0):
    """March from t_start to t_end, writing step k into out[k] (k = 0 is the initial state,
    whose local q0 and f0 are given). Returns the status; out.counters[C_STEPS] steps done."""
    counters = out.counters
    cap = out.t.shape[0] - 1
    for r in range(q0.shape[0]):
        out.q[0, r] = q0[r]
        out.f[0, r] = f0[r]
    t = fpar[T_START]
    t_end = fpar[T_END]
    _store(ws, out, 0, t, 0.0, 0)
    k = 0
    nd = ws.state.shape[0]
    adaptive = ipar[ADAPTIVE] == 1
    for d in range(nd):
        ws.dt_state[d] = 0
    tiny = 1e-12 * (t_end - t + 1e-300)
    status = OK
    while t < t_end - tiny:
        if k >= cap:
            status = CAPACITY
            break
        if adaptive:
            for d in range(nd):
                ws.dt_state[d] = ws.state[d]
            dt_nominal = state_step_limit(sys, fpar, ws, ws.state)
        else:
            dt_nominal = fpar[DT]
        dt = dt_nominal
        if t + dt > t_end - tiny:
            dt = t_end - t
        nominal = abs(dt - dt_nominal) <= 1e-12 * dt_nominal
        status, solves = solve_step(sys, fpar, ipar, ws, t + dt, dt, 1.0, nominal, counters)
        if adaptive and status == OK:
            for redo in range(ipar[MAX_REDO]):
                limit = state_step_limit(sys, fpar, ws, ws.state1)
                if limit >= dt * (1.0 - 1e-9):
                    break
                counters[C_REDOS] += 1
                for d in range(nd):
                    ws.dt_state[d] = ws.state1[d]
                dt = limit
                status, more = solve_step(sys, fpar, ipar, ws, t + dt, dt, 1.0, True, counters)
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


@njit(cache=True)
def preload(sys, fpar, ipar, ws, n_increments, q_out, f_out, counters):
    """Static preload: ramp the constant loads in n_increments quasi-static steps (p = 0).
    The caller sets ipar[INERTIA] = 0, ipar[SIGNALS] = 0 and the initial postulate in ws.state.
    Leaves the equilibrium in ws (x, w, S, gf) and q, f in q_out, f_out. Returns the status."""
    for k in range(1, n_increments + 1):
        status, solves = solve_step(sys, fpar, ipar, ws, 0.0, 1.0, k / n_increments, True, counters)
        if status != OK:
            counters[C_FAIL_STEP] = k
            return status
        _accept(ws)
        for r in range(ws.q1.shape[0]):
            q_out[r] = ws.q1[r]
            f_out[r] = ws.f1[r]
    return OK
