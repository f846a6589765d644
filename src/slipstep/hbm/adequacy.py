"""Harmonic adequacy: are the retained harmonics enough for the contact forces?

The AFT forces f(theta) of a converged point contain every harmonic (stick-slip kinks,
lift-off), the balance only the retained ones. Two numbers per point:

* ``force_content``: the share of the AFT forces' spectral content (harmonics 1..N/2,
  root-sum-square of the single-sided amplitudes) that lies outside the retained set,
  max over local coordinates: a cheap indicator, blind to how much the structure filters it;

* ``truncation_estimate`` (the criterion of the warning): the relative change of the
  response if the balance were extended to the set H' = {0, 1, ..., 2 h_max + 1} (and twice
  the AFT samples, so that the sampling error is part of the estimate), estimated
  by one corrector step of the extended balance from the current solution (the new harmonics
  start at zero, so the step's right-hand side is exactly the response the neglected force
  harmonics G_h F_h would produce, plus their feedback on the retained ones). The step is
  the pseudo-arclength corrector of :mod:`slipstep.hbm.continuation` with the branch's
  tangent t (so it stays defined at turning points, where dR/dZ is singular; it measures the
  distance between the two branches normal to the curve) or, for a point solved at a fixed
  parameter, a step at that fixed parameter p (Omega or the excitation level):

      [dR'/dZ  dR'/dp; t^T] [dZ; dp] = [-R'(Z_ext, p); 0],   Z' = Z_ext + dZ, p' = p + dp,
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
    """The harmonics of the extended balance: all of 0..2 h_max + 1 (and the retained ones)."""
    return np.unique(np.concatenate([np.arange(2 * int(h.max()) + 2), h]))


def force_content(hb: HarmonicBalance, point: Point) -> float:
    """Share of the AFT forces' spectral content (harmonics >= 1) outside the retained set."""
    if point.ft is None or point.ft.shape[1] == 0:
        return 0.0
    c = spectrum(point.ft)[1:]  # harmonics 1..N/2
    total = np.sqrt((c ** 2).sum(axis=0))
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
        self.ext = HarmonicBalance(hb.system, h_ext, samples, preload=(hb.x_pre, hb.w_pre))
        self.index = np.searchsorted(self.ext.h, hb.h)  # positions of the retained harmonics
        self.responses = responses

    def _embed(self, Z: np.ndarray) -> np.ndarray:
        out = np.zeros((self.ext.basis.n_coef, Z.shape[1]))
        out[0] = Z[0]
        for i, j in enumerate(self.index[1:], start=1):
            out[2 * j - 1], out[2 * j] = Z[2 * i - 1], Z[2 * i]
        return out

    def estimate(self, point: Point) -> float:
        """Relative change of response amplitude / friction energy after one extended Newton step."""
        ext, hb = self.ext, self.hb
        if hb.nq == 0:
            return 0.0
        Z = self._embed(point.Z)
        R, J, dw, dl = ext.evaluate(Z, point.omega, point.level)
        n = R.size
        if point.tangent is not None:
            tz, tp, zs, ps, parameter = point.tangent
            row = np.concatenate([self._embed(tz).ravel(), [tp]])
        else:
            zs, ps, parameter = 1.0, 1.0, "omega"
            row = np.zeros(n + 1)
            row[n] = 1.0
        Jp = dw if parameter == "omega" else dl
        A = np.zeros((n + 1, n + 1))
        A[:n, :n], A[:n, n], A[n] = J * zs, Jp * ps, row
        try:
            step = np.linalg.solve(A, -np.concatenate([R, [0.0]]))
        except np.linalg.LinAlgError:
            return float("inf")
        Z1 = Z + (step[:n] * zs).reshape(Z.shape)
        omega, level = point.omega, point.level
        if parameter == "omega":
            omega += step[n] * ps
        else:
            level += step[n] * ps
        ext.linear.at(omega, level)
        F1, _ = ext.aft.evaluate(Z1, False)
        X1 = ext.dofs(Z1, F1)
        a0 = half_peak_to_peak(hb.h, point.X[:, self.responses])
        a1 = half_peak_to_peak(ext.h, X1[:, self.responses])
        amp = float(np.abs(a1 - a0).max(initial=0.0) / max(a0.max(initial=0.0), 1e-300))
        e0 = contact_energy(hb, point.Z, point.F).sum()
        e1 = contact_energy(ext, Z1, F1).sum()
        scale = max(abs(e0), abs(e1), 1e-4 * abs(excitation_work(hb, point)))  # floor: a stuck point
        en = abs(e1 - e0) / scale if scale > 1e-300 else 0.0
        return max(amp, float(en))
