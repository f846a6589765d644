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
        eig_m = np.linalg.eigvalsh(M)
        if eig_m.min() <= 1e-12 * max(eig_m.max(), 1e-300):
            raise InputError("structure.mass",
                             f"is not positive definite (smallest eigenvalue {eig_m.min():.3g}); "
                             "a negative or zero mass or inertia",
                             "give every DOF a positive mass/inertia")
        for name, A in (("structure.damping", C), ("structure.stiffness", K)):
            eig = np.linalg.eigvalsh(A)
            if eig.min() < -1e-9 * max(np.abs(eig).max(), 1e-300):
                raise InputError(name, f"has a negative eigenvalue ({eig.min():.3g})",
                                 "give a positive semi-definite matrix (no negative stiffness/damping)")
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
