"""The inner loop of the exact event-driven dynamic march (method ``events``,
methods/exact_events.py): where does the first margin of a linear phase cross zero?

In a contact state S the system is linear with constant coefficients, and every margin of
the state table (docs/exact_events.md) is, over the phase starting at t0, an exponential
polynomial of tau = t - t0 known in closed form:

    m_j(tau)  = c_j + Re( sum_k a_jk exp(lambda_k tau) ) + Re( sum_h b_jh exp(i Omega_h (t0 + tau)) )
    m_j'(tau) =       Re( sum_k a_jk lambda_k exp(lambda_k tau) ) + Re( sum_h i Omega_h b_jh exp(...) )

(lambda_k the eigenvalues of the phase's first-order matrix, a_jk the margin's modal
coefficients for the phase's initial condition, Omega_h the excitation's angular
frequencies, b_jh the particular solution's harmonic coefficients). The state S holds while
every m_j >= 0. :func:`first_crossing` samples the margins at the safe sub-step ``h``
(a fraction of the period of the fastest term, chosen by the caller), takes the first sample
interval where a margin goes below -tol_j, or where its derivative turns from negative to
positive (a dip between samples: the minimum is located by the Illinois method on m_j' and
counts when m_j < -tol_j there), and refines the root of each margin that crosses in that
interval by the Illinois method to round-off. No Python objects, preallocated scratch,
status codes (no exceptions).
"""

import numpy as np
from numba import njit

#: first_crossing's statuses
NO_CROSSING, CROSSING = 0, 1
#: Illinois iterations at most (each halves the bracket at worst every other step)
MAX_REFINE = 200


@njit(cache=True, error_model="numpy")
def _exponentials(lam, om, t0, tau, e_mode, e_harm):
    """e_mode[k] = exp(lambda_k tau), e_harm[h] = exp(i Omega_h (t0 + tau))."""
    for k in range(lam.shape[0]):
        e_mode[k] = np.exp(lam[k] * tau)
    t = t0 + tau
    for h in range(om.shape[0]):
        e_harm[h] = complex(np.cos(om[h] * t), np.sin(om[h] * t))


@njit(cache=True, error_model="numpy")
def _margin(j, lam, a, c0, om, b, e_mode, e_harm, derivative):
    """m_j (derivative False) or m_j' (True) from the exponentials of one instant."""
    s = 0.0 if derivative else c0[j]
    for k in range(lam.shape[0]):
        term = a[j, k] * e_mode[k]
        if derivative:
            term *= lam[k]
        s += term.real
    for h in range(om.shape[0]):
        term = b[j, h] * e_harm[h]
        if derivative:
            term *= 1j * om[h]
        s += term.real
    return s


@njit(cache=True, error_model="numpy")
def margin_at(j, lam, a, c0, om, b, t0, tau, derivative):
    """m_j(tau) or m_j'(tau) (module docstring)."""
    e_mode = np.empty(lam.shape[0], np.complex128)
    e_harm = np.empty(om.shape[0], np.complex128)
    _exponentials(lam, om, t0, tau, e_mode, e_harm)
    return _margin(j, lam, a, c0, om, b, e_mode, e_harm, derivative)


@njit(cache=True, error_model="numpy")
def margins(lam, a, c0, om, b, t0, taus, values, slopes):
    """values[i, j] = m_j(taus[i]), slopes[i, j] = m_j'(taus[i]) (for checks and plots)."""
    e_mode = np.empty(lam.shape[0], np.complex128)
    e_harm = np.empty(om.shape[0], np.complex128)
    for i in range(taus.shape[0]):
        _exponentials(lam, om, t0, taus[i], e_mode, e_harm)
        for j in range(c0.shape[0]):
            values[i, j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, False)
            slopes[i, j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, True)


@njit(cache=True, error_model="numpy")
def _illinois(j, lam, a, c0, om, b, t0, lo, f_lo, hi, f_hi, derivative, shift):
    """A root of m_j - shift (or m_j' when ``derivative``) in [lo, hi] where f_lo > 0 > f_hi
    (f the function values minus shift), by the Illinois variant of regula falsi, to the
    resolution of the time axis (|hi - lo| <= 4 eps (t0 + hi)). Returns the point of the final
    bracket whose value is nearer zero."""
    side = 0
    for _ in range(MAX_REFINE):
        if hi - lo <= 4.0 * 2.220446049250313e-16 * (abs(t0) + abs(hi)) + 1e-300:
            break
        mid = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        f_mid = margin_at(j, lam, a, c0, om, b, t0, mid, derivative) - shift
        if f_mid == 0.0:
            return mid
        if f_mid > 0.0:
            lo, f_lo = mid, f_mid
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi, f_hi = mid, f_mid
            if side == -1:
                f_lo *= 0.5
            side = -1
    return lo if abs(f_lo) <= abs(f_hi) else hi


@njit(cache=True, error_model="numpy")
def _root_in(j, lam, a, c0, om, b, t0, lo, m_lo, d_lo, hi, m_hi, d_hi, tol):
    """The first root of m_j in [lo, hi] where it goes below -tol, or -1 if it does not:
    a crossing (m_hi < -tol) or a dip (m' turning from - to + inside, the minimum below -tol)."""
    if m_hi < -tol:
        if m_lo > 0.0:
            return _illinois(j, lam, a, c0, om, b, t0, lo, m_lo, hi, m_hi, False, 0.0)
        if m_lo + tol > 0.0:  # starts on the boundary (within tol): where it leaves the band
            return _illinois(j, lam, a, c0, om, b, t0, lo, m_lo + tol, hi, m_hi + tol, False, -tol)
        return lo
    if d_lo < 0.0 and d_hi > 0.0 and m_lo > 0.0:
        t_min = _min_of(j, lam, a, c0, om, b, t0, lo, d_lo, hi, d_hi)
        m_min = margin_at(j, lam, a, c0, om, b, t0, t_min, False)
        if m_min < -tol:
            return _illinois(j, lam, a, c0, om, b, t0, lo, m_lo, t_min, m_min, False, 0.0)
    return -1.0


@njit(cache=True, error_model="numpy")
def _min_of(j, lam, a, c0, om, b, t0, lo, d_lo, hi, d_hi):
    """The zero of m_j' in [lo, hi] where it turns from negative to positive (the minimum of m_j):
    the Illinois method on -m_j' (positive at lo, negative at hi)."""
    side = 0
    f_lo, f_hi = -d_lo, -d_hi
    for _ in range(MAX_REFINE):
        if hi - lo <= 4.0 * 2.220446049250313e-16 * (abs(t0) + abs(hi)) + 1e-300:
            break
        mid = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        if not (lo < mid < hi):
            mid = 0.5 * (lo + hi)
        f_mid = -margin_at(j, lam, a, c0, om, b, t0, mid, True)
        if f_mid == 0.0:
            return mid
        if f_mid > 0.0:
            lo, f_lo = mid, f_mid
            if side == 1:
                f_hi *= 0.5
            side = 1
        else:
            hi, f_hi = mid, f_mid
            if side == -1:
                f_lo *= 0.5
            side = -1
    return 0.5 * (lo + hi)


@njit(cache=True, error_model="numpy")
def first_crossing(lam, a, c0, om, b, t0, tau_max, h, tol, together, roots):
    """The first zero crossing of any margin over (0, tau_max] (module docstring).

    lam (nk,) complex, a (nm, nk) complex, c0 (nm,), om (nh,), b (nm, nh) complex, t0 [s],
    tau_max [s], h [s] the sampling sub-step, tol (nm,) the margins' tolerances, together [s]
    the time within which two roots count as one event. Writes roots[j]: the root of margin j
    in the first interval with a crossing (-1 if none). Returns (status, tau, j): CROSSING
    with the earliest root tau and its margin j, or NO_CROSSING with tau = tau_max."""
    nm = c0.shape[0]
    for j in range(nm):
        roots[j] = -1.0
    if nm == 0:
        return NO_CROSSING, tau_max, -1
    e_mode = np.empty(lam.shape[0], np.complex128)
    e_harm = np.empty(om.shape[0], np.complex128)
    m0 = np.empty(nm)
    d0 = np.empty(nm)
    m1 = np.empty(nm)
    d1 = np.empty(nm)
    _exponentials(lam, om, t0, 0.0, e_mode, e_harm)
    for j in range(nm):
        m0[j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, False)
        d0[j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, True)
    lo = 0.0
    n_int = max(int(np.ceil(tau_max / h)), 1)
    for i in range(1, n_int + 1):
        hi = tau_max if i == n_int else i * h
        _exponentials(lam, om, t0, hi, e_mode, e_harm)
        found = False
        best, best_j = tau_max, -1
        for j in range(nm):
            m1[j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, False)
            d1[j] = _margin(j, lam, a, c0, om, b, e_mode, e_harm, True)
            r = _root_in(j, lam, a, c0, om, b, t0, lo, m0[j], d0[j], hi, m1[j], d1[j], tol[j])
            if r >= 0.0:
                roots[j] = r
                found = True
                if r < best:
                    best, best_j = r, j
        if found:
            for j in range(nm):  # roots farther than `together` from the first are not this event
                if roots[j] > best + together:
                    roots[j] = -1.0
            return CROSSING, best, best_j
        for j in range(nm):
            m0[j] = m1[j]
            d0[j] = d1[j]
        lo = hi
    return NO_CROSSING, tau_max, -1
