"""Assemblies: substructures joined by contacts, with rigid dampers between blades.

The assembled DOFs are each substructure's DOFs prefixed by its name ('blade1.3.x'), then
each damper's (x_G, y_G, phi) prefixed by the damper's name ('damper1.x_G'). Matrices are
block diagonal; every coupling is a contact element, so the result is an ordinary
:class:`~slipstep.model.system.System` (no solver knows how it was assembled).

A damper platform follows a point P of a substructure (DOFs x_P, y_P, rz_P of a 2D node)
rigidly: the platform point touching damper contact c sits at l = offset + r_c from P
(offset: from P to the damper's centre of mass, r_c: the contact from the centre of
mass) and moves by

    p_c = H x_P,   H = [[1, 0, -l_y], [0, 1, l_x]]

(columns of missing components dropped). The damper's contact law of
:mod:`slipstep.model.damper` sees q = A_d x_d - B_c p_c + g; with p_c = H x_P the gather
over the assembled DOFs is [A_d on the damper, -B_c H on P]: the prescribed platform
motion is replaced by structure DOFs.

Engine-order excitation of N blades (:func:`engine_order_forces`): blade j (0-based) gets
F sin(2 pi f t - 2 pi EO j / N), i.e. it lags blade 0 by 2 pi EO j / N (a wave travelling
forward through the blade numbers).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError
from slipstep.model.contact import ContactElement
from slipstep.model.damper import DamperContact, Platform, rigid_damper
from slipstep.model.excitation import Excitation, Harmonic, Signal
from slipstep.model.structure import Structure
from slipstep.model.substructure import Substructure
from slipstep.model.validate import finite, positive
from slipstep.model.system import System


@dataclass(frozen=True)
class PlatformLink:
    """A damper platform face at ``angle`` [rad] that follows ``point`` of ``substructure``;
    ``offset`` (X, Y) [m]: from the point to the damper's centre of mass."""

    name: str
    angle: float
    substructure: str
    point: str = "platform"
    offset: tuple[float, float] = (0.0, 0.0)


@dataclass(frozen=True)
class DamperLink:
    """A rigid damper (as :func:`slipstep.model.damper.rigid_damper`) between platforms that
    follow substructure points."""

    name: str
    mass: float
    inertia: float
    centrifugal_force: float
    platforms: tuple[PlatformLink, ...]
    contacts: tuple[DamperContact, ...]
    centrifugal_angle: float = math.pi / 2


@dataclass(frozen=True)
class LinkContact:
    """A contact element on named assembled DOFs: ``dof_gather`` has one row per local
    coordinate (u or u1, u2, then v) and one column per name in ``dofs``."""

    name: str
    dofs: tuple[str, ...]
    dof_gather: object
    tangential_stiffness: float | tuple[float, ...]
    normal_stiffness: float
    friction_coefficient: float
    normal_offset: float = 0.0


@dataclass(frozen=True)
class HarmonicForce:
    """``amplitude`` [N] sin(2 pi ``frequency`` t + ``phase``) on an assembled DOF."""

    dof: str
    amplitude: float
    frequency: float
    phase: float = 0.0


@dataclass
class _Layout:
    names: list = field(default_factory=list)
    units: list = field(default_factory=list)

    def add(self, prefix: str, names, units) -> slice:
        start = len(self.names)
        self.names += [f"{prefix}.{n}" for n in names]
        self.units += list(units)
        return slice(start, len(self.names))


def assemble(
    substructures,
    dampers=(),
    contacts=(),
    forces=(),
    constant_forces=None,
    name: str = "assembly",
    ramp_time: float = 0.0,
    period: float | None = None,
) -> System:
    """The System of substructures + dampers + contacts + harmonic forces (module docstring).
    ``constant_forces``: {assembled DOF name: N}, ramped in the static preload."""
    subs = list(substructures)
    if not subs:
        raise InputError("substructures", "is empty", "give at least one substructure")
    by_name: dict[str, Substructure] = {}
    for s in subs:
        if not isinstance(s, Substructure):
            raise InputError("substructures", f"holds a {type(s).__name__}", "give slipstep Substructure objects")
        if s.name in by_name:
            raise InputError(f"substructures[{s.name}].name", "is used twice", "give every substructure its own name")
        by_name[s.name] = s
    dampers = list(dampers)
    for d in dampers:
        if d.name in by_name:
            raise InputError(f"dampers[{d.name}].name", "is also a substructure's name", "give the damper another name")
    layout = _Layout()
    blocks = []
    for s in subs:
        st = s.to_structure()
        blocks.append((layout.add(s.name, s.dof_names, s.dof_units), st.mass, st.damping, st.stiffness))
    damper_systems = []
    for d in dampers:
        try:
            dsys = rigid_damper(
                d.mass,
                d.inertia,
                [Platform(p.name, p.angle) for p in d.platforms],
                list(d.contacts),
                d.centrifugal_force,
                centrifugal_angle=d.centrifugal_angle,
                name=d.name,
            )
        except InputError as exc:  # name the damper: 'damper.mass' -> 'dampers[d1].mass'
            field = re.sub(r"^(damper\.|(?=contacts))", "", exc.field)
            raise InputError(f"dampers[{d.name}].{field}", exc.problem, exc.fix) from None
        sl = layout.add(d.name, dsys.structure.dof_names, dsys.structure.dof_units)
        blocks.append((sl, dsys.structure.mass, dsys.structure.damping, dsys.structure.stiffness))
        damper_systems.append((d, dsys, sl))
    n = len(layout.names)
    index = {nm: i for i, nm in enumerate(layout.names)}
    M, C, K = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for sl, m_, c_, k_ in blocks:
        M[sl, sl], C[sl, sl], K[sl, sl] = m_, c_, k_
    f0 = np.zeros(n)
    elements = []
    for d, dsys, sl in damper_systems:
        f0[sl] += dsys.excitation.constant_force
        elements += _damper_contacts(d, dsys, sl, by_name, index, n)
    for c in contacts:
        elements.append(_link_contact(c, index, n))
    for dof, value in (constant_forces or {}).items():
        f0[_dof(index, dof, f"constant_forces[{dof}]")] += finite(f"constant_forces[{dof}]", value)
    force = _force_signal(forces, index, tuple(layout.names), ramp_time)
    structure = Structure(M, C, K, tuple(layout.names), tuple(layout.units))
    exc = Excitation(constant_force=f0, force=force, period=period)
    return System(structure, tuple(elements), exc, name=name)


def _dof(index: dict, dof: str, field_name: str) -> int:
    if dof not in index:
        near = [k for k in index if k.split(".")[0] == dof.split(".")[0]][:6] or list(index)[:6]
        raise InputError(
            field_name, f"names unknown DOF {dof!r}", f"use an assembled DOF name such as {', '.join(near)}"
        )
    return index[dof]


def _damper_contacts(d: DamperLink, dsys: System, sl: slice, subs: dict, index: dict, n: int) -> list[ContactElement]:
    """The damper's contacts with their platform columns moved onto the followed points."""
    links = {p.name: p for p in d.platforms}
    out = []
    for c, el in zip(d.contacts, dsys.contacts):
        link = links[c.platform]
        where = f"dampers[{d.name}].platforms[{link.name}]"
        if link.substructure not in subs:
            raise InputError(
                f"{where}.substructure", f"names unknown substructure {link.substructure!r}", f"use one of {list(subs)}"
            )
        sub = subs[link.substructure]
        if link.point not in sub.points:
            raise InputError(
                f"{where}.point",
                f"names unknown point {link.point!r} of {sub.name}",
                f"use one of {list(sub.points) or ['(none defined: add points)']}",
            )
        pt = sub.points[link.point]
        lx = finite(f"{where}.offset", link.offset[0]) + c.position[0]
        ly = finite(f"{where}.offset", link.offset[1]) + c.position[1]
        H = {"x": np.array([1.0, 0.0]), "y": np.array([0.0, 1.0]), "rz": np.array([-ly, lx])}
        j = dsys.motion_names.index(f"{link.name}.x")
        Bc = el.motion_gather[:, j : j + 2]
        A = np.zeros((el.dof_gather.shape[0], n))
        A[:, sl] = el.dof_gather
        for comp, dof in pt.dofs.items():
            A[:, index[f"{sub.name}.{dof}"]] -= Bc @ H[comp]
        out.append(
            ContactElement(
                name=f"{d.name}.{c.name}",
                dof_gather=A,
                tangential_stiffness=el.tangential_stiffness,
                normal_stiffness=el.normal_stiffness,
                friction_coefficient=el.friction_coefficient,
            )
        )
    return out


def _link_contact(c: LinkContact, index: dict, n: int) -> ContactElement:
    where = f"contacts[{c.name}]"
    G = np.asarray(c.dof_gather, dtype=float)
    if G.ndim != 2 or G.shape[1] != len(c.dofs):
        raise InputError(
            f"{where}.dof_gather",
            f"has shape {G.shape} for {len(c.dofs)} DOFs",
            "give one row per local coordinate and one column per name in dofs",
        )
    A = np.zeros((G.shape[0], n))
    for col, dof in enumerate(c.dofs):
        A[:, _dof(index, dof, f"{where}.dofs")] += G[:, col]
    return ContactElement(
        name=c.name,
        dof_gather=A,
        tangential_stiffness=c.tangential_stiffness,
        normal_stiffness=c.normal_stiffness,
        friction_coefficient=c.friction_coefficient,
        normal_offset=c.normal_offset,
    )


def _force_signal(forces, index: dict, names: tuple, ramp_time: float) -> Signal | None:
    """Harmonic forces grouped by frequency into one Signal over all DOFs."""
    forces = list(forces)
    if not forces:
        return None
    groups: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    for k, f in enumerate(forces):
        i = _dof(index, f.dof, f"forces[{k}].dof")
        freq = positive(f"forces[{k}].frequency", f.frequency)
        amp, ph = groups.setdefault(freq, (np.zeros(len(names)), np.zeros(len(names))))
        if amp[i] != 0:
            raise InputError(
                f"forces[{k}].dof", f"{f.dof!r} has two forces at {freq:g} Hz", "give one per DOF and frequency"
            )
        amp[i], ph[i] = finite(f"forces[{k}].amplitude", f.amplitude), finite(f"forces[{k}].phase", f.phase)
    return Signal(names, tuple(Harmonic(fr, a, p) for fr, (a, p) in sorted(groups.items())), (), ramp_time)


def engine_order_forces(
    blades: list[str], dof: str, amplitude: float, frequency: float, engine_order: int, phase: float = 0.0
) -> list[HarmonicForce]:
    """One force per blade on '<blade>.<dof>': blade j lags by 2 pi EO j / N (module docstring)."""
    N = len(blades)
    if isinstance(engine_order, bool) or not isinstance(engine_order, (int, np.integer)):
        raise InputError("engine_order", f"is {engine_order!r}", "give a whole number")
    return [
        HarmonicForce(f"{b}.{dof}", amplitude, frequency, phase - 2 * math.pi * engine_order * j / N)
        for j, b in enumerate(blades)
    ]


def blade_chain(
    blade: Substructure,
    n_blades: int,
    damper: DamperLink,
    closed: bool = False,
    force_dof: str | None = None,
    force_amplitude: float = 0.0,
    frequency: float | None = None,
    engine_order: int = 0,
    name: str = "chain",
    ramp_time: float = 0.0,
) -> System:
    """N copies of ``blade`` named 'blade1'..'bladeN' with a copy of ``damper`` between each
    neighbouring pair ('damper<j>' between blade j and j + 1; ``closed``: also between
    blade N and blade 1, a ring). ``damper.platforms``: the first follows the left blade,
    the second the right one (their ``substructure`` fields are replaced). Optional
    engine-order forces on '<blade>.<force_dof>'."""
    if isinstance(n_blades, bool) or not isinstance(n_blades, (int, np.integer)) or n_blades < (3 if closed else 2):
        raise InputError("blades", f"is {n_blades!r}", f"give a whole number >= {3 if closed else 2}")
    if len(damper.platforms) != 2:
        raise InputError(
            f"dampers[{damper.name}].platforms",
            f"has {len(damper.platforms)} platforms",
            "give two: the first follows the left blade, the second the right blade",
        )
    names = [f"blade{j + 1}" for j in range(n_blades)]
    subs = [
        Substructure(
            nm,
            blade.mass,
            blade.stiffness,
            blade.dof_names,
            blade.dof_units,
            blade.damping,
            blade.rayleigh,
            blade.modal_damping_ratio,
            blade.points,
        )
        for nm in names
    ]
    pairs = [(j, j + 1) for j in range(n_blades - 1)] + ([(n_blades - 1, 0)] if closed else [])
    dampers = []
    for k, (jl, jr) in enumerate(pairs):
        left, right = damper.platforms
        plats = (
            PlatformLink(left.name, left.angle, names[jl], left.point, left.offset),
            PlatformLink(right.name, right.angle, names[jr], right.point, right.offset),
        )
        dampers.append(
            DamperLink(
                f"damper{k + 1}",
                damper.mass,
                damper.inertia,
                damper.centrifugal_force,
                plats,
                damper.contacts,
                damper.centrifugal_angle,
            )
        )
    forces = []
    if force_dof is not None and force_amplitude:
        if frequency is None:
            raise InputError("frequency", "is missing", "give the excitation frequency [Hz]")
        forces = engine_order_forces(names, force_dof, force_amplitude, frequency, engine_order)
    return assemble(subs, dampers, forces=forces, name=name, ramp_time=ramp_time)
