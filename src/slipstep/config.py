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
import sys
from collections import defaultdict
from pathlib import Path
from typing import Optional

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from slipstep.errors import InputError
from slipstep.model.contact import ContactElement
from slipstep.model.damper import DamperContact, Platform, rigid_damper
from slipstep.model.excitation import Excitation, Harmonic, Signal, Tabulated
from slipstep.model.structure import Structure
from slipstep.system import System

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

UM = 1e-6
MM = 1e-3
N_PER_UM = 1e6
CASES_DIR = Path(__file__).parent / "cases"


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
    mass_kg: list[list[float]]
    damping_N_s_per_m: Optional[list[list[float]]] = None
    stiffness_N_per_m: Optional[list[list[float]]] = None
    constant_force_N: Optional[list[float]] = None


class ContactSpec(_Strict):
    name: str
    dof_gather: list[list[float]]
    motion_gather: Optional[list[list[float]]] = None
    normal_stiffness_N_per_m: float
    tangential_stiffness_N_per_m: float | list[float]
    friction_coefficient: float
    normal_offset_m: float = 0.0
    law: Optional[str] = None


class HarmonicSpec(_Strict):
    component: str
    frequency_Hz: float
    amplitude: float
    phase_deg: float = 0.0


class TableSpec(_Strict):
    component: str
    times_s: list[float]
    values: list[float]


class RunSpec(_Strict):
    method: Optional[str] = None
    periods: Optional[float] = None
    duration_s: Optional[float] = None
    step_ratio: Optional[float] = None
    steps_per_period: Optional[int] = None
    ramp_time_s: Optional[float] = None


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


def _loc(err) -> str:
    return ".".join(str(p) for p in err["loc"]) or "case"


def parse_case(data: dict, source: str = "case") -> CaseSpec:
    try:
        return CaseSpec.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        field = _loc(first)
        if first["type"] == "extra_forbidden":
            raise InputError(field, f"is not a known key in {source}",
                             "check the spelling against the case format in the README (units are part of key names)") from None
        if first["type"] == "missing":
            raise InputError(field, f"is required in {source} but missing", "add it") from None
        raise InputError(field, f"{first['msg']} (got {first.get('input')!r})", "give a value of the right type") from None


def _signal(harmonics: list[HarmonicSpec], tables: list[TableSpec], components: tuple[str, ...],
            scale: float, kind: str, ramp: float) -> Signal | None:
    if not harmonics and not tables:
        return None
    index = {c: i for i, c in enumerate(components)}
    by_freq: dict[float, tuple[np.ndarray, np.ndarray]] = defaultdict(
        lambda: (np.zeros(len(components)), np.zeros(len(components))))
    for h in harmonics:
        if h.component not in index:
            raise InputError(f"{kind}.component", f"{h.component!r} is not a known component",
                             f"use one of {list(components)}")
        amp, ph = by_freq[h.frequency_Hz]
        amp[index[h.component]] = h.amplitude * scale
        ph[index[h.component]] = math.radians(h.phase_deg)
    tabs = []
    for tab in tables:
        if tab.component not in index:
            raise InputError(f"{kind}_table.component", f"{tab.component!r} is not a known component",
                             f"use one of {list(components)}")
        vals = np.zeros((len(tab.times_s), len(components)))
        if len(tab.values) != len(tab.times_s):
            raise InputError(f"{kind}_table.values", f"has {len(tab.values)} values for {len(tab.times_s)} times",
                             "give one value per time")
        vals[:, index[tab.component]] = np.asarray(tab.values) * scale
        tabs.append(Tabulated(np.asarray(tab.times_s), vals))
    harms = tuple(Harmonic(f, amp, ph) for f, (amp, ph) in sorted(by_freq.items()))
    return Signal(components, harms, tuple(tabs), ramp)


# model field -> TOML key, so that a case-file user reads the key they wrote
_TOML_KEYS = {
    "damper": [
        (r"^damper\.mass\b", "damper.mass_kg"), (r"^damper\.inertia\b", "damper.inertia_kg_m2"),
        (r"^damper\.centrifugal_force\b", "damper.centrifugal_force_N"),
        (r"^damper\.platforms\[(.*)\]\.angle$", r"damper.platforms[\1].angle_deg"),
        (r"^damper\.contacts\[(.*)\]\.position$", r"damper.contacts[\1].position_mm"),
        (r"^contacts\[(.*)\]\.(normal|tangential)_stiffness$", r"damper.contacts[\1].\2_stiffness_N_per_um"),
        (r"^contacts\[(.*)\]\.friction_coefficient$", r"damper.contacts[\1].friction_coefficient"),
    ],
    "structure": [
        (r"^structure\.mass$", "structure.mass_kg"), (r"^structure\.damping$", "structure.damping_N_s_per_m"),
        (r"^structure\.stiffness$", "structure.stiffness_N_per_m"),
        (r"^contacts\[(.*)\]\.(normal|tangential)_stiffness$", r"contacts[\1].\2_stiffness_N_per_m"),
        (r"^contacts\[(.*)\]\.normal_offset$", r"contacts[\1].normal_offset_m"),
        (r"^excitation\.constant_force$", "structure.constant_force_N"),
    ],
    "any": [(r"^harmonic\.frequency$", "motion/force.frequency_Hz"), (r"^table\.times$", "motion_table/force_table.times_s"),
            (r"^ramp_time$", "run.ramp_time_s")],
}


def build_system(spec: CaseSpec) -> System:
    """Build the System a case describes (SI inside); errors name the TOML keys."""
    kind = "damper" if spec.damper is not None else "structure"
    try:
        return _build_system(spec)
    except InputError as exc:
        field = exc.field
        for pattern, key in _TOML_KEYS.get(kind, []) + _TOML_KEYS["any"]:
            if re.search(pattern, field):
                field = re.sub(pattern, key, field)
                break
        if field == exc.field:
            raise
        raise InputError(field, exc.problem, exc.fix) from None


def _build_system(spec: CaseSpec) -> System:
    ramp = spec.run.ramp_time_s or 0.0
    if (spec.damper is None) == (spec.structure is None):
        raise InputError("case", "must contain exactly one of [damper] or [structure]",
                         "describe a rigid damper ([damper]) or a general structure ([structure] + [[contacts]])")
    if spec.damper is not None:
        d = spec.damper
        if spec.contacts:
            raise InputError("contacts", "is for [structure] cases", "put damper contacts under [[damper.contacts]]")
        motion_names = tuple(f"{p.name}.{ax}" for p in d.platforms for ax in ("x", "y"))
        motion = _signal(spec.motion, spec.motion_table, motion_names, UM, "motion", ramp)
        if spec.force or spec.force_table:
            raise InputError("force", "is not supported for [damper] cases", "drive the damper through platform motions")
        return rigid_damper(
            mass=d.mass_kg, inertia=d.inertia_kg_m2,
            platforms=[Platform(p.name, math.radians(p.angle_deg)) for p in d.platforms],
            contacts=[DamperContact(c.name, c.platform, tuple(np.asarray(c.position_mm) * MM),
                                    c.normal_stiffness_N_per_um * N_PER_UM, c.tangential_stiffness_N_per_um * N_PER_UM,
                                    c.friction_coefficient) for c in d.contacts],
            centrifugal_force=d.centrifugal_force_N, motion=motion,
            centrifugal_angle=math.radians(d.centrifugal_angle_deg), name=spec.name)
    s = spec.structure
    structure = Structure(np.asarray(s.mass_kg), None if s.damping_N_s_per_m is None else np.asarray(s.damping_N_s_per_m),
                          None if s.stiffness_N_per_m is None else np.asarray(s.stiffness_N_per_m),
                          tuple(s.dof_names or ()), tuple(s.dof_units or ()))
    motion_names = tuple(spec.motion_names or ())
    contacts = tuple(ContactElement(
        name=c.name, dof_gather=np.asarray(c.dof_gather),
        motion_gather=None if c.motion_gather is None else np.asarray(c.motion_gather),
        tangential_stiffness=c.tangential_stiffness_N_per_m, normal_stiffness=c.normal_stiffness_N_per_m,
        friction_coefficient=c.friction_coefficient, normal_offset=c.normal_offset_m,
        law=c.law) for c in spec.contacts or ())
    motion = _signal(spec.motion, spec.motion_table, motion_names, 1.0, "motion", ramp)
    force = _signal(spec.force, spec.force_table, structure.dof_names, 1.0, "force", ramp)
    exc = Excitation(constant_force=s.constant_force_N, force=force, motion=motion, period=spec.period_s)
    return System(structure, contacts, exc, motion_names=motion_names, name=spec.name)


def read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("case", f"file {str(path)!r} not found",
                         f"give a TOML file path or a built-in case name ({', '.join(builtin_cases())})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError("case", f"{path} is not valid TOML ({exc})", "fix the TOML syntax") from None
    except UnicodeDecodeError:
        raise InputError("case", f"{path} is not UTF-8 text", "give a TOML text file (UTF-8)") from None
    except OSError as exc:  # a directory, no permission, ...
        raise InputError("case", f"{str(path)!r} cannot be read ({exc.strerror})",
                         "give a readable TOML file or a built-in case name") from None


def builtin_cases() -> list[str]:
    return sorted(p.stem for p in CASES_DIR.glob("*.toml"))


def load_case(name_or_path: str | Path) -> tuple[System, RunSpec]:
    """A built-in case by name (``paper``) or a TOML file: (System, default run options)."""
    path = Path(name_or_path)
    if not path.suffix and str(name_or_path) in builtin_cases():
        path = CASES_DIR / f"{name_or_path}.toml"
    spec = parse_case(read_toml(path), source=str(path))
    return build_system(spec), spec.run


def load_system(name_or_path: str | Path) -> System:
    return load_case(name_or_path)[0]
