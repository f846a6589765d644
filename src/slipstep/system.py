"""A System is the whole model (structure + contacts + excitation); compile() makes arrays.

The :class:`CompiledSystem` is the only thing kernels see: contiguous float64/int64
arrays, one contact *direction* per tangential direction (each with its own slider and
state), and the signals of :mod:`slipstep.model.excitation` in compiled form.

Legend: n DOFs, m motion components, nq local coordinates (all contacts stacked),
nc contacts, nd tangential directions (= sliders = state entries).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from slipstep.errors import InputError
from slipstep.kernels.codes import N_LAW_PAR, P_KN, P_MU
from slipstep.model.contact import ContactElement
from slipstep.model.excitation import Excitation, compile_signal
from slipstep.model.structure import Structure
from slipstep.model.validate import check_name, float_array


class CompiledSystem(NamedTuple):
    M: np.ndarray  # (n, n) kg
    C: np.ndarray  # (n, n) N s/m
    K: np.ndarray  # (n, n) N/m
    A: np.ndarray  # (nq, n) gather from DOFs
    AT: np.ndarray  # (n, nq) its transpose, contiguous (scatter A^T f)
    B: np.ndarray  # (nq, m) gather from prescribed motions
    g: np.ndarray  # (nq,) offsets (normal interference)
    normal_row: np.ndarray  # (nc,) int64 row of v in q
    kn: np.ndarray  # (nc,) N/m (= law_par[:, P_KN], for readers of results)
    mu: np.ndarray  # (nc,) (= law_par[:, P_MU])
    first_direction: np.ndarray  # (nc,) int64 index of the contact's first direction
    n_directions: np.ndarray  # (nc,) int64 1 (2D) or 2 (quasi-3D)
    tangential_row: np.ndarray  # (nd,) int64 row of u in q
    direction_contact: np.ndarray  # (nd,) int64 owning contact
    kt: np.ndarray  # (nd,) N/m
    constant_force: np.ndarray  # (n,) N
    force_frequency: np.ndarray
    force_sin: np.ndarray
    force_cos: np.ndarray
    force_table_time: np.ndarray
    force_table_value: np.ndarray
    force_ramp: float
    motion_frequency: np.ndarray
    motion_sin: np.ndarray
    motion_cos: np.ndarray
    motion_table_time: np.ndarray
    motion_table_value: np.ndarray
    motion_ramp: float
    length_scale: float  # m, for tolerances
    law: np.ndarray  # (nc,) int64 contact-law code (kernels/codes.py LAW_*, names in model.contact.CONTACT_LAWS)
    law_par: np.ndarray  # (nc, N_LAW_PAR) the law parameter table: P_KN k_n [N/m], P_MU mu (kernels read these)


@dataclass(frozen=True)
class System:
    """Structure + contact elements + excitation; validated once, then compiled to arrays."""

    structure: Structure
    contacts: tuple[ContactElement, ...]
    excitation: Excitation = field(default_factory=Excitation)
    motion_names: tuple[str, ...] = ()
    name: str = "system"

    def __post_init__(self):
        n = self.structure.n_dofs
        contacts = tuple(self.contacts)
        names = [c.name for c in contacts]
        if len(set(names)) != len(names):
            raise InputError("contacts", f"names are not unique: {names}", "give every contact its own name")
        check_name("name", self.name)
        for kind, values in (
            ("contacts", names),
            ("motion_names", self.motion_names),
            ("structure.dof_names", self.structure.dof_names),
        ):
            for value in values:
                check_name(kind, value)
        motion_names = tuple(self.motion_names)
        if len(set(motion_names)) != len(motion_names):
            raise InputError(
                "motion_names",
                f"are not unique: {list(motion_names)}",
                "give every prescribed motion component its own name",
            )
        if self.excitation.motion is not None:
            if motion_names and motion_names != self.excitation.motion.components:
                raise InputError(
                    "excitation.motion.components",
                    f"{self.excitation.motion.components} differ from motion_names {motion_names}",
                    "use the same component names",
                )
            motion_names = self.excitation.motion.components
        m = len(motion_names)
        for c in contacts:
            if c.dof_gather.shape[1] != n:
                raise InputError(
                    f"contacts[{c.name}].dof_gather",
                    f"has {c.dof_gather.shape[1]} columns, structure has {n} DOFs",
                    f"give {n} columns",
                )
            if c.motion_gather is not None and c.motion_gather.shape[1] != m:
                raise InputError(
                    f"contacts[{c.name}].motion_gather",
                    f"has {c.motion_gather.shape[1]} columns for {m} motion components {motion_names}",
                    f"give {m} columns, one per prescribed motion component",
                )
        exc = self.excitation
        if exc.constant_force is not None:
            object.__setattr__(
                exc, "constant_force", float_array("excitation.constant_force", exc.constant_force, shape=(n,))
            )
        if exc.force is not None and len(exc.force.components) != n:
            raise InputError(
                "excitation.force.components",
                f"has {len(exc.force.components)} components, structure has {n} DOFs",
                "give one force component per DOF",
            )
        object.__setattr__(self, "contacts", contacts)
        object.__setattr__(self, "motion_names", motion_names)

    @property
    def n_dofs(self) -> int:
        return self.structure.n_dofs

    @property
    def contact_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.contacts)

    def local_coordinate_names(self) -> list[tuple[str, str]]:
        """(contact, component) per local row: components u / u1, u2 and v."""
        rows = []
        for c in self.contacts:
            tang = ["u"] if c.n_tangential == 1 else ["u1", "u2"]
            rows += [(c.name, comp) for comp in tang + ["v"]]
        return rows

    def direction_names(self) -> list[str]:
        """One label per tangential direction (slider): 'P1' or 'P1.u1', 'P1.u2'."""
        out = []
        for c in self.contacts:
            out += [c.name] if c.n_tangential == 1 else [f"{c.name}.u1", f"{c.name}.u2"]
        return out

    @property
    def period(self) -> float | None:
        f = self.excitation.fundamental_frequency
        return None if f is None else 1.0 / f

    def compile(self) -> CompiledSystem:
        s = self.structure
        n, m = s.n_dofs, len(self.motion_names)
        A_rows, B_rows, g = [], [], []
        normal_row, kn, mu, first_dir, n_dir = [], [], [], [], []
        tan_row, dir_contact, kt = [], [], []
        row = 0
        for ic, c in enumerate(self.contacts):
            nrow = c.dof_gather.shape[0]
            A_rows.append(c.dof_gather)
            B_rows.append(np.zeros((nrow, m)) if c.motion_gather is None else c.motion_gather)
            g += [0.0] * (nrow - 1) + [c.normal_offset]
            first_dir.append(len(tan_row))
            n_dir.append(c.n_tangential)
            for d in range(c.n_tangential):
                tan_row.append(row + d)
                dir_contact.append(ic)
                kt.append(c.tangential_stiffness[d])
            normal_row.append(row + nrow - 1)
            kn.append(c.normal_stiffness)
            mu.append(c.friction_coefficient)
            row += nrow
        A = np.vstack(A_rows) if A_rows else np.zeros((0, n))
        exc = self.excitation
        f0 = np.zeros(n) if exc.constant_force is None else np.asarray(exc.constant_force, float)
        fs = compile_signal(exc.force, n)
        ms = compile_signal(exc.motion, m)
        scale = _length_scale(f0, fs, ms, np.concatenate([np.array(kn, float), np.diag(s.stiffness)]))
        as_i = lambda v: np.asarray(v, dtype=np.int64)
        as_f = lambda v: np.ascontiguousarray(np.asarray(v, dtype=np.float64))
        return CompiledSystem(
            as_f(s.mass),
            as_f(s.damping),
            as_f(s.stiffness),
            as_f(A),
            as_f(A.T),
            as_f(np.vstack(B_rows) if B_rows else np.zeros((0, m))).reshape(row, m),
            as_f(g),
            as_i(normal_row),
            as_f(kn),
            as_f(mu),
            as_i(first_dir),
            as_i(n_dir),
            as_i(tan_row),
            as_i(dir_contact),
            as_f(kt),
            as_f(f0),
            as_f(fs.frequency),
            as_f(fs.sin_coefficient),
            as_f(fs.cos_coefficient),
            as_f(fs.table_time),
            as_f(fs.table_value),
            float(fs.ramp_time),
            as_f(ms.frequency),
            as_f(ms.sin_coefficient),
            as_f(ms.cos_coefficient),
            as_f(ms.table_time),
            as_f(ms.table_value),
            float(ms.ramp_time),
            scale,
            as_i([c.law_code for c in self.contacts]),
            _law_table(kn, mu),
        )


def _law_table(kn, mu) -> np.ndarray:
    """The law parameter table (nc, N_LAW_PAR), columns kernels.codes.P_*."""
    table = np.zeros((len(kn), N_LAW_PAR))
    table[:, P_KN] = kn
    table[:, P_MU] = mu
    return table


def _length_scale(f0, fs, ms, stiffnesses) -> float:
    """A displacement scale [m] for tolerances: the larger of the motion amplitude and the
    static deflection ``|f| / k`` the loads produce (k the largest contact normal or structural
    diagonal stiffness), never below 1 nm."""
    motion = max(
        np.abs(ms.sin_coefficient).sum(initial=0.0) + np.abs(ms.cos_coefficient).sum(initial=0.0),
        np.abs(ms.table_value).max(initial=0.0),
    )
    force = max(
        np.abs(f0).sum(),
        np.abs(fs.sin_coefficient).sum(initial=0.0) + np.abs(fs.cos_coefficient).sum(initial=0.0),
        np.abs(fs.table_value).max(initial=0.0),
    )
    k = stiffnesses.max(initial=0.0)
    return float(max(motion, force / k if k > 0 else 0.0, 1e-9))
