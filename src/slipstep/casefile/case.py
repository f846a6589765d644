"""TOML case files <-> model objects, validated with pydantic (unknown keys are errors).

Units are part of every key name (``mass_kg``, ``position_mm``, ``normal_stiffness_N_per_um``);
they are converted to SI here and nowhere else. Two kinds of case:

* ``[damper]``: a rigid 2D underplatform damper (slipstep.model.damper), geometry in mm,
  stiffness in N/um, platform angles in degrees, motions in um;
* ``[structure]`` + ``[[contacts]]``: any linear structure in SI with explicit gather maps.

Both take ``[[motion]]`` / ``[[force]]`` harmonics, ``[[motion_table]]`` / ``[[force_table]]``
time series, and a ``[run]`` table of default run options (see slipstep.methods.RunOptions).
"""

from __future__ import annotations

import math
import re
import zipfile
from collections import defaultdict
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from slipstep.casefile.files import CASES_DIR, builtin_cases, case_path, read_toml  # noqa: F401 (re-exported)
from slipstep.casefile.check import check_case, key_path, spec_error
from slipstep.casefile.specs import (  # noqa: F401 (re-exported: the schema of a case file)
    MM,
    N_PER_UM,
    UM,
    CaseSpec,
    ContactSpec,
    DamperContactSpec,
    DamperSpec,
    HarmonicSpec,
    PlatformSpec,
    RunSpec,
    SaveSpec,
    StructureSpec,
    TableSpec,
    damper_contact,
)
from slipstep.errors import InputError
from slipstep.model.contact import ContactElement
from slipstep.model.damper import Platform, rigid_damper
from slipstep.model.excitation import Excitation, Harmonic, Signal, Tabulated
from slipstep.model.fe_files import case_face_contacts, case_structure
from slipstep.model.structure import Structure
from slipstep.model.substructure import read_mtx
from slipstep.model.system import System


def parse_case(data: dict, source: str = "case") -> CaseSpec:
    """Validate the TOML data of a case: the schema (pydantic: keys, types), then the checks in
    the user's terms (slipstep.casefile.check: names, duplicates, ranges, shapes)."""
    try:
        spec = CaseSpec.model_validate(data)
    except ValidationError as exc:
        raise spec_error(exc.errors(), data, CaseSpec, source) from None
    check_case(data)
    spec._data = data
    return spec


def _signal(
    harmonics: list[HarmonicSpec],
    tables: list[TableSpec],
    components: tuple[str, ...],
    scale: float,
    kind: str,
    ramp: float,
) -> Signal | None:
    if not harmonics and not tables:
        return None
    index = {c: i for i, c in enumerate(components)}
    by_freq: dict[float, tuple[np.ndarray, np.ndarray]] = defaultdict(
        lambda: (np.zeros(len(components)), np.zeros(len(components)))
    )
    for h in harmonics:  # components and duplicates checked by config_check
        amp, ph = by_freq[h.frequency_Hz]
        amp[index[h.component]] = h.amplitude * scale
        ph[index[h.component]] = math.radians(h.phase_deg)
    tabs = []
    for tab in tables:
        vals = np.zeros((len(tab.times_s), len(components)))
        vals[:, index[tab.component]] = np.asarray(tab.values) * scale
        tabs.append(Tabulated(np.asarray(tab.times_s), vals))
    harms = tuple(Harmonic(f, amp, ph) for f, (amp, ph) in sorted(by_freq.items()))
    return Signal(components, harms, tuple(tabs), ramp)


# model field -> (key in the case file, pydantic-style location): errors raised by the model
# layer (slipstep.model) name SI fields; a case-file user reads the key they wrote
_MODEL_KEYS = {
    "damper": [
        (r"^damper\.mass$", ("damper", "mass_kg")),
        (r"^damper\.inertia$", ("damper", "inertia_kg_m2")),
        (r"^damper\.centrifugal_force$", ("damper", "centrifugal_force_N")),
        (r"^damper\.platforms\[(.*)\]\.angle$", ("damper", "platforms", "{platforms}", "angle_deg")),
        (r"^damper\.platforms$", ("damper", "platforms")),
        (r"^damper\.contacts\[(.*)\]\.position$", ("damper", "contacts", "{contacts}", "position_mm")),
        (r"^damper\.contacts\[(.*)\]\.platform$", ("damper", "contacts", "{contacts}", "platform")),
        (
            r"^contacts\[(.*)\]\.(normal|tangential)_stiffness$",
            ("damper", "contacts", "{contacts}", "{2}_stiffness_N_per_um"),
        ),
        (r"^contacts\[(.*)\]\.friction_coefficient$", ("damper", "contacts", "{contacts}", "friction_coefficient")),
        (r"^(contacts|damper\.contacts)$", ("damper", "contacts")),
        (r"^motion\.component$", ("motion",)),
    ],
    "structure": [
        (r"^structure\.mass$", ("structure", "mass_kg")),
        (r"^structure\.damping$", ("structure", "damping_N_s_per_m")),
        (r"^structure\.stiffness$", ("structure", "stiffness_N_per_m")),
        (r"^structure\.dof_(names|units)$", ("structure", "dof_{1}")),
        (r"^contacts\[(.*)\]\.(normal|tangential)_stiffness$", ("contacts", "{contacts}", "{2}_stiffness_N_per_m")),
        (r"^contacts\[(.*)\]\.normal_offset$", ("contacts", "{contacts}", "normal_offset_m")),
        (r"^contacts\[(.*)\]\.(\w+)$", ("contacts", "{contacts}", "{2}")),
        (r"^contacts$", ("contacts",)),
        (r"^excitation\.constant_force$", ("structure", "constant_force_N")),
        (r"^excitation\.motion\.components$", ("motion_names",)),
        (r"^excitation\.force\.components$", ("structure", "dof_names")),
    ],
    "any": [
        (r"^harmonic\.frequency$", ("motion",)),
        (r"^table\.times$", ("motion_table",)),
        (r"^ramp_time$", ("run", "ramp_time_s")),
    ],
}


def _case_key(field: str, kind: str, data: dict) -> str | None:
    """The case-file key path of a model field, or None if it has none."""
    for pattern, loc in _MODEL_KEYS.get(kind, []) + _MODEL_KEYS["any"]:
        match = re.search(pattern, field)
        if not match:
            continue
        path = []
        for seg in loc:
            if seg in ("{contacts}", "{platforms}"):
                table = path[-1]
                items = (data.get("damper", {}) if path[:1] == ["damper"] else data).get(table, [])
                names = [item.get("name") for item in items]
                seg = names.index(match.group(1)) if match.group(1) in names else 0
            elif isinstance(seg, str) and "{" in seg:
                seg = re.sub(r"\{(\d)\}", lambda m: match.group(int(m.group(1))), seg)  # noqa: B023 (called here)
            path.append(seg)
        return key_path(tuple(path), data)
    return None


def build_system(spec: CaseSpec) -> System:
    """Build the System a case describes (SI inside); errors name the TOML keys."""
    kind = "damper" if spec.damper is not None else "structure"
    data = getattr(spec, "_data", None) or spec.model_dump(exclude_unset=True)
    try:
        return _build_system(spec)
    except InputError as exc:
        field = _case_key(exc.field, kind, data)
        if field is None:
            raise
        raise InputError(field, exc.problem, exc.fix) from None


def _build_system(spec: CaseSpec) -> System:
    ramp = spec.run.ramp_time_s or 0.0
    if (spec.damper is None) == (spec.structure is None):
        raise InputError(
            "case",
            "must contain exactly one of [damper] or [structure]",
            "describe a rigid damper ([damper]) or a general structure ([structure] + [[contacts]])",
        )
    if spec.damper is not None:
        d = spec.damper
        if spec.contacts:
            raise InputError("contacts", "is for [structure] cases", "put damper contacts under [[damper.contacts]]")
        motion_names = tuple(f"{p.name}.{ax}" for p in d.platforms for ax in ("x", "y"))
        motion = _signal(spec.motion, spec.motion_table, motion_names, UM, "motion", ramp)
        if spec.force or spec.force_table:
            raise InputError(
                "force", "is not supported for [damper] cases", "drive the damper through platform motions"
            )
        return rigid_damper(
            mass=d.mass_kg,
            inertia=d.inertia_kg_m2,
            platforms=[Platform(p.name, math.radians(p.angle_deg)) for p in d.platforms],
            contacts=[damper_contact(c) for c in d.contacts],
            centrifugal_force=d.centrifugal_force_N,
            motion=motion,
            centrifugal_angle=math.radians(d.centrifugal_angle_deg),
            name=spec.name,
        )
    s = spec.structure
    base = Path(getattr(spec, "_base", "."))
    fe = case_structure(s, base)  # matrices from an FE code's file (slipstep.model.fe_files)
    if fe is not None:
        structure = Structure(
            fe.mass, fe.damping, fe.stiffness, fe.dofs or tuple(s.dof_names or ()), s.dof_units or fe.dof_units
        )
    else:
        mass = _structure_matrix(s, "mass_kg", "mass_file_kg", base, required=True)
        structure = Structure(
            mass,
            _structure_matrix(s, "damping_N_s_per_m", "damping_file_N_s_per_m", base),
            _structure_matrix(s, "stiffness_N_per_m", "stiffness_file_N_per_m", base),
            tuple(s.dof_names or ()),
            tuple(s.dof_units or ()),
        )
    motion_names = tuple(spec.motion_names or ())
    gathers = []  # (contact spec, name, gather map): a face of nodes gives one contact per node
    for i, c in enumerate(spec.contacts or ()):
        face = case_face_contacts(c, i, structure.dof_names)
        gathers += [(c, c.name, _contact_gather(c, i, structure.n_dofs))] if face is None else [(c, *f) for f in face]
    contacts = tuple(
        ContactElement(
            name=name,
            dof_gather=gather,
            motion_gather=None if c.motion_gather is None else np.asarray(c.motion_gather),
            tangential_stiffness=c.tangential_stiffness_N_per_m,
            normal_stiffness=c.normal_stiffness_N_per_m,
            friction_coefficient=c.friction_coefficient,
            normal_offset=c.normal_offset_m,
            law=c.law,
        )
        for c, name, gather in gathers
    )
    motion = _signal(spec.motion, spec.motion_table, motion_names, 1.0, "motion", ramp)
    for table in ("force", "force_table"):  # components of a matrix file's DOFs (not known to config_check)
        for i, item in enumerate(getattr(spec, table)):
            if item.component not in structure.dof_names:
                raise InputError(
                    f"[[{table}]] {i + 1}: component",
                    f"{item.component!r} is not a DOF of the structure ({structure.n_dofs} DOFs)",
                    f"use a DOF name: {', '.join(structure.dof_names[:3])}, ... (structure.dof_names, default x0, x1, ...)",
                )
    force = _signal(spec.force, spec.force_table, structure.dof_names, 1.0, "force", ramp)
    exc = Excitation(constant_force=s.constant_force_N, force=force, motion=motion, period=spec.period_s)
    return System(structure, contacts, exc, motion_names=motion_names, name=spec.name)


MATRIX_FILE_TYPES = (".npz", ".mtx", ".npy")


def _structure_matrix(s: StructureSpec, inline: str, file_key: str, base: Path, required: bool = False):
    """A structure matrix from its inline key or its file key (exactly one; the mass required)."""
    value, path = getattr(s, inline), getattr(s, file_key)
    if value is not None and path is not None:
        raise InputError(
            f"[structure] {file_key}", f"and {inline} are both given", f"give the matrix once: {inline} or {file_key}"
        )
    if path is not None:
        return read_matrix_file(f"[structure] {file_key}", base / path)
    if value is None:
        if required:
            raise InputError(
                "[structure] mass_kg",
                "is missing",
                "give mass_kg (a list of rows) or mass_file_kg (an .npz, .mtx or .npy file)",
            )
        return None
    return np.asarray(value)


def read_matrix_file(key: str, path: Path):
    """A matrix file: .npz of scipy.sparse.save_npz (kept sparse), .mtx Matrix Market (sparse
    when stored as coordinates), .npy a dense array. Errors name ``key`` and the fix."""
    import scipy.sparse as sp

    suffix = path.suffix.lower()
    if suffix not in MATRIX_FILE_TYPES:
        raise InputError(
            key,
            f"is {str(path)!r}, not a matrix file type slipstep reads",
            "give an .npz (scipy.sparse.save_npz), .mtx (scipy.io.mmwrite) or .npy (numpy.save) file",
        )
    if not path.is_file():
        raise InputError(key, f"file {str(path)!r} not found", "give a path relative to the case file")
    if suffix == ".mtx":  # pattern and complex files refused there
        return read_mtx(path, key)
    try:
        if suffix == ".npz":
            A = sp.load_npz(path)
        else:
            A = np.load(path, allow_pickle=False)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile) as exc:
        raise InputError(
            key,
            f"{str(path)!r} cannot be read as {suffix} ({' '.join(str(exc).split())[:100]})",
            f"write it with {_WRITERS[suffix]}",
        ) from None
    if not isinstance(A, np.ndarray) and not sp.issparse(A):
        raise InputError(key, f"{str(path)!r} holds no matrix", f"write one matrix with {_WRITERS[suffix]}")
    if A.dtype.kind not in "fiub":
        kind = {"c": "complex", "U": "text", "S": "text", "O": "object"}.get(A.dtype.kind, str(A.dtype))
        raise InputError(key, f"{str(path)!r} holds {kind} values", "save a real matrix (float64)")
    if A.ndim != 2:
        raise InputError(key, f"{str(path)!r} holds a {A.ndim}-d array", "save a square 2-d matrix")
    return A.tocsr() if sp.issparse(A) else A


_WRITERS = {".npz": "scipy.sparse.save_npz", ".mtx": "scipy.io.mmwrite", ".npy": "numpy.save"}


def _contact_gather(c: "ContactSpec", i: int, n: int):
    """A contact's gather map A: dof_gather (rows of n numbers) or dof_gather_entries
    ([row, DOF index, value] triples of a sparse A with dof_gather_rows rows)."""
    import scipy.sparse as sp

    where = f"[[contacts]] {i + 1} ({c.name})"
    if (c.dof_gather is None) == (c.dof_gather_entries is None):
        raise InputError(
            f"{where}: dof_gather",
            "and dof_gather_entries are both given" if c.dof_gather is not None else "is missing",
            "give dof_gather (rows of one number per DOF) or dof_gather_entries ([row, DOF index, value] triples)",
        )
    if c.dof_gather is not None:
        return np.asarray(c.dof_gather)
    key = f"{where}: dof_gather_entries"
    rows = c.dof_gather_rows
    entries = c.dof_gather_entries
    if isinstance(rows, bool) or not isinstance(rows, int) or rows not in (2, 3):
        raise InputError(
            f"{where}: dof_gather_rows",
            f"is {rows!r}",
            "give 2 (a 2D contact: tangential, normal) or 3 (quasi-3D / 3D: two tangential, normal)",
        )
    if any(len(e) != 3 for e in entries):
        raise InputError(
            key, "has an entry that is not [row, DOF index, value]", "give triples [row, DOF index, value]"
        )
    r = np.array([e[0] for e in entries], dtype=float)
    j = np.array([e[1] for e in entries], dtype=float)
    for name, idx, bound in (("row", r, rows), ("DOF index", j, n)):
        bad = (idx != np.round(idx)) | (idx < 0) | (idx >= bound)
        if bad.any():
            raise InputError(
                key,
                f"has {name} {idx[bad][0]:g}, not a whole number in 0..{bound - 1}",
                f"give {name}s from 0 to {bound - 1}" + (" (or set dof_gather_rows)" if name == "row" else ""),
            )
    pairs = list(zip(r.astype(int).tolist(), j.astype(int).tolist()))
    if len(set(pairs)) != len(pairs):
        twice = next(p for p in pairs if pairs.count(p) > 1)
        raise InputError(
            key,
            f"gives row {twice[0]}, DOF index {twice[1]} more than once (the values would be summed)",
            "give each [row, DOF index] once, with the total value",
        )
    vals = np.array([e[2] for e in entries], dtype=float)
    return sp.csr_matrix((vals, (r.astype(int), j.astype(int))), shape=(rows, n))


def load_case(name_or_path: str | Path) -> tuple[System, RunSpec]:
    """A built-in case by name (``paper``) or a TOML file: (System, default run options)."""
    if not str(name_or_path).strip():
        raise InputError(
            "case", "is empty", f"give a TOML file path or a built-in case name ({', '.join(builtin_cases())})"
        )
    path = case_path(name_or_path)
    data = read_toml(path)
    if "substructures" in data:  # the third kind: an assembly (slipstep.casefile.assembly)
        from slipstep.casefile.assembly import load_assembly_case

        return load_assembly_case(data, path)
    spec = parse_case(data, source=str(path))
    spec._base = str(Path(path).parent)
    return build_system(spec), spec.run


def load_system(name_or_path: str | Path) -> System:
    return load_case(name_or_path)[0]
