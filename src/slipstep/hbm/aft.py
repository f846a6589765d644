"""Alternating frequency-time (AFT) contact forces and their exact Jacobian.

Given the harmonic coefficients Z (n_coef x nq) of the local contact displacements q(theta)
(q = A x - B p + g, physics.md section 1), the AFT

1. samples q_k = E Z at theta_k = 2 pi k / N (:mod:`slipstep.hbm.fourier`);
2. marches the kernels' own contact law (:func:`slipstep.kernels.contact.law`, physics.md
   section 2) over the samples, k = 0..N-1, period after period, from the sliders w_init
   (the static preload's), until the sliders at the end of a period equal those at its start
   (a converged hysteresis cycle: the cycle is periodic, f_k = f(q_k, w_{k-1}), w_{-1} = w_{N-1});
3. returns the Fourier coefficients F = P f of the forces of that cycle.

Exact Jacobian from the piecewise-linear form (paper Eq. 5). In the converged cycle each
sample has a state S_k; the law is then linear in (q_k, w_{k-1}):

    df_k = Fq(S_k) dq_k + Fw(S_k) dw_{k-1},     dw_k = Wq(S_k) dq_k + Ww(S_k) dw_{k-1}.

Fq, Fw, Wq, Ww are read off the kernels' piecewise-linear law (:func:`tangent_tables`: the
law evaluated at unit vectors; nothing about the law is restated here). For this law every
slider either keeps its value (stick: Ww = 1, Wq = 0) or is reset from the current sample
(slip, lift-off: Ww = 0), so dw_{k-1} of direction d is Wq(S_s) dq_s of the last reset sample
s before k, in the converged cycle or in any earlier period of the march (q is periodic, so
dq_s = E_s dZ there too: a slider that slipped only while the cycle settled, then stuck for
good, "shakedown", keeps its dependence on that sample; no reset since w_init: dw = 0). With
dq_k = E_k dZ:

    dF/dZ = P [ Fq(S_k) E_k + sum_d Fw(S_k)[:, d] Wq(S_s)[d, :] E_s ]_k

assembled per contact (contacts are independent): the first term is P diag(a) E, whose
entries are the DFT of the sample weights a_k at h_i -+ h_j (one FFT per tangent entry), the
second one outer product P_I c_I (x) E_s per stick interval I (its source s is constant).
It is the exact derivative of the discrete AFT wherever no sample sits exactly on
a state boundary (checked against finite differences in tests/test_hbm_aft.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slipstep.kernels import contact as _law
from slipstep.kernels.settings import contact_table

# ---- the kernels' contact law (its table: kernels.settings.contact_table) --------------------


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


# ---- tangents of the piecewise-linear form ---------------------------------------------------

N_STATES = 4  # LIFT, STICK, SLIP_POS, SLIP_NEG (slipstep.kernels.contact)


def tangent_tables(args, nq: int, nd: int):
    """Fq (4, nq, nq), Fw (4, nq, nd), Wq (4, nd, nq), Ww (4, nd, nd): the derivatives of the
    piecewise-linear law with every direction in state S (index 0..3), from the law itself
    (it is linear in (q, w_old) for a fixed state and zero at q = 0, w_old = 0, so its values
    at unit vectors are its columns). The rows of a direction in a mixed state are read from
    the table of that direction's own state (directions are uncoupled; the normal row follows
    the contact's first direction)."""
    Fq, Fw = np.zeros((N_STATES, nq, nq)), np.zeros((N_STATES, nq, nd))
    Wq, Ww = np.zeros((N_STATES, nd, nq)), np.zeros((N_STATES, nd, nd))
    f, w_new = np.zeros(nq), np.zeros(nd)
    for s in range(N_STATES):
        state = np.full(nd, s, np.int8)
        for j in range(nq):
            q = np.zeros(nq)
            q[j] = 1.0
            apply_linear_law(args, state, q, np.zeros(nd), f, w_new)
            Fq[s, :, j], Wq[s, :, j] = f, w_new
        for d in range(nd):
            w = np.zeros(nd)
            w[d] = 1.0
            apply_linear_law(args, state, np.zeros(nq), w, f, w_new)
            Fw[s, :, d], Ww[s, :, d] = f, w_new
    keeps = np.abs(np.diagonal(Ww, axis1=1, axis2=2) - 1.0) < 1e-12
    resets = np.abs(np.diagonal(Ww, axis1=1, axis2=2)) < 1e-12
    off = Ww - np.einsum("sd,de->sde", np.diagonal(Ww, axis1=1, axis2=2), np.eye(nd))
    if (
        not np.all(keeps | resets)
        or np.abs(off).max(initial=0.0) > 0
        or np.abs(Wq[:, :, :][np.broadcast_to(keeps[:, :, None], Wq.shape)]).max(initial=0.0) > 0
    ):
        raise NotImplementedError(
            "the contact law's sliders neither keep nor reset per sample: the AFT Jacobian assumes they do"
        )
    return Fq, Fw, Wq, Ww


def row_tables(cs):
    """dir_of_row (nq,): the direction whose state governs each local row; contact_of_row (nq,);
    row_start (nc + 1,): the rows of contact c are row_start[c]:row_start[c+1]."""
    nq = cs.A.shape[0]
    nc = cs.kn.shape[0]
    dir_of_row = np.zeros(nq, np.int64)
    contact_of_row = np.zeros(nq, np.int64)
    row_start = np.zeros(nc + 1, np.int64)
    for c in range(nc):
        d0, nd_c = cs.first_direction[c], cs.n_directions[c]
        rows = [cs.tangential_row[d] for d in range(d0, d0 + nd_c)] + [cs.normal_row[c]]
        row_start[c], row_start[c + 1] = min(rows), max(rows) + 1
        if row_start[c + 1] - row_start[c] != nd_c + 1:
            raise ValueError("contact rows are not contiguous")
        for d in range(d0, d0 + nd_c):
            dir_of_row[cs.tangential_row[d]] = d
        dir_of_row[cs.normal_row[c]] = d0
        contact_of_row[rows] = c
    return dir_of_row, contact_of_row, row_start


# ---- the compiled AFT cycle and its Jacobian -------------------------------------------------


@njit(cache=True, nogil=True, error_model="numpy")
def march_cycle(args, qt, w_init, max_periods, w_tol, resets, ft, wt, st, src0, src0_state):
    """March the law over the samples qt (N, nq) from w_init until the sliders repeat after a
    period (max |w_N - w_0| <= w_tol). Writes the last period's forces ft, sliders wt and
    states st, and per direction the sample and state of its last slider reset (resets[state, d]:
    the state sets the slider from the current sample) before that period began (src0 = -1:
    none since w_init); returns the periods marched (negative: not
    converged within max_periods)."""
    n = qt.shape[0]
    nd = w_init.shape[0]
    w_start = w_init.copy()
    w_old = w_init.copy()
    last = np.full(nd, -1, np.int64)
    last_state = np.zeros(nd, np.int8)
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
def cycle_coefficients(st, src0, src0_state, Fq, Fw, Wq, Ww, dir_of_row, contact_of_row, row_start, Ac, Mc, src):
    """The time-sample tangents of the converged cycle (see the module docstring), per row r
    and column l of r's contact:  df_k[r] = sum_l Ac[k, r, l] dq_k[r0 + l] + Mc[k, r, l] dq_s[r0 + l]
    with s = src[k, r] (-1: no memory term), the last slider reset of r's direction before k
    (src0, src0_state: its last reset before the cycle, in any earlier period)."""
    n = st.shape[0]
    nq = dir_of_row.shape[0]
    nd = st.shape[1]
    Ac[:] = 0.0
    Mc[:] = 0.0
    last = src0.copy()
    last_state = src0_state.copy()
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


def product_indices(h: np.ndarray, n: int):
    """For the real basis of harmonics h (fourier.Basis order) the indices and weights that turn
    the DFT of a sample weight a_k into P diag(a) E (phi_i phi_j = (alpha cos((h_i - h_j) t) +
    beta cos((h_i + h_j) t) + gamma sin((h_i + h_j) t) + delta sin((h_i - h_j) t)) / 2)."""
    hh = np.concatenate([[0], np.repeat(h[1:], 2)])
    kind = np.concatenate([[0], np.tile([0, 1], h.size - 1)])  # 0 cos, 1 sin
    hi, hj = hh[:, None], hh[None, :]
    ki, kj = kind[:, None], kind[None, :]
    cc, ss = (ki == 0) & (kj == 0), (ki == 1) & (kj == 1)
    alpha = np.where(cc | ss, 1.0, 0.0)
    beta = np.where(cc, 1.0, np.where(ss, -1.0, 0.0))
    gamma = np.where(ki != kj, 1.0, 0.0)
    delta = np.where((ki == 0) & (kj == 1), -1.0, np.where((ki == 1) & (kj == 0), 1.0, 0.0))
    weight = np.full(hh.size, 2.0 / n)
    weight[0] = 1.0 / n
    w = 0.5 * weight[:, None]
    return ((hi - hj) % n, (hi + hj) % n, w * alpha, w * beta, w * gamma, w * delta)


class AFT:
    """The AFT of one system on one basis: ``evaluate(Z)`` -> F (and dF/dZ on request).

    Layout of the flattened unknowns: index j * nq + r (coefficient j, local row r)."""

    def __init__(self, cs, basis, w_init: np.ndarray, max_periods: int = 50):
        self.args = contact_table(cs)
        self.basis = basis
        self.nq, self.nd = cs.A.shape[0], cs.kt.shape[0]
        self.w_init = np.ascontiguousarray(w_init, dtype=np.float64)
        self.max_periods = int(max_periods)
        self.w_tol = 1e-12 * cs.length_scale
        self.tables = tangent_tables(self.args, self.nq, self.nd)
        self.rows = row_tables(cs)
        Ww = self.tables[3]
        self.resets = np.ascontiguousarray(np.diagonal(Ww, axis1=1, axis2=2) == 0.0)  # (4, nd)
        n = basis.samples
        self.ft = np.zeros((n, self.nq))
        self.wt = np.zeros((n, self.nd))
        self.st = np.zeros((n, self.nd), np.int8)
        self.src0 = np.zeros(self.nd, np.int64)
        self.src0_state = np.zeros(self.nd, np.int8)
        self.periods = 0
        width = int(np.max(np.diff(self.rows[2]), initial=1))
        self._Ac = np.zeros((n, self.nq, width))
        self._Mc = np.zeros((n, self.nq, width))
        self._src = np.zeros((n, self.nq), np.int64)
        self._products = product_indices(basis.h, n)
        Fw = self.tables[1]
        own = np.zeros((self.nq, self.nd), bool)
        own[np.arange(self.nq), self.rows[0]] = True
        if np.abs(Fw[:, ~own]).max(initial=0.0) > 0:
            raise NotImplementedError("a contact force row depends on another direction's slider")

    def evaluate(self, Z: np.ndarray, jacobian: bool = True):
        """F (n_coef, nq) of the converged cycle at coefficients Z (n_coef, nq); with
        ``jacobian`` also dF/dZ as an (n_coef nq) x (n_coef nq) matrix."""
        b = self.basis
        qt = np.ascontiguousarray(b.inverse @ Z)
        self.qt = qt
        self.periods = march_cycle(
            self.args,
            qt,
            self.w_init,
            self.max_periods,
            self.w_tol,
            self.resets,
            self.ft,
            self.wt,
            self.st,
            self.src0,
            self.src0_state,
        )
        F = b.forward @ self.ft
        if not jacobian:
            return F, None
        return F, self.jacobian()

    def jacobian(self) -> np.ndarray:
        """dF/dZ of the last evaluated cycle: P diag(Ac) E by one FFT per tangent column (the
        product-to-sum identities of :func:`product_indices`), plus the memory terms grouped by
        their source sample (one outer product per stick interval)."""
        b, nq = self.basis, self.nq
        Fq, Fw, Wq, Ww = self.tables
        dir_of_row, contact_of_row, row_start = self.rows
        Ac, Mc, src = self._Ac, self._Mc, self._src
        cycle_coefficients(
            self.st, self.src0, self.src0_state, Fq, Fw, Wq, Ww, dir_of_row, contact_of_row, row_start, Ac, Mc, src
        )
        n, _, width = Ac.shape
        dm, sm, wa, wb, wg, wd = self._products
        spec = np.fft.fft(Ac.reshape(n, -1), axis=0)  # a_hat[m] = sum_k a_k exp(-i m theta_k)
        C, S = spec.real, -spec.imag
        D = wa[..., None] * C[dm] + wb[..., None] * C[sm] + wg[..., None] * S[sm] + wd[..., None] * S[dm]
        D = D.reshape(D.shape[0], D.shape[1], nq, width)  # [i, j, r, l]
        P, E = b.forward, b.inverse
        for r in range(nq):
            ks = src[:, r]
            used = np.flatnonzero(ks >= 0)
            if used.size == 0:
                continue
            u, inv = np.unique(ks[used], return_inverse=True)
            groups = (inv[None, :] == np.arange(u.size)[:, None]).astype(float)  # (u, used) indicator
            G = groups @ (P[:, used].T[:, :, None] * Mc[used, r, None, :]).reshape(used.size, -1)
            D[:, :, r, :] += np.einsum("uil,uj->ijl", G.reshape(u.size, P.shape[0], width), E[u])
        ncoef = b.n_coef
        J = np.zeros((ncoef, nq, ncoef, nq))
        for r in range(nq):
            c = contact_of_row[r]
            r0, r1 = row_start[c], row_start[c + 1]
            J[:, r, :, r0:r1] = D[:, :, r, : r1 - r0]
        return J.reshape(ncoef * nq, ncoef * nq)
