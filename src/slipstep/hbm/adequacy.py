"""Harmonic adequacy: are the retained harmonics enough for the contact forces?

The AFT forces f(theta) of a converged point contain every harmonic (stick-slip kinks,
lift-off), the balance only the retained ones. Two numbers per point:

* ``force_content``: the share of the AFT forces' spectral content (harmonics 1..N/2,
  root-sum-square of the single-sided amplitudes) that lies outside the retained set,
  max over local coordinates: a cheap indicator, blind to how much the structure filters it;

* ``truncation_estimate`` (the criterion of the warning): the relative change of the
  response if the balance were extended to the set H' = {0, 1, ..., max(2 h_max + 1, h_max + 8)}
  (and twice
  the AFT samples, so that the sampling error is part of the estimate), estimated
  by solving the extended balance from the current solution (the new harmonics start at
  zero, so the first step's right-hand side is exactly the response the neglected force
  harmonics G_h F_h would produce, plus their feedback on the retained ones; the first one
  or two Newton steps at the point's own frequency and level converge it). Where that fails
  (at or next to a turning point, where dR/dZ is singular) the pseudo-arclength corrector of
  :mod:`slipstep.hbm.continuation` with the branch's tangent t takes over (it measures the
  distance between the two branches normal to the curve):

      [dR'/dZ  dR'/dp; t^T] [dZ; dp] = [-R'(Z, p); t^T (y - y_0)],   until R' = 0,
      estimate = max( max_j |A_j(Z', p') - A_j(Z)| / max_j A_j(Z),  |E(Z', p') - E(Z)| / |E(Z)| )

  A: half peak-to-peak amplitude of the response DOFs j, E: total friction energy per cycle
  (floored at 1e-4 of the excitation work: a point whose friction dissipates almost nothing
  is judged by its amplitude).

A warning (:class:`HarmonicAdequacyWarning`) is issued when the estimate exceeds the
tolerance (default 1 %) at any point; :func:`slipstep.hbm.frf` can then raise H and redo
the FRF (``auto_harmonics=True``).
"""

from __future__ import annotations

import numpy as np

from slipstep.hbm.energy import contact_energy, excitation_work, half_peak_to_peak
from slipstep.hbm.fourier import spectrum
from slipstep.hbm.residual import HarmonicBalance, Point, default_samples


class HarmonicAdequacyWarning(UserWarning):
    """The retained harmonics under-represent the contact forces (see slipstep.hbm.adequacy)."""


def extended_set(h: np.ndarray) -> np.ndarray:
    """The harmonics of the extended balance: all of 0..max(2 h_max + 1, h_max + 8)."""
    top = max(2 * int(h.max()) + 1, int(h.max()) + 8)
    return np.unique(np.concatenate([np.arange(top + 1), h]))


def force_content(hb: HarmonicBalance, point: Point) -> float:
    """Share of the AFT forces' spectral content (harmonics >= 1) outside the retained set."""
    if point.ft is None or point.ft.shape[1] == 0:
        return 0.0
    c = spectrum(point.ft)[1:]  # harmonics 1..N/2
    total = np.sqrt((c**2).sum(axis=0))
    keep = np.zeros(c.shape[0], bool)
    keep[hb.h[hb.h >= 1] - 1] = True
    outside = np.sqrt((c[~keep] ** 2).sum(axis=0))
    ratio = np.where(total > 0, outside / np.where(total > 0, total, 1.0), 0.0)
    return float(ratio.max(initial=0.0))


class Adequacy:
    """The extended balance of a HarmonicBalance, built once, and the per-point estimate."""

    def __init__(self, hb: HarmonicBalance, responses: np.ndarray):
        self.hb = hb
        h_ext = extended_set(hb.h)
        samples = max(2 * hb.basis.samples, default_samples(int(h_ext.max())))  # and finer sampling
        self.ext = HarmonicBalance(hb.system, h_ext, samples, preload=(hb.x_pre, hb.w_pre), condense=hb.gather.mode)
        self.index = np.searchsorted(self.ext.h, hb.h)  # positions of the retained harmonics
        self.responses = responses

    def _embed(self, Z: np.ndarray) -> np.ndarray:
        out = np.zeros((self.ext.basis.n_coef, Z.shape[1]))
        out[0] = Z[0]
        for i, j in enumerate(self.index[1:], start=1):
            out[2 * j - 1], out[2 * j] = Z[2 * i - 1], Z[2 * i]
        return out

    def extended_solution(self, point: Point, iterations: int = 25):
        """(Y', omega', level') of the extended balance near ``point``: Newton at the point's own
        frequency and level (a few iterations from the embedded solution); where that fails (at
        or near a turning point, where dR/dZ is singular) corrector steps with the branch's tangent.
        None when neither converges."""
        ext = self.ext
        Z = self._embed(point.Y)
        omega, level = point.omega, point.level
        fixed = ext.solve(omega, level, Z, max_iterations=iterations)
        if fixed.converged:
            return fixed.Y, omega, level
        if point.tangent is None:
            return None
        tz, tp, zs, ps, parameter = point.tangent
        row = np.concatenate([self._embed(tz).ravel(), [tp]])
        y0 = np.concatenate([Z.ravel() / zs, [(omega if parameter == "omega" else level) / ps]])
        y = y0.copy()
        n = Z.size
        for _ in range(iterations):
            Zi = (y[:n] * zs).reshape(Z.shape)
            p = y[n] * ps
            w_i, l_i = (p, level) if parameter == "omega" else (omega, p)
            R, J, dw, dl = ext.evaluate(Zi, w_i, l_i)
            g = row @ (y - y0)
            if ext.converged(R, Zi, l_i, 1e-10) and abs(g) <= 1e-12:
                return Zi, w_i, l_i
            A = np.zeros((n + 1, n + 1))
            A[:n, :n], A[:n, n], A[n] = J * zs, (dw if parameter == "omega" else dl) * ps, row
            try:
                y = y + np.linalg.solve(A, -np.concatenate([R, [g]]))
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(y)):
                return None
        return None

    def estimate(self, point: Point) -> float:
        """Relative change of response amplitude / friction energy in the extended balance
        (inf when the extended balance finds no solution near the point)."""
        ext, hb = self.ext, self.hb
        if hb.nq == 0:
            return 0.0
        sol = self.extended_solution(point)
        if sol is None:
            return float("inf")
        Y1, omega, level = sol
        ext.linear.at(omega, level)
        p1 = ext.point(Y1, omega, level, 0, True, 0.0)
        Z1, F1, X1 = p1.Z, p1.F, p1.X
        a0 = half_peak_to_peak(hb.h, point.X[:, self.responses])
        a1 = half_peak_to_peak(ext.h, X1[:, self.responses])
        amp = float(np.abs(a1 - a0).max(initial=0.0) / max(a0.max(initial=0.0), 1e-300))
        e0 = contact_energy(hb, point.Z, point.F).sum()
        e1 = contact_energy(ext, Z1, F1).sum()
        scale = max(abs(e0), abs(e1), 1e-4 * abs(excitation_work(hb, point)))  # floor: a stuck point
        en = abs(e1 - e0) / scale if scale > 1e-300 else 0.0
        return max(amp, float(en))
