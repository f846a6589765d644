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

Step solvers (kernels/step_solvers.py):
    0 modified Newton (Method 1): J(all stick) factorised once per dt, iterate on dx until
      BOTH the increment test (the error estimate theta/(1-theta) of the scaled increment on
      the contact coordinates and the DOFs, theta the larger of the last two contraction
      ratios, step_solvers.newton_update) and the force-residual test at the new iterate
      (step_solvers.residual_converged) hold; each iteration = one contact-law call + one solve.
    1 full Newton: J(S) of the current iterate's state.
    2 piecewise linear (Method 3/4): postulate S = S_n, one solve with J(S), accept if S is
      compatible at the computed q (keeping the law's f, w and S at that q: a postulate within
      the tolerance of a boundary takes the law's side, |T| <= mu N and N >= 0 exactly), else
      postulate the law's states there and re-solve. If the states cycle, fall back to modified Newton for that step (counted).
      A postulated state without a piecewise-linear form (a coupled slip of the friction-
      circle law) is solved by Newton on the consistent tangent (solver 1) instead.
    3 modified Newton with J(S) of the state whose T_min set the step (Method 2: the state
      at the step start, or the one a redo found; fixed step: S_n), cached per state, given
      up for J(all stick) from the dx reached when it stops contracting (theta >= 0.5).
    (4 EVENTS: not a solver of this march; kernels/events.py.)
Accuracy control (MarchSettings.rtol > 0, RunOptions.rtol): dt = min(rule, dt_acc) for the Newton
solvers (rule: the fixed step or the contact-state step below), min(dt_acc, dt_max) for the
piecewise-linear solve; dt_acc follows the local error of each step (:func:`_local_error`),
a step above it is redone smaller (counted as a redo). Every step then factorises afresh.
Adaptive step (Method 2): dt = min(step_factor * T_min(S_n), dt_max), with
T_min = 2 pi / sqrt(max|eig(M^-1 (K + K_D(S)))|) cached per state; redo the step with the
smaller dt when the new state's limit is below the dt used (a redone step postulates the
state it found).
Every operation on n x n structure matrices (Lin, M y, C y, K y, Lin dx, the factorisations
and solves with J(S)) goes through kernels/structure_ops.py, with the backend of
MarchSettings.structure: a cached LU per (S, dt state) (kernels/state_solve.py), or the
low-rank update of J(all stick) for structures with few contact coordinates.

One step of :func:`march`, in order (each a function below or in step_solvers.py):
    step size (fixed / contact-state rule / accuracy)      -> _step_size, _state_step_limit
    Newmark coefficients and Lin (once per dt)             -> _newmark_matrix
    loads and motions f_e(t_{n+1}), p(t_{n+1})             -> _loads_and_motions
    q_base and the residual base r0                        -> _residual_base
    the step solve per solver                              -> step_solvers.*_step
    the accuracy / redo rule                               -> _accuracy_redo, _state_redo
    accept: x_{n+1} = x_n + dx and the Newmark relations   -> _accept
    store output point n+1                                 -> _store (+ q, f)
Inputs: the CompiledSystem, MarchSettings (kernels/settings.py), the Workspace, Outputs.
"""

import functools
from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.banded import band_contact_stiffness, band_is_diagonal, band_lambda_max, band_to_lu_storage
from slipstep.kernels.arguments import pack_arguments, unpacked
from slipstep.kernels.borrow import borrowed, keep_alive
from slipstep.kernels.cache import find_slot
from slipstep.kernels.codes import (  # noqa: F401  (re-exported: the counters and status codes)
    C_FACTORISATIONS, C_FAIL_STEP, C_FALLBACKS, C_LAW_CALLS, C_N_VISITED, C_REDOS, C_SOLVES, C_STATE_CHANGES, C_STEPS,
    CAPACITY, N_COUNTERS, NON_FINITE, NOT_CONVERGED, OK, SINGULAR, STATE_CYCLING,
)
from slipstep.kernels.codes import (  # noqa: F401
    C_PROGRESS, C_STOP, EVENTS, FULL_NEWTON, INTERRUPTED, LAW_CIRCLE, MODIFIED_NEWTON, MODIFIED_NEWTON_STATE,
    PIECEWISE_LINEAR,
)
from slipstep.kernels.contact import contact_stiffness
from slipstep.kernels.lean_compiler import LeanCompiler
from slipstep.kernels.eigen import EIG_RTOL, MAX_BASIS, MAX_RESTARTS, largest_eigenvalue_modulus
from slipstep.kernels.settings import (  # noqa: F401  (re-exported: the settings)
    MarchSettings, contact_table, march_settings, replace_settings, state_cache, step_vectors,
)
from slipstep.kernels.signals import evaluate_signal, harmonic_basis, signal_from_basis
from slipstep.kernels import structure_ops as so
from slipstep.kernels.structure_ops import BANDED, DENSE, LOW_RANK  # noqa: F401
from slipstep.kernels.step_solvers import (  # noqa: F401
    CV_FLOOR, CV_TOL, CV_TOL_Q, CV_X, THETA_GIVE_UP, full_newton, piecewise_linear_step, state_tangent_step,
    stick_tangent_step,
)
from slipstep.kernels.state_solve import LowRank

ACC_GROWTH = 1.5  # the largest growth of the accuracy step from one step to the next


class Workspace(NamedTuple):
    """Scratch and carried state of a march; allocated once in Python (see methods.base)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    fe: np.ndarray  # f_e(t_n)
    gf: np.ndarray  # A^T f_n
    w: np.ndarray
    state: np.ndarray  # int8
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
    Lin: np.ndarray
    J: np.ndarray
    mass_factor: np.ndarray  # L with M = L L^T (zero pivots: DOFs without mass), kernels/eigen.py
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
    basis: np.ndarray  # (4, nh) the harmonic basis of the loads and motions (signals.harmonic_basis)
    clock: np.ndarray  # (4,) its time, rotation step, rotations since the exact anchor, previous step
    mpiv: np.ndarray  # int64 (n) banded backend (issue 10): pivots of M's banded LU (held in mass_factor); (0,) otherwise
    lr: LowRank  # the low-rank solve's arrays (placeholders in direct mode), see state_solve.py


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
    step: np.ndarray  # int64 (rows,): the step stored in each row
    dofs: np.ndarray  # int64: the kernel DOF of each x, v, a column (methods/save.py kernel_dofs)
    rows: np.ndarray  # int64: the contact row of each q, f column
    dirs: np.ndarray  # int64: the direction of each w, state column
    plan: np.ndarray  # int64 (6,): S_CAPACITY steps, S_EVERY k; kept by _store: S_ROWS, S_LAST, S_GRID, S_NEXT
    times: np.ndarray  # (3 + G,): S_FROM window start [s], S_FAIL time of a failed step [s], G given times, +inf


# Outputs.plan and Outputs.times (the save plan of methods/save.py). S_ROWS rows kept, S_LAST the last
# kept step, S_GRID the next given time, S_NEXT the next multiple of S_EVERY: set by Python before each
# march (methods/simulation.reset_outputs: 0, -1, 0, 0; times[S_FAIL] = nan), then kept by _store.
S_CAPACITY, S_EVERY, S_ROWS, S_LAST, S_GRID, S_NEXT = range(6)
S_FROM, S_FAIL = 0, 1


@njit(cache=True, error_model="numpy", inline="always")
def newmark_coefficients(beta, gamma, dt):
    """(a0, a1, a2, a3, b1, b2) of the Newmark relations in the module docstring:
    a_{n+1} = a0 dx - a2 v_n - a3 a_n,  v_{n+1} = a1 dx + b1 v_n + b2 a_n."""
    return (1.0 / (beta * dt * dt), gamma / (beta * dt), 1.0 / (beta * dt), 1.0 / (2.0 * beta) - 1.0,
            1.0 - gamma / beta, dt * (1.0 - gamma / (2.0 * beta)))


@njit(cache=True, nogil=True, error_model="numpy")
def _local_error(backend, sys, mdiag, A, dx, v, a, a0, a2, a3, dt, beta, err_tol):
    """Accuracy control: the local displacement error of a Newmark step (Zienkiewicz & Xie
    1991), e_j = dt^2 |beta - 1/6| (a_{n+1} - a_n)_j, a_{n+1} = a0 dx - a2 v_n - a3 a_n; for a
    massless DOF (M_jj = 0, methods/massless.py: a quasi-static path) the error of its linear
    interpolation in time, e_j = |dx_j - v_j dt| / 8 (dt^2/8 of its second derivative).
    Measured on the contact coordinates (A e; on the DOFs without contacts) against
    err_tol = rtol L. Returns max |e| / err_tol (> 1: reject the step). The step that
    follows is dt (0.9 / err)^(1/3), within [0.2, ACC_GROWTH] dt (the local error is O(dt^3))."""
    n = dx.shape[0]
    c = dt * dt * max(abs(beta - 1.0 / 6.0), 1.0 / 12.0)
    e = np.empty(n)
    for j in range(n):
        if mdiag[j] != 0.0:
            e[j] = c * (a0 * dx[j] - a2 * v[j] - a3 * a[j] - a[j])
        else:
            e[j] = (dx[j] - v[j] * dt) / 8.0
    err = 0.0
    if A.shape[0] == 0:
        for j in range(n):
            err = max(err, abs(e[j]))
    elif backend == BANDED:  # banded backend (issue 10): A in CSR
        err = so.gather_abs_max(so.csr_of(sys), e)
    else:
        for rr in range(A.shape[0]):
            s = 0.0
            for j in range(n):
                s += A[rr, j] * e[j]
            err = max(err, abs(s))
    return err / err_tol


@njit(cache=True, error_model="numpy", inline="always")
def _accuracy_redo(err, dt, attempt, max_redo):
    """The accuracy rule on a solved step of local error err (relative, :func:`_local_error`):
    (redo, dt_redo, dt_next). err > 1 (and a redo left): redo with dt max(0.2, 0.9 err^(-1/3));
    else the next step dt min(ACC_GROWTH, max(0.2, 0.9 err^(-1/3))) (ACC_GROWTH dt at err 0)."""
    if err > 1.0 and attempt < max_redo:
        return True, dt * max(0.2, 0.9 * err ** (-1.0 / 3.0)), dt
    dt_next = dt * min(ACC_GROWTH, max(0.2, 0.9 * err ** (-1.0 / 3.0))) if err > 0.0 else ACC_GROWTH * dt
    return False, dt, dt_next


@njit(cache=True, nogil=True, error_model="numpy")
def _convergence_parameters(backend, sys, tol):
    """The Newton tolerances conv (step_solvers.CV_*): tol, tol L and per DOF j tol L / max_r |A_rj|
    (a rotation: L over its lever arm; tol L for a DOF no contact sees); CV_FLOOR is set per dt."""
    A = sys.A
    n, nq = sys.constant_force.shape[0], A.shape[0]
    length_scale = sys.length_scale
    conv = np.empty(CV_X + n)
    conv[CV_TOL] = tol
    conv[CV_TOL_Q] = tol * length_scale
    conv[CV_FLOOR] = 0.0
    for i in range(n):
        amax = 0.0
        if backend == BANDED:  # banded backend (issue 10): A^T in CSR
            amax = so.column_abs_max_banded(sys, i)
        for rr in range(nq if backend != BANDED else 0):
            amax = max(amax, abs(A[rr, i]))
        conv[CV_X + i] = tol * (length_scale / amax if amax > 0.0 else length_scale)
    return conv


@njit(cache=True, error_model="numpy", inline="always")
def _loads_and_motions(sys, t1, signals, load_factor, basis, clock, fe1, p):
    """f_e(t1) = f_var(t1) + load_factor f_const and p(t1) (p = 0 and f_var = 0 without signals).
    Harmonic signals (no table, outside the ramp) from the rotated harmonic basis of
    signals.harmonic_basis (no sin / cos call on a march of equal steps), others by
    signals.evaluate_signal."""
    n = fe1.shape[0]
    if signals:
        harmonic_basis(t1, sys.force_frequency, sys.motion_frequency, basis, clock)
        if sys.force_table_time.shape[0] == 0 and not (sys.force_ramp > 0.0 and t1 < sys.force_ramp):
            signal_from_basis(sys.force_sin, sys.force_cos, basis, 0, fe1)
        else:
            evaluate_signal(t1, sys.force_frequency, sys.force_sin, sys.force_cos, sys.force_table_time,
                            sys.force_table_value, sys.force_ramp, fe1)
        if sys.motion_table_time.shape[0] == 0 and not (sys.motion_ramp > 0.0 and t1 < sys.motion_ramp):
            signal_from_basis(sys.motion_sin, sys.motion_cos, basis, sys.force_frequency.shape[0], p)
        else:
            evaluate_signal(t1, sys.motion_frequency, sys.motion_sin, sys.motion_cos, sys.motion_table_time,
                            sys.motion_table_value, sys.motion_ramp, p)
    else:
        for i in range(n):
            fe1[i] = 0.0
        for i in range(p.shape[0]):
            p[i] = 0.0
    f_const = sys.constant_force
    for i in range(n):
        fe1[i] += load_factor * f_const[i]


@njit(cache=True, error_model="numpy", inline="always")
def _residual_base(backend, sys, inertia, has_damping, has_stiffness, am, af, a2, a3, b1, b2, x, v, a, fe, gf, fe1,
                   acc_pred, vel_pred, r0):
    """The dx-independent part of the residual (module docstring):
        r0 = (1 - af) f_e(t_{n+1}) + af (f_e(t_n) - A^T f_n) - M acc_pred - C vel_pred - K x_n
        acc_pred = (1 - am)(-a2 v_n - a3 a_n) + am a_n,  vel_pred = (1 - af)(b1 v_n + b2 a_n) + af v_n
    (the predictor parts of a_{n+1-am} and v_{n+1-af}; the dx terms are in Lin); quasi-static:
    r0 = f_e(t_{n+1}) - K x_n."""
    n = x.shape[0]
    for i in range(n):
        r0[i] = (1.0 - af) * fe1[i] + af * (fe[i] - gf[i]) if inertia else fe1[i]
    if inertia:
        for j in range(n):
            acc_pred[j] = (1.0 - am) * (-a2 * v[j] - a3 * a[j]) + am * a[j]
            vel_pred[j] = (1.0 - af) * (b1 * v[j] + b2 * a[j]) + af * v[j]
    so.sub_predictor(backend, sys, inertia, has_damping, has_stiffness, acc_pred, vel_pred, x, r0)


@njit(cache=True, error_model="numpy", inline="always")
def _accept(mdiag, inertia, a0, c1, a2, a3, b1, b2, dt, dx, x, v, a, fe, gf, fe1, gf1):
    """x_{n+1} = x_n + dx and the Newmark relations a_{n+1} = a0 dx - a2 v_n - a3 a_n,
    v_{n+1} = a1 dx + b1 v_n + b2 a_n (a massless DOF in a dynamic march, methods/massless.py:
    v = dx/dt, a = 0); f_e and A^T f move to the new step."""
    for i in range(x.shape[0]):
        if inertia and mdiag[i] != 0.0:
            a_new = a0 * dx[i] - a2 * v[i] - a3 * a[i]
            v[i] = c1 * dx[i] + b1 * v[i] + b2 * a[i]
            a[i] = a_new
        elif inertia:
            v[i] = dx[i] / dt
            a[i] = 0.0
        x[i] += dx[i]
        fe[i] = fe1[i]
        gf[i] = gf1[i]


@njit(cache=True, error_model="numpy", inline="always")
def _accept_contacts(w, state, w1, state1):
    """Take the step's sliders and states; True if any state changed."""
    changed = False
    for d in range(w.shape[0]):
        w[d] = w1[d]
        if state[d] != state1[d]:
            changed = True
        state[d] = state1[d]
    return changed


@njit(cache=True, error_model="numpy", inline="always")
def _same(s1, s2):
    for d in range(s1.shape[0]):
        if s1[d] != s2[d]:
            return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def _state_step_limit(Kst, mass_factor, A, nrow, lcode, lpar, fdir, ndir, trow, kt, state, tkeys, tused, tvalue,
                      step_factor, dt_max):
    """dt limit of a state: step_factor * T_min(S), capped at dt_max; T_min cached per state,
    T_min = 2 pi / sqrt(max |eig(M^-1 (K + K_D(S)))|) (paper Eq. 8), the largest |eigenvalue| alone
    to EIG_RTOL (kernels/eigen.py; mass_factor: L with M = L L^T)."""
    slot, found = find_slot(tkeys, tused, state)
    if not found:
        Keff = Kst.copy()
        contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, state, np.empty(0), np.empty(0), 1.0, Keff)
        wmax2 = largest_eigenvalue_modulus(Keff, mass_factor, EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
        tvalue[slot] = 2.0 * np.pi / np.sqrt(wmax2) if wmax2 > 0.0 else np.inf
    return min(step_factor * tvalue[slot], dt_max)


@njit(cache=True, nogil=True, error_model="numpy")
def _state_step_limit_banded(sys, ws, cl, state, step_factor, dt_max):
    """:func:`_state_step_limit` for the banded backend: omega_max^2 of K + K_D(S) against M by
    Arnoldi on the band (kernels.banded.band_lambda_max; M^-1 by its banded LU in ws.mass_factor,
    pivots ws.mpiv), cached per state."""
    slot, found = find_slot(ws.tmin_keys, ws.tmin_used, state)
    if not found:
        nrow, lcode, lpar, fdir, ndir, trow, kt = cl
        kl, ku = sys.kl, sys.ku
        Keff = np.zeros((sys.Kb.shape[0], 2 * kl + ku + 1))
        band_to_lu_storage(sys.Kb, kl, ku, Keff)
        band_contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, sys.A_ptr, sys.A_idx, sys.A_val, state,
                               np.empty(0), np.empty(0), 1.0, Keff, kl + ku)
        wmax2 = band_lambda_max(sys.Mb, Keff, kl, ku, ws.mass_factor, ws.mpiv, band_is_diagonal(sys.Mb, ku))
        ws.tmin_value[slot] = 2.0 * np.pi / np.sqrt(wmax2) if wmax2 > 0.0 else np.inf
    return min(step_factor * ws.tmin_value[slot], dt_max)


@njit(cache=True, error_model="numpy", inline="always")
def _limit_of(backend, sys, ws, cl, state, st):
    """:func:`_state_step_limit` of a state with this march's arrays."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    if backend == BANDED:  # banded backend (issue 10): T_min by Arnoldi on the band
        return _state_step_limit_banded(sys, ws, cl, state, st.step_factor, st.dt_max)
    return _state_step_limit(sys.K, ws.mass_factor, sys.A, nrow, lcode, lpar, fdir, ndir, trow, kt, state, ws.tmin_keys,
                             ws.tmin_used, ws.tmin_value, st.step_factor, st.dt_max)


@njit(cache=True, error_model="numpy", inline="always")
def _state_redo(backend, sys, ws, cl, st, state1, dt):
    """The redo rule of the adaptive step (paper 4.2): (redo, limit), redo when the state the
    step reached needs a smaller step than the dt used (its limit below dt (1 - 1e-9))."""
    if _same(state1, ws.dt_state):
        return False, dt
    limit = _limit_of(backend, sys, ws, cl, state1, st)
    return limit < dt * (1.0 - 1e-9), limit


def march(sys, st, ws, out, q0, f0):
    """March from st.t_start to st.t_end, writing step k into out[k] (k = 0: the initial state,
    whose local q0 and f0 are given); st: the MarchSettings. Returns the status;
    out.counters[C_STEPS] steps done. The kernel of st.structure (:func:`implicit_kernel`) on the
    packed arguments (kernels/arguments.py).

    Preload mode (st.preload = N > 0): N quasi-static increments at t = 0 with the constant
    loads scaled by k/N and p = 0 (set inertia and signals False)."""
    return implicit_kernel(st.structure)(pack_arguments(sys, ws, out, q0, f0), st)


@functools.cache
def implicit_kernel(backend: int):
    """The implicit march of one structure backend (structure_ops: DENSE, LOW_RANK, BANDED),
    ``kernel(args, st)`` on a kernels.arguments.KernelArguments; st.structure must be ``backend``.

    The backend is a constant of the kernel (a free variable of a closure, cached on disk per
    backend): numba's dead-branch pruning drops the other backends' branches, of this body and of
    every ``inline="always"`` helper it inlines, before they are typed. The step solver stays a
    run-time choice (st.solver): every command marches the piecewise-linear solver (the static
    preload, the pilot of the step rule) beside its own, and one kernel holding all four compiles
    in less time than two kernels of two solvers each (docs/measured.md, "Compile time")."""
    return _implicit_kernel(int(backend))


def _implicit_kernel(backend):
    """:func:`implicit_kernel` (backend a plain int: the closure's cache key)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def march_packed(args, st):
        """:func:`march` of this backend on a KernelArguments."""
        # ---- the arguments' arrays without reference counting (kernels/arguments.py, kernels/borrow.py) ----
        sys, ws, out, q0, f0 = unpacked(args)
        A = sys.A
        cl = contact_table(sys)
        cache = state_cache(ws)
        sv = step_vectors(ws)
        length_scale = sys.length_scale
        x, v, a, fe, gf, w, state = ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w, ws.state
        fe1, gf1, f1, q1, w1, state1 = ws.fe1, ws.gf1, ws.f1, ws.q1, ws.w1, ws.state1
        dx, p, qbase, r0 = ws.dx, ws.p, ws.qbase, ws.r0
        Lin, J, dt_state, visited = ws.Lin, ws.J, ws.dt_state, ws.visited
        lus, pivs = ws.cache_lu, ws.cache_piv
        counters = out.counters
        n = x.shape[0]
        nd = state.shape[0]
        beta, gamma, am, af = st.beta, st.gamma, st.alpha_m, st.alpha_f
        own_conv = _convergence_parameters(backend, sys, st.tol)  # the Newton convergence tolerances (step_solvers.CV_*)
        own_kd = so.stick_diagonal(sys)
        own_mdiag = so.mass_diagonal(backend, sys)
        state_rtol = st.state_rtol
        singular_rtol = st.singular_rtol
        solver = st.solver
        n_preload = st.preload
        adaptive = st.adaptive and n_preload == 0
        inertia = st.inertia
        signals = st.signals
        max_iter, max_state_iter, max_redo, fallback = st.max_iter, st.max_state_iter, st.max_redo, st.fallback
        kfac = (1.0 - af) if inertia else 1.0
        has_damping = so.has_nonzero(backend, sys, 1)
        has_circle = np.any(cl.lcode == LAW_CIRCLE)
        has_stiffness = so.has_nonzero(backend, sys, 2)
        own_pred = np.empty((2, n))
        cap = out.plan[S_CAPACITY]
        # ---- initial point ----
        t = st.t_start
        t_end = st.t_end
        o_q, o_f, o_rows = out.q, out.f, out.rows
        row = _store(x, v, a, w, state, out, 0, t, 0.0, 0)
        for ii in range(o_rows.shape[0]):
            o_q[row, ii] = q0[o_rows[ii]]
            o_f[row, ii] = f0[o_rows[ii]]
        for d in range(nd):
            dt_state[d] = 0
        tiny = 1e-12 * (t_end - t + 1e-300)
        status = OK
        k = 0
        last_slot = -1  # cache slot of the last piecewise-linear factorisation (fast path)
        stick_dt = np.nan  # step size of the current full-stick factorisation (lu0, piv0), Method 1
        tan_dt = np.nan  # step size and state of the current J(S) factorisation (luS, pivS), solver 3
        own_tan = np.full(nd, -1, np.int8)
        # the arrays allocated here, borrowed too (kernels/borrow.py; kept alive to the end below)
        conv, kd_stick, mdiag, tan_state = borrowed(own_conv), borrowed(own_kd), borrowed(own_mdiag), borrowed(own_tan)
        acc_pred, vel_pred = borrowed(own_pred[0]), borrowed(own_pred[1])
        okS = False
        luS = lus[0]
        pivS = pivs[0]
        ok0 = False
        lu0 = lus[0]
        piv0 = pivs[0]
        dt_state_limit = 0.0  # step limit of dt_state (adaptive)
        a0 = c1 = a2 = a3 = b1 = b2 = 0.0  # Newmark coefficients of the current dt
        ws.lin_dt[0] = np.nan
        basis, clock = ws.basis, ws.clock
        clock[0], clock[1], clock[2], clock[3] = t, np.nan, 0.0, np.nan  # the harmonic basis: exact at the first step
        accuracy = st.rtol > 0.0 and n_preload == 0 and inertia
        err_tol = st.rtol * st.err_scale
        dt_acc = st.dt  # the accuracy step, adapted after every step (accuracy control)
        dt_next = dt_acc
        while (n_preload > 0 and k < n_preload) or (n_preload == 0 and t < t_end - tiny):
            # (written out here and in kernels/quasi_static.py: as shared inline helpers, this check and
            # the q, f output rows below made Method 1 about 8 % slower, bench_method1.py, and Method 4's
            # kernel 3-7 %)
            if counters[C_STOP] != 0:  # stop request from another thread (Ctrl-C): keep the k steps done
                status = INTERRUPTED
                counters[C_FAIL_STEP] = k
                break
            if k >= cap or out.plan[S_ROWS] + 2 > out.t.shape[0]:  # out of steps or of output rows
                status = CAPACITY
                break
            # ---- step size (fixed, or by contact state; the accuracy step) ----
            if n_preload > 0:
                dt_nominal = 1.0
            elif adaptive:
                if k == 0 or not _same(state, dt_state):
                    for d in range(nd):
                        dt_state[d] = state[d]
                    dt_state_limit = _limit_of(backend, sys, ws, cl, state, st)
                dt_nominal = dt_state_limit
            else:
                dt_nominal = st.dt
            if accuracy:  # the step of the local error estimate, never beyond the convergence / stability rule
                dt_nominal = min(dt_acc, st.dt_max) if solver == PIECEWISE_LINEAR else min(dt_nominal, dt_acc)
            dt = dt_nominal
            if n_preload == 0 and t + dt > t_end - tiny:
                dt = t_end - t
            nominal = abs(dt - dt_nominal) <= 1e-12 * dt_nominal and not accuracy
            load_factor = (k + 1.0) / n_preload if n_preload > 0 else 1.0
            solves = 0
            for attempt in range(max_redo + 1):
                t1 = t + dt if n_preload == 0 else t
                # ---- Newmark coefficients and Lin = (1-am) a0 M + (1-af) a1 C + (1-af) K (per dt) ----
                if ws.lin_dt[0] != dt:
                    a0, c1, a2, a3, b1, b2 = newmark_coefficients(beta, gamma, dt)
                    last_slot = -1
                    so.build_lin(backend, sys, inertia, (1.0 - am) * a0, (1.0 - af) * c1, 1.0 - af, Lin)
                    ws.lin_dt[0] = dt
                    # the floor of a step at rest: the stiffness forces of a displacement L (no inertia term:
                    # tol L a0 M exceeds the step's forces by (2 / omega dt)^2 and let steps off by 1e-8 pass)
                    conv[CV_FLOOR] = st.tol * length_scale * so.max_diagonal(
                        backend, sys.Kb if backend == BANDED else sys.K, kfac, kd_stick)
                # ---- loads, motion, q_base, r0 (the dx-independent part of the residual) ----
                _loads_and_motions(sys, t1, signals, load_factor, basis, clock, fe1, p)
                so.gather_state(backend, sys, x, p, qbase)
                _residual_base(backend, sys, inertia, has_damping, has_stiffness, am, af, a2, a3, b1, b2, x, v, a, fe, gf,
                               fe1, acc_pred, vel_pred, r0)
                # ---- the step solver ----
                if solver == PIECEWISE_LINEAR:
                    status, more, last_slot = piecewise_linear_step(backend, sys, cl, cache, Lin, J, kfac, sv, state,
                                                                    visited, attempt, nominal, last_slot, has_circle,
                                                                    max_state_iter, fallback, max_iter, conv, state_rtol,
                                                                    singular_rtol, length_scale, counters)
                elif solver == FULL_NEWTON:
                    status, more = full_newton(backend, sys, cl, cache, Lin, J, kfac, sv, nominal, max_iter, conv,
                                               singular_rtol, counters)
                elif solver == MODIFIED_NEWTON_STATE:  # the tangent of the state that set the step
                    tstate = dt_state if adaptive else state
                    status, more, okS, luS, pivS, tan_dt = state_tangent_step(backend, sys, cl, cache, Lin, J, kfac, sv,
                                                                              tstate, dt, nominal, max_iter, conv,
                                                                              singular_rtol, counters, okS, luS, pivS,
                                                                              tan_dt, tan_state)
                else:
                    status, more, ok0, lu0, piv0, stick_dt = stick_tangent_step(backend, sys, cl, cache, Lin, J, kfac, sv,
                                                                                dt, nominal, max_iter, conv,
                                                                                singular_rtol, counters, ok0, lu0, piv0,
                                                                                stick_dt)
                solves += more
                # ---- accuracy / redo rule ----
                if accuracy and status == OK:
                    err = _local_error(backend, sys, mdiag, A, dx, v, a, a0, a2, a3, dt, beta, err_tol)
                    redo, dt, dt_next = _accuracy_redo(err, dt, attempt, max_redo)
                    if redo:  # reject: redo with the step the estimate asks for
                        counters[C_REDOS] += 1
                        continue
                if status != OK or not adaptive or attempt == max_redo:
                    break
                redo, limit = _state_redo(backend, sys, ws, cl, st, state1, dt)  # paper 4.2: the new state needs a smaller step
                if not redo:
                    break
                counters[C_REDOS] += 1
                for d in range(nd):
                    dt_state[d] = state1[d]
                dt_state_limit = limit
                dt = limit
                nominal = True
            counters[C_SOLVES] += solves
            if accuracy and status == OK:
                dt_acc = dt_next
            if status != OK:
                counters[C_FAIL_STEP] = k + 1
                out.times[S_FAIL] = t + dt if n_preload == 0 else t
                break
            # ---- accept: x_{n+1} = x_n + dx and the Newmark relations ----
            _accept(mdiag, inertia, a0, c1, a2, a3, b1, b2, dt, dx, x, v, a, fe, gf, fe1, gf1)
            if _accept_contacts(w, state, w1, state1):
                counters[C_STATE_CHANGES] += 1
            if n_preload == 0:
                t += dt
            k += 1
            row = _store(x, v, a, w, state, out, k, t, dt, solves)
            counters[C_PROGRESS] = k
            for ii in range(o_rows.shape[0]):
                o_q[row, ii] = q1[o_rows[ii]]
                o_f[row, ii] = f1[o_rows[ii]]
        counters[C_STEPS] = k
        keep_alive((own_conv, own_kd, own_mdiag, own_tan, own_pred))
        return status

    return march_packed


def implicit_callees(backend: int, sys, ws) -> tuple[list, list]:
    """The out-of-line kernels that numba compiles while it types :func:`implicit_kernel` of the
    dense or low-rank backend (none for the banded one), as two lists of ("module:name", argument
    types), with the numba types of their call sites in the march for the CompiledSystem ``sys``
    and the Workspace ``ws`` (the types hold the arrays' dtypes and ranks and the tuples' classes,
    not their sizes): what another process can compile ahead into numba's cache
    (methods/compile_ahead.py). ``first``: what the typing meets soon after it starts (the
    convergence parameters and the two diagonals of its first lines, then the Krylov routine, the
    biggest part of T_min's step limit), small enough for a helper to have compiled them by then;
    ``rest``: the others, in the order the typing meets them. tests/test_compile_ahead.py checks
    that these are the types the march's typing asks for."""
    from numba import typeof, types  # the Python side only: the kernels above never call this

    if backend not in (DENSE, LOW_RANK):
        return [], []
    own = "_dense" if backend == DENSE else "_low_rank"
    solvers = "slipstep.kernels.step_solvers:"
    structure = "slipstep.kernels.structure_ops:"
    table = contact_table(sys)  # (register_jitable: a Python function here)
    cl_type, cache, sv = typeof(table), typeof(state_cache.py_func(ws)), typeof(step_vectors.py_func(ws))  # not compiled
    cl = tuple(typeof(a) for a in table)
    f, b, i = types.float64, types.boolean, types.int64
    f1, f2, i1 = types.float64[::1], types.float64[:, ::1], types.int64[::1]  # arrays of the march's own
    solve = (typeof(sys), cl_type, cache, f2, f2, f)  # sys, cl, cache, Lin, J, kfac
    first = [
        (__name__ + ":_convergence_parameters", (types.literal(backend), typeof(sys), f)),
        (structure + "stick_diagonal", (typeof(sys),)),
        (structure + "mass_diagonal", (types.literal(backend), typeof(sys))),
        ("slipstep.kernels.eigen:krylov_largest_modulus", (f2, f2, f, types.literal(MAX_BASIS), types.literal(MAX_RESTARTS))),
    ]
    rest = [
        (__name__ + ":_state_step_limit",
         (typeof(sys.K), typeof(ws.mass_factor), typeof(sys.A), *cl, typeof(ws.state), typeof(ws.tmin_keys),
          typeof(ws.tmin_used), typeof(ws.tmin_value), f, f)),
        (solvers + "_full_newton" + own, (*solve, sv, b, i, f1, f, i1)),
        (solvers + "_stick_factorisation" + own, (*solve, b, f, i1)),
        (solvers + "_modified_newton_dense", (f2, i1, f2, f, typeof(()), f2, f2, cl_type, sv, i, f1, f, b, i1)),
        (solvers + "_stick_fallback" + own, (*solve, sv, b, i, f1, f, i, i1)),
        (solvers + "_state_factorisation" + own, (*solve, typeof(ws.state), b, f, i1)),
        (__name__ + ":_local_error", (types.literal(backend), typeof(sys), f1, typeof(sys.A), f1, f1, f1, *(f,) * 6)),
    ]
    return first, rest


@njit(cache=True, error_model="numpy", inline="always")
def _store(x, v, a, w, state, out, k, t, dt, solves):
    """Write the carried state of step k (time t) into the row of :func:`_keep_row` (the saved
    DOFs and directions): :func:`_store_positions`, then v and a. Returns the row written."""
    j = _store_positions(x, w, state, out, k, t, dt, solves)
    o_v, o_a, dofs = out.v, out.a, out.dofs
    for ii in range(dofs.shape[0]):
        i = dofs[ii]
        o_v[j, ii] = v[i]
        o_a[j, ii] = a[i]
    return j


@njit(cache=True, error_model="numpy", inline="always")
def _keep_row(out, k, t, dt, solves):
    """The output row of step k (time t): write step, t, dt and solves into the pending row
    out.plan[S_ROWS] and keep it, or leave it pending (overwritten by the next step),
    by the save plan (methods/save.py): every S_EVERY-th step from the window start
    times[S_FROM] (the pending step before the window is kept with its first step), or, with
    given times, the two step ends around each given time (one given time passed per step: a
    step holding several keeps the following pairs too, at most two rows per given time).
    Returns the row written."""
    # branch-free (a branch here costs 0.2 us per step: numba then keeps the loop's array refcounts)
    plan, times = out.plan, out.times
    given = np.int64(times.shape[0] > 3)  # given times (the last entry is an +inf sentinel)
    g = plan[S_GRID]
    cross = np.int64(times[2 + g] <= t)  # step k reached given time g: keep it and step k - 1
    plan[S_GRID] = g + cross
    inside = np.int64(t >= times[S_FROM])
    hit = np.int64(k == plan[S_NEXT])  # a multiple of S_EVERY
    plan[S_NEXT] += hit * plan[S_EVERY]
    first = inside * np.int64(plan[S_LAST] < 0)  # the first step of the window (nothing kept yet)
    keep = given * cross + (1 - given) * inside * (hit | first)
    prev = np.int64(k > 0) * np.int64(plan[S_LAST] != k - 1) * (given * cross + (1 - given) * first)
    j = plan[S_ROWS] + prev  # the pending row holds step k - 1: kept with step k when prev
    plan[S_LAST] = keep * k + (1 - keep) * plan[S_LAST]
    plan[S_ROWS] = j + keep
    out.step[j] = k
    out.t[j] = t
    out.dt[j] = dt
    out.solves[j] = solves
    return j


@njit(cache=True, error_model="numpy", inline="always")
def _store_positions(x, w, state, out, k, t, dt, solves):
    """The row of :func:`_keep_row` with x, w and the states (the saved DOFs and directions),
    without v and a: a quasi-static march, whose v = a = 0 stay as the outputs were allocated
    (zeros), writes a fifth less per step. Returns the row written."""
    j = _keep_row(out, k, t, dt, solves)
    o_x, dofs = out.x, out.dofs
    for ii in range(dofs.shape[0]):
        o_x[j, ii] = x[dofs[ii]]
    o_w, o_state, dirs = out.w, out.state, out.dirs
    for ii in range(dirs.shape[0]):
        d = dirs[ii]
        o_w[j, ii] = w[d]
        o_state[j, ii] = state[d]
    return j
