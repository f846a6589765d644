"""Amplitudes and energies per cycle of a harmonic balance solution, from its phasors.

With y = Re(sum_h Y_h exp(i h theta)), theta = Omega t, the integral over one cycle of
y1 dy2 is pi sum_h h Im(conj(Y2_h) Y1_h) (only common harmonics contribute; for the AFT
force, whose other harmonics meet no displacement harmonic, this is exact):

    friction energy per cycle of contact c    E_c  = sum_{d of c} pi sum_h h Im(conj(U_dh) T_dh)
    work of the excitation                    W    = pi sum_h h [Im(X_h^H Fe_h) - Im(P_h^H B^T F_h)]
    viscous dissipation                       D_v  = pi Omega sum_h h^2 Re(X_h^H C X_h)

(physics.md section 1) with U_d, T_d the tangential displacement and force of direction d;
the elastic parts, and the normal force N(v) (a function of v alone), integrate to zero over a
cycle in exact arithmetic (the discrete AFT leaves a residue of the order of the aliasing of N).
Because the balance holds exactly on the retained harmonics,
W = D_v + sum_c E_c + (the normal residue) to the solver tolerance.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=32)
def _grid(h: tuple, points: int) -> np.ndarray:
    theta = 2 * np.pi * np.arange(points) / points
    return np.exp(1j * np.outer(theta, np.array(h)))


def _refine(hv: np.ndarray, X: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Newton steps on y'(theta) = 0 from grid extrema theta (nj,); returns y at the extrema."""
    for _ in range(4):
        e = np.exp(1j * np.outer(theta, hv))  # (nj, nh)
        d1 = np.real(np.einsum("jh,hj->j", e * (1j * hv), X))
        d2 = np.real(np.einsum("jh,hj->j", e * (-(hv**2.0)), X))
        step = np.where(d2 != 0, -d1 / np.where(d2 != 0, d2, 1.0), 0.0)
        theta = theta + np.clip(step, -0.01, 0.01)
    e = np.exp(1j * np.outer(theta, hv))
    return np.real(np.einsum("jh,hj->j", e, X))


def half_peak_to_peak(h: np.ndarray, X: np.ndarray, points: int | None = None) -> np.ndarray:
    """(max - min) / 2 over one period of y_j = Re(sum_h X_hj exp(i h theta)), X (nh, nj): the
    extrema on a grid of ``points`` phases (default 64 per period of the highest harmonic, at
    least 2048), refined by Newton's method on y' = 0 (exact to rounding for a band-limited y)."""
    h = tuple(int(v) for v in np.asarray(h))
    n = points or max(2048, 64 * max(h))
    y = np.real(_grid(h, n) @ X)
    theta = 2 * np.pi * np.arange(n) / n
    hv = np.array(h, dtype=float)
    top = np.maximum(_refine(hv, X, theta[y.argmax(axis=0)]), y.max(axis=0))
    bottom = np.minimum(_refine(hv, X, theta[y.argmin(axis=0)]), y.min(axis=0))
    return 0.5 * (top - bottom)


def contact_energy(hb, Z: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Friction energy per cycle [J] of each contact (its tangential directions), from the coefficients Z, F (n_coef, nq)."""
    b, cs = hb.basis, hb.cs
    Q, Fp = b.phasors(Z), b.phasors(F)
    per_row = np.pi * (b.h[:, None] * np.imag(np.conj(Q) * Fp)).sum(axis=0)
    nc = cs.kn.shape[0]
    out = np.zeros(nc)
    for c in range(nc):
        d0, nd = cs.first_direction[c], cs.n_directions[c]
        out[c] = per_row[[cs.tangential_row[d] for d in range(d0, d0 + nd)]].sum()
    return out


def excitation_work(hb, point) -> float:
    """Work of the external forces and prescribed motions per cycle [J]."""
    lin, b, cs = hb.linear, hb.basis, hb.cs
    Fe = lin.external(point.level)
    W = np.pi * (b.h * np.imag(np.einsum("hn,hn->h", np.conj(point.X), Fe))).sum()
    if cs.B.shape[1] and hb.nq:
        P = point.level * lin.P
        BF = b.phasors(point.F) @ cs.B  # (nh, nm): B^T F per harmonic
        W -= np.pi * (b.h * np.imag(np.einsum("hm,hm->h", np.conj(P), BF))).sum()
    return float(W)


def viscous_dissipation(hb, point) -> float:
    """Energy dissipated by C per cycle [J]."""
    h = hb.basis.h
    CX = hb.linear.damping_times(point.X)
    return float(np.pi * point.omega * (h**2 * np.real(np.einsum("hn,hn->h", np.conj(point.X), CX))).sum())
