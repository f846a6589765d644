"""TOML assembly cases: ``[[substructures]]`` joined by ``[[dampers]]`` and ``[[contacts]]``.

The third kind of case file (beside ``[damper]`` and ``[structure]``, see slipstep.casefile.case):
substructures (a built-in frame blade, or M/K matrices from .npz / Matrix Market files,
optionally Craig-Bampton reduced), rigid dampers whose platforms follow substructure points,
contacts on named assembled DOFs, harmonic and engine-order forces, and an optional
``[chain]`` that copies one blade and one damper into a chain or a closed ring. Units are
part of every key name and converted to SI here only (mm, mm^2, mm^4, GPa, N/um, deg);
matrix files are in SI. Errors name the TOML key (``substructures[blade].length_mm``).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, ValidationError

from slipstep.casefile.specs import (
    GPA,
    MM,
    DamperContactSpec,
    HarmonicSpec,
    RunSpec,
    _loc,
    _Strict,
    damper_contact,
)
from slipstep.errors import InputError
from slipstep.model.assembly import (
    DamperLink,
    HarmonicForce,
    LinkContact,
    PlatformLink,
    assemble,
    engine_order_forces,
)
from slipstep.model.substructure import (
    Point,
    Substructure,
    craig_bampton,
    frame_blade,
    load_mtx,
    load_npz,
)
from slipstep.model.system import System


class PointSpec(_Strict):
    name: str = Field(description="point name (the `point` a damper platform follows)", json_schema_extra={"unit": "-"})
    x: str | None = Field(
        None, description="the DOF carrying the point's x displacement", json_schema_extra={"unit": "-"}
    )
    y: str | None = Field(
        None, description="the DOF carrying the point's y displacement", json_schema_extra={"unit": "-"}
    )
    rz: str | None = Field(None, description="the DOF carrying the point's rotation", json_schema_extra={"unit": "-"})
    position_mm: list[float] = Field([0.0, 0.0], description="position of the point")


class ReductionSpec(_Strict):
    boundary_dofs: list[str] = Field(
        description="DOFs kept as boundary DOFs (a point keeps only its components on the boundary)",
        json_schema_extra={"unit": "-"},
    )
    modes: int = Field(
        description="fixed-interface modes kept (DOFs mode1..modeN, in m)", json_schema_extra={"unit": "1"}
    )


class SubstructureSpec(_Strict):
    name: str = Field(
        description="substructure name, the prefix of its DOF names (`blade1.8.x`)", json_schema_extra={"unit": "-"}
    )
    kind: Literal["frame_blade", "matrices"] = Field(
        "frame_blade",
        description="`frame_blade`: a 2D cantilever Euler-Bernoulli frame (axial and bending, DOFs `<node>.x`, `.y`, `.rz`); `matrices`: M, K (and C) imported from files, SI",
        json_schema_extra={"unit": "-"},
    )
    copy_of: str | None = Field(
        None, description="a renamed copy of an earlier substructure", json_schema_extra={"unit": "-"}
    )
    # frame_blade
    length_mm: float | None = Field(None, description="frame blade: length")
    elements: int | None = Field(None, description="frame blade: number of elements", json_schema_extra={"unit": "1"})
    youngs_modulus_GPa: float | None = Field(None, description="frame blade: Young's modulus")
    density_kg_per_m3: float | None = Field(None, description="frame blade: density")
    area_mm2: float | None = Field(None, description="frame blade: cross-section area")
    second_moment_mm4: float | None = Field(None, description="frame blade: second moment of area of the cross-section")
    platform_node: int | None = Field(
        None,
        description="frame blade: node of the point `platform` (default: the tip; the point `tip` is the last node)",
        json_schema_extra={"unit": "1"},
    )
    platform_mass_kg: float = Field(0.0, description="frame blade: lumped mass at the platform node")
    tip_mass_kg: float = Field(0.0, description="frame blade: lumped mass at the tip")
    root_mm: list[float] = Field([0.0, 0.0], description="frame blade: position of the root")
    angle_deg: float = Field(90.0, description="frame blade: direction of the blade axis from X")
    # matrices (SI)
    file: str | None = Field(
        None,
        description="matrices: a .npz file with M, K (and C, dof_names, dof_units), dense or CSR, SI",
        json_schema_extra={"unit": "-"},
    )
    mass_file: str | None = Field(
        None, description="matrices: M as a Matrix Market (.mtx) file, SI", json_schema_extra={"unit": "-"}
    )
    stiffness_file: str | None = Field(
        None, description="matrices: K as a Matrix Market (.mtx) file, SI", json_schema_extra={"unit": "-"}
    )
    damping_file: str | None = Field(
        None, description="matrices: C as a Matrix Market (.mtx) file, SI", json_schema_extra={"unit": "-"}
    )
    dofs_file: str | None = Field(
        None, description='matrices: the DOFs, one "name unit" a line', json_schema_extra={"unit": "-"}
    )
    dof_names: list[str] | None = Field(
        None, description="matrices: DOF names, when the files do not give them", json_schema_extra={"unit": "-"}
    )
    dof_units: list[str] | None = Field(
        None,
        description="matrices: DOF units (m or rad), when the files do not give them",
        json_schema_extra={"unit": "-"},
    )
    points: list[PointSpec] = Field([], description="named points for damper platforms")
    # damping
    modal_damping_ratio: float | None = Field(
        None, description="damping ratio of every mode", json_schema_extra={"unit": "1"}
    )
    rayleigh_alpha_per_s: float | None = Field(None, description="alpha of Rayleigh damping C = alpha M + beta K")
    rayleigh_beta_s: float | None = Field(None, description="beta of Rayleigh damping C = alpha M + beta K")
    reduction: ReductionSpec | None = Field(None, description="optional Craig-Bampton reduction")
    # mistuning: the stiffness times 1 + mistuning (a blade of an assembly without [chain])
    mistuning: float | None = Field(
        None,
        description="mistuning of a blade without [chain]: its stiffness times 1 + delta, delta > -1 (default: tuned)",
        json_schema_extra={"unit": "1"},
    )


class PlatformLinkSpec(_Strict):
    name: str = Field(description="platform name", json_schema_extra={"unit": "-"})
    angle_deg: float = Field(description="angle of the face from X: tangent (cos, sin)")
    substructure: str | None = Field(
        None,
        description="the substructure the platform moves with (set by `[chain]` for chained dampers)",
        json_schema_extra={"unit": "-"},
    )
    point: str = Field("platform", description="the point of that substructure", json_schema_extra={"unit": "-"})
    offset_mm: list[float] = Field(
        [0.0, 0.0], description="from the point to the damper's centre of mass (lever arm of the point's rotation)"
    )


class DamperLinkSpec(_Strict):
    name: str = Field(description="damper name, the prefix of its DOF names", json_schema_extra={"unit": "-"})
    mass_kg: float = Field(description="damper mass")
    inertia_kg_m2: float = Field(description="moment of inertia about the centre of mass")
    centrifugal_force_N: float = Field(description="constant load on the centre of mass (ramped in the static preload)")
    centrifugal_angle_deg: float = Field(90.0, description="direction of the centrifugal load from X (90: +Y)")
    platforms: list[PlatformLinkSpec] = Field(description="the platform faces, each following a substructure point")
    contacts: list[DamperContactSpec] = Field(
        description="the contact points (the `[[damper.contacts]]` keys of kind 1)"
    )


class LinkContactSpec(_Strict):
    name: str = Field(
        description="contact name (a `contact` coordinate of the result)", json_schema_extra={"unit": "-"}
    )
    dofs: list[str] = Field(
        description="assembled DOF names, one per column of `dof_gather`", json_schema_extra={"unit": "-"}
    )
    dof_gather: list[list[float]] = Field(
        description="rows u (tangential) then v (normal), one column per name in `dofs`",
        json_schema_extra={"unit": "1"},
    )
    normal_stiffness_N_per_m: float = Field(description="normal contact stiffness k_n")
    tangential_stiffness_N_per_m: float | list[float] = Field(
        description="tangential stiffness k_t, or [k_t1, k_t2] (quasi-3D)"
    )
    friction_coefficient: float = Field(description="friction coefficient mu >= 0", json_schema_extra={"unit": "1"})
    normal_offset_m: float = Field(0.0, description="g on v: initial interference (> 0) or gap (< 0)")


class EngineOrderSpec(_Strict):
    dof: str = Field(
        description="the DOF of each blade, without the blade's name (e.g. `8.x`)", json_schema_extra={"unit": "-"}
    )
    amplitude_N: float = Field(description="force amplitude on each blade")
    frequency_Hz: float = Field(description="excitation frequency")
    engine_order: int = Field(
        description="engine order EO: blade j (0-based) lags by 2 pi EO j / N", json_schema_extra={"unit": "1"}
    )
    phase_deg: float = Field(0.0, description="phase of blade 0")
    blades: list[str] | None = Field(
        None, description="the blades (default: the `[chain]`'s blades)", json_schema_extra={"unit": "-"}
    )


class ChainSpec(_Strict):
    blade: str = Field(
        description="the substructure copied into `<blade>1` .. `<blade>N`", json_schema_extra={"unit": "-"}
    )
    damper: str = Field(
        description="the damper copied between each neighbouring pair of blades", json_schema_extra={"unit": "-"}
    )
    blades: int = Field(description="number of blades N", json_schema_extra={"unit": "1"})
    closed: bool = Field(
        False, description="true: also a damper between blade N and blade 1 (a ring)", json_schema_extra={"unit": "-"}
    )
    # blade j's stiffness scaled by 1 + mistuning[j] (blade-to-blade scatter: every modal
    # frequency of blade j times sqrt(1 + delta_j)); None: a tuned chain
    mistuning: list[float] | None = Field(
        None,
        description="blade-to-blade scatter: blade j's stiffness times 1 + delta_j, one delta > -1 per blade (default: tuned)",
        json_schema_extra={"unit": "1"},
    )


class AssemblyCaseSpec(_Strict):
    name: str = Field(
        "assembly", description="case name, used in output file names and reports", json_schema_extra={"unit": "-"}
    )
    description: str = Field("", description="free text shown by `slipstep cases`", json_schema_extra={"unit": "-"})
    substructures: list[SubstructureSpec] = Field(description="the substructures (blades, imported models)")
    dampers: list[DamperLinkSpec] = Field([], description="rigid dampers whose platforms follow substructure points")
    contacts: list[LinkContactSpec] = Field([], description="contacts on named assembled DOFs")
    chain: ChainSpec | None = Field(None, description="copy one blade and one damper into a chain or a closed ring")
    force: list[HarmonicSpec] = Field([], description="harmonic forces on assembled DOFs")
    engine_order_force: list[EngineOrderSpec] = Field(
        [], description="one harmonic force per blade with an engine-order phase lag"
    )
    constant_force_N: dict[str, float] = Field(
        {},
        description='constant loads by assembled DOF name, e.g. `{"blade1.8.x" = 1.0}`',
        json_schema_extra={"unit": "N"},
    )
    period_s: float | None = Field(None, description="excitation period when no harmonic sets it")
    run: RunSpec = Field(RunSpec(), description="default run options")


def parse_assembly(data: dict, source: str = "case") -> AssemblyCaseSpec:
    """Validate the TOML table (strict, unknown keys are errors naming the key)."""
    try:
        return AssemblyCaseSpec.model_validate(data)
    except ValidationError as exc:
        from slipstep.casefile.check import _model_at, suggestion

        order = {"extra_forbidden": 0, "missing": 2}  # an unknown key first, not the key it misspells
        first = sorted(exc.errors(), key=lambda e: order.get(e["type"], 1))[0]
        field = _named_loc(data, first["loc"])
        if first["type"] == "extra_forbidden":
            valid = getattr(_model_at(AssemblyCaseSpec, first["loc"]), "model_fields", {})
            raise InputError(
                field,
                f"is not a known key in {source}{suggestion(str(first['loc'][-1]), valid)}",
                "check the spelling against the assembly keys of the documentation (Reference: Case-file keys; units are part of key names)",
            ) from None
        if first["type"] == "missing":
            raise InputError(field, f"is required in {source} but missing", "add it") from None
        raise InputError(
            field, f"{first['msg']} (got {first.get('input')!r})", "give a value of the right type"
        ) from None


def _named_loc(data: dict, loc) -> str:
    """'substructures.0.length_mm' -> 'substructures[blade].length_mm' (the entry's name)."""
    parts, node = [], data
    for p in loc:
        if isinstance(p, int) and isinstance(node, list):
            item = node[p] if p < len(node) else None
            label = item.get("name") if isinstance(item, dict) and isinstance(item.get("name"), str) else p
            parts[-1] = f"{parts[-1]}[{label}]" if parts else f"[{label}]"
            node = item
        else:
            parts.append(str(p))
            node = node.get(p) if isinstance(node, dict) else None
    return ".".join(parts) or _loc({"loc": loc})


# model field -> TOML key (the builders name model fields)
_TOML_KEYS = [
    (r"^substructures\[(.*)\]\.(length|root)$", r"substructures[\1].\2_mm"),
    (r"^substructures\[(.*)\]\.(tip_mass|platform_mass)$", r"substructures[\1].\2_kg"),
    (r"^substructures\[(.*)\]\.youngs_modulus$", r"substructures[\1].youngs_modulus_GPa"),
    (r"^substructures\[(.*)\]\.density$", r"substructures[\1].density_kg_per_m3"),
    (r"^substructures\[(.*)\]\.area$", r"substructures[\1].area_mm2"),
    (r"^substructures\[(.*)\]\.second_moment$", r"substructures[\1].second_moment_mm4"),
    (r"^substructures\[(.*)\]\.rayleigh$", r"substructures[\1].rayleigh_alpha_per_s/rayleigh_beta_s"),
    (r"^substructures\[(.*)\]\.(boundary_dofs|modes)$", r"substructures[\1].reduction.\2"),
    (r"^dampers\[(.*)\]\.mass$", r"dampers[\1].mass_kg"),
    (r"^dampers\[(.*)\]\.inertia$", r"dampers[\1].inertia_kg_m2"),
    (r"^dampers\[(.*)\]\.centrifugal_force$", r"dampers[\1].centrifugal_force_N"),
    (r"^dampers\[(.*)\]\.platforms\[(.*)\]\.(angle|offset)$", r"dampers[\1].platforms[\2].\3_deg"),
    (r"^dampers\[(.*)\]\.contacts\[(.*)\]\.position$", r"dampers[\1].contacts[\2].position_mm"),
    (
        r"^dampers\[(.*)\]\.contacts\[(.*)\]\.(normal|tangential)_stiffness$",
        r"dampers[\1].contacts[\2].\3_stiffness_N_per_um",
    ),
    (r"^contacts\[(.*)\]\.(normal|tangential)_stiffness$", r"contacts[\1].\2_stiffness_N_per_m"),
    (r"^contacts\[(.*)\]\.normal_offset$", r"contacts[\1].normal_offset_m"),
    (r"^forces\[(\d+)\]\.dof$", r"force[\1].component"),
    (r"^forces\[(\d+)\]\.frequency$", r"force[\1].frequency_Hz"),
]


def _toml_field(field: str) -> str:
    for pattern, key in _TOML_KEYS:
        if re.search(pattern, field):
            return re.sub(pattern, key, field).replace("offset_deg", "offset_mm")
    return field


def build_assembly(spec: AssemblyCaseSpec, base_dir: Path = Path(".")) -> System:
    """The System an assembly case describes (SI inside); errors name the TOML keys."""
    try:
        return _build(spec, base_dir)
    except InputError as exc:
        field = _toml_field(exc.field)
        if field == exc.field:
            raise
        raise InputError(field, exc.problem, exc.fix) from None


def _build(spec: AssemblyCaseSpec, base_dir: Path) -> System:
    subs: dict[str, Substructure] = {}
    originals: dict[str, Substructure] = {}
    for s in spec.substructures:
        if s.name in subs:
            raise InputError(f"substructures[{s.name}].name", "is used twice", "give every substructure its own name")
        originals[s.name] = subs[s.name] = _substructure(s, originals, base_dir)  # copy_of: the unmistuned one
        if s.mistuning is not None:
            subs[s.name] = _renamed(
                subs[s.name], s.name, 1.0 + _delta(f"substructures[{s.name}].mistuning", s.mistuning)
            )
    dampers = {d.name: d for d in spec.dampers}
    if len(dampers) != len(spec.dampers):
        raise InputError("dampers.name", "a damper name is used twice", "give every damper its own name")
    links = []
    chain = spec.chain
    chain_blades: list[str] = []
    if chain is not None:
        if chain.blade not in subs:
            raise InputError("chain.blade", f"names unknown substructure {chain.blade!r}", f"use one of {list(subs)}")
        if chain.damper not in dampers:
            raise InputError("chain.damper", f"names unknown damper {chain.damper!r}", f"use one of {list(dampers)}")
        if chain.blades < (3 if chain.closed else 2):
            raise InputError("chain.blades", f"is {chain.blades}", f"give at least {3 if chain.closed else 2} blades")
        if len(dampers[chain.damper].platforms) != 2:
            raise InputError(
                f"dampers[{chain.damper}].platforms",
                "must hold two platforms in a chain",
                "give the platform on the left blade first, then the one on the right blade",
            )
        template = subs.pop(chain.blade)
        chain_blades = [f"{chain.blade}{j + 1}" for j in range(chain.blades)]
        deltas = _mistuning(chain)
        for nm, delta in zip(chain_blades, deltas):
            subs[nm] = _renamed(template, nm, 1.0 + delta)
        pairs = [(j, j + 1) for j in range(chain.blades - 1)] + ([(chain.blades - 1, 0)] if chain.closed else [])
        d = dampers.pop(chain.damper)
        for k, (jl, jr) in enumerate(pairs):
            links.append(_damper(d, f"{d.name}{k + 1}", (chain_blades[jl], chain_blades[jr])))
    for d in dampers.values():
        links.append(_damper(d, d.name, None))
    contacts = [
        LinkContact(
            c.name,
            tuple(c.dofs),
            c.dof_gather,
            tuple(c.tangential_stiffness_N_per_m)
            if isinstance(c.tangential_stiffness_N_per_m, list)
            else c.tangential_stiffness_N_per_m,
            c.normal_stiffness_N_per_m,
            c.friction_coefficient,
            c.normal_offset_m,
        )
        for c in spec.contacts
    ]
    forces = [HarmonicForce(f.component, f.amplitude, f.frequency_Hz, math.radians(f.phase_deg)) for f in spec.force]
    for k, eo in enumerate(spec.engine_order_force):
        blades = eo.blades or chain_blades
        if not blades:
            raise InputError(
                f"engine_order_force[{k}].blades",
                "is missing and there is no [chain]",
                "list the blades in order (blade j lags by 2 pi EO j / N)",
            )
        unknown = [b for b in blades if b not in subs]
        if unknown:
            raise InputError(
                f"engine_order_force[{k}].blades",
                f"names unknown substructure(s) {unknown}",
                f"use names from {list(subs)}",
            )
        for b in blades:
            if eo.dof not in subs[b].dof_names:
                raise InputError(
                    f"engine_order_force[{k}].dof",
                    f"{eo.dof!r} is not a DOF of {b}",
                    f"use one of {', '.join(subs[b].dof_names[:6])} (without the blade's name)",
                )
        forces += engine_order_forces(
            blades, eo.dof, eo.amplitude_N, eo.frequency_Hz, eo.engine_order, math.radians(eo.phase_deg)
        )
    return assemble(
        list(subs.values()),
        links,
        contacts,
        forces,
        spec.constant_force_N,
        name=spec.name,
        ramp_time=spec.run.ramp_time_s or 0.0,
        period=spec.period_s,
    )


def _mistuning(chain: ChainSpec) -> list[float]:
    """The chain's blade deltas (zeros for a tuned chain), checked: one per blade, each > -1."""
    if chain.mistuning is None:
        return [0.0] * chain.blades
    deltas = [float(d) for d in chain.mistuning]
    if len(deltas) != chain.blades:
        raise InputError(
            "chain.mistuning", f"has {len(deltas)} values for {chain.blades} blades", "give one delta per blade"
        )
    return [_delta(f"chain.mistuning.{j + 1}", d) for j, d in enumerate(deltas)]


def _delta(field: str, d: float) -> float:
    """A mistuning delta, checked: finite and > -1 (the stiffness times 1 + delta stays positive)."""
    if not math.isfinite(d) or d <= -1.0:
        raise InputError(field, f"is {d}", "give a finite delta > -1 (stiffness x (1 + delta))")
    return float(d)


def _renamed(s: Substructure, name: str, stiffness_scale: float = 1.0) -> Substructure:
    """A copy of ``s`` named ``name``, its stiffness times ``stiffness_scale`` (mistuning: the
    scaled reduced stiffness is the reduction of the scaled full one, the basis being unchanged)."""
    K = s.stiffness if stiffness_scale == 1.0 else s.stiffness * stiffness_scale
    return Substructure(
        name, s.mass, K, s.dof_names, s.dof_units, s.damping, s.rayleigh, s.modal_damping_ratio, s.points
    )


def _damping(s: SubstructureSpec) -> dict:
    ray = (s.rayleigh_alpha_per_s, s.rayleigh_beta_s)
    if any(v is not None for v in ray):
        if s.modal_damping_ratio is not None:
            raise InputError(
                f"substructures[{s.name}].modal_damping_ratio",
                "is given together with rayleigh_*",
                "give one damping description",
            )
        return {"rayleigh": tuple(0.0 if v is None else v for v in ray)}
    return {} if s.modal_damping_ratio is None else {"modal_damping_ratio": s.modal_damping_ratio}


def _substructure(s: SubstructureSpec, done: dict, base_dir: Path) -> Substructure:
    where = f"substructures[{s.name}]"
    damping = _damping(s)
    if s.copy_of is not None:
        if s.copy_of not in done:
            raise InputError(
                f"{where}.copy_of",
                f"names {s.copy_of!r}, not an earlier substructure",
                f"use one of {list(done)} (define the original first)",
            )
        return _renamed(done[s.copy_of], s.name)
    if s.kind == "frame_blade":
        for key in (
            "length_mm",
            "elements",
            "youngs_modulus_GPa",
            "density_kg_per_m3",
            "area_mm2",
            "second_moment_mm4",
        ):
            if getattr(s, key) is None:
                raise InputError(f"{where}.{key}", "is required for kind = 'frame_blade' but missing", "add it")
        for key in ("file", "mass_file", "stiffness_file", "damping_file", "dofs_file", "dof_names", "dof_units"):
            if getattr(s, key) not in (None, []):
                raise InputError(f"{where}.{key}", "is for kind = 'matrices'", "remove it or set kind = 'matrices'")
        sub = frame_blade(
            s.name,
            s.length_mm * MM,
            s.elements,
            s.youngs_modulus_GPa * GPA,
            s.density_kg_per_m3,
            s.area_mm2 * MM**2,
            s.second_moment_mm4 * MM**4,
            s.platform_node,
            root=tuple(np.asarray(s.root_mm) * MM),
            angle=math.radians(s.angle_deg),
            tip_mass=s.tip_mass_kg,
            platform_mass=s.platform_mass_kg,
            **({} if s.reduction else damping),
        )
    else:
        points = {
            p.name: Point(
                {c: getattr(p, c) for c in ("x", "y", "rz") if getattr(p, c) is not None},
                tuple(np.asarray(p.position_mm, float) * MM),
            )
            for p in s.points
        }
        kwargs = dict(points=points, **({} if s.reduction else damping))
        if s.dof_names is not None:
            kwargs["dof_names"] = tuple(s.dof_names)
        if s.dof_units is not None:
            kwargs["dof_units"] = tuple(s.dof_units)
        path = lambda p: p if Path(p).is_absolute() else base_dir / p
        if s.file is not None:
            if s.mass_file or s.stiffness_file:
                raise InputError(
                    f"{where}.file", "is given together with mass_file/stiffness_file", "give one of the two forms"
                )
            sub = load_npz(path(s.file), s.name, field_name=f"{where}.file", **kwargs)
        elif s.mass_file and s.stiffness_file:
            sub = load_mtx(
                path(s.mass_file),
                path(s.stiffness_file),
                s.name,
                damping=None if s.damping_file is None else path(s.damping_file),
                dofs_file=None if s.dofs_file is None else path(s.dofs_file),
                **kwargs,
            )
        else:
            raise InputError(
                f"{where}.file",
                "is missing (kind = 'matrices')",
                "give file = an .npz, or mass_file and stiffness_file (.mtx)",
            )
    if s.reduction is not None:
        sub = craig_bampton(sub, list(s.reduction.boundary_dofs), s.reduction.modes, **damping)
    return sub


def _damper(d: DamperLinkSpec, name: str, chain_pair: tuple[str, str] | None) -> DamperLink:
    plats = []
    for k, p in enumerate(d.platforms):
        sub = chain_pair[k] if chain_pair is not None else p.substructure
        if sub is None:
            raise InputError(
                f"dampers[{d.name}].platforms[{p.name}].substructure",
                "is missing",
                "name the substructure whose point the platform follows",
            )
        if len(p.offset_mm) != 2:
            raise InputError(
                f"dampers[{d.name}].platforms[{p.name}].offset_mm",
                f"has {len(p.offset_mm)} values",
                "give [X, Y] in mm",
            )
        plats.append(PlatformLink(p.name, math.radians(p.angle_deg), sub, p.point, tuple(np.asarray(p.offset_mm) * MM)))
    contacts = []
    for c in d.contacts:
        if len(c.position_mm) != 2:
            raise InputError(
                f"dampers[{d.name}].contacts[{c.name}].position_mm",
                f"has {len(c.position_mm)} values",
                "give [a, b] in mm",
            )
        contacts.append(damper_contact(c))
    return DamperLink(
        name,
        d.mass_kg,
        d.inertia_kg_m2,
        d.centrifugal_force_N,
        tuple(plats),
        tuple(contacts),
        math.radians(d.centrifugal_angle_deg),
    )


def load_assembly_case(data: dict, path: Path) -> tuple[System, RunSpec]:
    """(System, default run options) of an assembly case table read from ``path``."""
    spec = parse_assembly(data, source=str(path))
    return build_assembly(spec, Path(path).parent), spec.run
