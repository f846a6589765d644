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

from slipstep.kernels.arguments import pack_arguments, unpacked
from slipstep.kernels.lean_compiler import LeanCompiler
from slipstep.kernels.codes import DIVERGED
from slipstep.kernels.contact import gather, law, scatter
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.march import (
    C_FACTORISATIONS, C_FAIL_STEP, C_LAW_CALLS, C_REDOS, C_SOLVES, C_STATE_CHANGES, C_STEPS,
    CAPACITY, NON_FINITE, OK, S_CAPACITY, S_FAIL, S_ROWS, SINGULAR, _accept_contacts, _state_step_limit, _store,
)
from slipstep.kernels.codes import C_PROGRESS, C_STOP, INTERRUPTED
from slipstep.kernels.settings import contact_table
from slipstep.kernels.signals import evaluate_signal

# explicit schemes (MarchSettings.solver of explicit_march; the settings it reads: dt, step_factor,
# dt_max, t_start, t_end, singular_rtol, divergence, adaptive, max_redo)
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
    mass_factor: np.ndarray  # L with M = L L^T (kernels/eigen.py)
    tmin_keys: np.ndarray  # int8 (cap, nd)
    tmin_used: np.ndarray  # bool (cap)
    tmin_value: np.ndarray  # (cap,) s


@njit(cache=True, nogil=True, error_model="numpy")
def _accel(sys, A, AT, B, g, nrow, lcode, lpar, fdir, ndir, trow, kt, Kst, Cd, lu, piv, p, fe, gf, rhs,
           t, x, v, w_old, f, w_new, state, q, out):
    """out = M^-1 (f_e(t) - C v - K x - A^T f(q(x, t), w_old)); also fills q, f, w_new, state.
    (lu, piv: the factorised M, or M + dt/2 C for central difference.)"""
    n = x.shape[0]
    evaluate_signal(t, sys.motion_frequency, sys.motion_sin, sys.motion_cos, sys.motion_table_time,
                    sys.motion_table_value, sys.motion_ramp, p)
    evaluate_signal(t, sys.force_frequency, sys.force_sin, sys.force_cos, sys.force_table_time,
                    sys.force_table_value, sys.force_ramp, fe)
    gather(AT, B, g, x, p, q)
    law(nrow, lcode, lpar, fdir, ndir, trow, kt, q, w_old, f, w_new, state)
    scatter(A, f, gf)
    for i in range(n):
        s = fe[i] + sys.constant_force[i] - gf[i]
        for j in range(n):
            s -= Cd[i, j] * v[j] + Kst[i, j] * x[j]
        rhs[i] = s
    lu_solve(lu, piv, rhs, out)


def explicit_march(sys, st, ws, out, q0, f0):
    """March from t_start to t_end writing step k into out[k] (k = 0: the initial state with
    local q0, f0; st: the MarchSettings), same layout and counters as :func:`slipstep.kernels.march.march`.
    Returns the status; out.counters[C_STEPS] steps done. :func:`explicit_march_packed` on the
    packed arguments (kernels/arguments.py)."""
    return explicit_march_packed(pack_arguments(sys, ws, out, q0, f0), st)


def explicit_kernel(backend: int):
    """The explicit march's kernel ``kernel(args, st)`` on a kernels.arguments.KernelArguments:
    :func:`explicit_march_packed`, one for every structure backend (the dense matrices only)."""
    return explicit_march_packed


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def explicit_march_packed(args, st):
    """:func:`explicit_march` on a KernelArguments."""
    # ---- the arguments' arrays without reference counting (kernels/arguments.py, kernels/borrow.py) ----
    sys, ws, out, q0, f0 = unpacked(args)
    M, Cd, Kst, A, AT, B, g = sys.M, sys.C, sys.K, sys.A, sys.AT, sys.B, sys.g
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(sys)
    x, v, a, w, state = ws.x, ws.v, ws.a, ws.w, ws.state
    x1, v1, a1, q1, f1, w1, state1 = ws.x1, ws.v1, ws.a1, ws.q1, ws.f1, ws.w1, ws.state1
    gf, fe, p, rhs, xs, vs, kx, kv = ws.gf, ws.fe, ws.p, ws.rhs, ws.xs, ws.vs, ws.kx, ws.kv
    fs, w_s, ss, lu, piv = ws.fs, ws.ws_, ws.ss, ws.lu, ws.piv
    tkeys, tused, tvalue, mass_factor = ws.tmin_keys, ws.tmin_used, ws.tmin_value, ws.mass_factor
    counters = out.counters
    n = x.shape[0]
    nq = q1.shape[0]
    rk4 = st.solver == RK4
    adaptive = st.adaptive
    bound = st.divergence
    cap = out.plan[S_CAPACITY]
    t = st.t_start
    t_end = st.t_end
    o_rows = out.rows
    row = _store(x, v, a, w, state, out, 0, t, 0.0, 0)
    for ii in range(o_rows.shape[0]):
        out.q[row, ii] = q0[o_rows[ii]]
        out.f[row, ii] = f0[o_rows[ii]]
    k = 0
    tiny = 1e-12 * (t_end - t + 1e-300)
    lu_dt = np.nan
    status = OK
    while t < t_end - tiny:
        if counters[C_STOP] != 0:  # stop request from another thread (Ctrl-C): keep the k steps done
            status = INTERRUPTED
            counters[C_FAIL_STEP] = k
            break
        if k >= cap or out.plan[S_ROWS] + 2 > out.t.shape[0]:  # out of steps or of output rows
            status = CAPACITY
            break
        if adaptive:
            dt = _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state, tkeys, tused, tvalue,
                                   st.step_factor, st.dt_max)
        else:
            dt = st.dt
        if t + dt > t_end - tiny:
            dt = t_end - t
        solves = 0
        for attempt in range(st.max_redo + 1):
            # ---- factorise M (RK4, once) or M + dt/2 C (central difference, per dt) ----
            if (rk4 and lu_dt != lu_dt) or (not rk4 and lu_dt != dt):
                c = 0.0 if rk4 else 0.5 * dt
                Meff = np.empty((n, n))
                for i in range(n):
                    for j in range(n):
                        Meff[i, j] = M[i, j] + c * Cd[i, j]
                counters[C_FACTORISATIONS] += 1
                lu_dt = dt
                if not lu_factor(Meff, lu, piv, st.singular_rtol):
                    status = SINGULAR
                    break
            h = 0.5 * dt
            if rk4:
                # ---- RK4 on [x, v]: k1 = (v_n, a_n); stages with the slider w_n ----
                for i in range(n):
                    kx[0, i] = v[i]
                    kv[0, i] = a[i]
                for stage in range(1, 4):
                    c = 1.0 if stage == 3 else 0.5
                    for i in range(n):
                        xs[i] = x[i] + c * dt * kx[stage - 1, i]
                        vs[i] = v[i] + c * dt * kv[stage - 1, i]
                    _accel(sys, A, AT, B, g, nrow, lcode, lpar, fdir, ndir, trow, kt, Kst, Cd, lu, piv, p, fe, gf, rhs,
                           t + c * dt, xs, vs, w, fs, w_s, ss, q1, kv[stage])
                    for i in range(n):
                        kx[stage, i] = vs[i]
                for i in range(n):
                    x1[i] = x[i] + dt / 6.0 * (kx[0, i] + 2.0 * kx[1, i] + 2.0 * kx[2, i] + kx[3, i])
                    v1[i] = v[i] + dt / 6.0 * (kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i])
                # accepted-step law at q_{n+1}: forces, sliders, states and a_{n+1} (k1 of the next step)
                _accel(sys, A, AT, B, g, nrow, lcode, lpar, fdir, ndir, trow, kt, Kst, Cd, lu, piv, p, fe, gf, rhs,
                       t + dt, x1, v1, w, f1, w1, state1, q1, a1)
                counters[C_LAW_CALLS] += 4
                solves += 4
            else:
                # ---- central difference: x_{n+1} explicit, then (M + dt/2 C) a_{n+1} = ... ----
                for i in range(n):
                    x1[i] = x[i] + dt * v[i] + h * dt * a[i]
                    vs[i] = v[i] + h * a[i]
                _accel(sys, A, AT, B, g, nrow, lcode, lpar, fdir, ndir, trow, kt, Kst, Cd, lu, piv, p, fe, gf, rhs,
                       t + dt, x1, vs, w, f1, w1, state1, q1, a1)
                for i in range(n):
                    v1[i] = vs[i] + h * a1[i]
                counters[C_LAW_CALLS] += 1
                solves += 1
            status = OK
            for i in range(n):
                if not (np.isfinite(x1[i]) and np.isfinite(v1[i]) and np.isfinite(a1[i])):
                    status = NON_FINITE
            for r in range(nq):
                if status == OK and not abs(q1[r]) <= bound:
                    status = DIVERGED  # |q| beyond 1e6 length scales: the scheme's instability
            if status != OK or not adaptive or attempt == st.max_redo:
                break
            # ---- redo rule: the state reached needs a smaller step ----
            limit = _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state1, tkeys, tused,
                                      tvalue, st.step_factor, st.dt_max)
            if limit >= dt * (1.0 - 1e-9):
                break
            counters[C_REDOS] += 1
            dt = limit
        counters[C_SOLVES] += solves
        if status != OK:
            counters[C_FAIL_STEP] = k + 1
            out.times[S_FAIL] = t + dt
            break
        # ---- accept ----
        for i in range(n):
            x[i] = x1[i]
            v[i] = v1[i]
            a[i] = a1[i]
        if _accept_contacts(w, state, w1, state1):
            counters[C_STATE_CHANGES] += 1
        t += dt
        k += 1
        row = _store(x, v, a, w, state, out, k, t, dt, solves)
        counters[C_PROGRESS] = k
        for ii in range(o_rows.shape[0]):
            out.q[row, ii] = q1[o_rows[ii]]
            out.f[row, ii] = f1[o_rows[ii]]
    counters[C_STEPS] = k
    return status
