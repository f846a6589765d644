"""The linear structure of paper Eq. 1: ``M a + C v + K x`` with named DOFs (SI units).

A rigid damper has ``K = 0`` and ``C = 0``; the contacts alone hold it in place.
M, C, K are dense arrays or scipy.sparse matrices (kept sparse, canonical CSR; validated
without forming a dense n x n matrix: symmetry on the sparse difference, definiteness by a
sparse LU's pivots). A sparse structure compiles to the banded backend (slipstep.model.system).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError
from slipstep.model.validate import names, square_matrix_or_sparse


@dataclass(frozen=True)
class Structure:
    """Mass ``M`` [kg, kg m^2], damping ``C`` [N s/m], stiffness ``K`` [N/m] of n DOFs.

    ``M`` must be symmetric positive definite (every DOF has inertia); ``C`` and ``K``
    default to zero and must be symmetric positive semi-definite.
    """

    mass: object  # np.ndarray or scipy.sparse (CSR)
    damping: object = None
    stiffness: object = None
    dof_names: tuple[str, ...] = field(default=())
    dof_units: tuple[str, ...] = field(default=())

    def __post_init__(self):
        M = square_matrix_or_sparse("structure.mass", self.mass)
        n = M.shape[0]
        if n == 0:
            raise InputError("structure.mass", "is empty", "give at least one DOF")
        sparse = _issparse(M)
        C = _zeros(n, sparse) if self.damping is None else square_matrix_or_sparse("structure.damping", self.damping, n)
        K = (
            _zeros(n, sparse)
            if self.stiffness is None
            else square_matrix_or_sparse("structure.stiffness", self.stiffness, n)
        )
        for name, A in (("structure.mass", M), ("structure.damping", C), ("structure.stiffness", K)):
            asym, scale = _asymmetry(A)
            if asym > 1e-9 * scale:
                raise InputError(name, "is not symmetric", "give a symmetric matrix (A == A.T)")
        if not _positive_definite(M, shift=0.0):
            raise InputError(
                "structure.mass",
                f"is not positive definite ({_smallest_eigenvalue(M)}); a negative or zero mass or inertia",
                "give every DOF a positive mass/inertia",
            )
        for name, A in (("structure.damping", C), ("structure.stiffness", K)):
            if not _positive_definite(A, shift=PSD_RTOL):
                raise InputError(
                    name,
                    f"has a negative eigenvalue ({_smallest_eigenvalue(A)})",
                    "give a positive semi-definite matrix (no negative stiffness/damping)",
                )
        dof_names = names("structure.dof_names", self.dof_names, "DOF", unique=False)
        dof_names = dof_names or tuple(f"x{i}" for i in range(n))
        if len(dof_names) != n:
            raise InputError("structure.dof_names", f"has {len(dof_names)} names for {n} DOFs", f"give {n} names")
        if len(set(dof_names)) != n:
            raise InputError("structure.dof_names", "contains duplicates", "give unique names")
        units = _units(self.dof_units) or ("m",) * n
        if len(units) != n:
            raise InputError("structure.dof_units", f"has {len(units)} units for {n} DOFs", f"give {n} units")
        object.__setattr__(self, "mass", M)
        object.__setattr__(self, "damping", C)
        object.__setattr__(self, "stiffness", K)
        object.__setattr__(self, "dof_names", dof_names)
        object.__setattr__(self, "dof_units", units)

    @property
    def n_dofs(self) -> int:
        return self.mass.shape[0]

    @property
    def sparse(self) -> bool:
        """True when M, C or K is a scipy.sparse matrix (the banded backend's input)."""
        return any(_issparse(A) for A in (self.mass, self.damping, self.stiffness))

    def dense_matrices(self, field: str = "structure", feature: str = "this feature") -> tuple:
        """(M, C, K) as dense arrays for the features that need them: refused (InputError
        naming ``field``) for a sparse structure above DENSE_MAX_N DOFs."""
        if self.sparse and self.n_dofs > DENSE_MAX_N:
            refuse_sparse(field, feature, self.n_dofs)
        return tuple(A.toarray() if _issparse(A) else A for A in (self.mass, self.damping, self.stiffness))

    def diagonal(self, which: str) -> np.ndarray:
        """diag of 'mass', 'damping' or 'stiffness' (sparse or dense)."""
        A = getattr(self, which)
        return A.diagonal() if _issparse(A) else np.diag(A).copy()


#: the unit of a DOF: a translation in metres or a rotation in radians (slipstep works in SI)
DOF_UNITS = ("m", "rad")


def _units(values) -> tuple:
    """The DOF units, each one of :data:`DOF_UNITS`."""
    values = names("structure.dof_units", values, "DOF", unique=False)
    for value in values:
        if value not in DOF_UNITS:
            raise InputError(
                "structure.dof_units",
                f"{value!r} is not a unit slipstep knows",
                f"give {' or '.join(repr(u) for u in DOF_UNITS)} per DOF (SI: metres for a translation, "
                "radians for a rotation; convert the matrices if the model is in other units)",
            )
    return values


#: a sparse structure up to this many DOFs may be densified by the features that need dense matrices
DENSE_MAX_N = 2000


def refuse_sparse(field: str, feature: str, n: int):
    """The InputError of a feature that needs dense n x n matrices, given a large sparse model."""
    raise InputError(
        field,
        f"is a sparse structure of {n} DOFs: {feature} needs dense n x n matrices (at most {DENSE_MAX_N} DOFs)",
        "use a time march (newmark, piecewise-linear, their adaptive variants or quasi-static), which take "
        "sparse structures, or reduce the model (slipstep.craig_bampton)",
    )


def _issparse(A) -> bool:
    import scipy.sparse as sp

    return sp.issparse(A)


def _zeros(n: int, sparse: bool):
    if sparse:
        import scipy.sparse as sp

        return sp.csr_matrix((n, n))
    return np.zeros((n, n))


def _asymmetry(A) -> tuple[float, float]:
    """(max |A - A^T|, max(max |A|, 1e-300)), sparse or dense (no dense copy of a sparse A)."""
    if _issparse(A):
        d = (A - A.T).tocsr()
        asym = float(np.abs(d.data).max(initial=0.0))
        return asym, max(float(np.abs(A.data).max(initial=0.0)), 1e-300)
    return float(np.abs(A - A.T).max()), max(float(np.abs(A).max()), 1e-300)


PSD_RTOL = 1e-9  # a semi-definite matrix may have eigenvalues down to -PSD_RTOL * its largest entry
PD_RTOL = 1e-12  # a definite one needs every pivot above PD_RTOL * the largest
SPARSE_CHECK_MIN_N, SPARSE_CHECK_DENSITY = 200, 0.05  # the sparse check for larger matrices with < 5 % non-zeros


def _positive_definite(A, shift: float) -> bool:
    """True if A + shift * max|A_ij| * I is positive definite, by Sylvester's criterion on the
    pivots of a symmetric (diagonal-pivot) factorisation P A P^T = L D U, never by an
    eigen-decomposition: a dense Cholesky (n^3/3 flops) for dense matrices, a sparse LU with a
    symmetric fill-reducing ordering and diagonal pivots (SuperLU, threshold 0) for sparse ones
    (a lumped or banded FE mass or stiffness: about linear in n). A definite matrix has every
    pivot > 0; with shift = 0 also every pivot above PD_RTOL times the largest (a zero mass)."""
    import scipy.sparse as sp

    n = A.shape[0]
    if _issparse(A):
        scale = float(np.abs(A.data).max(initial=0.0))
        dense_small = False
    else:
        scale = float(np.abs(A).max(initial=0.0))
        dense_small = n <= SPARSE_CHECK_MIN_N or np.count_nonzero(A) > SPARSE_CHECK_DENSITY * n * n
    if scale == 0.0:
        return shift > 0.0
    if dense_small:
        shifted = A + (shift * scale) * np.eye(n) if shift > 0.0 else A
        try:
            pivots = np.diag(np.linalg.cholesky(shifted)) ** 2
        except np.linalg.LinAlgError:
            return False
    else:
        from scipy.sparse.linalg import splu

        shifted = sp.csc_matrix(A) + (shift * scale) * sp.identity(n, format="csc") if shift > 0.0 else sp.csc_matrix(A)
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


def _smallest_eigenvalue(A) -> str:
    """For the error message only (the matrix was refused): its smallest eigenvalue, as text
    (a large sparse matrix: no eigen-solve, the factorisation's verdict)."""
    if _issparse(A) and A.shape[0] > SPARSE_CHECK_MIN_N:
        return "a non-positive pivot of its sparse symmetric factorisation"
    dense = A.toarray() if _issparse(A) else A
    return f"smallest eigenvalue {float(np.linalg.eigvalsh(dense).min()):.3g}"
