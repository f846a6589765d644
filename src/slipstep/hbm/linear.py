"""The linear part of a harmonic balance: excitation phasors and the dynamic compliance.

Per retained harmonic h (angular frequency h Omega) the linear structure is the complex
dynamic stiffness (x = Re(X exp(i h Omega t)))

    D_h = K - (h Omega)^2 M + i h Omega C + A^T Kc_h A,

where Kc_h is a reference contact stiffness added on both sides of the balance so that
D_0 stays invertible when K is singular (a damper held only by its contacts): Kc_0 = the
full-stick contact stiffness diag(k_t, k_n), Kc_h = 0 for h > 0. The balance of harmonic h,

    (K - (h Omega)^2 M + i h Omega C) X_h + A^T F_h = Fe_h,

then gives the DOF phasors from the contact force phasors

    X_h = D_h^-1 ( Fe_h - A^T (F_h - Kc_h A X_h) ),    A X_h = Q_h + B P_h - g [h = 0],

with Q_h the local displacement phasors (q = A x - B p + g), P_h the prescribed-motion
phasors and Fe_h the external force phasors; the constant loads are Fe_0. The dynamic
compliance seen by the contacts is G_h = A D_h^-1 A^T.

The gather (:class:`Gather`, issue 24): A = L W with W x the coordinates y the contacts see,
either the DOFs with a nonzero column in A (W a selection, L = A[:, dofs]: few when the
contacts sit on a few rigid-body DOFs, however many contact points) or the contact
coordinates themselves (W = A, L = I). The balance is written on y (r per harmonic) with the
compliance S_h = W D_h^-1 W^T (r x r), so that G_h = L S_h L^T is never formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slipstep.errors import InputError

CONDENSE = ("auto", "dofs", "contacts")


@dataclass(frozen=True)
class Gather:
    """q = L y - B p + g with y = W x: ``mode`` "dofs" (y = x[dofs], L = A[:, dofs]) or
    "contacts" (y = A x, L = I, dofs None)."""

    mode: str
    L: np.ndarray  # (nq, r)
    dofs: np.ndarray | None  # (r,) DOF indices of y (mode "dofs")

    @property
    def size(self) -> int:
        """r, the gathered coordinates per harmonic coefficient."""
        return self.L.shape[1]

    def of_dofs(self, X: np.ndarray, A: np.ndarray) -> np.ndarray:
        """W X for DOF values X (..., n): (..., r)."""
        return X[..., self.dofs] if self.dofs is not None else X @ A.T


def choose_gather(cs, condense: str = "auto") -> Gather:
    """The gather of a CompiledSystem: ``condense`` "dofs", "contacts", or "auto" (the DOFs
    with a nonzero column in A when they are fewer than the contact coordinates)."""
    if condense not in CONDENSE:
        raise InputError("condense", f"is {condense!r}", f"use one of {list(CONDENSE)}")
    A = np.asarray(cs.A, dtype=float)
    nq = A.shape[0]
    dofs = np.flatnonzero(np.abs(A).sum(axis=0) > 0)
    if condense == "dofs" or (condense == "auto" and dofs.size < nq):
        return Gather("dofs", np.ascontiguousarray(A[:, dofs]), dofs)
    return Gather("contacts", np.eye(nq), None)


def excitation_multiples(system, fundamental_hz: float | None = None):
    """The harmonic excitation as multiples of its fundamental frequency.

    Returns (fundamental [Hz], force phasors dict {m: (n,) complex}, motion phasors dict
    {m: (nm,) complex}, constant force (n,)): a sin(2 pi m f t + phi) has the phasor
    a (sin phi - i cos phi) at multiple m (x = Re(X exp(i m Omega t))). Tables cannot be
    balanced harmonically and are an InputError; ramps are ignored (steady state)."""
    exc = system.excitation
    f0 = exc.fundamental_frequency if fundamental_hz is None else fundamental_hz
    if f0 is None:
        raise InputError("excitation", "has no harmonic force or motion", "give [[force]] or [[motion]] harmonics")
    out = []
    for label, signal in (("force", exc.force), ("motion", exc.motion)):
        phasors: dict[int, np.ndarray] = {}
        if signal is not None:
            if signal.tables:
                raise InputError(
                    f"{label}_table",
                    "is tabulated: a harmonic balance needs harmonic excitation",
                    f"replace the {label} table by [[{label}]] harmonics or use a time-marching solver",
                )
            for hm in signal.harmonics:
                ratio = hm.frequency / (1.0 / exc.period if exc.period is not None else f0)
                m = round(ratio)
                if m < 1 or abs(ratio - m) > 1e-9 * max(ratio, 1.0):
                    raise InputError(
                        f"{label}.frequency_Hz",
                        f"{hm.frequency} Hz is not a whole multiple of the fundamental {f0} Hz",
                        "give harmonics at multiples of one fundamental",
                    )
                ph = hm.amplitude * (np.sin(hm.phase) - 1j * np.cos(hm.phase))
                phasors[m] = phasors.get(m, 0.0) + ph
        out.append(phasors)
    n = system.n_dofs
    f_const = np.zeros(n) if exc.constant_force is None else np.asarray(exc.constant_force, float)
    return f0, out[0], out[1], f_const


class _DenseLU:
    """LAPACK's LU of a dense complex matrix, with the ``solve`` of SuperLU's objects."""

    def __init__(self, D: np.ndarray):
        self.factors = scipy.linalg.lu_factor(np.asarray(D, complex), check_finite=False)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return scipy.linalg.lu_solve(self.factors, b, check_finite=False)


def _SparseLU(D) -> spla.SuperLU:
    """SuperLU's LU of a sparse complex matrix."""
    return spla.splu(sp.csc_matrix(D, dtype=complex))


class LinearPart:
    """D_h, S_h and the linear local response per retained harmonic at a frequency Omega.

    ``h``: retained harmonics (with 0); ``cs``: CompiledSystem. ``at(omega)`` factorises
    the D_h; the excitation is scaled by ``level`` (constant loads and offsets are not).

    Two forms of D_h^-1, one interface (:meth:`solve`, :meth:`solve_gathered`):
    - dense (a CompiledSystem with n x n matrices): one LAPACK LU of D_h per harmonic;
    - sparse (a CompiledSystem compiled with backend "contacts", whose M, C, K are empty: the
      structure's scipy.sparse matrices are used): one SuperLU of D_h per harmonic;
    either way S_h = W D_h^-1 W^T costs r solves and no inverse is formed (issue 24, item 7)."""

    def __init__(self, system, cs, h: np.ndarray, gather: Gather | None = None):
        self.cs, self.h = cs, np.asarray(h)
        self.gather = choose_gather(cs) if gather is None else gather
        self.f0, force, motion, self.f_const = excitation_multiples(system)
        n, nq = cs.M.shape[0], cs.A.shape[0]
        nm = cs.B.shape[1]
        self.sparse = cs.M.shape[1] == 0 and n > 0
        if self.sparse:
            s = system.structure
            self.M, self.C, self.K = (sp.csc_matrix(X, dtype=float) for X in (s.mass, s.damping, s.stiffness))
        else:
            self.M, self.C, self.K = cs.M, cs.C, cs.K
        missing = sorted((set(force) | set(motion)) - {int(x) for x in self.h})
        self.missing = missing
        self.Fe = np.zeros((self.h.size, n), complex)  # varying forces (scaled by level)
        self.P = np.zeros((self.h.size, nm), complex)
        for i, hh in enumerate(self.h):
            if hh in force:
                self.Fe[i] = force[hh]
            if hh in motion:
                self.P[i] = motion[hh]
        self.Fc = np.zeros((self.h.size, n), complex)
        self.Fc[0] = self.f_const
        kc = np.zeros(nq)
        kc[cs.tangential_row] = cs.kt
        kc[cs.normal_row] = cs.kn
        self.Kc = np.zeros((self.h.size, nq))
        self.Kc[0] = kc
        A = sp.csr_matrix(cs.A)
        KcD0 = (A.T @ sp.diags(kc) @ A).tocsc()  # A^T Kc_0 A, constant (Kc_h = 0 for h > 0)
        self.KcD0 = KcD0 if self.sparse else KcD0.toarray()
        self.g0 = np.zeros((self.h.size, nq))
        self.g0[0] = cs.g
        self.omega = None  # the omega of the current factorisation (none yet)

    def at(self, omega: float, level: float = 1.0):
        """Factorise D_h(omega) and form S_h = W D_h^-1 W^T (the compliance on the gathered coordinates);
        kept while omega is unchanged (a continuation in the level, or a Jacobian column in it)."""
        self.level = level
        if omega != self.omega:
            self._factorise(omega)
            self.omega = omega
        return self

    def _dynamic_stiffness(self, i: int, omega: float):
        """D_h = K - (h Omega)^2 M + i h Omega C (+ A^T Kc_0 A for h = 0), harmonic index i."""
        w = self.h[i] * omega
        D = self.K - (w * w) * self.M + (1j * w) * self.C
        return D + self.KcD0 if i == 0 else D

    def _factorise(self, omega: float):
        """One LU of D_h per harmonic (dense: LAPACK's; sparse: SuperLU), then D_h^-1 W^T by r
        solves and S_h = W D_h^-1 W^T; no inverse (an LU is a third of its cost, and a solve with
        it is one BLAS triangular pair per harmonic)."""
        cs, g = self.cs, self.gather
        factor = _SparseLU if self.sparse else _DenseLU
        self.lu = [factor(self._dynamic_stiffness(i, omega)) for i in range(self.h.size)]
        WT = self._scatter(np.eye(g.size, dtype=complex)).T  # (n, r): the columns of W^T
        DinvWT = [lu.solve(WT) for lu in self.lu]
        self.S = np.stack([g.of_dofs(X.T, cs.A).T for X in DinvWT])
        # kept for the dense form only (n x r per harmonic: small there; r sparse solves instead)
        self.DinvWT = None if self.sparse else np.stack(DinvWT)
        # the linear response to the constant and to the varying loads (the latter scaled by level)
        self.Xc, self.Xf = self.solve(self.Fc), self.solve(self.Fe)

    def _scatter(self, U: np.ndarray) -> np.ndarray:
        """W^T U for gathered values U (k, r): (k, n)."""
        g = self.gather
        if g.dofs is None:
            return U @ self.cs.A
        out = np.zeros((U.shape[0], self.cs.M.shape[0]), U.dtype)
        out[:, g.dofs] = U
        return out

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """D_h^-1 rhs_h for DOF right-hand sides rhs (nh, n)."""
        return np.stack([lu.solve(np.ascontiguousarray(r, dtype=complex)) for lu, r in zip(self.lu, rhs)])

    def solve_gathered(self, U: np.ndarray) -> np.ndarray:
        """D_h^-1 W^T U_h for gathered values U (nh, r): (nh, n)."""
        if self.DinvWT is not None:
            return np.einsum("hnm,hm->hn", self.DinvWT, U)
        return self.solve(self._scatter(U))

    def external_response(self, level: float | None = None) -> np.ndarray:
        """D_h^-1 Fe_h (nh, n) of :meth:`external`, from the two responses of the factorisation."""
        lv = self.level if level is None else level
        return self.Xc + lv * self.Xf

    def external(self, level: float | None = None) -> np.ndarray:
        """Fe_h (nh, n): constant + level x varying forces."""
        lv = self.level if level is None else level
        return self.Fc + lv * self.Fe

    def dofs(self, Q: np.ndarray, F: np.ndarray) -> np.ndarray:
        """DOF phasors X_h (nh, n) from local displacement and force phasors (nh, nq)."""
        cs = self.cs
        rhs = self.external() - (F - self.Kc * (Q + self.level * (self.P @ cs.B.T) - self.g0)) @ cs.A
        return self.solve(rhs)

    def dD_times(self, X: np.ndarray) -> np.ndarray:
        """(dD_h/dOmega) X_h for DOF phasors X (nh, n): dD_h/dOmega = -2 h^2 Omega M + i h C."""
        h = self.h
        MX = (self.M @ X.T).T
        CX = (self.C @ X.T).T
        return -2.0 * (h**2 * self.omega)[:, None] * MX + 1j * h[:, None] * CX

    def damping_times(self, X: np.ndarray) -> np.ndarray:
        """C X_h for DOF phasors X (nh, n)."""
        return (self.C @ X.T).T
