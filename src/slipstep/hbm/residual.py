"""The multi-harmonic balance condensed onto the contact coordinates.

Unknowns: the harmonic coefficients Z (n_coef x nq) of the local contact displacements
q = A x - B p + g over the retained harmonics (:mod:`slipstep.hbm.fourier`). With the
linear part of :mod:`slipstep.hbm.linear` (G_h = A D_h^-1 A^T, the dynamic compliance) the
balance of harmonic h, condensed onto the contacts, is (phasors, lambda the excitation level)

    R_h = Q_h - Q^lin_h + G_h U_h = 0,
    U_h = F_h(Q) - Kc_h (Q_h + lambda B P_h - g [h = 0]),
    Q^lin_h = A D_h^-1 (Fc_h + lambda Fe_h) - lambda B P_h + g [h = 0],

F_h(Q) the AFT contact forces (:mod:`slipstep.hbm.aft`). Its Jacobian is exact:

    dR/dZ = I + G (dF/dZ - Kc)              (G in real 2x2 block form per harmonic),
    dR_h/dOmega = A D_h^-1 (dD_h/dOmega) X_h,   dD_h/dOmega = -2 h^2 Omega M + i h C,
    dR_h/dlambda = -A D_h^-1 Fe_h + B P_h - G_h Kc_h B P_h,

with X_h = D_h^-1 (Fc_h + lambda Fe_h - A^T U_h) the DOF phasors (the response).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
from threadpoolctl import ThreadpoolController

from slipstep.errors import InputError
from slipstep.hbm.aft import AFT
from slipstep.hbm.fourier import Basis, harmonic_set
from slipstep.hbm.linear import LinearPart
from slipstep.methods.plan import plan_run
from slipstep.methods.start import static_equilibrium
from slipstep.system import System


def preload_sliders(system: System) -> tuple[np.ndarray, np.ndarray]:
    """(x, w) of the static preload, the same one every time march starts from
    (methods/start.py static_equilibrium)."""
    start = static_equilibrium(plan_run(system, "piecewise-linear", periods=1, error_estimate=False))
    return start.x.copy(), start.w.copy()


_THREADPOOLS = None


def blas_threads(size: int = 0):
    """A context limiting BLAS to one thread for the small dense systems of a harmonic balance
    (size unknowns < 2000): multi-threaded BLAS on matrices of a few hundred rows is 10-30x
    slower on a loaded machine than one thread. (The library scan is done once.)"""
    global _THREADPOOLS
    if size >= 2000:
        return contextlib.nullcontext()
    if _THREADPOOLS is None:
        _THREADPOOLS = ThreadpoolController()
    return _THREADPOOLS.limit(limits=1, user_api="blas")


def default_samples(h_max: int) -> int:
    """Time samples per period: the power of 2 at or above 8 h_max, at least 64."""
    return int(max(64, 2 ** int(np.ceil(np.log2(8 * h_max)))))


@dataclass
class Point:
    """One solved harmonic balance point."""

    omega: float
    level: float
    Z: np.ndarray  # (n_coef, nq) local displacement coefficients
    F: np.ndarray  # (n_coef, nq) contact force coefficients
    X: np.ndarray  # (nh, n) DOF phasors
    iterations: int
    converged: bool
    residual: float
    aft_periods: int
    ft: np.ndarray | None = None  # (N, nq) the AFT force samples
    qt: np.ndarray | None = None  # (N, nq) the local displacement samples
    tangent: tuple | None = None  # continuation: (t_Z (n_coef, nq), t_p, z_scale, p_scale, parameter), scaled
    wall_time: float = float("nan")  # s spent on the point (set by the FRF drivers)


class HarmonicBalance:
    """The condensed balance of one System on one harmonic set.

    ``harmonics``: int H (0..H) or a set like (1, 3, 5); the excitation's own multiples are
    added when missing. ``samples``: AFT time samples per period (default 8 H, power of 2)."""

    def __init__(
        self, system: System, harmonics=5, samples: int | None = None, *, aft_max_periods: int = 50, preload=None
    ):
        if not isinstance(system, System):
            raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
        circles = [c.name for c in system.contacts if c.law == "3d-circle"]
        if circles:  # the AFT Jacobian (hbm/aft.py) is built from the piecewise-linear form of the law
            raise InputError(
                "contacts",
                f"{circles} use law '3d-circle', whose coupled slip has no piecewise-linear form: the harmonic "
                "balance's AFT Jacobian supports the piecewise-linear laws only",
                "compute this frequency response in the time domain (slipstep.frequency.frf with solver 'shoot' or "
                "'march', or `slipstep frf ... --solver shoot`), or use a piecewise-linear law",
            )
        h = harmonic_set(harmonics)
        self.system = system
        self.cs = cs = system.compile_dense("harmonic balance")
        lin0 = LinearPart(system, cs, h)
        if lin0.missing:
            h = np.unique(np.concatenate([h, lin0.missing]))
            lin0 = LinearPart(system, cs, h)
        self.h = h
        if samples is None:
            samples = default_samples(int(h.max()))
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)):
            raise InputError("samples", f"is {samples!r}", "give a whole number of time samples per period")
        self.basis = Basis(h, int(samples))
        self.linear = lin0
        self.nq = cs.A.shape[0]
        x_pre, w_pre = preload_sliders(system) if preload is None else preload
        self.x_pre, self.w_pre = x_pre, w_pre
        self.aft = AFT(cs, self.basis, w_pre, aft_max_periods)
        self.f0 = lin0.f0
        self.length_scale = cs.length_scale

    # -- pieces ---------------------------------------------------------------------------
    def initial_guess(self) -> np.ndarray:
        """Z at the static preload (q constant: every contact stuck, one Newton step from it
        gives the stuck linear response)."""
        Z = np.zeros((self.basis.n_coef, self.nq))
        Z[0] = self.cs.A @ self.x_pre + self.cs.g
        return Z

    def _real_blocks(self, G: np.ndarray) -> np.ndarray:
        """The real (n_coef nq)^2 form of per-harmonic complex matrices G (nh, nq, nq) acting
        on phasors Y = a - i b: [y_a; y_b] = [[Gr, Gi], [-Gi, Gr]] [u_a; u_b]."""
        nq, nc = self.nq, self.basis.n_coef
        out = np.zeros((nc, nq, nc, nq))
        out[0, :, 0, :] = G[0].real
        for i in range(1, G.shape[0]):
            a, b = 2 * i - 1, 2 * i
            out[a, :, a, :] = G[i].real
            out[a, :, b, :] = G[i].imag
            out[b, :, a, :] = -G[i].imag
            out[b, :, b, :] = G[i].real
        return out.reshape(nc * nq, nc * nq)

    def evaluate(
        self, Z: np.ndarray, omega: float, level: float = 1.0, *, jacobian: bool = True, refactor: bool = True
    ):
        """R (n_coef nq,), and with ``jacobian`` dR/dZ, dR/dOmega, dR/dlambda, at (Z, omega, level)."""
        b, lin, cs = self.basis, self.linear, self.cs
        if refactor or getattr(lin, "omega", None) != omega:
            lin.at(omega, level)
        lin.level = level
        F, dF = self.aft.evaluate(Z, jacobian)
        Q, Fp = b.phasors(Z), b.phasors(F)
        BP = level * (lin.P @ cs.B.T)
        U = Fp - lin.Kc * (Q + BP - lin.g0)
        Xe = np.einsum("hnm,hm->hn", lin.Dinv, lin.external(level))
        Qlin = Xe @ cs.AT - BP + lin.g0
        R = Q - Qlin + np.einsum("hrs,hs->hr", lin.G, U)
        self._last = (F, U, Xe)
        Rr = b.coefficients(R).ravel()
        if not jacobian:
            return Rr
        Gr = self._real_blocks(lin.G)
        kc = np.zeros((b.n_coef, self.nq))
        kc[0] = lin.Kc[0]
        J = np.eye(Rr.size) + Gr @ (dF - np.diag(kc.ravel()))
        X = Xe - np.einsum("hnm,hm->hn", lin.DinvAT, U)
        dD = lin.dD_domega()
        dR_dw = np.einsum("hnm,hm->hn", lin.Dinv, np.einsum("hmk,hk->hm", dD, X)) @ cs.AT
        Pb = lin.P @ cs.B.T
        dR_dl = -(np.einsum("hnm,hm->hn", lin.Dinv, lin.Fe) @ cs.AT) + Pb - np.einsum("hrs,hs->hr", lin.G, lin.Kc * Pb)
        return Rr, J, b.coefficients(dR_dw).ravel(), b.coefficients(dR_dl).ravel()

    def dofs(self, Z: np.ndarray, F: np.ndarray | None = None) -> np.ndarray:
        """DOF phasors X_h (nh, n) of a solution (after :meth:`evaluate` at its omega, level)."""
        b = self.basis
        if F is None:
            F, _ = self.aft.evaluate(Z, False)
        return self.linear.dofs(b.phasors(Z), b.phasors(F))

    def scale(self, Z: np.ndarray | None = None) -> float:
        """Displacement scale for tolerances [m]: the largest coefficient, at least the system's length scale."""
        s = self.length_scale
        if Z is not None:
            s = max(s, float(np.abs(Z[1:]).max(initial=0.0)))
        return s

    # -- one point --------------------------------------------------------------------------
    def solve(
        self,
        omega: float,
        level: float = 1.0,
        Z0: np.ndarray | None = None,
        *,
        tol: float = 1e-10,
        max_iterations: int = 50,
    ) -> Point:
        """Newton on R(Z) = 0 at fixed (omega, level), exact Jacobian, backtracking on |R|."""
        with blas_threads(self.size):
            return self._solve(omega, level, Z0, tol, max_iterations)

    @property
    def size(self) -> int:
        """Number of unknowns (harmonic coefficients of the local displacements)."""
        return self.basis.n_coef * self.nq

    def _solve(self, omega, level, Z0, tol, max_iterations) -> Point:
        Z = self.initial_guess() if Z0 is None else np.array(Z0, dtype=float)
        shape = Z.shape
        self.linear.at(omega, level)
        R, J, _, _ = self.evaluate(Z, omega, level, refactor=False)
        norm = np.linalg.norm(R)
        it, converged = 0, False
        for it in range(1, max_iterations + 1):
            if norm <= tol * self.scale(Z):
                converged = True
                it -= 1
                break
            dz = np.linalg.solve(J, -R)
            alpha = 1.0
            for _ in range(8):
                Zt = Z + alpha * dz.reshape(shape)
                Rt = self.evaluate(Zt, omega, level, jacobian=False, refactor=False)
                nt = np.linalg.norm(Rt)
                if nt < norm * (1 - 1e-4 * alpha) or nt <= tol * self.scale(Zt):
                    break
                alpha *= 0.5
            Z = Zt
            R, J, _, _ = self.evaluate(Z, omega, level, refactor=False)
            norm = np.linalg.norm(R)
        else:
            converged = norm <= tol * self.scale(Z)
        return self.point(Z, omega, level, it, converged, norm)

    def point(self, Z, omega, level, iterations, converged, residual) -> Point:
        """Package a solution (the AFT state must be that of Z)."""
        F, _ = self.aft.evaluate(Z, False)
        X = self.linear.dofs(self.basis.phasors(Z), self.basis.phasors(F))
        return Point(
            omega,
            level,
            Z.copy(),
            F,
            X,
            iterations,
            bool(converged),
            float(residual),
            int(self.aft.periods),
            self.aft.ft.copy(),
            self.aft.qt.copy(),
        )
