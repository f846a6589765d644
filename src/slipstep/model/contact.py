"""Spring-slider contact elements with variable normal load (paper Fig. 2-3, physics.md 1-2).

A contact element gathers its local relative displacement from the structure's DOFs x
and the prescribed motions p:

    q = A x - B p + g,    q = [u, v] (2D)  or  [u1, u2, v] (quasi-3D)

u: tangential relative displacement(s), v: normal approach (v > 0 = interference),
g: a constant offset (``normal_offset`` on v: initial interference > 0, gap < 0).
The local force is f = [T, N] (or [T1, T2, N]), N >= 0 compression; it acts on the
structure as ``-A^T f``. Each contact has a friction law (:data:`CONTACT_LAWS`, implemented in
slipstep.kernels.laws); the default is the paper's law for its number of rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError
from slipstep.kernels.codes import LAW_CIRCLE, LAW_UNCOUPLED
from slipstep.model.validate import finite, float_array, gather_matrix, positive


@dataclass(frozen=True)
class ContactLaw:
    """A contact law a contact element can use: its kernel code and what it bounds."""

    name: str
    code: int  # slipstep.kernels.codes.LAW_*
    rows: tuple[int, ...]  # allowed numbers of local rows (2: 2D, 3: quasi-3D / 3D)
    bounds: str
    description: str
    #: every state has a piecewise-linear form (a step in it is one linear solve): what Methods 3 and 4
    #: solve without Newton, the event-driven method and harmonic balance's AFT Jacobian need
    piecewise_linear: bool = True
    #: the tangential directions share one state and slip along the vector T (state slip-circle)
    coupled_slip: bool = False


CONTACT_LAWS: dict[str, ContactLaw] = {
    law.name: law
    for law in (
        ContactLaw(
            "2d",
            LAW_UNCOUPLED,
            (2,),
            "abs(T) <= mu N",
            "the paper's 2D spring-slider with variable normal load N = k_n v and lift-off (default, 2 rows)",
        ),
        ContactLaw(
            "quasi-3d-uncoupled",
            LAW_UNCOUPLED,
            (3,),
            "abs(T1) <= mu N and abs(T2) <= mu N separately: the vector T can reach sqrt(2) mu N",
            "the paper's quasi-3D law: one independent spring-slider per tangential direction (default, 3 rows)",
        ),
        ContactLaw(
            "jenkins",
            LAW_UNCOUPLED,
            (2, 3),
            "abs(T_i) <= mu N0 per direction, N0 = k_n normal_offset constant",
            "Jenkins element: constant normal load (all-zero normal row, normal_offset > 0), never lifts off "
            "(default when the normal row is all zero)",
        ),
        ContactLaw(
            "3d-circle",
            LAW_CIRCLE,
            (3,),
            "norm(T1, T2) <= mu N: the friction circle",
            "coupled 3D friction: one slider in the tangent plane, radial return, variable normal load and "
            "lift-off; one tangential stiffness for both directions",
            piecewise_linear=False,
            coupled_slip=True,
        ),
    )
}

#: the kernel codes of the laws whose directions share one state (the capability, by code, for arrays)
COUPLED_SLIP_CODES = frozenset(law.code for law in CONTACT_LAWS.values() if law.coupled_slip)


def without_piecewise_linear_form(contacts) -> list[str]:
    """The names of the contacts whose law has no piecewise-linear form in some state."""
    return [c.name for c in contacts if not CONTACT_LAWS[c.law].piecewise_linear]


@dataclass(frozen=True)
class ContactElement:
    """One contact point: gather maps, stiffnesses [N/m], friction coefficient [-].

    ``dof_gather`` (A, dense or scipy.sparse) has one row per local coordinate, tangential
    rows first and the normal row last: 2 rows for a 2D element, 3 for quasi-3D (two uncoupled tangential
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
    law: str | None = None

    def __post_init__(self):
        where = f"contacts[{self.name}]"
        A = gather_matrix(f"{where}.dof_gather", self.dof_gather)  # dense, or sparse kept sparse (CSR)
        if A.shape[0] not in (2, 3):
            raise InputError(
                f"{where}.dof_gather",
                f"has {A.shape[0]} rows",
                "give 2 rows (u, v) for a 2D contact or 3 rows (u1, u2, v) for quasi-3D",
            )
        n_tangential = A.shape[0] - 1
        kt = np.atleast_1d(float_array(f"{where}.tangential_stiffness", self.tangential_stiffness))
        if kt.size == 1 and n_tangential == 2:
            kt = np.repeat(kt, 2)
        if kt.ndim != 1 or kt.size != n_tangential:
            raise InputError(
                f"{where}.tangential_stiffness",
                f"has {kt.size} values for {n_tangential} tangential direction(s)",
                f"give {n_tangential} value(s)",
            )
        for k in kt:
            positive(f"{where}.tangential_stiffness", k)
        kn = positive(f"{where}.normal_stiffness", self.normal_stiffness)
        mu = positive(f"{where}.friction_coefficient", self.friction_coefficient, allow_zero=True)
        B = None
        if self.motion_gather is not None:
            B = float_array(f"{where}.motion_gather", self.motion_gather, ndim=2, shape=(A.shape[0], None))
        offset = finite(f"{where}.normal_offset", self.normal_offset)
        normal_row = A[[A.shape[0] - 1]]
        normal_zero = normal_row.nnz == 0 if hasattr(normal_row, "nnz") else bool(np.all(normal_row == 0))
        fixed_normal = normal_zero and (B is None or np.all(B[-1] == 0))
        if fixed_normal and offset <= 0:
            raise InputError(
                f"{where}.dof_gather",
                "has an all-zero normal row, no motion and no interference: the contact can never close",
                "put the normal direction in the last row, or give normal_offset > 0 for a constant "
                "normal load N = k_n * normal_offset (a Jenkins element)",
            )
        law = self._resolve_law(A.shape[0], fixed_normal, kt)
        object.__setattr__(self, "law", law)
        object.__setattr__(self, "dof_gather", A)
        object.__setattr__(self, "motion_gather", B)
        object.__setattr__(self, "tangential_stiffness", tuple(float(k) for k in kt))
        object.__setattr__(self, "normal_stiffness", kn)
        object.__setattr__(self, "friction_coefficient", mu)
        object.__setattr__(self, "normal_offset", offset)

    def _resolve_law(self, rows: int, fixed_normal: bool, kt: np.ndarray) -> str:
        """The law's name (the default for the rows if none given), checked against the rows."""
        where = f"contacts[{self.name}]"
        if self.law is None:
            return "jenkins" if fixed_normal else ("2d" if rows == 2 else "quasi-3d-uncoupled")
        if not isinstance(self.law, str) or self.law not in CONTACT_LAWS:
            raise InputError(f"{where}.law", f"is {self.law!r}", f"use one of {', '.join(map(repr, CONTACT_LAWS))}")
        law = CONTACT_LAWS[self.law]
        if rows not in law.rows:
            raise InputError(
                f"{where}.law",
                f"is {law.name!r}, which needs {' or '.join(map(str, law.rows))} rows of dof_gather, not {rows}",
                "use '2d' for a 2-row contact, 'quasi-3d-uncoupled' or '3d-circle' for 3 rows",
            )
        if law.name == "jenkins" and not fixed_normal:
            raise InputError(
                f"{where}.law",
                "is 'jenkins' (constant normal load) but the normal row of dof_gather or motion_gather is not all zero",
                "zero the normal rows and set normal_offset > 0, or use the paper's law",
            )
        if law.coupled_slip and kt[0] != kt[1]:
            raise InputError(
                f"{where}.tangential_stiffness",
                f"is {list(kt)}: the friction circle ({law.name!r}) needs one tangential stiffness for both directions",
                "give a single value, or use law = 'quasi-3d-uncoupled'",
            )
        return law.name

    @property
    def contact_law(self) -> ContactLaw:
        """The law this contact uses, with its capabilities."""
        return CONTACT_LAWS[self.law]

    @property
    def law_code(self) -> int:
        return CONTACT_LAWS[self.law].code

    def dense_gather(self) -> np.ndarray:
        """The gather map A as a dense array (rows x DOFs)."""
        A = self.dof_gather
        return A.toarray() if hasattr(A, "toarray") else A

    @property
    def n_tangential(self) -> int:
        return self.dof_gather.shape[0] - 1
