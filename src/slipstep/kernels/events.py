"""Event-driven quasi-static march (beyond the paper): exact contact-state transitions.

Quasi-static equilibrium (paper Eq. 10) in a fixed contact state S with piecewise-linear
law f = K(S) q + s(S, w) (stick sliders w fixed during the phase) is linear in the loads
and motions:

    J(S) x(t) = f_e(t) - A^T K(S) (g - B p(t)) - A^T s(S, w),      J(S) = K + A^T K(S) A

With harmonic loads and motions, f_e and p are combinations of the basis b_0 = 1,
b_j(t) = sin(w_h t), cos(w_h t), so x(t) = sum_j X_j b_j(t) and q(t) = sum_j Q_j b_j(t)
with one solve J(S) X_j = RHS_j per basis function (J(S) and the harmonic columns cached
per state; the constant column, which holds the stick sliders, solved every phase). Every condition of the state
table (kernels.laws.margins, the laws' rows in time) is then a known smooth function of time (a trigonometric polynomial), a margin that
stays >= 0 while S holds:

    in contact      v >= 0;                 lift-off      -v >= 0
    stick           mu k_n v -/+ k_t (u - w) >= 0 (both signs)
    slip+ / slip-   +/- dw/dt >= 0, w = u -/+ mu k_n v / k_t (the slider keeps moving)

(the time-continuous limit of the compatibility check of Method 4). The phase ends at the
first root of any margin: in closed form for one harmonic (c0 + R sin(w t + phi)), else
by scanning (64 points per period of the highest frequency) and refining the bracket by
the Illinois method to 1e-13 of the period (a margin counts as crossed below
-state_tolerance times the sum of its coefficients' magnitudes; a margin already past that
at the phase start, such as a slip whose rate has reversed, ends the phase at once); there
the states whose margin reaches zero with a negative slope change (stick -> slip+/-,
slip -> stick with the slider frozen where it is, contact <-> lift-off, re-contact in stick
with w = u) and a new phase starts. Outputs are sampled on the uniform grid of
``MarchSettings.dt`` at the cost of a sum over the basis (x, q, and the forces and sliders, affine in
q within a phase; sin and cos advanced by rotation). Piecewise-linear laws only (no coupled
slip), harmonic signals without tables or ramps (checked in Python).
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.codes import (
    C_FACTORISATIONS, C_FAIL_STEP, C_LAW_CALLS, C_SOLVES, C_STATE_CHANGES, C_STEPS, NON_FINITE, OK, SINGULAR,
    STATE_CYCLING,
)
from slipstep.kernels import laws
from slipstep.kernels.arguments import pack_arguments, unpacked
from slipstep.kernels.lean_compiler import LeanCompiler
from slipstep.kernels.borrow import borrowed, keep_alive
from slipstep.kernels.cache import find_slot
from slipstep.kernels.contact import contact_stiffness, piecewise_law
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.march import S_CAPACITY, S_EVERY, S_FAIL, S_FROM, S_LAST, S_NEXT, S_ROWS, _store

class EventSystem(NamedTuple):
    """The fields of slipstep.system.CompiledSystem that :func:`event_march` reads (same names
    and meaning): 19 arrays instead of 44 (:func:`event_arguments`), so that the packed
    arguments (kernels/arguments.py) hold and pass fewer."""

    K: np.ndarray
    A: np.ndarray
    AT: np.ndarray
    B: np.ndarray
    g: np.ndarray
    normal_row: np.ndarray
    first_direction: np.ndarray
    n_directions: np.ndarray
    tangential_row: np.ndarray
    kt: np.ndarray
    law: np.ndarray
    law_par: np.ndarray
    constant_force: np.ndarray
    force_frequency: np.ndarray
    force_sin: np.ndarray
    force_cos: np.ndarray
    motion_frequency: np.ndarray
    motion_sin: np.ndarray
    motion_cos: np.ndarray


class EventWorkspace(NamedTuple):
    """The fields of kernels.march.Workspace that :func:`event_march` reads (same arrays)."""

    x: np.ndarray
    w: np.ndarray
    state: np.ndarray
    q1: np.ndarray
    f1: np.ndarray
    w1: np.ndarray
    J: np.ndarray
    key: np.ndarray
    cache_keys: np.ndarray
    cache_used: np.ndarray
    cache_lu: np.ndarray
    cache_piv: np.ndarray


def event_arguments(sys, ws):
    """(EventSystem, EventWorkspace) of a CompiledSystem and a Workspace: views of the same
    arrays, so what the kernel writes lands in ``ws``."""
    return (EventSystem(*(getattr(sys, f) for f in EventSystem._fields)),
            EventWorkspace(*(getattr(ws, f) for f in EventWorkspace._fields)))


MAX_FLIPS = 20  # state changes allowed at one instant before STATE_CYCLING
ANCHOR = 64  # output points between exact evaluations of the basis (rotation in between)


@njit(cache=True, error_model="numpy", inline="always")
def _basis(t, om, b):
    """b_0 = 1, b_(2h+1) = sin(om_h t), b_(2h+2) = cos(om_h t)."""
    b[0] = 1.0
    for h in range(om.shape[0]):
        b[2 * h + 1] = np.sin(om[h] * t)
        b[2 * h + 2] = np.cos(om[h] * t)


@njit(cache=True, error_model="numpy", inline="always")
def _value(c, b):
    s = 0.0
    for j in range(b.shape[0]):
        s += c[j] * b[j]
    return s


@njit(cache=True, error_model="numpy", inline="always")
def _slope(c, om, b):
    """d/dt of sum_j c_j b_j(t)."""
    s = 0.0
    for h in range(om.shape[0]):
        s += om[h] * (c[2 * h + 1] * b[2 * h + 2] - c[2 * h + 2] * b[2 * h + 1])
    return s


@njit(cache=True, nogil=True, error_model="numpy")
def _root(c, om, ta, tb, b, tol_t):
    """The root of sum_j c_j b_j(t) in (ta, tb] (value >= 0 at ta, < 0 at tb): Illinois."""
    _basis(ta, om, b)
    fa = _value(c, b)
    _basis(tb, om, b)
    fb = _value(c, b)
    side = 0
    for _ in range(200):
        if tb - ta <= tol_t:
            break
        t = (ta * fb - tb * fa) / (fb - fa) if fb != fa else 0.5 * (ta + tb)
        if not (ta < t < tb):
            t = 0.5 * (ta + tb)
        _basis(t, om, b)
        f = _value(c, b)
        if f < 0.0:
            tb, fb = t, f
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            ta, fa = t, f
            if side == 1:
                fb *= 0.5
            side = 1
    return tb


@njit(cache=True, error_model="numpy", inline="always")
def _first_root_1h(c, om, ta, sa, ca, t_end, tol):
    """One harmonic: the first t in [ta, t_end] where c0 + a sin(om t) + b cos(om t) falls
    below 0 and then below -tol, in closed form (a sin + b cos = R sin(om t + phi)); t_end + 1
    if none. sa, ca = sin(om ta), cos(om ta).

    The zero crossing downwards is at psi0 = om t + phi with sin psi0 = r0 = -c0 / R,
    cos psi0 = -sqrt(1 - r0^2), the band's edge (value -tol) at psi1 = psi0 + dpsi. Where the
    band is thin (dr = tol / R <= 1e-6, |r0| < 0.9) dpsi = dr / sqrt(1 - r0^2) to first order
    (the next term below 6 dr^2 < 6e-12) and the angle from om ta to the crossing comes from
    one arctan2 of its sine and cosine (the rotation of (cos psi0, sin psi0) by -phi and by
    -om ta, no phase angle formed); else by arcsin and arctan2."""
    c0, a, b = c[0], c[1], c[2]
    lim = abs(c0) + tol
    R2 = a * a + b * b
    if R2 <= lim * lim:  # never crosses -tol (or is below it everywhere)
        return ta if c0 + np.sqrt(R2) < -tol else t_end + 1.0
    R = np.sqrt(R2)
    two_pi = 2.0 * np.pi
    r0 = -c0 / R
    dr = min(tol / R, r0 + 1.0)  # r0 - r1, r1 = max(-1, (-c0 - tol) / R)
    if dr <= 1e-6 and abs(r0) < 0.9:
        cq = np.sqrt(1.0 - r0 * r0)  # -cos psi0
        ua, ub = a / R, b / R  # cos phi, sin phi
        c_t = -cq * ua + r0 * ub  # cos(psi0 - phi)
        s_t = r0 * ua + cq * ub  # sin(psi0 - phi)
        delta0 = np.arctan2(s_t * ca - c_t * sa, c_t * ca + s_t * sa)  # psi0 - phi - om ta, in (-pi, pi]
        dpsi = dr / cq
        d1 = delta0 + dpsi  # (psi1 - psi_a) mod 2 pi
        if d1 < 0.0:
            d1 += two_pi
        d0 = d1 - dpsi
    else:
        r1 = r0 - dr
        phi = np.arctan2(b, a)
        e0 = np.pi - np.arcsin(r0)
        e1 = np.pi - np.arcsin(r1)
        x1 = e1 - (om[0] * ta + phi)
        d1 = x1 - two_pi * np.floor(x1 / two_pi)  # (e1 - psi_a) mod 2 pi, in [0, 2 pi)
        d0 = d1 - (e1 - e0)
    t = ta + max(d0, 0.0) / om[0]
    return t if t <= t_end else t_end + 1.0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _phase(sys, nrow, lcode, lpar, fdir, ndir, trow, kt, state, w, Fb, Pb, om, J, keys, used, lus, pivs,
           Xc, Qc, key, scr, wtmp, MC, kind, owner, scale, singular_rtol, counters):
    """The basis responses X_j, Q_j of state S and its margins (rows of MC over the basis,
    their kind, owner and scale). J(S) and the harmonic columns (j >= 1, independent of the
    sliders) are cached per state; the constant column (it holds s(S, w)) is solved every
    phase. Returns (ok, n_margins, solves, slot): X_j = Xc[slot, j], Q_j = Qc[slot, j]."""
    Kst, A, AT = sys.K, sys.A, sys.AT
    n, nq, nb = Kst.shape[0], A.shape[0], Fb.shape[0]
    rhs, ylin, flin, fs, zero_q = scr[0, :n], scr[1, :nq], scr[2, :nq], scr[3, :nq], scr[4, :nq]
    for r in range(nq):
        zero_q[r] = 0.0
    nd = state.shape[0]
    for d in range(nd):
        key[d] = state[d]
        key[nd + d] = 0
    slot, found = find_slot(keys, used, key)
    solves = 1
    if not found:
        for i in range(n):
            for j in range(n):
                J[i, j] = Kst[i, j]
        nowhere = zero_q[:0]
        contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, state, nowhere, nowhere, 1.0, J)
        counters[C_FACTORISATIONS] += 1
        if not lu_factor(J, lus[slot], pivs[slot], singular_rtol):
            used[slot] = False
            return False, 0, 0, slot
    piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, zero_q, w, fs, wtmp)  # s(S, w)
    for j in range(nb if not found else 1):
        for r in range(nq):  # y_j = g d_j0 - B P_j
            s = sys.g[r] if j == 0 else 0.0
            for c in range(Pb.shape[1]):
                s -= sys.B[r, c] * Pb[j, c]
            ylin[r] = s
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, ylin, w, flin, wtmp)
        for r in range(nq):  # K(S) y_j (+ s for the constant column)
            if j != 0:
                flin[r] -= fs[r]
        for i in range(n):
            s = Fb[j, i]
            for r in range(nq):
                s -= AT[i, r] * flin[r]
            rhs[i] = s
        lu_solve(lus[slot], pivs[slot], rhs, Xc[slot, j])
        for r in range(nq):
            s = ylin[r]
            for i in range(n):
                s += A[r, i] * Xc[slot, j, i]
            Qc[slot, j, r] = s
        solves += 1 if j > 0 else 0
    Q = Qc[slot]
    k = 0
    for c in range(nrow.shape[0]):  # the margins
        k = laws.margins(c, nrow, lpar, fdir, ndir, trow, kt, state, w, Q, om, MC, kind, owner, k)
    for i in range(k):
        s = 0.0
        for j in range(nb):
            s += abs(MC[i, j])
        scale[i] = s + 1e-300
    return True, k, solves, slot


@njit(cache=True, error_model="numpy", inline="always")
def _take(blk, at, size):
    """The next ``size`` entries of a scratch block from ``at``: (view, at + size)."""
    return blk[at:at + size], at + size


@njit(cache=True, error_model="numpy", inline="always")
def _rotate(b, rot_c, rot_s):
    """Advance the basis by one output step in place: (sin, cos)(om (t + dt)) from (sin, cos)(om t)
    with rot_c, rot_s = cos(om dt), sin(om dt)."""
    for h in range(rot_c.shape[0]):
        sn, cn = b[2 * h + 1], b[2 * h + 2]
        b[2 * h + 1] = sn * rot_c[h] + cn * rot_s[h]
        b[2 * h + 2] = cn * rot_c[h] - sn * rot_s[h]


@njit(cache=True, error_model="numpy", inline="always")
def _point_row(i, k, t, t_prev, pending, b_step, b_t, b_dt, b_solves):
    """Row i of a block: output point k at time t, its step t - t_prev and the solves since the last point."""
    b_step[i] = k
    b_t[i] = t
    b_dt[i] = t - t_prev
    b_solves[i] = pending


@njit(cache=True, error_model="numpy", inline="always")
def _block_basis(k0, cm, dt_out, t0, t_end, t_prev, pending, om, rot_c, rot_s, bb, Bk, b_step, b_t, b_dt, b_solves):
    """The cm output points k0 + 1.. of a block (t_k = min(k dt + t0, t_end)): their step, time,
    step size and solves (into the block's rows b_*), and their basis values Bk[j, i] =
    b_j(t_(k0 + 1 + i)), exact at the first point and then advanced by rotation (:func:`_rotate`;
    one harmonic: sin and cos in registers). Returns the time of the last point."""
    nb = bb.shape[0]
    if nb == 3:
        rc, rs = rot_c[0], rot_s[0]
        sn, cn = 0.0, 1.0
        for i in range(cm):
            kk = k0 + i + 1
            tk = min(kk * dt_out + t0, t_end)
            if i == 0:
                sn, cn = np.sin(om[0] * tk), np.cos(om[0] * tk)
            else:
                sn, cn = sn * rc + cn * rs, cn * rc - sn * rs
            Bk[1, i] = sn  # (b_0 = 1 is not read: _block_fill)
            Bk[2, i] = cn
            _point_row(i, kk, tk, t_prev, pending, b_step, b_t, b_dt, b_solves)
            pending = 0
            t_prev = tk
        return t_prev
    for i in range(cm):
        kk = k0 + i + 1
        tk = min(kk * dt_out + t0, t_end)
        if i == 0:
            _basis(tk, om, bb)
        else:
            _rotate(bb, rot_c, rot_s)
        for j in range(nb):
            Bk[j, i] = bb[j]
        _point_row(i, kk, tk, t_prev, pending, b_step, b_t, b_dt, b_solves)
        pending = 0
        t_prev = tk
    return t_prev


@njit(cache=True, error_model="numpy", inline="always")
def _block_fill(blk, cm, Bk, Gs, c0):
    """blk[i, ii] = sum_j b_j(t_i) G_j,(c0 + ii) at the cm points of a block (blk: the block's rows of
    one output array, Bk[j, i] = b_j(t_i)), summed in the order of the basis (b_0 = 1: G_0c +
    b_1 G_1c + ...; one harmonic: the G_jc in registers). Column by column: long loops over the
    points, no index arithmetic beyond the loop counters."""
    nb = Gs.shape[0]
    for ii in range(blk.shape[1]):
        c = c0 + ii
        if nb == 3:
            g0, g1, g2 = Gs[0, c], Gs[1, c], Gs[2, c]
            for i in range(cm):
                blk[i, ii] = g0 + Bk[1, i] * g1 + Bk[2, i] * g2
        else:
            for i in range(cm):
                s = Bk[0, i] * Gs[0, c]
                for j in range(1, nb):
                    s += Bk[j, i] * Gs[j, c]
                blk[i, ii] = s


@njit(cache=True, error_model="numpy", inline="always")
def _outputs_every(k0, m, row0, dt_out, t0, t_end, t_prev, pending, om, rot_c, rot_s, bb, Bk, Gs, n_x, n_r,
                   state, dirs, o_rows, o_vals):
    """Output points k0 + 1 .. k0 + m of a phase into rows row0.. (the default save plan: every
    point kept): x, q, f, w = sum_j b_j(t_k) G_j over the saved columns of Gs and the phase's
    state; v = a = 0 are the zeros the runner allocates the buffers with
    (methods/simulation._allocate_outputs: a quasi-static runner never writes them). In blocks
    of ANCHOR points (the basis exact at a block's first point): times and basis
    (:func:`_block_basis`), then the columns (:func:`_block_fill`). o_rows = (out.step, out.t,
    out.dt, out.solves), o_vals = (out.x, out.q, out.f, out.w, out.state).
    Returns the time of the last point (t_prev if m = 0)."""
    o_step, o_t, o_dt, o_solves = o_rows
    o_x, o_q, o_f, o_w, o_state = o_vals
    done = 0
    while done < m:
        cm = min(ANCHOR, m - done)
        r0, r1 = row0 + done, row0 + done + cm
        t_prev = _block_basis(k0 + done, cm, dt_out, t0, t_end, t_prev, pending, om, rot_c, rot_s, bb, Bk,
                              o_step[r0:r1], o_t[r0:r1], o_dt[r0:r1], o_solves[r0:r1])
        pending = 0
        _block_fill(o_x[r0:r1], cm, Bk, Gs, 0)
        _block_fill(o_q[r0:r1], cm, Bk, Gs, n_x)
        _block_fill(o_f[r0:r1], cm, Bk, Gs, n_x + n_r)
        _block_fill(o_w[r0:r1], cm, Bk, Gs, n_x + 2 * n_r)
        b_state = o_state[r0:r1]
        for ii in range(b_state.shape[1]):
            s = state[dirs[ii]]
            for i in range(cm):
                b_state[i, ii] = s
        done += cm
    return t_prev


def event_march(sys, st, ws, out, q0, f0):
    """Event-driven quasi-static march from st.t_start to st.t_end with outputs every st.dt
    (module docstring); same arguments (st: the MarchSettings), layout and counters as
    kernels.march.march, sys and ws as the slim tuples of :func:`event_arguments` (or the full
    CompiledSystem and Workspace: the same fields are read). :func:`event_march_packed` on the
    packed arguments (kernels/arguments.py)."""
    return event_march_packed(pack_arguments(sys, ws, out, q0, f0), st)


def event_kernel(backend: int):
    """The event-driven march's kernel ``kernel(args, st)`` on a kernels.arguments.KernelArguments
    (registry.Method.kernel): :func:`event_march_packed`, one for every structure backend (it
    reads the dense matrices of the slim tuples)."""
    return event_march_packed


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def event_march_packed(args, st):
    """:func:`event_march` on a KernelArguments."""
    # ---- the arguments' arrays without reference counting (kernels/arguments.py, kernels/borrow.py) ----
    sys, ws, out, q0, f0 = unpacked(args)
    Kst, A = sys.K, sys.A
    nrow, lcode, lpar, fdir = sys.normal_row, sys.law, sys.law_par, sys.first_direction
    ndir, trow, kt = sys.n_directions, sys.tangential_row, sys.kt
    counters = out.counters
    n, nq, nd, m = Kst.shape[0], A.shape[0], kt.shape[0], sys.B.shape[1]
    nfh, nmh = sys.force_frequency.shape[0], sys.motion_frequency.shape[0]
    nh = nfh + nmh
    nb = 1 + 2 * nh
    # scratch: one zeroed block, one for the per-state responses and one of ints, carved into borrowed views
    # (no reference counts in the loops; kept alive to the end, kernels/borrow.py)
    nmax = nrow.shape[0] + 2 * nd  # margins at most: one per contact, two per stick direction
    dofs, o_rows, dirs = out.dofs, out.rows, out.dirs
    n_x, n_r, n_w = dofs.shape[0], o_rows.shape[0], dirs.shape[0]
    ns = n_x + 2 * n_r + n_w
    nslot = ws.cache_used.shape[0]
    own_f = np.zeros(3 * nh + nb * (n + m + nq + nd + nmax + ns + ANCHOR) + 5 * max(n, nq) + nd + nmax + 2 * nb
                     + 2 * n + nd + ns)
    own_x = np.empty(nslot * nb * (n + nq))
    own_i = np.zeros(2 * nmax, np.int64)
    blk, blk_x, blk_i = borrowed(own_f), borrowed(own_x), borrowed(own_i)
    om, at = _take(blk, 0, nh)
    rot_c, at = _take(blk, at, nh)
    rot_s, at = _take(blk, at, nh)
    v_, at = _take(blk, at, nb * n)
    Fb = v_.reshape((nb, n))
    v_, at = _take(blk, at, nb * m)
    Pb = v_.reshape((nb, m))
    v_, at = _take(blk, at, 5 * max(n, nq))
    scr = v_.reshape((5, max(n, nq)))
    v_, at = _take(blk, at, nb * nq)
    Fp = v_.reshape((nb, nq))
    v_, at = _take(blk, at, nb * nd)
    Wp = v_.reshape((nb, nd))
    v_, at = _take(blk, at, nmax * nb)
    MC = v_.reshape((nmax, nb))
    v_, at = _take(blk, at, nb * ns)
    Gs = v_.reshape((nb, ns))  # per phase: the saved columns [x dofs, q rows, f rows, w dirs] per basis function
    v_, at = _take(blk, at, nb * ANCHOR)
    Bk = v_.reshape((nb, ANCHOR))  # the basis at a block of output points
    wtmp, at = _take(blk, at, nd)
    scale, at = _take(blk, at, nmax)
    bb, at = _take(blk, at, nb)
    broot, at = _take(blk, at, nb)
    zero, at = _take(blk, at, n)  # v = a = 0 of every output
    xo, at = _take(blk, at, n)
    wo, at = _take(blk, at, nd)
    vals, at = _take(blk, at, ns)
    kind, owner = blk_i[:nmax], blk_i[nmax:]
    Xc = blk_x[:nslot * nb * n].reshape((nslot, nb, n))
    Qc = blk_x[nslot * nb * n:].reshape((nslot, nb, nq))
    for i in range(n):
        Fb[0, i] = sys.constant_force[i]
    om_max = 0.0
    for h in range(nfh):
        om[h] = 2.0 * np.pi * sys.force_frequency[h]
        for i in range(n):
            Fb[2 * h + 1, i] = sys.force_sin[i, h]
            Fb[2 * h + 2, i] = sys.force_cos[i, h]
    for h in range(nmh):
        om[nfh + h] = 2.0 * np.pi * sys.motion_frequency[h]
        for c in range(m):
            Pb[2 * (nfh + h) + 1, c] = sys.motion_sin[c, h]
            Pb[2 * (nfh + h) + 2, c] = sys.motion_cos[c, h]
    for h in range(nh):
        om_max = max(om_max, om[h])
        rot_c[h] = np.cos(om[h] * st.dt)
        rot_s[h] = np.sin(om[h] * st.dt)
    period = 2.0 * np.pi / om_max if nh > 0 else st.t_end - st.t_start
    scan = min(period / 64.0, (st.t_end - st.t_start) / 16.0)
    tol_t = 1e-13 * period
    rtol = st.state_rtol
    keys, used, lus, pivs = ws.cache_keys, ws.cache_used, ws.cache_lu, ws.cache_piv
    used[:] = False
    state, w, x = ws.state, ws.w, ws.x
    q1, f1, w1 = ws.q1, ws.f1, ws.w1
    # ---- initial point ----
    t = st.t_start
    t_end = st.t_end
    dt_out = st.dt
    prev = state.copy()
    n_rows = out.t.shape[0]
    row = _store(x, zero, zero, w, state, out, 0, t, 0.0, 0)
    for ii in range(o_rows.shape[0]):
        out.q[row, ii] = q0[o_rows[ii]]
        out.f[row, ii] = f0[o_rows[ii]]
    cap = out.plan[S_CAPACITY]
    t_prev = t
    k = 0
    tiny = 1e-12 * (t_end - t + 1e-300)
    status = OK
    pending = 0  # solves of the phases since the last output
    flips = 0
    t0 = st.t_start
    o_q, o_f = out.q, out.f
    plan = out.plan
    o_x, o_w, o_state = out.x, out.w, out.state
    o_step, o_t, o_dt, o_solves = out.step, out.t, out.dt, out.solves
    # the default save plan (every point from the start, no given times): rows written here, as _store would
    every_point = plan[S_EVERY] == 1 and out.times.shape[0] == 3 and out.times[S_FROM] <= st.t_start
    sa, ca = (np.sin(om[0] * t), np.cos(om[0] * t)) if nh == 1 else (0.0, 1.0)
    while t < t_end - tiny:
        ok, nm, solves, slot = _phase(sys, nrow, lcode, lpar, fdir, ndir, trow, kt, state, w, Fb, Pb, om, ws.J,
                                      keys, used, lus, pivs, Xc, Qc, ws.key, scr, wtmp, MC, kind, owner, scale,
                                      st.singular_rtol, counters)
        X = Xc[slot]
        Q = Qc[slot]
        # forces and sliders are affine in q within the phase: their basis columns F_j, W_j
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, scr[4, :nq], w, f1, w1)  # at q = 0
        for j in range(nb):
            piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, Q[j], w, Fp[j], Wp[j])
            if j > 0:
                for r in range(nq):
                    Fp[j, r] -= f1[r]
                for d in range(nd):
                    Wp[j, d] -= w1[d]
        if not ok:
            status = SINGULAR
            break
        pending += solves
        counters[C_SOLVES] += solves
        # ---- the first root of a margin after t ----
        t_ev = t_end
        hit = -1
        ta = t
        _basis(t, om, bb)  # a margin already below its band at the phase start ends the phase at once
        for i in range(nm):  # (a slip whose rate has reversed by the start: the root search looks ahead only)
            if _value(MC[i], bb) < -rtol * scale[i]:
                t_ev, hit = t, i
                ta = t_end
                break
        if nh == 1 and hit < 0:  # sa, ca = sin(om t), cos(om t): from the last transition
            for i in range(nm):
                tr_ = _first_root_1h(MC[i], om, t, sa, ca, t_end, rtol * scale[i])
                if tr_ <= t_end and tr_ < t_ev:
                    t_ev, hit = tr_, i
            ta = t_end
        while ta < t_end - tiny and hit < 0:
            tb = min(ta + scan, t_end)
            _basis(tb, om, bb)
            for i in range(nm):
                if _value(MC[i], bb) < -rtol * scale[i]:
                    tr_ = _root(MC[i], om, ta, tb, broot, tol_t)
                    if tr_ < t_ev:
                        t_ev, hit = tr_, i
            ta = tb
        # ---- outputs in (t, t_ev]: the saved columns of G summed over the basis (v = a = 0) ----
        for j in range(nb):
            c = 0
            for ii in range(n_x):
                Gs[j, c] = X[j, dofs[ii]]
                c += 1
            for ii in range(n_r):
                Gs[j, c] = Q[j, o_rows[ii]]
                Gs[j, n_r + c] = Fp[j, o_rows[ii]]
                c += 1
            c += n_r
            for ii in range(n_w):
                Gs[j, c] = Wp[j, dirs[ii]]
                c += 1
        if k < cap and plan[S_ROWS] + 2 <= n_rows and (k + 1) * dt_out + t0 <= t_ev + tiny:  # a first output: new state?
            for d in range(nd):
                if state[d] != prev[d]:
                    counters[C_STATE_CHANGES] += 1
                    break
            for d in range(nd):
                prev[d] = state[d]
        if every_point:  # the default plan keeps every output point: rows k0 + 1.. are the next ones (no _store)
            row0 = plan[S_ROWS]
            k_max = min(cap, k + n_rows - 1 - row0)  # k < cap and row + 2 <= n_rows at every output
            k1 = k
            while k1 < k_max and (k1 + 1) * dt_out + t0 <= t_ev + tiny:
                k1 += 1
            m = k1 - k
            t_prev = _outputs_every(k, m, row0, dt_out, t0, t_end, t_prev, pending, om, rot_c, rot_s, bb, Bk,
                                    Gs, n_x, n_r, state, dirs, (o_step, o_t, o_dt, o_solves),
                                    (o_x, o_q, o_f, o_w, o_state))
            if m > 0:
                k = k1
                plan[S_ROWS] = row0 + m
                plan[S_LAST] = k
                plan[S_NEXT] = k + 1
                pending = 0
        n_out = 0
        while not every_point and k < cap and plan[S_ROWS] + 2 <= n_rows and (k + 1) * dt_out + t0 <= t_ev + tiny:
            tk = min((k + 1) * dt_out + t0, t_end)
            if n_out % ANCHOR == 0:  # exact basis, then advanced by rotation (a few ulps per output)
                _basis(tk, om, bb)
            else:
                _rotate(bb, rot_c, rot_s)
            n_out += 1
            k += 1
            b0 = bb[0]  # sum_j b_j G_jc in the order of the basis (columns innermost: independent sums)
            for c in range(ns):
                vals[c] = b0 * Gs[0, c]
            for j in range(1, nb):
                bj = bb[j]
                for c in range(ns):
                    vals[c] += bj * Gs[j, c]
            for ii in range(n_x):
                xo[dofs[ii]] = vals[ii]
            for ii in range(n_w):
                wo[dirs[ii]] = vals[n_x + 2 * n_r + ii]
            row = _store(xo, zero, zero, wo, state, out, k, tk, tk - t_prev, pending)
            for ii in range(n_r):
                o_q[row, ii] = vals[n_x + ii]
                o_f[row, ii] = vals[n_x + n_r + ii]
            t_prev = tk
            pending = 0
        if (k >= cap or out.plan[S_ROWS] + 2 > n_rows) and (k + 1) * dt_out + t0 <= t_ev + tiny:
            status = 4  # CAPACITY: out of output points or rows
            break
        if hit < 0:
            t = t_end
            break
        # ---- the transition at t_ev: every margin reaching zero with a negative slope ----
        _basis(t_ev, om, bb)
        sa, ca = bb[1 % nb], bb[2 % nb]  # (nh = 1: the next phase's sin, cos of om t)
        for r in range(nq):
            q1[r] = _value(Q[:, r], bb)
        for i in range(n):
            x[i] = _value(X[:, i], bb)
            if not np.isfinite(x[i]):
                status = NON_FINITE
        if status != OK:
            break
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q1, w, f1, w1)
        for d in range(nd):
            wtmp[d] = w1[d]  # sliders at t_ev (slip: where they are; lift: w = u)
        changed = False
        for i in range(nm):
            val = _value(MC[i], bb)
            if not (i == hit or (val <= 1e-7 * scale[i] and _slope(MC[i], om, bb) < 0.0)):
                continue
            changed = True
            laws.cross(kind[i], owner[i], fdir, ndir, trow, q1, state, wtmp)
        for d in range(nd):
            w[d] = wtmp[d]
        counters[C_LAW_CALLS] += 1
        flips = flips + 1 if t_ev - t <= tol_t else 0
        if flips > MAX_FLIPS or not changed:
            status = STATE_CYCLING
            break
        t = t_ev
    if status != OK:
        counters[C_FAIL_STEP] = k + 1
        out.times[S_FAIL] = t
    counters[C_STEPS] = k
    keep_alive((own_f, own_x, own_i))
    return status
