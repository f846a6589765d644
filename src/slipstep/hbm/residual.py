"""The multi-harmonic balance condensed onto the coordinates the contacts see.

Unknowns: the harmonic coefficients Y (n_coef x r) of the gathered coordinates y = W x
(:class:`slipstep.hbm.linear.Gather`: the DOFs the contacts act on, or the contact coordinates
themselves), over the retained harmonics (:mod:`slipstep.hbm.fourier`); the local contact
displacements are q = L y - lambda B p + g (A = L W). With the linear part of
:mod:`slipstep.hbm.linear` (S_h = W D_h^-1 W^T, the dynamic compliance on y) the balance of
harmonic h condensed onto y is (phasors, lambda the excitation level)

    R_h = Y_h - W D_h^-1 (Fc_h + lambda Fe_h) + S_h L^T U_h = 0,
    U_h = F_h(Q) - Kc_h L Y_h,        Q_h = L Y_h - lambda B P_h + g [h = 0],

F_h(Q) the AFT contact forces (:mod:`slipstep.hbm.aft`); R_h = W X_h(U) - Y_h with the DOF
phasors X_h = D_h^-1 (Fc_h + lambda Fe_h - A^T U_h). Its Jacobian is exact:

    dR/dY = I + S (L^T (dF/dZ) L - L^T Kc L)     (S in real 2x2 block form per harmonic),
    dR_h/dOmega = W D_h^-1 (dD_h/dOmega) X_h,   dD_h/dOmega = -2 h^2 Omega M + i h C,
    dR_h/dlambda = -W D_h^-1 Fe_h - S_h L^T (dF/dZ B P)_h,

L^T (dF/dZ) L from the gathered sample tangents (:meth:`slipstep.hbm.aft.AFT.gathered_jacobian`)
when y are DOFs, dF/dZ itself when y are the contact coordinates (L = I: the balance of
issue 13, R = Q - Q^lin + G U with G = A D^-1 A^T). Convergence is judged on the residual
seen by the contacts, |L R| <= tol x (displacement scale), the same number in both forms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError
from slipstep.hbm.aft import AFT
from slipstep.hbm.fourier import Basis, harmonic_set
from slipstep.hbm.linear import LinearPart, choose_gather
from slipstep.methods.blas import one_blas_thread
from slipstep.methods.plan import plan_run
from slipstep.methods.start import static_equilibrium
from slipstep.model.contact import without_piecewise_linear_form
from slipstep.model.system import System


def preload_sliders(system: System) -> tuple[np.ndarray, np.ndarray]:
    """(x, w) of the static preload, the same one every time march starts from
    (methods/start.py static_equilibrium). The plan's step is T / 4: the preload does not depend
    on it, and the default step rule (T_min) would size outputs for a period of a stiff model
    (1.5e6 steps and 35 GB on the unreduced blade pair) that nothing marches here."""
    plan = plan_run(system, "piecewise-linear", periods=1, error_estimate=False, dt=system.period / 4)
    start = static_equilibrium(plan)
    return start.x.copy(), start.w.copy()


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
    tangent: tuple | None = None  # continuation: (t_Y (n_coef, r), t_p, z_scale, p_scale, parameter), scaled
    wall_time: float = float("nan")  # s spent on the point (set by the FRF drivers)
    Y: np.ndarray | None = None  # (n_coef, r) the unknowns: coefficients of the gathered coordinates
    kind: str = "continuation"  # "asked" (a requested frequency), "continuation" or "turning"


class HarmonicBalance:
    """The condensed balance of one System on one harmonic set.

    ``harmonics``: int H (0..H) or a set like (1, 3, 5); the excitation's own multiples are
    added when missing. ``samples``: AFT time samples per period (default 8 H, power of 2).
    ``condense``: the unknowns, "dofs" (the DOFs the contacts act on), "contacts" (the contact
    coordinates) or "auto" (the fewer; slipstep.hbm.linear.choose_gather)."""

    def __init__(
        self,
        system: System,
        harmonics=5,
        samples: int | None = None,
        *,
        aft_max_periods: int = 50,
        preload=None,
        condense: str = "auto",
    ):
        if not isinstance(system, System):
            raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
        circles = without_piecewise_linear_form(system.contacts)
        if circles:  # the AFT Jacobian (hbm/aft.py) is built from the piecewise-linear form of the law
            laws = sorted({c.law for c in system.contacts if c.name in circles})
            raise InputError(
                "contacts",
                f"{circles} use law {', '.join(map(repr, laws))}, which has no piecewise-linear form: the harmonic "
                "balance's AFT Jacobian supports the piecewise-linear laws only",
                "compute this frequency response in the time domain (slipstep.frequency.frf with solver 'shoot' or "
                "'march', or `slipstep frf ... --solver shoot`), or use a piecewise-linear law",
            )
        h = harmonic_set(harmonics)
        self.system = system
        self.cs = cs = system.compile_for_frequency_domain()
        self.gather = choose_gather(cs, condense)
        self.L = self.gather.L
        lin0 = LinearPart(system, cs, h, self.gather)
        if lin0.missing:
            h = np.unique(np.concatenate([h, lin0.missing]))
            lin0 = LinearPart(system, cs, h, self.gather)
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
    @property
    def r(self) -> int:
        """Gathered coordinates per harmonic coefficient."""
        return self.gather.size

    def initial_guess(self) -> np.ndarray:
        """Y at the static preload (y constant: every contact stuck, one Newton step from it
        gives the stuck linear response)."""
        Y = np.zeros((self.basis.n_coef, self.r))
        Y[0] = self.gather.of_dofs(self.x_pre, self.cs.A)
        return Y

    def local(self, Y: np.ndarray, level: float) -> np.ndarray:
        """Z (n_coef, nq): the coefficients of q = L y - lambda B p + g."""
        lin = self.linear
        return Y @ self.L.T + self.basis.coefficients(lin.g0 - level * (lin.P @ self.cs.B.T))

    def _blocks_times(self, G: np.ndarray, T: np.ndarray) -> np.ndarray:
        """G_r T for per-harmonic complex matrices G (nh, r, r) in their real block form on
        phasors Y = a - i b, [y_a; y_b] = [[Gr, Gi], [-Gi, Gr]] [u_a; u_b], times T
        (n_coef r, m): one product per block, never the (n_coef r)^2 block-diagonal matrix."""
        r, nc = G.shape[1], self.basis.n_coef
        if r == 0:  # no contact coordinates: nothing to couple
            return np.zeros_like(T)
        Tb = T.reshape(nc, r, -1)
        out = np.empty_like(Tb)
        out[0] = G[0].real @ Tb[0]
        for i in range(1, G.shape[0]):
            a, b = 2 * i - 1, 2 * i
            Gr, Gi = G[i].real, G[i].imag
            out[a] = Gr @ Tb[a] + Gi @ Tb[b]
            out[b] = Gr @ Tb[b] - Gi @ Tb[a]
        return out.reshape(T.shape)

    def _gathered_tangent(self) -> np.ndarray:
        """L^T (dF/dZ) L of the last AFT cycle, (n_coef r)^2."""
        if self.gather.mode == "contacts":
            return self.aft.jacobian()
        return self.aft.gathered_jacobian(self.L)

    def evaluate(
        self, Y: np.ndarray, omega: float, level: float = 1.0, *, jacobian: bool = True, refactor: bool = True
    ):
        """R (n_coef r,), and with ``jacobian`` dR/dY, dR/dOmega, dR/dlambda, at (Y, omega, level)."""
        b, lin, cs, L = self.basis, self.linear, self.cs, self.L
        if refactor or getattr(lin, "omega", None) != omega:
            lin.at(omega, level)
        lin.level = level
        Z = self.local(Y, level)
        F, _ = self.aft.evaluate(Z, False)
        LY = b.phasors(Y) @ L.T
        U = b.phasors(F) - lin.Kc * LY
        LtU = U @ L
        Xe = lin.external_response(level)
        R = b.phasors(Y) - self.gather.of_dofs(Xe, cs.A) + np.einsum("hrs,hs->hr", lin.S, LtU)
        Rr = b.coefficients(R).ravel()
        if not jacobian:
            return Rr
        T = self._gathered_tangent()
        r = self.r
        T[:r, :r] -= (L.T * lin.Kc[0]) @ L
        J = self._blocks_times(lin.S, T)
        J[np.diag_indices_from(J)] += 1.0
        X = Xe - lin.solve_gathered(LtU)
        dR_dw = self.gather.of_dofs(lin.solve(lin.dD_times(X)), cs.A)
        dR_dl = -self.gather.of_dofs(lin.Xf, cs.A)
        if cs.B.shape[1] and np.any(lin.P != 0):
            V = b.coefficients(-(lin.P @ cs.B.T))
            dF = (self.aft.jacobian() @ V.ravel()).reshape(V.shape) if self.gather.mode == "contacts" else None
            dF = self.aft.tangent_times(V) if dF is None else dF
            dR_dl = dR_dl + np.einsum("hrs,hs->hr", lin.S, b.phasors(dF) @ L)
        return Rr, J, b.coefficients(dR_dw).ravel(), b.coefficients(dR_dl).ravel()

    def dofs(self, Y: np.ndarray, level: float | None = None) -> np.ndarray:
        """DOF phasors X_h (nh, n) of a solution Y (after :meth:`evaluate` at its omega, level)."""
        b, lin = self.basis, self.linear
        Z = self.local(Y, lin.level if level is None else level)
        F, _ = self.aft.evaluate(Z, False)
        return lin.dofs(b.phasors(Z), b.phasors(F))

    def scale(self, Y: np.ndarray | None = None, level: float = 1.0) -> float:
        """Displacement scale for tolerances [m]: the largest local displacement coefficient
        (harmonics >= 1), at least the system's length scale."""
        s = self.length_scale
        if Y is not None and self.nq:
            s = max(s, float(np.abs(self.local(Y, level)[1:]).max(initial=0.0)))
        return s

    # -- one point --------------------------------------------------------------------------
    def residual_norm(self, R: np.ndarray) -> float:
        """|L R|: the residual seen by the contacts [m] (R flat, n_coef r)."""
        return float(np.linalg.norm(R.reshape(self.basis.n_coef, self.r) @ self.L.T))

    def converged(self, R: np.ndarray, Y: np.ndarray, level: float, tol: float) -> bool:
        """The convergence test of every solver here: |L R| <= tol x scale(Y)."""
        return self.residual_norm(R) <= tol * self.scale(Y, level)

    def solve(
        self,
        omega: float,
        level: float = 1.0,
        Y0: np.ndarray | None = None,
        *,
        tol: float = 1e-10,
        max_iterations: int = 50,
    ) -> Point:
        """Newton on R(Y) = 0 at fixed (omega, level), exact Jacobian, backtracking on |R|."""
        with one_blas_thread(self.size):
            return self._solve(omega, level, Y0, tol, max_iterations)

    @property
    def size(self) -> int:
        """Number of unknowns (harmonic coefficients of the gathered coordinates)."""
        return self.basis.n_coef * self.r

    def _solve(self, omega, level, Y0, tol, max_iterations) -> Point:
        Y = self.initial_guess() if Y0 is None else np.array(Y0, dtype=float)
        shape = Y.shape
        self.linear.at(omega, level)
        R, J, _, _ = self.evaluate(Y, omega, level, refactor=False)
        norm = np.linalg.norm(R)
        it, converged = 0, False
        for it in range(1, max_iterations + 1):
            if self.converged(R, Y, level, tol):
                converged = True
                it -= 1
                break
            try:
                dy = np.linalg.solve(J, -R)
            except np.linalg.LinAlgError:
                break
            alpha = 1.0
            for _ in range(8):
                Yt = Y + alpha * dy.reshape(shape)
                Rt = self.evaluate(Yt, omega, level, jacobian=False, refactor=False)
                nt = np.linalg.norm(Rt)
                if nt < norm * (1 - 1e-4 * alpha) or self.converged(Rt, Yt, level, tol):
                    break
                alpha *= 0.5
            Y = Yt
            R, J, _, _ = self.evaluate(Y, omega, level, refactor=False)
            norm = np.linalg.norm(R)
        else:
            converged = self.converged(R, Y, level, tol)
        return self.point(Y, omega, level, it, converged, self.residual_norm(R))

    def point(self, Y, omega, level, iterations, converged, residual) -> Point:
        """Package a solution: Y, its local displacements Z, the AFT forces F and the DOF
        phasors X (the linear part must be at omega)."""
        self.linear.level = level
        Z = self.local(Y, level)
        F, _ = self.aft.evaluate(Z, False)
        X = self.linear.dofs(self.basis.phasors(Z), self.basis.phasors(F))
        return Point(
            omega,
            level,
            Z,
            F,
            X,
            iterations,
            bool(converged),
            float(residual),
            int(self.aft.periods),
            self.aft.ft.copy(),
            self.aft.qt.copy(),
            Y=np.array(Y, dtype=float),
        )
