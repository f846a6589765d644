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

assembled per contact (contacts are independent) and contracted over k with one matrix
product. It is the exact derivative of the discrete AFT wherever no sample sits exactly on
a state boundary (checked against finite differences in tests/test_hbm_aft.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from slipstep.kernels import contact as _law

# ---- the one adapter to the kernels' contact law (its argument list lives here only) -------


def law_arguments(cs) -> tuple:
    """The contact table the kernels' law takes, from a CompiledSystem."""
    return (cs.normal_row, cs.kn, cs.mu, cs.first_direction, cs.n_directions, cs.tangential_row, cs.kt)


@njit(cache=True, nogil=True, error_model="numpy")
def apply_law(args, q, w_old, f, w_new, state):
    """The kernels' nonlinear law at one sample (see slipstep.kernels.contact.law)."""
    nrow, kn, mu, fdir, ndir, trow, kt = args
    _law.law(nrow, kn, mu, fdir, ndir, trow, kt, q, w_old, f, w_new, state)


@njit(cache=True, nogil=True, error_model="numpy")
def apply_linear_law(args, state, q, w_old, f, w_new):
    """The kernels' piecewise-linear law for a postulated state (slipstep.kernels.contact.piecewise_law)."""
    nrow, kn, mu, fdir, ndir, trow, kt = args
    _law.piecewise_law(nrow, kn, mu, fdir, ndir, trow, kt, state, q, w_old, f, w_new)


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
    if not np.all(keeps | resets) or np.abs(off).max(initial=0.0) > 0 or \
            np.abs(Wq[:, :, :][np.broadcast_to(keeps[:, :, None], Wq.shape)]).max(initial=0.0) > 0:
        raise NotImplementedError("the contact law's sliders neither keep nor reset per sample: "
                                  "the AFT Jacobian assumes they do")
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
def cycle_derivative(E, st, src0, src0_state, Fq, Fw, Wq, Ww, dir_of_row, contact_of_row, row_start, Y):
    """Y[k, r, l, j] = d f_k[r] / d Z[j, row_start[c(r)] + l]: the time-sample rows of the
    Jacobian of the converged cycle (see the module docstring), l over the rows of r's contact.
    src0, src0_state: each direction's last slider reset before the cycle (any earlier period)."""
    n, ncoef = E.shape
    nq = dir_of_row.shape[0]
    nd = st.shape[1]
    Y[:] = 0.0
    src = src0.copy()
    src_state = src0_state.copy()
    for k in range(n):
        for r in range(nq):
            s_r = st[k, dir_of_row[r]]
            c = contact_of_row[r]
            r0, r1 = row_start[c], row_start[c + 1]
            for l in range(r1 - r0):
                a = Fq[s_r, r, r0 + l]
                if a != 0.0:
                    for j in range(ncoef):
                        Y[k, r, l, j] += a * E[k, j]
            for d in range(nd):
                b = Fw[s_r, r, d]
                if b == 0.0 or src[d] < 0:
                    continue
                ks = src[d]
                ss_ = src_state[d]
                for l in range(r1 - r0):
                    cwl = b * Wq[ss_, d, r0 + l]
                    if cwl != 0.0:
                        for j in range(ncoef):
                            Y[k, r, l, j] += cwl * E[ks, j]
        for d in range(nd):
            if Ww[st[k, d], d, d] == 0.0:
                src[d] = k
                src_state[d] = st[k, d]


class AFT:
    """The AFT of one system on one basis: ``evaluate(Z)`` -> F (and dF/dZ on request).

    Layout of the flattened unknowns: index j * nq + r (coefficient j, local row r)."""

    def __init__(self, cs, basis, w_init: np.ndarray, max_periods: int = 50):
        self.args = law_arguments(cs)
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
        self._Y = np.zeros((n, self.nq, width, basis.n_coef))

    def evaluate(self, Z: np.ndarray, jacobian: bool = True):
        """F (n_coef, nq) of the converged cycle at coefficients Z (n_coef, nq); with
        ``jacobian`` also dF/dZ as an (n_coef nq) x (n_coef nq) matrix."""
        b = self.basis
        qt = np.ascontiguousarray(b.inverse @ Z)
        self.qt = qt
        self.periods = march_cycle(self.args, qt, self.w_init, self.max_periods, self.w_tol, self.resets, self.ft,
                                   self.wt, self.st,
                                   self.src0, self.src0_state)
        F = b.forward @ self.ft
        if not jacobian:
            return F, None
        return F, self.jacobian()

    def jacobian(self) -> np.ndarray:
        """dF/dZ of the last evaluated cycle."""
        b, nq = self.basis, self.nq
        Fq, Fw, Wq, Ww = self.tables
        dir_of_row, contact_of_row, row_start = self.rows
        Y = self._Y
        cycle_derivative(b.inverse, self.st, self.src0, self.src0_state, Fq, Fw, Wq, Ww, dir_of_row, contact_of_row,
                         row_start, Y)
        n, _, width, ncoef = Y.shape
        D = (b.forward @ Y.reshape(n, -1)).reshape(ncoef, nq, width, ncoef)  # [i, r, l, j]
        J = np.zeros((ncoef, nq, ncoef, nq))
        for r in range(nq):
            c = contact_of_row[r]
            r0, r1 = row_start[c], row_start[c + 1]
            J[:, r, :, r0:r1] = D[:, r, : r1 - r0, :].transpose(0, 2, 1)
        return J.reshape(ncoef * nq, ncoef * nq)
