"""Spring-slider contact elements with variable normal load (paper Fig. 2-3, physics.md 1-2).

A contact element gathers its local relative displacement from the structure's DOFs x
and the prescribed motions p:

    q = A x - B p + g,    q = [u, v] (2D)  or  [u1, u2, v] (quasi-3D)

u: tangential relative displacement(s), v: normal approach (v > 0 = interference),
g: a constant offset (``normal_offset`` on v: initial interference > 0, gap < 0).
The local force is f = [T, N] (or [T1, T2, N]), N >= 0 compression; it acts on the
structure as ``-A^T f``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError
from slipstep.model.validate import finite, float_array, positive


@dataclass(frozen=True)
class ContactElement:
    """One contact point: gather maps, stiffnesses [N/m], friction coefficient [-].

    ``dof_gather`` (A) has one row per local coordinate, tangential rows first and the
    normal row last: 2 rows for a 2D element, 3 for quasi-3D (two uncoupled tangential
    directions). ``motion_gather`` (B) has the same rows and one column per prescribed
    motion component (omit it when the contact sees no prescribed motion).
    """

    name: str
    dof_gather: np.ndarray
    tangential_stiffness: float | tuple[float, ...]
    normal_stiffness: float
    friction_coefficient: float
    motion_gather: np.ndarray | None = None
    normal_offset: float = 0.0

    def __post_init__(self):
        where = f"contacts[{self.name}]"
        A = float_array(f"{where}.dof_gather", self.dof_gather, ndim=2)
        if A.shape[0] not in (2, 3):
            raise InputError(f"{where}.dof_gather", f"has {A.shape[0]} rows",
                             "give 2 rows (u, v) for a 2D contact or 3 rows (u1, u2, v) for quasi-3D")
        n_tangential = A.shape[0] - 1
        kt = np.atleast_1d(float_array(f"{where}.tangential_stiffness", self.tangential_stiffness))
        if kt.size == 1 and n_tangential == 2:
            kt = np.repeat(kt, 2)
        if kt.ndim != 1 or kt.size != n_tangential:
            raise InputError(f"{where}.tangential_stiffness", f"has {kt.size} values for {n_tangential} tangential direction(s)",
                             f"give {n_tangential} value(s)")
        for k in kt:
            positive(f"{where}.tangential_stiffness", k)
        kn = positive(f"{where}.normal_stiffness", self.normal_stiffness)
        mu = positive(f"{where}.friction_coefficient", self.friction_coefficient, allow_zero=True)
        B = None
        if self.motion_gather is not None:
            B = float_array(f"{where}.motion_gather", self.motion_gather, ndim=2, shape=(A.shape[0], None))
        offset = finite(f"{where}.normal_offset", self.normal_offset)
        fixed_normal = np.all(A[-1] == 0) and (B is None or np.all(B[-1] == 0))
        if fixed_normal and offset <= 0:
            raise InputError(f"{where}.dof_gather", "has an all-zero normal row, no motion and no interference: "
                             "the contact can never close",
                             "put the normal direction in the last row, or give normal_offset > 0 for a constant "
                             "normal load N = k_n * normal_offset (a Jenkins element)")
        object.__setattr__(self, "dof_gather", A)
        object.__setattr__(self, "motion_gather", B)
        object.__setattr__(self, "tangential_stiffness", tuple(float(k) for k in kt))
        object.__setattr__(self, "normal_stiffness", kn)
        object.__setattr__(self, "friction_coefficient", mu)
        object.__setattr__(self, "normal_offset", offset)

    @property
    def n_tangential(self) -> int:
        return self.dof_gather.shape[0] - 1
