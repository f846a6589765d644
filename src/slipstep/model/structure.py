"""The linear structure of paper Eq. 1: ``M a + C v + K x`` with named DOFs (SI units).

A rigid damper has ``K = 0`` and ``C = 0``; the contacts alone hold it in place.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError
from slipstep.model.validate import square_matrix


@dataclass(frozen=True)
class Structure:
    """Mass ``M`` [kg, kg m^2], damping ``C`` [N s/m], stiffness ``K`` [N/m] of n DOFs.

    ``M`` must be symmetric positive definite (every DOF has inertia); ``C`` and ``K``
    default to zero and must be symmetric positive semi-definite.
    """

    mass: np.ndarray
    damping: np.ndarray | None = None
    stiffness: np.ndarray | None = None
    dof_names: tuple[str, ...] = field(default=())
    dof_units: tuple[str, ...] = field(default=())

    def __post_init__(self):
        M = square_matrix("structure.mass", self.mass)
        n = M.shape[0]
        if n == 0:
            raise InputError("structure.mass", "is empty", "give at least one DOF")
        C = np.zeros((n, n)) if self.damping is None else square_matrix("structure.damping", self.damping, n)
        K = np.zeros((n, n)) if self.stiffness is None else square_matrix("structure.stiffness", self.stiffness, n)
        for name, A in (("structure.mass", M), ("structure.damping", C), ("structure.stiffness", K)):
            scale = max(np.abs(A).max(), 1e-300)
            if np.abs(A - A.T).max() > 1e-9 * scale:
                raise InputError(name, "is not symmetric", "give a symmetric matrix (A == A.T)")
        if not _positive_definite(M, shift=0.0):
            raise InputError(
                "structure.mass",
                f"is not positive definite (smallest eigenvalue {_smallest_eigenvalue(M):.3g}); "
                "a negative or zero mass or inertia",
                "give every DOF a positive mass/inertia",
            )
        for name, A in (("structure.damping", C), ("structure.stiffness", K)):
            if not _positive_definite(A, shift=PSD_RTOL):
                raise InputError(
                    name,
                    f"has a negative eigenvalue ({_smallest_eigenvalue(A):.3g})",
                    "give a positive semi-definite matrix (no negative stiffness/damping)",
                )
        names = tuple(self.dof_names) or tuple(f"x{i}" for i in range(n))
        if len(names) != n:
            raise InputError("structure.dof_names", f"has {len(names)} names for {n} DOFs", f"give {n} names")
        if len(set(names)) != n:
            raise InputError("structure.dof_names", "contains duplicates", "give unique names")
        units = tuple(self.dof_units) or ("m",) * n
        if len(units) != n:
            raise InputError("structure.dof_units", f"has {len(units)} units for {n} DOFs", f"give {n} units")
        object.__setattr__(self, "mass", M)
        object.__setattr__(self, "damping", C)
        object.__setattr__(self, "stiffness", K)
        object.__setattr__(self, "dof_names", names)
        object.__setattr__(self, "dof_units", units)

    @property
    def n_dofs(self) -> int:
        return self.mass.shape[0]


PSD_RTOL = 1e-9  # a semi-definite matrix may have eigenvalues down to -PSD_RTOL * its largest entry
PD_RTOL = 1e-12  # a definite one needs every pivot above PD_RTOL * the largest
SPARSE_CHECK_MIN_N, SPARSE_CHECK_DENSITY = 200, 0.05  # the sparse check for larger matrices with < 5 % non-zeros


def _positive_definite(A: np.ndarray, shift: float) -> bool:
    """True if A + shift * max|A_ij| * I is positive definite, by Sylvester's criterion on the
    pivots of a symmetric (diagonal-pivot) factorisation P A P^T = L D U, never by an
    eigen-decomposition: a dense Cholesky (n^3/3 flops) for dense matrices, a sparse LU with a
    symmetric fill-reducing ordering and diagonal pivots (SuperLU, threshold 0) for sparse ones
    (a lumped or banded FE mass or stiffness: about linear in n). A definite matrix has every
    pivot > 0; with shift = 0 also every pivot above PD_RTOL times the largest (a zero mass)."""
    n = A.shape[0]
    scale = float(np.abs(A).max(initial=0.0))
    if scale == 0.0:
        return shift > 0.0
    shifted = A + (shift * scale) * np.eye(n) if shift > 0.0 else A
    if n <= SPARSE_CHECK_MIN_N or np.count_nonzero(A) > SPARSE_CHECK_DENSITY * n * n:
        try:
            pivots = np.diag(np.linalg.cholesky(shifted)) ** 2
        except np.linalg.LinAlgError:
            return False
    else:
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        try:
            lu = splu(
                sp.csc_matrix(shifted),
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError:  # exactly singular
            return False
        if not np.array_equal(lu.perm_r, lu.perm_c):  # an off-diagonal pivot: a zero on the diagonal
            return False
        pivots = lu.U.diagonal()
    return bool(pivots.min() > 0.0 and (shift > 0.0 or pivots.min() > PD_RTOL * pivots.max()))


def _smallest_eigenvalue(A: np.ndarray) -> float:
    """For the error message only (the matrix was refused): its smallest eigenvalue."""
    return float(np.linalg.eigvalsh(A).min())
