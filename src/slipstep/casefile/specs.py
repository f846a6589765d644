"""The case-file schema: the pydantic spec classes of ``[damper]`` and ``[structure]`` case files
and the parts an assembly case shares with them (``[[force]]``, ``[run]``, damper contacts).

Units are part of every key name and converted to SI where a spec becomes a model object
(slipstep.casefile.case, slipstep.casefile.assembly). Each field's ``description`` is what
the documentation's key tables print (docs/gen_pages.py).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np
from pydantic import Field, BaseModel, ConfigDict, PrivateAttr

from slipstep.model.damper import DamperContact

#: The one unit table of the case files: the unit a key name's suffix carries and its SI factor
#: (longest suffix first). The conversions below and the documentation's key tables read it.
UNITS: tuple[tuple[str, str, float], ...] = (
    ("_kg_per_m3", "kg/m^3", 1.0),
    ("_per_s", "1/s", 1.0),
    ("_mm2", "mm^2", 1e-6),
    ("_mm4", "mm^4", 1e-12),
    ("_GPa", "GPa", 1e9),
    ("_N_s_per_m", "N s/m", 1.0),
    ("_N_per_um", "N/um", 1e6),
    ("_N_per_m", "N/m", 1.0),
    ("_kg_m2", "kg m^2", 1.0),
    ("_kg", "kg", 1.0),
    ("_mm", "mm", 1e-3),
    ("_um", "um", 1e-6),
    ("_deg", "deg", math.pi / 180.0),
    ("_Hz", "Hz", 1.0),
    ("_N", "N", 1.0),
    ("_m", "m", 1.0),
    ("_s", "s", 1.0),
)


def unit_of_key(key: str) -> tuple[str, float] | None:
    """(unit, SI factor) a key name carries (``position_mm`` -> ("mm", 1e-3)), or None."""
    return next(((unit, factor) for suffix, unit, factor in UNITS if key.endswith(suffix)), None)


def si_factor(unit: str) -> float:
    """The SI factor of a unit of :data:`UNITS` (``"mm"`` -> 1e-3)."""
    return next(factor for _, name, factor in UNITS if name == unit)


UM = si_factor("um")
MM = si_factor("mm")
N_PER_UM = si_factor("N/um")
GPA = si_factor("GPa")


class _Strict(BaseModel):
    # strict: no silent coercion (``mass_kg = true`` or ``= "0.012"`` is an error, not 1.0 / 0.012)
    model_config = ConfigDict(extra="forbid", strict=True)


class PlatformSpec(_Strict):
    name: str = Field(
        description="platform name; its motion components are `<name>.x` and `<name>.y`",
        json_schema_extra={"unit": "-"},
    )
    angle_deg: float = Field(
        description="angle of the face from X: tangent (cos, sin); the normal points from the damper into the platform"
    )


class DamperContactSpec(_Strict):
    name: str = Field(
        description="contact point name (a `contact` coordinate of the result)", json_schema_extra={"unit": "-"}
    )
    platform: str = Field(description="name of the platform this point touches", json_schema_extra={"unit": "-"})
    position_mm: list[float] = Field(description="[a, b] of the point from the centre of mass")
    normal_stiffness_N_per_um: float = Field(description="normal contact stiffness k_n")
    tangential_stiffness_N_per_um: float = Field(description="tangential contact stiffness k_t")
    friction_coefficient: float = Field(description="friction coefficient mu >= 0", json_schema_extra={"unit": "1"})


class DamperSpec(_Strict):
    mass_kg: float = Field(description="damper mass")
    inertia_kg_m2: float = Field(description="moment of inertia about the centre of mass")
    centrifugal_force_N: float = Field(description="constant load on the centre of mass (ramped in the static preload)")
    centrifugal_angle_deg: float = Field(
        90.0, description="direction of the centrifugal load from X (90: +Y, radial outward)"
    )
    platforms: list[PlatformSpec] = Field(description="the platform faces the damper touches")
    contacts: list[DamperContactSpec] = Field(description="the contact points of the damper")


class StructureSpec(_Strict):
    dof_names: Optional[list[str]] = Field(
        None,
        description="DOF names (default x0, x1, ...); `[[force]]` components refer to them",
        json_schema_extra={"unit": "-"},
    )
    dof_units: Optional[list[str]] = Field(
        None, description='unit of each DOF: "m" or "rad" (default m)', json_schema_extra={"unit": "-"}
    )
    mass_kg: Optional[list[list[float]]] = Field(
        None,
        description="mass matrix M, symmetric positive definite",
        json_schema_extra={"unit": "kg (kg m^2 on rad DOFs)"},
    )
    damping_N_s_per_m: Optional[list[list[float]]] = Field(
        None,
        description="damping matrix C, symmetric positive semi-definite",
        json_schema_extra={"unit": "N s/m (SI per DOF unit)"},
    )
    stiffness_N_per_m: Optional[list[list[float]]] = Field(
        None,
        description="stiffness matrix K, symmetric positive semi-definite",
        json_schema_extra={"unit": "N/m (SI per DOF unit)"},
    )
    # the matrices from files (issue 10), paths relative to the case file: .npz (scipy.sparse.save_npz),
    # .mtx (Matrix Market) or .npy (dense); instead of the inline matrix of the same name
    mass_file_kg: Optional[str] = Field(
        None,
        description="M from a file instead of mass_kg, relative to the case file: .npz (scipy.sparse.save_npz, kept sparse), .mtx (Matrix Market) or .npy (dense); a sparse model runs on the banded backend",
        json_schema_extra={"unit": "kg"},
    )
    damping_file_N_s_per_m: Optional[str] = Field(
        None,
        description="C from a file instead of damping_N_s_per_m (as mass_file_kg)",
        json_schema_extra={"unit": "N s/m"},
    )
    stiffness_file_N_per_m: Optional[str] = Field(
        None,
        description="K from a file instead of stiffness_N_per_m (as mass_file_kg)",
        json_schema_extra={"unit": "N/m"},
    )
    constant_force_N: Optional[list[float]] = Field(
        None,
        description="constant load per DOF, ramped in the static preload",
        json_schema_extra={"unit": "N (N m on rad DOFs)"},
    )
    # matrices from FE codes (issue 26, item 4; slipstep.model.fe_files): an OP4, DMIG or ANSYS
    # .full file and the matrix names in it; format = "abaqus" reads the *_file_* keys as Abaqus
    file: Optional[str] = Field(
        None,
        description="an FE code's matrix file, relative to the case file: Nastran OP4 text (.op4), DMIG bulk data (.bdf, .dat, .nas, .blk) or ANSYS .full, see [Matrices from FE codes](../guide/fe_files.md)",
        json_schema_extra={"unit": "-"},
    )
    format: Optional[str] = Field(
        None,
        description='the format of `file`: "op4", "dmig", "ansys" (default: from the suffix); "abaqus" reads mass_file_kg, stiffness_file_N_per_m (and damping_file_N_s_per_m) as Abaqus matrix output',
        json_schema_extra={"unit": "-"},
    )
    mass_matrix: Optional[str] = Field(
        None,
        description="the name of M in `file` (default: the first of MAA, MGG, MHH, MAAX, ...)",
        json_schema_extra={"unit": "-"},
    )
    stiffness_matrix: Optional[str] = Field(
        None,
        description="the name of K in `file` (default: the first of KAA, KGG, KHH, KAAX, ...)",
        json_schema_extra={"unit": "-"},
    )
    damping_matrix: Optional[str] = Field(
        None,
        description="the name of C in `file` (default: BAA, BGG, ... if present, else none)",
        json_schema_extra={"unit": "-"},
    )


class ContactSpec(_Strict):
    name: str = Field(
        description="contact name (a `contact` coordinate of the result)", json_schema_extra={"unit": "-"}
    )
    dof_gather: Optional[list[list[float]]] = Field(
        None,
        description="A: rows u (tangential) then v (normal, > 0 = interference), one column per DOF; 2 rows = 2D contact, 3 rows = quasi-3D",
        json_schema_extra={"unit": "1"},
    )
    # the sparse form of dof_gather (issue 10): [row, DOF index, value] triples, dof_gather_rows rows
    dof_gather_entries: Optional[list[list[float]]] = Field(
        None,
        description="the sparse form of dof_gather: [row, DOF index (from 0), value] triples; for models with many DOFs",
        json_schema_extra={"unit": "1"},
    )
    dof_gather_rows: int = Field(
        2,
        description="rows of dof_gather_entries' matrix: 2 (2D, default) or 3 (quasi-3D)",
        json_schema_extra={"unit": "1"},
    )
    motion_gather: Optional[list[list[float]]] = Field(
        None, description="B: one column per `motion_names` entry, q = A x - B p + g", json_schema_extra={"unit": "1"}
    )
    normal_stiffness_N_per_m: float = Field(description="normal contact stiffness k_n")
    tangential_stiffness_N_per_m: float | list[float] = Field(
        description="tangential stiffness k_t, or [k_t1, k_t2] of a quasi-3D contact"
    )
    friction_coefficient: float = Field(description="friction coefficient mu >= 0", json_schema_extra={"unit": "1"})
    normal_offset_m: float = Field(0.0, description="g on v: initial interference (> 0) or gap (< 0)")
    law: Optional[str] = Field(
        None,
        description="the contact's friction law, see [Contact laws](#contact-laws) (default: the paper's law for its number of rows)",
        json_schema_extra={"unit": "-"},
    )
    # a contact face of an FE file (issue 26, item 4): one contact per node, "<name>.<node>"
    nodes: Optional[list[int]] = Field(
        None,
        description='node ids of a contact face of an FE file: one contact per node, named "<name>.<node>", instead of dof_gather',
        json_schema_extra={"unit": "-"},
    )
    normal: Optional[list[float]] = Field(
        None, description="the face's outward normal [nx, ny, nz] (with nodes)", json_schema_extra={"unit": "1"}
    )
    tangent: Optional[list[float]] = Field(
        None,
        description="the first tangential direction (made normal to `normal`; default: the axis least aligned with it)",
        json_schema_extra={"unit": "1"},
    )


class HarmonicSpec(_Strict):
    component: str = Field(
        description="what is driven: a prescribed motion component or a DOF", json_schema_extra={"unit": "-"}
    )
    frequency_Hz: float = Field(description="frequency f of amplitude sin(2 pi f t + phase)")
    amplitude: float = Field(description="amplitude")
    phase_deg: float = Field(0.0, description="phase")


class TableSpec(_Strict):
    component: str = Field(
        description="what is driven: a prescribed motion component or a DOF", json_schema_extra={"unit": "-"}
    )
    times_s: list[float] = Field(description="sample times, increasing; linear interpolation between them")
    values: list[float] = Field(description="one value per time")


class SaveSpec(_Strict):
    """``[run.save]``: what a march stores (slipstep.methods.save; times in seconds)."""

    dofs: Optional[str | list[str]] = Field(
        None,
        description='"all", "none", "response" (the DOFs the contacts see, the forced DOFs and `response`) or DOF names / shell patterns (`["blade*"]`)',
        json_schema_extra={"unit": "-"},
    )
    contacts: Optional[str | list[str]] = Field(
        None,
        description='"all", "none" or contact names: their q, f, sliders and states',
        json_schema_extra={"unit": "-"},
    )
    every: Optional[int] = Field(
        None,
        description="save every k-th step and the last one (default 1: every step)",
        json_schema_extra={"unit": "1"},
    )
    last_periods: Optional[float] = Field(
        None,
        description="save only the last P >= 1 excitation periods (from the step at or before)",
        json_schema_extra={"unit": "1"},
    )
    times_s: Optional[list[float]] = Field(
        None,
        description="save at these times instead (x by the cubic Hermite of x, v; v, a by the Newmark relations; contacts linear, states of the nearest step end)",
        json_schema_extra={"unit": "s"},
    )
    response: Optional[list[str]] = Field(
        None,
        description="DOF names / patterns added to the response DOFs (the large-model default)",
        json_schema_extra={"unit": "-"},
    )

    def options(self) -> dict:
        """The ``save`` run option (a dict of slipstep.Save keys) of this table."""
        out = {k: v for k, v in self.model_dump().items() if v is not None}
        if "times_s" in out:
            out["times"] = out.pop("times_s")
        return out


class RunSpec(_Strict):
    method: Optional[str] = Field(
        None,
        description="a method name or the paper's number (see Methods; default newmark)",
        json_schema_extra={"unit": "-"},
    )
    periods: Optional[float] = Field(
        None, description="excitation periods simulated after the preload (default 3)", json_schema_extra={"unit": "1"}
    )
    duration_s: Optional[float] = Field(None, description="simulated time instead of periods")
    step_ratio: Optional[float] = Field(
        None, description="r in dt = r T_min / pi of the dynamic methods (default 1)", json_schema_extra={"unit": "1"}
    )
    steps_per_period: Optional[int] = Field(
        None, description="steps per period of the quasi-static method (default 300)", json_schema_extra={"unit": "1"}
    )
    step_rule: Optional[str] = Field(
        None,
        description="what sets the step of a dynamic run: `accuracy` (the cap T / 50 refined by the error estimate; "
        "default of the piecewise-linear methods) or `t-min` (the paper's T_min rule; default of the others); "
        "command line `--step-rule`",
        json_schema_extra={"unit": "-"},
    )
    tolerance: Optional[float] = Field(
        None,
        description="Newton tolerance of the methods that iterate within a step (newmark, newmark-adaptive, "
        "full-newton): a step stops when its increment is below tolerance x length_scale and its residual below "
        "tolerance x its forces (default 1e-11; 0 < tolerance < 1); the piecewise-linear methods do not iterate and "
        "ignore it; command line `--tolerance`",
        json_schema_extra={"unit": "1"},
    )
    ramp_time_s: Optional[float] = Field(None, description="smooth start (1 - cos) / 2 of forces and motions")
    save: Optional[SaveSpec] = Field(
        None,
        description="`[run.save]`: what the march stores (default: everything up to 200 DOFs, above it the contacts and the response DOFs, every step); command line `--save-dofs`, `--save-contacts`, `--save-every`, `--save-last-periods`, `--save-times`",
        json_schema_extra={"unit": "-"},
    )


class CaseSpec(_Strict):
    name: str = Field(
        "case", description="case name, used in output file names and reports", json_schema_extra={"unit": "-"}
    )
    description: str = Field("", description="free text shown by `slipstep cases`", json_schema_extra={"unit": "-"})
    damper: Optional[DamperSpec] = Field(None, description="a rigid 2D underplatform damper (Kind 1)")
    structure: Optional[StructureSpec] = Field(None, description="a general linear structure (Kind 2)")
    contacts: Optional[list[ContactSpec]] = Field(None, description="contact elements of a `[structure]` case")
    motion_names: Optional[list[str]] = Field(
        None,
        description="names of the prescribed motion components p (the columns of `motion_gather`)",
        json_schema_extra={"unit": "-"},
    )
    motion: list[HarmonicSpec] = Field([], description="harmonic prescribed motions")
    force: list[HarmonicSpec] = Field([], description="harmonic forces on structure DOFs")
    motion_table: list[TableSpec] = Field([], description="tabulated prescribed motions")
    force_table: list[TableSpec] = Field([], description="tabulated forces on structure DOFs")
    period_s: Optional[float] = Field(
        None, description="excitation period when no harmonic sets it (tabulated excitation)"
    )
    run: RunSpec = Field(RunSpec(), description="default run options (command-line options and `ss.run` keywords win)")
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
