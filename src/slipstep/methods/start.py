"""The states a march starts from (docs/architecture.md, "Starting states").

- :func:`static_equilibrium`: the static preload, K x + A^T f(q, w) = f_c (the constant loads
  and contact offsets ramped quasi-statically from x = 0, w = 0, full stick postulated), and
  the first point of the march at t = 0 from it;
- :func:`consistent_start`: a given (x, v, w) at time t with the consistent acceleration
  a = M^-1 (f_e(t) - C v - K x - A^T f(x, w)), the contact force in elastic form.

Both return a :class:`slipstep.methods.state.State` carrying the first point's force terms
(:class:`slipstep.methods.state.StartTerms`), so a marcher starts from it as it is.
"""

from __future__ import annotations

import warnings

import numpy as np

from slipstep.errors import SolverError, Status
from slipstep.kernels import banded as BD
from slipstep.kernels import march as K
from slipstep.kernels import sparse as KS
from slipstep.kernels.contact import STICK, contact_law, generalised_force, local_displacement
from slipstep.methods import compile_ahead
from slipstep.methods import massless as ML
from slipstep.methods.buffers import allocate_outputs, allocate_workspace, reset_cache
from slipstep.methods.eigen import band_mass_lu
from slipstep.methods import sparse as SB
from slipstep.methods.plan import RunPlan
from slipstep.methods.registry import IMPLICIT_KERNEL
from slipstep.methods.state import StartTerms, State
from slipstep.model.excitation import evaluate_compiled, force_signal, motion_signal
from slipstep.output.results import STATE_NAMES
from slipstep.model.system import CompiledSystem, is_sparse, structure_matrix, to_user_order


def static_equilibrium(plan: RunPlan, workspace: K.Workspace | None = None) -> State:
    """The static preload and the march's first point at t = 0 (module docstring): ramp the
    constant loads and offsets quasi-statically in ``preload_increments`` piecewise-linear
    increments, postulating full stick (without loads or offsets x = 0 is the equilibrium);
    then q = A x - B p(0) + g, the law's forces and sliders at it, f_e(0) and the consistent
    a (dynamic methods). Quasi-static methods whose p(0), f_e(0) differ from the constant
    loads start from the static equilibrium at t = 0 instead (:func:`_static_start`).
    ``workspace``: the one to march the ramp in (a marcher's: its T_min cache is kept), else
    a new one."""
    cs, opt = plan.compiled, plan.options
    sparse = is_sparse(cs)  # the condensed sparse backend: its workspace and kernel (methods/sparse.py)
    if sparse:
        ws = SB.preload_workspace(plan, workspace)
    else:
        ws = workspace if workspace is not None else allocate_workspace(cs, opt.max_state_iterations, plan.low_rank)
    for arr in (ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w):
        arr[:] = 0.0
    ws.state[:] = STICK
    if not sparse:
        reset_cache(ws)
    settings = K.replace_settings(
        plan.settings,
        inertia=False,
        signals=False,
        solver=K.PIECEWISE_LINEAR,
        adaptive=False,
        fallback=True,
        preload=opt.preload_increments,
    )
    nq = cs.A.shape[0]
    q, f = np.zeros(nq), np.zeros(nq)
    ramp = allocate_outputs(cs, opt.preload_increments)
    if np.any(cs.constant_force != 0) or np.any(cs.g != 0):
        if not sparse:  # the first march of a run: its callees compiled in a second process
            compile_ahead.start(
                IMPLICIT_KERNEL,
                K.implicit_kernel(settings.structure),
                (cs, settings, ws, ramp, q, f),
                _start_kernels(cs),
            )
        status = (KS.sparse_march if sparse else K.march)(cs, settings, ws, ramp, q, f)
        compile_ahead.stop()
        counters = ramp.counters
        q[:], f[:] = ramp.q[counters[K.C_STEPS]], ramp.f[counters[K.C_STEPS]]
    else:
        status = K.OK
        local_displacement(cs, ws.x, np.zeros(cs.B.shape[1]), q)
        contact_law(cs, q, ws.w.copy(), f, ws.w, ws.state)
    if not sparse:
        reset_cache(ws)  # the ramp's quasi-static J(S) = K + K_D(S) are not the run's
    if status != K.OK:
        states = ", ".join(f"{d}={STATE_NAMES[s]}" for d, s in zip(plan.system.direction_names(), ws.state1))
        raise SolverError(
            f"static preload failed at increment {ramp.counters[K.C_FAIL_STEP]} of "
            f"{opt.preload_increments}: {Status(status).message} (states: {states})"
        )
    # initial point of the march: p(0), f_e(0), consistent acceleration
    p0 = evaluate_compiled(motion_signal(cs), np.zeros(1))[0]
    fe0 = evaluate_compiled(force_signal(cs), np.zeros(1))[0] + cs.constant_force
    quasi = plan.method.quasi_static
    if np.abs(p0).max(initial=0.0) > 1e-6 * cs.length_scale and not quasi:
        warnings.warn(
            "the prescribed motion does not start from zero (p(0) != 0): a dynamic run receives it "
            "as an impulse and rings at the internal frequencies for as long as nothing damps them. "
            "Start motions from zero (sine phase) or set ramp_time.",
            stacklevel=3,
        )
    if quasi and (np.any(p0 != 0) or np.any(fe0 != cs.constant_force)):
        q[:], f[:] = _static_start(plan, ws, settings)
    else:
        w_pre = ws.w.copy()
        local_displacement(cs, ws.x, p0, q)
        contact_law(cs, q, w_pre, f, ws.w, ws.state)
        generalised_force(cs, f, ws.gf)
    ws.fe[:] = fe0
    if not quasi:
        ws.a[:] = mass_solve(cs, fe0 - structure_product(cs, "K", ws.x) - ws.gf)
    user = lambda values: to_user_order(cs, values).copy()  # noqa: E731
    terms = StartTerms(user(ws.fe), user(ws.gf), q.copy(), f.copy())
    return State(0.0, user(ws.x), user(ws.v), user(ws.a), ws.w.copy(), ws.state.copy(), terms)


def _static_start(plan: RunPlan, ws: K.Workspace, settings: K.MarchSettings) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static runs start from the static equilibrium at p(0), f_e(0): one
    piecewise-linear quasi-static step from the preload (x, w) to t = 0 (K x + A^T f(q, w)
    = f_e(0) with q = A x - B p(0) + g, the sliders moved by that solve). Returns (q, f)."""
    cs = plan.compiled
    delta = 1e-9 * (plan.period if plan.period is not None else plan.t_end)
    settings = K.replace_settings(settings, t_start=-delta, t_end=0.0, dt=delta, rtol=0.0, signals=True, preload=0)
    out = allocate_outputs(cs, 1)
    nq = cs.A.shape[0]
    q, f = np.zeros(nq), np.zeros(nq)
    local_displacement(cs, ws.x, np.zeros(cs.B.shape[1]), q)
    contact_law(cs, q, ws.w.copy(), f, np.empty_like(ws.w), np.empty_like(ws.state))
    status = K.march(cs, settings, ws, out, q, f)
    reset_cache(ws)  # the quasi-static J(S) = K + K_D(S) are not the run's (even when it failed)
    if status != K.OK:
        raise SolverError(f"the static equilibrium at t = 0 (p(0), f_e(0)) failed: {Status(status).message}")
    return out.q[1].copy(), out.f[1].copy()


def _start_kernels(cs) -> list[tuple[str, tuple]]:
    """The kernels :func:`consistent_start` calls after the preload, as ("module:name", argument
    types) for methods/compile_ahead.py."""
    from numba import typeof, types

    f1, contact = types.float64[::1], "slipstep.kernels.contact:"
    return [
        (contact + "local_displacement", (typeof(cs), f1, f1, f1)),
        (contact + "contact_law", (typeof(cs), f1, f1, f1, f1, types.int8[::1])),
        (contact + "generalised_force", (typeof(cs), f1, f1)),
    ]


def consistent_start(plan: RunPlan, x, v=None, w=None, contact_state=None, t: float = 0.0, a=None) -> State:
    """The state (x, v, w) at time t [s] completed for a march (module docstring): ``v``
    defaults to 0 (and is 0 for quasi-static methods), ``w`` to 0, ``contact_state`` to the
    law's states at (x, w); ``a`` (optional) to the consistent acceleration
    a = M^-1 (f_e(t) - C v - K x - A^T f(x, w)) with the contact force in elastic form
    T = k_t (u - w), N = k_n v for v > 0 (0 in lift-off). Arrays in the user's DOF order."""
    cs = plan.compiled
    n, nd = cs.M.shape[0], cs.kt.shape[0]
    order = np.asarray(cs.dof_order)  # user order -> kernel order (the banded backend reorders)
    quasi = plan.method.quasi_static
    x = np.array(x, float).reshape(n)[order]
    v = np.zeros(n) if v is None or quasi else np.array(v, float).reshape(n)[order]
    if a is not None:
        a = np.array(a, float).reshape(n)[order]
    w = np.zeros(nd) if w is None else np.array(w, float).reshape(nd)
    p0 = evaluate_compiled(motion_signal(cs), np.array([t]))[0]
    fe0 = evaluate_compiled(force_signal(cs), np.array([t]))[0] + cs.constant_force
    q = np.empty(cs.A.shape[0])
    local_displacement(cs, x, p0, q)
    f = elastic_contact_force(cs, q, w)
    if contact_state is None:
        contact_state = np.empty(nd, np.int8)
        contact_law(cs, q, w.copy(), np.empty_like(q), np.empty(nd), contact_state)
    gf = np.empty(n)
    generalised_force(cs, f, gf)
    if quasi:
        a = np.zeros(n)
    elif a is None:
        a = mass_solve(cs, fe0 - structure_product(cs, "C", v) - structure_product(cs, "K", x) - gf)
    user = lambda values: to_user_order(cs, values)  # noqa: E731
    terms = StartTerms(user(fe0), user(gf), q, f)
    a = np.array(a, float).reshape(n)
    return State(float(t), user(x), user(v), user(a), w, np.asarray(contact_state, np.int8).copy(), terms)


def elastic_contact_force(cs: CompiledSystem, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Local contact forces from (q, w) in elastic form: T_d = k_t (u_d - w_d), N = k_n v for a
    contact with v > 0, all zero in lift-off (in stick and in slip alike, since a slipping
    slider sits at w = u - T / k_t)."""
    f = np.zeros(cs.A.shape[0])
    v = q[cs.normal_row]
    closed = v > 0.0
    f[cs.normal_row] = np.where(closed, cs.kn * v, 0.0)
    d_closed = closed[cs.direction_contact]
    f[cs.tangential_row] = np.where(d_closed, cs.kt * (q[cs.tangential_row] - w), 0.0)
    return f


def structure_product(cs: CompiledSystem, which: str, x: np.ndarray) -> np.ndarray:
    """M x, C x or K x (``which`` 'M', 'C', 'K') in the kernel DOF order, dense, banded or sparse."""
    if is_sparse(cs):
        return structure_matrix(cs, which) @ x
    if not cs.banded:
        return getattr(cs, which) @ x
    out = np.empty(cs.Mb.shape[0])
    BD.band_matvec(getattr(cs, which + "b"), cs.kl, cs.ku, np.ascontiguousarray(x, dtype=float), out)
    return out


def mass_solve(cs: CompiledSystem, rhs: np.ndarray) -> np.ndarray:
    """a = M^-1 rhs on the DOFs with inertia (methods/massless.py), dense, banded or sparse."""
    if is_sparse(cs):
        return SB.mass_solve(cs, rhs)
    if not cs.banded:
        return ML.initial_acceleration(cs.M, rhs)
    lu, piv = band_mass_lu(cs)
    out = np.empty(rhs.shape[0])
    BD.band_lu_solve(lu, cs.kl, cs.ku, piv, np.ascontiguousarray(rhs, dtype=float), out)
    return out
