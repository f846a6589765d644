"""The case-file schema: the pydantic spec classes of ``[damper]`` and ``[structure]`` case files
and the parts an assembly case shares with them (``[[force]]``, ``[run]``, damper contacts).

Units are part of every key name and converted to SI where a spec becomes a model object
(slipstep.casefile.case, slipstep.casefile.assembly). Each field's ``description`` is what
the documentation's key tables print (docs/gen_pages.py).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from pydantic import BaseModel, ConfigDict, PrivateAttr

from slipstep.model.damper import DamperContact

UM = 1e-6
MM = 1e-3
N_PER_UM = 1e6


class _Strict(BaseModel):
    # strict: no silent coercion (``mass_kg = true`` or ``= "0.012"`` is an error, not 1.0 / 0.012)
    model_config = ConfigDict(extra="forbid", strict=True)


class PlatformSpec(_Strict):
    name: str
    angle_deg: float


class DamperContactSpec(_Strict):
    name: str
    platform: str
    position_mm: list[float]
    normal_stiffness_N_per_um: float
    tangential_stiffness_N_per_um: float
    friction_coefficient: float


class DamperSpec(_Strict):
    mass_kg: float
    inertia_kg_m2: float
    centrifugal_force_N: float
    centrifugal_angle_deg: float = 90.0
    platforms: list[PlatformSpec]
    contacts: list[DamperContactSpec]


class StructureSpec(_Strict):
    dof_names: Optional[list[str]] = None
    dof_units: Optional[list[str]] = None
    mass_kg: Optional[list[list[float]]] = None
    damping_N_s_per_m: Optional[list[list[float]]] = None
    stiffness_N_per_m: Optional[list[list[float]]] = None
    # the matrices from files (issue 10), paths relative to the case file: .npz (scipy.sparse.save_npz),
    # .mtx (Matrix Market) or .npy (dense); instead of the inline matrix of the same name
    mass_file_kg: Optional[str] = None
    damping_file_N_s_per_m: Optional[str] = None
    stiffness_file_N_per_m: Optional[str] = None
    constant_force_N: Optional[list[float]] = None
    # matrices from FE codes (issue 26, item 4; slipstep.model.fe_files): an OP4, DMIG or ANSYS
    # .full file and the matrix names in it; format = "abaqus" reads the *_file_* keys as Abaqus
    file: Optional[str] = None
    format: Optional[str] = None
    mass_matrix: Optional[str] = None
    stiffness_matrix: Optional[str] = None
    damping_matrix: Optional[str] = None


class ContactSpec(_Strict):
    name: str
    dof_gather: Optional[list[list[float]]] = None
    # the sparse form of dof_gather (issue 10): [row, DOF index, value] triples, dof_gather_rows rows
    dof_gather_entries: Optional[list[list[float]]] = None
    dof_gather_rows: int = 2
    motion_gather: Optional[list[list[float]]] = None
    normal_stiffness_N_per_m: float
    tangential_stiffness_N_per_m: float | list[float]
    friction_coefficient: float
    normal_offset_m: float = 0.0
    law: Optional[str] = None
    # a contact face of an FE file (issue 26, item 4): one contact per node, "<name>.<node>"
    nodes: Optional[list[int]] = None
    normal: Optional[list[float]] = None
    tangent: Optional[list[float]] = None


class HarmonicSpec(_Strict):
    component: str
    frequency_Hz: float
    amplitude: float
    phase_deg: float = 0.0


class TableSpec(_Strict):
    component: str
    times_s: list[float]
    values: list[float]


class SaveSpec(_Strict):
    """``[run.save]``: what a march stores (slipstep.methods.save; times in seconds)."""

    dofs: Optional[str | list[str]] = None
    contacts: Optional[str | list[str]] = None
    every: Optional[int] = None
    last_periods: Optional[float] = None
    times_s: Optional[list[float]] = None
    response: Optional[list[str]] = None

    def options(self) -> dict:
        """The ``save`` run option (a dict of slipstep.Save keys) of this table."""
        out = {k: v for k, v in self.model_dump().items() if v is not None}
        if "times_s" in out:
            out["times"] = out.pop("times_s")
        return out


class RunSpec(_Strict):
    method: Optional[str] = None
    periods: Optional[float] = None
    duration_s: Optional[float] = None
    step_ratio: Optional[float] = None
    steps_per_period: Optional[int] = None
    ramp_time_s: Optional[float] = None
    save: Optional[SaveSpec] = None


class CaseSpec(_Strict):
    name: str = "case"
    description: str = ""
    damper: Optional[DamperSpec] = None
    structure: Optional[StructureSpec] = None
    contacts: Optional[list[ContactSpec]] = None
    motion_names: Optional[list[str]] = None
    motion: list[HarmonicSpec] = []
    force: list[HarmonicSpec] = []
    motion_table: list[TableSpec] = []
    force_table: list[TableSpec] = []
    period_s: Optional[float] = None
    run: RunSpec = RunSpec()
    _data: dict = PrivateAttr(default_factory=dict)  # the TOML data, for messages naming its keys
    _base: str = PrivateAttr(default=".")  # the case file's directory (matrix files are relative to it)


def damper_contact(c: "DamperContactSpec") -> DamperContact:
    """A ``[[damper.contacts]]`` entry in SI: position mm -> m, stiffnesses N/um -> N/m."""
    return DamperContact(
        c.name,
        c.platform,
        tuple(np.asarray(c.position_mm) * MM),
        c.normal_stiffness_N_per_um * N_PER_UM,
        c.tangential_stiffness_N_per_um * N_PER_UM,
        c.friction_coefficient,
    )


def _loc(err) -> str:
    """A pydantic error location as a dotted path (slipstep.casefile.assembly names its fields so)."""
    return ".".join(str(p) for p in err["loc"]) or "case"
