"""The quasi-static time march of Method 4 (paper Eq. 10; physics.md section 4), a kernel of
its own: at every step of the fixed step dt,

    K x_{n+1} + A^T f(q_{n+1}, w_n) = f_e(t_{n+1}),    q_{n+1} = A x_{n+1} - B p(t_{n+1}) + g

solved by the piecewise-linear step solver of the implicit march
(kernels/step_solvers.piecewise_linear_step: postulate S_{n+1} = S_n, one solve with the cached
J(S) = K + K_D(S), the compatibility check, re-solve on a transition; modified Newton with
J(all stick) when the states cycle; Newton on the consistent tangent in a coupled slip), with
Lin = K and kfac = 1, in one of two forms of the same equations:

* direct (no friction-circle contact): the unknown is x_{n+1} itself, q_base = g - B p(t_{n+1}),
  r0 = f_e(t_{n+1}); a step saves the products A x_n and K x_n of the increment form;
* increment: the unknown is dx = x_{n+1} - x_n, q_base = A x_n - B p + g, r0 = f_e - K x_n, as in
  the implicit march (kernels/march.py). The Newton iterations start from dx = 0, i.e. from
  x_n, so they run in this form: the fallback after cycling postulates or a singular J(S)
  (the step is set up again in this form, step_solvers.stick_fallback) and every step of a
  march with a friction-circle contact (a coupled slip is solved by Newton).

The two forms agree to rounding (about 1e-13 of the force scale on the paper case) and take
the same states, steps and solves; tests/test_quasi_static.py checks this kernel against the
implicit march's quasi-static mode on every backend and law, the fallback included.

Why a kernel of its own: the implicit march carries every dynamic path (the Newmark and
generalised-alpha relations, the Newton solvers, the contact-state adaptive step, the accuracy
control), and its compiled loop is several times the size of what a quasi-static step runs.
The static preload and the static start of a run stay on the implicit march (kernels.march,
``inertia`` False, ``preload``), which keeps its quasi-static mode as the independent path this
kernel is checked against.

One step, in order: loads and motions (march._loads_and_motions), q_base and r0 (the form
above), the piecewise-linear step (the law's f, w and S at the accepted q), x_{n+1}, the contact
states and sliders, the output row
(march._store_positions, save plan included: v = a = 0 are never written, the outputs keep the
zeros they were allocated with). Inputs as kernels.march.march; the MarchSettings it reads: dt,
tol, state_rtol, singular_rtol, t_start, t_end, max_iter, max_state_iter, fallback, signals,
structure.
"""

import functools

import numpy as np
from numba import njit

from slipstep.kernels import structure_ops as so
from slipstep.kernels.arguments import pack_arguments, unpacked
from slipstep.kernels.borrow import borrowed, keep_alive
from slipstep.kernels.codes import (
    C_FAIL_STEP, C_PROGRESS, C_SOLVES, C_STATE_CHANGES, C_STEPS, C_STOP, CAPACITY, INTERRUPTED, LAW_CIRCLE, OK, SINGULAR,
    STATE_CYCLING,
)
from slipstep.kernels.march import (
    S_CAPACITY, S_FAIL, S_ROWS, _accept_contacts, _convergence_parameters, _loads_and_motions, _store,
    _store_positions,
)
from slipstep.kernels.settings import contact_table, state_cache, step_vectors
from slipstep.kernels.step_solvers import CV_FLOOR, piecewise_linear_step, stick_fallback
from slipstep.kernels.lean_compiler import LeanCompiler


@njit(cache=True, error_model="numpy", inline="always")
def _increment_base(backend, sys, has_stiffness, x, p, qbase, r0):
    """The step's base in the dx form: q_base = A x_n - B p + g and r0 -= K x_n (r0 holds f_e)."""
    so.gather_state(backend, sys, x, p, qbase)
    so.sub_predictor(backend, sys, False, False, has_stiffness, r0, r0, x, r0)


def quasi_static_march(sys, st, ws, out, q0, f0):
    """March the quasi-static equilibrium (module docstring) from st.t_start to st.t_end on the
    fixed step st.dt, writing step k into out[k] (k = 0: the given state, local q0 and f0).
    Returns the status; out.counters[C_STEPS] steps done. The kernel of st.structure
    (:func:`quasi_static_kernel`) on the packed arguments (kernels/arguments.py)."""
    return quasi_static_kernel(st.structure)(pack_arguments(sys, ws, out, q0, f0), st)


@functools.cache
def quasi_static_kernel(backend: int):
    """:func:`quasi_static_march` of one structure backend, ``kernel(args, st)`` on a
    kernels.arguments.KernelArguments: the backend a constant of the kernel, its other
    backends' branches pruned before typing (kernels.march.implicit_kernel)."""
    return _quasi_static_kernel(int(backend))


def _quasi_static_kernel(backend):
    """:func:`quasi_static_kernel` (backend a plain int: the closure's cache key)."""

    @njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
    def quasi_static_march_packed(args, st):
        """:func:`quasi_static_march` of this backend on a KernelArguments."""
        sys, ws, out, q0, f0 = unpacked(args)
        cl = contact_table(sys)
        cache = state_cache(ws)
        sv = step_vectors(ws)
        length_scale = sys.length_scale
        x, v, a, fe, w, state = ws.x, ws.v, ws.a, ws.fe, ws.w, ws.state
        fe1, f1, q1, w1, state1, dx, p, qbase, r0 = ws.fe1, ws.f1, ws.q1, ws.w1, ws.state1, ws.dx, ws.p, ws.qbase, ws.r0
        counters = out.counters
        own_conv = _convergence_parameters(backend, sys, st.tol)  # the Newton tolerances of the fallback
        own_kd = so.stick_diagonal(sys)
        conv, kd_stick = borrowed(own_conv), borrowed(own_kd)
        has_circle = np.any(cl.lcode == LAW_CIRCLE)
        has_stiffness = so.has_nonzero(backend, sys, 2)
        direct = not has_circle  # a coupled slip's Newton (full_newton) starts from dx = 0: the dx form
        t = st.t_start
        t_end = st.t_end
        cap = out.plan[S_CAPACITY]
        o_q, o_f, o_rows = out.q, out.f, out.rows
        row = _store(x, v, a, w, state, out, 0, t, 0.0, 0)
        for ii in range(o_rows.shape[0]):
            o_q[row, ii] = q0[o_rows[ii]]
            o_f[row, ii] = f0[o_rows[ii]]
        for d in range(state.shape[0]):
            ws.dt_state[d] = 0  # a fixed step: the cache keys carry no step state
        tiny = 1e-12 * (t_end - t + 1e-300)
        status = OK
        k = 0
        last_slot = -1  # cache slot of the last factorisation (the piecewise-linear fast path)
        ws.lin_dt[0] = np.nan
        basis, clock = ws.basis, ws.clock
        clock[0], clock[1], clock[2], clock[3] = t, np.nan, 0.0, np.nan  # the harmonic basis: exact at the first step
        while t < t_end - tiny:
            if counters[C_STOP] != 0:  # stop request from another thread (Ctrl-C): keep the k steps done
                status = INTERRUPTED
                counters[C_FAIL_STEP] = k
                break
            if k >= cap or out.plan[S_ROWS] + 2 > out.t.shape[0]:  # out of steps or of output rows (march.py)
                status = CAPACITY
                break
            dt = st.dt if t + st.dt <= t_end - tiny else t_end - t  # the last step ends at t_end
            nominal = abs(dt - st.dt) <= 1e-12 * st.dt
            if ws.lin_dt[0] != dt:  # Lin = K (the cache is keyed per step size, like the march's)
                last_slot = -1
                so.build_lin(backend, sys, False, 0.0, 0.0, 1.0, ws.Lin)
                ws.lin_dt[0] = dt
                conv[CV_FLOOR] = st.tol * length_scale * so.max_diagonal(backend, ws.Lin, 1.0, kd_stick)
            _loads_and_motions(sys, t + dt, st.signals, 1.0, basis, clock, fe1, p)
            increment = not direct
            for i in range(r0.shape[0]):
                r0[i] = fe1[i]
            if direct:  # solve for x_{n+1}: q_base = g - B p, r0 = f_e
                so.motion_base(sys, p, qbase)
            else:  # solve for dx: q_base = A x_n - B p + g, r0 = f_e - K x_n
                _increment_base(backend, sys, has_stiffness, x, p, qbase, r0)
            status, solves, last_slot = piecewise_linear_step(backend, sys, cl, cache, ws.Lin, ws.J, 1.0, sv, state,
                                                              ws.visited, 0, nominal, last_slot, has_circle,
                                                              st.max_state_iter, st.fallback and increment, st.max_iter,
                                                              conv, st.state_rtol, st.singular_rtol, length_scale,
                                                              counters)
            if direct and st.fallback and (status == STATE_CYCLING or status == SINGULAR):
                increment = True  # the fallback's Newton starts from x_n: the dx form
                for i in range(r0.shape[0]):
                    r0[i] = fe1[i]
                _increment_base(backend, sys, has_stiffness, x, p, qbase, r0)
                status, more = stick_fallback(backend, sys, cl, cache, ws.Lin, ws.J, 1.0, sv, nominal, st.max_iter, conv,
                                              st.singular_rtol, status, counters)
                solves += more
            counters[C_SOLVES] += solves
            if status != OK:
                counters[C_FAIL_STEP] = k + 1
                out.times[S_FAIL] = t + dt
                break
            if increment:
                for i in range(x.shape[0]):
                    x[i] += dx[i]
            else:
                for i in range(x.shape[0]):
                    x[i] = dx[i]
            for i in range(x.shape[0]):
                fe[i] = fe1[i]
            if _accept_contacts(w, state, w1, state1):
                counters[C_STATE_CHANGES] += 1
            t += dt
            k += 1
            row = _store_positions(x, w, state, out, k, t, dt, solves)
            for ii in range(o_rows.shape[0]):
                o_q[row, ii] = q1[o_rows[ii]]
                o_f[row, ii] = f1[o_rows[ii]]
            counters[C_PROGRESS] = k
        counters[C_STEPS] = k
        keep_alive((own_conv, own_kd))
        return status

    return quasi_static_march_packed
