"""Contact laws: one module per law, the normal part they share, and here the one dispatch on
the law code that every kernel calls (so no kernel outside this package writes a row of a
law's state table).

A law module gives the tangential part of the law as small scalar functions (no arrays: numba
inlines them into the loops over the contacts below at no cost, which functions taking arrays
in a loop do not get), for one direction (uncoupled) or one contact
(coupled), in contact (v > 0), with the friction limit mu N given:

* ``law``         the return mapping: T, w_new and the state from u and w_old;
* ``linear``      the piecewise-linear form T = K_i(S) q + s_i(S, w_old) of a postulated state
                  S (a state without one, the coupled slip, evaluates the law's force);
* ``compatible``  does S satisfy its row of the state table at q (within a tolerance)?
* ``tangent``     the local stiffness entries dT/du, dT/dv: K_i(S), or the consistent
                  tangent of the return mapping where it is not piecewise constant;
* piecewise-linear laws also: ``slider_derivative`` (dw/dq of the state, for the shooting
  sensitivity) and ``stick_margin`` (the stick rows of the state table in time, for the
  event-driven march).

The normal part (N = k_n v; v <= 0 lift-off: T = N = 0, w = u) is laws/normal.py. The
functions below hold the state table's rows over all contacts of the contact table (nrow,
lcode, lpar, fdir, ndir, trow, kt: kernels/settings.ContactLaw) and the one dispatch on the law
code: the loops over the contacts (law, piecewise_law, compatible, compatible_law, coupled,
delta_stiffness, delta_rows; re-exported by kernels/contact.py) and, for one contact c, its
local stiffness (stiffness: K_D assembly in contact.py and banded.py) and its margins in time
(margins, cross: kernels/events.py). Inside a loop over the contacts only scalar functions are
called: an inlined function taking arrays costs numba's reference counting of each array per
call (kernels/borrow.py), unless the caller borrows them (contact_stiffness does).

Adding a law: a module here with law, linear, compatible and tangent; a code in codes.py (and,
if its states are new, a state code and its name in STATE_NAMES); one branch on that code in
each function below; a name in slipstep.model.contact.CONTACT_LAWS (with its capabilities);
its row in the README.
"""

from numba import njit

from slipstep.kernels.codes import LAW_CIRCLE, LIFT, P_KN, P_MU, SLIP_COUPLED, SLIP_POS, STICK
from slipstep.kernels.laws import circle, normal, uncoupled

# margin kinds of the event-driven march (:func:`margins`, :func:`cross`): a contact's normal
# margin, or M_INTO + the state a direction's margin leads into
M_CONTACT, M_LIFT, M_INTO = 0, 1, 2


# ---- the friction circle out of line (keeps the paper's law compact where it is inlined) -----
@njit(cache=True, nogil=True, error_model="numpy")
def _circle_law(trow, kt, d0, limit, q, w_old, f, w_new, state):
    """circle.law for the contact whose first direction is d0 (limit = mu N)."""
    r1, r2 = trow[d0], trow[d0 + 1]
    f[r1], f[r2], w_new[d0], w_new[d0 + 1], s = circle.law(kt[d0], limit, q[r1], q[r2], w_old[d0], w_old[d0 + 1])
    state[d0] = s
    state[d0 + 1] = s


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new):
    """circle.linear for the contact whose first direction is d0."""
    r1, r2 = trow[d0], trow[d0 + 1]
    f[r1], f[r2], w_new[d0], w_new[d0 + 1] = circle.linear(kt[d0], limit, state[d0], q[r1], q[r2], w_old[d0],
                                                           w_old[d0 + 1])


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_compatible(trow, kt, d0, limit, state, q, w_old, tol_t):
    """circle.compatible for the contact whose first direction is d0."""
    return circle.compatible(kt[d0], limit, state[d0], q[trow[d0]], q[trow[d0 + 1]], w_old[d0], w_old[d0 + 1], tol_t)


@njit(cache=True, error_model="numpy", inline="always")
def _circle_tangent(c, nrow, lpar, fdir, trow, kt, state, q, w_old):
    """circle.tangent of contact c at (q, w_old), or without a point (q of length 0) the
    stick one."""
    d0 = fdir[c]
    mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
    if q.shape[0] == 0:
        return circle.tangent(kt[d0], mu_kn, 0.0, state[d0], False, 0.0, 0.0, 0.0, 0.0)
    return circle.tangent(kt[d0], mu_kn, mu_kn * q[nrow[c]], state[d0], True, q[trow[d0]], q[trow[d0 + 1]],
                          w_old[d0], w_old[d0 + 1])


# ---- the rows of the state table over all contacts --------------------------------------------
# The loops over the contacts are here, not in the kernels that call them: the per-contact
# functions taking arrays tried first made Method 1's kernel 2.3x slower (reference counting).
@njit(cache=True, error_model="numpy", inline="always")
def law(nrow, lcode, lpar, fdir, ndir, trow, kt, q, w_old, f, w_new, state):
    """The nonlinear law (return mapping): forces f (local, like q), new sliders and states
    from q and w_old."""
    for c in range(nrow.shape[0]):
        nr = nrow[c]
        v = q[nr]
        d0 = fdir[c]
        if v <= 0.0:
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]], w_new[d], state[d] = normal.lift_off(q[trow[d]])
            continue
        N = lpar[c, P_KN] * v
        f[nr] = N
        limit = lpar[c, P_MU] * N
        if lcode[c] == LAW_CIRCLE:
            _circle_law(trow, kt, d0, limit, q, w_old, f, w_new, state)
            continue
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            f[tr], w_new[d], state[d] = uncoupled.law(kt[d], limit, q[tr], w_old[d])


@njit(cache=True, error_model="numpy", inline="always")
def piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, f, w_new):
    """The law in a postulated state S: f = K(S) q + s(S, w_old) where S is linear."""
    for c in range(nrow.shape[0]):
        nr = nrow[c]
        d0 = fdir[c]
        if state[d0] == LIFT:
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]], w_new[d], _ = normal.lift_off(q[trow[d]])
            continue
        N = lpar[c, P_KN] * q[nr]
        f[nr] = N
        limit = lpar[c, P_MU] * N
        if lcode[c] == LAW_CIRCLE:
            _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new)
            continue
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            f[tr], w_new[d] = uncoupled.linear(kt[d], limit, state[d], q[tr], w_old[d])


@njit(cache=True, error_model="numpy", inline="always")
def compatible(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, rtol, length_scale):
    """Does the postulated state satisfy its row of the state table at q (within tolerance)?

    Tolerances: rtol * L on v (L the system length scale) and rtol * (mu k_n |v| + k_t L)
    on the friction test, so that a point on a stick/slip or contact boundary is accepted.
    """
    tol_v = rtol * length_scale
    for c in range(nrow.shape[0]):
        v = q[nrow[c]]
        d0 = fdir[c]
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            continue
        if v < -tol_v:
            return False
        limit = lpar[c, P_MU] * lpar[c, P_KN] * v
        if lcode[c] == LAW_CIRCLE:
            if not _circle_compatible(trow, kt, d0, limit, state, q, w_old, rtol * (abs(limit) + kt[d0] * length_scale)):
                return False
            continue
        for d in range(d0, d0 + ndir[c]):
            tol_t = rtol * (abs(limit) + kt[d] * length_scale)
            if not uncoupled.compatible(kt[d], limit, state[d], q[trow[d]], w_old[d], tol_t):
                return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def compatible_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, rtol, length_scale, f, w_new):
    """:func:`compatible` and, when the postulated state holds, :func:`piecewise_law` at q in the same
    pass over the contacts. Returns the compatibility; f and w_new are meaningful only when it
    is True."""
    tol_v = rtol * length_scale
    for c in range(nrow.shape[0]):
        nr = nrow[c]
        v = q[nr]
        d0 = fdir[c]
        if state[d0] == LIFT:
            if v > tol_v:
                return False
            f[nr] = 0.0
            for d in range(d0, d0 + ndir[c]):
                f[trow[d]], w_new[d], _ = normal.lift_off(q[trow[d]])
            continue
        if v < -tol_v:
            return False
        N = lpar[c, P_KN] * v
        limit = lpar[c, P_MU] * N
        f[nr] = N
        climit = lpar[c, P_MU] * lpar[c, P_KN] * v  # the limit of compatible (rounded as there)
        if lcode[c] == LAW_CIRCLE:
            if not _circle_compatible(trow, kt, d0, climit, state, q, w_old, rtol * (abs(climit) + kt[d0] * length_scale)):
                return False
            _circle_linear(trow, kt, d0, limit, state, q, w_old, f, w_new)
            continue
        for d in range(d0, d0 + ndir[c]):
            tr = trow[d]
            tol_t = rtol * (abs(climit) + kt[d] * length_scale)
            if not uncoupled.compatible(kt[d], climit, state[d], q[tr], w_old[d], tol_t):
                return False
            f[tr], w_new[d] = uncoupled.linear(kt[d], limit, state[d], q[tr], w_old[d])
    return True


@njit(cache=True, error_model="numpy", inline="always")
def coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, state):
    """True if some contact is in a state without a piecewise-linear form (coupled slip)."""
    for c in range(nrow.shape[0]):
        if state[fdir[c]] == SLIP_COUPLED:
            return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def delta_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, kfac, y, out):
    """out = kfac (K(S) - K(stick)) y, local: lift-off -k_t on u, -k_n on v; slip the slip
    tangent minus k_t on u; stick 0."""
    for r in range(out.shape[0]):
        out[r] = 0.0
    for c in range(nrow.shape[0]):
        d0 = fdir[c]
        nr = nrow[c]
        if state[d0] == LIFT:
            out[nr] = kfac * normal.lift_delta(lpar[c, P_KN]) * y[nr]
            for d in range(d0, d0 + ndir[c]):
                out[trow[d]] = kfac * normal.lift_delta(kt[d]) * y[trow[d]]
            continue
        if lcode[c] == LAW_CIRCLE:
            if state[d0] == STICK:
                continue
            r1, r2 = trow[d0], trow[d0 + 1]
            k11, k12, k21, k22, k1v, k2v = _circle_tangent(c, nrow, lpar, fdir, trow, kt, state, q, w_old)
            out[r1] = kfac * ((k11 - kt[d0]) * y[r1] + k12 * y[r2] + k1v * y[nr])
            out[r2] = kfac * (k21 * y[r1] + (k22 - kt[d0]) * y[r2] + k2v * y[nr])
            continue
        mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
        for d in range(d0, d0 + ndir[c]):
            if state[d] != STICK:
                kuu, kuv = uncoupled.tangent(kt[d], mu_kn, state[d])
                out[trow[d]] = kfac * (kuv * y[nr] + (kuu - kt[d]) * y[trow[d]])


@njit(cache=True, error_model="numpy", inline="always")
def delta_rows(nrow, lpar, fdir, ndir, trow, kt, state, rows, kdiag, kcol, koff):
    """The rows of K(S) - K(stick) that are not zero: row, diagonal entry, one off-diagonal
    column (-1: none) and entry. Lift-off -k_t on u, -k_n on v; slip k_uu - k_t on u and k_uv
    at v. Piecewise-linear laws (a coupled slip has two off-diagonal entries: the sparse
    backend refuses the friction circle). Returns their number."""
    m = 0
    for c in range(nrow.shape[0]):
        d0 = fdir[c]
        nr = nrow[c]
        if state[d0] == LIFT:
            for d in range(d0, d0 + ndir[c]):
                rows[m], kdiag[m], kcol[m], koff[m] = trow[d], normal.lift_delta(kt[d]), -1, 0.0
                m += 1
            rows[m], kdiag[m], kcol[m], koff[m] = nr, normal.lift_delta(lpar[c, P_KN]), -1, 0.0
            m += 1
            continue
        mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
        for d in range(d0, d0 + ndir[c]):
            if state[d] != STICK:
                kuu, kuv = uncoupled.tangent(kt[d], mu_kn, state[d])
                rows[m], kdiag[m], kcol[m], koff[m] = trow[d], kuu - kt[d], nr, kuv
                m += 1
    return m


# ---- one contact's local stiffness (K_D assembly: dense, banded) -------------------------------
@njit(cache=True, error_model="numpy", inline="always")
def stiffness(c, nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old):
    """The local stiffness K(S) of contact c (laws' tangent; a contact has 1 or 2 directions)
    as seven entries k with their rows (ra, rb): K_D(S) = sum_k k A[ra]^T A[rb] (paper Eq. 7),
    in the order they are added; unused entries are 0. At (q, w_old) for a coupled slip (q of
    length 0: no point, the stiffest tangent, used for T_min). Lift-off: all 0."""
    nr = nrow[c]
    d0 = fdir[c]
    kn = lpar[c, P_KN]
    if state[d0] == LIFT:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), (nr, nr, nr, nr, nr, nr, nr), (nr, nr, nr, nr, nr, nr, nr)
    r1 = trow[d0]
    if lcode[c] == LAW_CIRCLE:
        r2 = trow[d0 + 1]
        k11, k12, k21, k22, k1v, k2v = _circle_tangent(c, nrow, lpar, fdir, trow, kt, state, q, w_old)
        return (kn, k11, k12, k21, k22, k1v, k2v), (nr, r1, r1, r2, r2, r1, r2), (nr, r1, r2, r1, r2, nr, nr)
    mu_kn = lpar[c, P_MU] * kn
    kuu1, kuv1 = uncoupled.tangent(kt[d0], mu_kn, state[d0])
    if ndir[c] == 1:
        return (kn, kuu1, kuv1, 0.0, 0.0, 0.0, 0.0), (nr, r1, r1, nr, nr, nr, nr), (nr, r1, nr, nr, nr, nr, nr)
    r2 = trow[d0 + 1]
    kuu2, kuv2 = uncoupled.tangent(kt[d0 + 1], mu_kn, state[d0 + 1])
    return (kn, kuu1, kuv1, kuu2, kuv2, 0.0, 0.0), (nr, r1, r1, r2, r2, nr, nr), (nr, r1, nr, r2, nr, nr, nr)


# ---- the state table in time (kernels/events.py: piecewise-linear laws) ---------------------
@njit(cache=True, error_model="numpy", inline="always")
def margins(c, nrow, lpar, fdir, ndir, trow, kt, state, w, Q, om, MC, kind, owner, k):
    """The margins of contact c in state S from slot k (rows of MC over the basis b_0 = 1,
    sin, cos of om_h t; Q[j] the basis coefficients of q), >= 0 while S holds: in contact v,
    lifted -v (owner c); per direction d (owner d) stick a v - b (u - w) on both sides
    (uncoupled.stick_margin), slip sgn dw/dt with dw = du - s dv (uncoupled.slider_derivative,
    sgn +1 in slip+). kind[k] says what crosses (:func:`cross`). Returns the next slot."""
    nb = Q.shape[0]
    nr = nrow[c]
    d0 = fdir[c]
    lift = state[d0] == LIFT
    for j in range(nb):
        MC[k, j] = -Q[j, nr] if lift else Q[j, nr]
    kind[k] = M_LIFT if lift else M_CONTACT
    owner[k] = c
    k += 1
    if lift:
        return k
    mu_kn = lpar[c, P_MU] * lpar[c, P_KN]
    for d in range(d0, d0 + ndir[c]):
        tr = trow[d]
        if state[d] == STICK:
            for side in range(2):
                a, b, crossed = uncoupled.stick_margin(kt[d], mu_kn, side)
                for j in range(nb):
                    MC[k, j] = a * Q[j, nr] - b * (Q[j, tr] - (w[d] if j == 0 else 0.0))
                kind[k] = M_INTO + crossed
                owner[k] = d
                k += 1
        else:
            sgn = 1.0 if state[d] == SLIP_POS else -1.0
            _, s = uncoupled.slider_derivative(kt[d], mu_kn, state[d])
            for h in range(om.shape[0]):
                cs_ = sgn * (Q[2 * h + 1, tr] - s * Q[2 * h + 1, nr])
                cc_ = sgn * (Q[2 * h + 2, tr] - s * Q[2 * h + 2, nr])
                MC[k, 2 * h + 1] = -om[h] * cc_
                MC[k, 2 * h + 2] = om[h] * cs_
            MC[k, 0] = 0.0
            kind[k] = M_INTO + STICK
            owner[k] = d
            k += 1
    return k


@njit(cache=True, error_model="numpy", inline="always")
def cross(kind, o, fdir, ndir, trow, q, state, w):
    """The state change where a margin (:func:`margins`: its kind and owner o) crosses zero at
    q: contact -> lift-off; lift-off -> stick with w = u; stick -> slip+/-; slip -> stick (the
    slider stays where it is)."""
    if kind == M_CONTACT:
        for d in range(fdir[o], fdir[o] + ndir[o]):
            state[d] = LIFT
    elif kind == M_LIFT:
        for d in range(fdir[o], fdir[o] + ndir[o]):
            state[d] = STICK
            w[d] = q[trow[d]]
    else:
        state[o] = kind - M_INTO
