"""Compiled parts of the harmonic balance's alternating frequency-time (AFT) step (issue 13,
moved here from hbm/aft.py by issue 24): the kernels' contact law marched over the time
samples of one period, the per-sample tangents of the converged cycle, and their gathered
(condensed) form. The mathematics is stated in :mod:`slipstep.hbm.aft`.

Layout: qt, ft (N, nq) local displacements and forces per sample; wt, st (N, nd) sliders and
states; per row r of contact c (rows row_start[c]:row_start[c+1]) the tangent of sample k is

    df_k[r] = sum_l Ac[k, r, l] dq_k[r0 + l] + Mc[k, r, l] dq_s[r0 + l],   s = src[k, r]

(s = -1: no memory term). No Python objects; outputs preallocated by the caller.
"""

from numba import njit

from slipstep.kernels import contact as _law


@njit(cache=True, nogil=True, error_model="numpy")
def apply_law(args, q, w_old, f, w_new, state):
    """The kernels' nonlinear law at one sample (see slipstep.kernels.contact.law)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = args
    _law.law(nrow, lcode, lpar, fdir, ndir, trow, kt, q, w_old, f, w_new, state)


@njit(cache=True, nogil=True, error_model="numpy")
def apply_linear_law(args, state, q, w_old, f, w_new):
    """The kernels' piecewise-linear law for a postulated state (slipstep.kernels.contact.piecewise_law)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = args
    _law.piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old, f, w_new)


@njit(cache=True, nogil=True, error_model="numpy")
def march_cycle(args, qt, w_init, max_periods, w_tol, resets, ft, wt, st, src0, src0_state, scratch, last, last_state):
    """March the law over the samples qt (N, nq) from w_init until the sliders repeat after a
    period (max |w_N - w_0| <= w_tol). Writes the last period's forces ft, sliders wt and
    states st, and per direction the sample and state of its last slider reset (resets[state, d]:
    the state sets the slider from the current sample) before that period began (src0 = -1:
    none since w_init). scratch (2, nd), last (nd,), last_state (nd,): workspace. Returns the
    periods marched (negative: not converged within max_periods)."""
    n = qt.shape[0]
    nd = w_init.shape[0]
    w_start, w_old = scratch[0], scratch[1]
    for d in range(nd):
        w_start[d] = w_init[d]
        w_old[d] = w_init[d]
        last[d] = -1
        last_state[d] = 0
    for p in range(1, max_periods + 1):
        for d in range(nd):
            src0[d] = last[d]
            src0_state[d] = last_state[d]
        for k in range(n):
            apply_law(args, qt[k], w_old, ft[k], wt[k], st[k])
            for d in range(nd):
                if resets[st[k, d], d]:
                    last[d] = k
                    last_state[d] = st[k, d]
                w_old[d] = wt[k, d]
        change = 0.0
        for d in range(nd):
            change = max(change, abs(w_old[d] - w_start[d]))
            w_start[d] = w_old[d]
        if change <= w_tol:
            return p
    return -max_periods


@njit(cache=True, nogil=True, error_model="numpy")
def cycle_coefficients(
    st, src0, src0_state, Fq, Fw, Wq, Ww, dir_of_row, contact_of_row, row_start, Ac, Mc, src, last, last_state
):
    """The time-sample tangents of the converged cycle (module docstring): Ac, Mc, src, from
    the states st and the tangent tables of the piecewise-linear law; s = src[k, r] is the
    last slider reset of r's direction before k (src0, src0_state: its last reset before the
    cycle, in any earlier period). last, last_state (nd,): workspace."""
    n = st.shape[0]
    nq = dir_of_row.shape[0]
    nd = st.shape[1]
    Ac[:] = 0.0
    Mc[:] = 0.0
    for d in range(nd):
        last[d] = src0[d]
        last_state[d] = src0_state[d]
    for k in range(n):
        for r in range(nq):
            d = dir_of_row[r]
            s_r = st[k, d]
            c = contact_of_row[r]
            r0, r1 = row_start[c], row_start[c + 1]
            for l in range(r1 - r0):
                Ac[k, r, l] = Fq[s_r, r, r0 + l]
            b = Fw[s_r, r, d]
            if b != 0.0 and last[d] >= 0:
                src[k, r] = last[d]
                for l in range(r1 - r0):
                    Mc[k, r, l] = b * Wq[last_state[d], d, r0 + l]
            else:
                src[k, r] = -1
        for d in range(nd):
            if Ww[st[k, d], d, d] == 0.0:
                last[d] = k
                last_state[d] = st[k, d]


@njit(cache=True, nogil=True, error_model="numpy")
def gathered_tangent(Ac, Mc, src, contact_of_row, row_start, L, pair_of, pair_k, pair_s, blocks):
    """The sample tangents seen through the gather q = L y (L (nq, r)): the generalised force
    g_k = L^T f_k changes as dg_k = sum_s W[k, s] dy_s with

        W[k, k] += L[r]^T Ac[k, r, l] L[r0 + l],   W[k, src[k, r]] += L[r]^T Mc[k, r, l] L[r0 + l]

    summed over rows r and their contact's columns l. Only the sample pairs (k, s) that occur
    are stored: pair p is (pair_k[p], pair_s[p]) with the r x r block blocks[p]. pair_of (N, N)
    must be -1 on entry and is left so (workspace). Returns the number of pairs (-1: more
    pairs than blocks has room for)."""
    n, nq, width = Ac.shape
    nr = L.shape[1]
    count = 0
    for k in range(n):
        for row in range(nq):
            c = contact_of_row[row]
            r0, r1 = row_start[c], row_start[c + 1]
            s = src[k, row]
            for l in range(r1 - r0):
                for which in range(2):
                    if which == 0:
                        a, t = Ac[k, row, l], k
                    else:
                        if s < 0:
                            break
                        a, t = Mc[k, row, l], s
                    if a == 0.0:
                        continue
                    p = pair_of[k, t]
                    if p < 0:
                        if count == blocks.shape[0]:  # out of room: reset and report
                            for q in range(count):
                                pair_of[pair_k[q], pair_s[q]] = -1
                            return -1
                        p = count
                        pair_of[k, t] = p
                        pair_k[p] = k
                        pair_s[p] = t
                        blocks[p] = 0.0
                        count += 1
                    for m in range(nr):
                        lm = L[row, m] * a
                        if lm == 0.0:
                            continue
                        for m2 in range(nr):
                            blocks[p, m, m2] += lm * L[r0 + l, m2]
    for p in range(count):
        pair_of[pair_k[p], pair_s[p]] = -1
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def tangent_product(Ac, Mc, src, contact_of_row, row_start, dq, df):
    """df_k = (the cycle's tangent) dq, sample by sample (dq, df (N, nq); module docstring)."""
    n, nq, width = Ac.shape
    for k in range(n):
        for row in range(nq):
            c = contact_of_row[row]
            r0, r1 = row_start[c], row_start[c + 1]
            s = src[k, row]
            acc = 0.0
            for l in range(r1 - r0):
                acc += Ac[k, row, l] * dq[k, r0 + l]
                if s >= 0:
                    acc += Mc[k, row, l] * dq[s, r0 + l]
            df[k, row] = acc
