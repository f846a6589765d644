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

Gathered form (:meth:`AFT.gathered_jacobian`, issue 24). When the contacts see the structure
through few coordinates y (q = L y + const, L (nq, r), r << nq: the contacts sit on a few
rigid-body DOFs), the balance needs only L^T (dF/dZ) L, an (n_coef r)^2 matrix: the sample
tangents are gathered per sample pair (k, s) into r x r blocks Wt[k, s] = L^T (Fq or the memory
term) L (kernels/aft.py gathered_tangent, O(N nq width r) work) and transformed once,
P Wt E; dF/dZ itself ((n_coef nq)^2 entries) is never formed.

The compiled loops (the law over the samples, the sample tangents, their gathered form) are
in :mod:`slipstep.kernels.aft`.
"""

from __future__ import annotations

import numpy as np

from slipstep.kernels.aft import (
    apply_linear_law,
    cycle_coefficients,
    gathered_tangent,
    march_cycle,
    tangent_product,
)
from slipstep.kernels.settings import contact_table

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
        self._scratch = np.zeros((2, self.nd))
        self._last = np.zeros(self.nd, np.int64)
        self._last_state = np.zeros(self.nd, np.int8)
        self._cycle = 0  # cycles evaluated
        self._coefficients_of = -1  # the cycle whose Ac, Mc, src are current
        self._pairs = None  # workspace of gathered_jacobian
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
            self._scratch,
            self._last,
            self._last_state,
        )
        self._cycle += 1
        F = b.forward @ self.ft
        if not jacobian:
            return F, None
        return F, self.jacobian()

    def _sample_tangents(self):
        """Ac, Mc, src of the last evaluated cycle (kernels/aft.py cycle_coefficients), once per cycle."""
        if self._coefficients_of != self._cycle:
            Fq, Fw, Wq, Ww = self.tables
            dir_of_row, contact_of_row, row_start = self.rows
            cycle_coefficients(
                self.st,
                self.src0,
                self.src0_state,
                Fq,
                Fw,
                Wq,
                Ww,
                dir_of_row,
                contact_of_row,
                row_start,
                self._Ac,
                self._Mc,
                self._src,
                self._last,
                self._last_state,
            )
            self._coefficients_of = self._cycle
        return self._Ac, self._Mc, self._src

    def gathered_jacobian(self, L: np.ndarray) -> np.ndarray:
        """L^T (dF/dZ) L of the last evaluated cycle for the gather q = L y (L (nq, r)), as an
        (n_coef r) x (n_coef r) matrix (index j r + m), without forming dF/dZ:

            d(L^T F)_j / dy_i = sum over the sample pairs (k, s) of P[j, k] E[s, i] W[k, s]

        with W the gathered sample tangents (kernels/aft.py gathered_tangent: r x r blocks, the
        diagonal k = s and the slider-memory pairs only)."""
        b = self.basis
        Ac, Mc, src = self._sample_tangents()
        n, r = Ac.shape[0], L.shape[1]
        L = np.ascontiguousarray(L, dtype=np.float64)
        _, contact_of_row, row_start = self.rows
        count, room = -1, 4 * n  # pairs: the diagonal and a few memory sources per sample, grown on demand
        while count < 0:
            if self._pairs is None or self._pairs[3].shape[1] != r or self._pairs[3].shape[0] < room:
                room = max(room, 0 if self._pairs is None else self._pairs[3].shape[0])
                self._pairs = (
                    np.full((n, n), -1, np.int64),
                    np.zeros(room, np.int64),
                    np.zeros(room, np.int64),
                    np.zeros((room, r, r)),
                )
            pair_of, pk, ps, blocks = self._pairs
            count = gathered_tangent(Ac, Mc, src, contact_of_row, row_start, L, pair_of, pk, ps, blocks)
            room = 2 * blocks.shape[0]
        pk, ps = pk[:count], ps[:count]
        weights = b.forward[:, None, pk] * b.inverse.T[None, :, ps]  # (n_coef, n_coef, pairs): P[j, k] E[s, i]
        nc = b.n_coef
        J = (weights.reshape(nc * nc, count) @ blocks[:count].reshape(count, r * r)).reshape(nc, nc, r, r)
        return np.ascontiguousarray(J.transpose(0, 2, 1, 3)).reshape(nc * r, nc * r)

    def tangent_times(self, V: np.ndarray) -> np.ndarray:
        """(dF/dZ) V of the last evaluated cycle for coefficients V (n_coef, nq), sample by sample."""
        b = self.basis
        Ac, Mc, src = self._sample_tangents()
        _, contact_of_row, row_start = self.rows
        dq = np.ascontiguousarray(b.inverse @ V)
        df = np.zeros_like(dq)
        tangent_product(Ac, Mc, src, contact_of_row, row_start, dq, df)
        return b.forward @ df

    def jacobian(self) -> np.ndarray:
        """dF/dZ of the last evaluated cycle: P diag(Ac) E by one FFT per tangent column (the
        product-to-sum identities of :func:`product_indices`), plus the memory terms grouped by
        their source sample (one outer product per stick interval)."""
        b, nq = self.basis, self.nq
        contact_of_row, row_start = self.rows[1], self.rows[2]
        Ac, Mc, src = self._sample_tangents()
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
