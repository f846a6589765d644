"""Rigid 2D underplatform damper between blade platforms (paper Section 2, Fig. 2b).

DOFs x = [x_G, y_G, phi] at the centre of mass (phi counter-clockwise). A damper point at
r = (a, b) from the centre of mass moves by G(r) x with G = [[1, 0, -b], [0, 1, a]].
A platform at angle theta has the contact tangent t = (cos theta, sin theta) and the normal
n = (-sin theta, cos theta) pointing from the damper into the platform. With platform
motion p_P = (x_P, y_P) the contact sees

    u = t . (G x - p_P),   v = n . (G x - p_P)      (v > 0: interference)

so A_i = [t^T G; n^T G] and B_i = [t^T; n^T] on the platform's two motion components.
The centrifugal force acts on the centre of mass (default along +Y, the radial direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError
from slipstep.model.contact import ContactElement
from slipstep.model.excitation import Excitation, Harmonic, Signal, Tabulated
from slipstep.model.structure import Structure
from slipstep.model.validate import finite, float_array, positive
from slipstep.model.system import System


@dataclass(frozen=True)
class Platform:
    """A blade platform face: ``angle`` [rad] of its tangent from the X axis."""

    name: str
    angle: float


@dataclass(frozen=True)
class DamperContact:
    """A contact point at ``position`` (a, b) [m] from the damper's centre of mass."""

    name: str
    platform: str
    position: tuple[float, float]
    normal_stiffness: float
    tangential_stiffness: float
    friction_coefficient: float


def rigid_damper(
    mass: float,
    inertia: float,
    platforms: list[Platform],
    contacts: list[DamperContact],
    centrifugal_force: float,
    motion: Signal | None = None,
    centrifugal_angle: float = math.pi / 2,
    name: str = "damper",
) -> System:
    """Build the System of a rigid damper. ``motion`` components are named
    '<platform>.x' and '<platform>.y' (missing components are held fixed)."""
    m = positive("damper.mass", mass)
    J = positive("damper.inertia", inertia)
    cf = positive("damper.centrifugal_force", centrifugal_force, allow_zero=True)
    by_name = {}
    for p in platforms:
        if p.name in by_name:
            raise InputError("damper.platforms", f"platform {p.name!r} defined twice", "give each platform once")
        by_name[p.name] = finite(f"damper.platforms[{p.name}].angle", p.angle)
    if not contacts:
        raise InputError("damper.contacts", "is empty", "give at least one contact point")
    motion_names = tuple(f"{p.name}.{axis}" for p in platforms for axis in ("x", "y"))
    if motion is not None:
        unknown = set(motion.components) - set(motion_names)
        if unknown:
            raise InputError(
                "motion.component", f"unknown platform motion(s) {sorted(unknown)}", f"use one of {list(motion_names)}"
            )
        motion = _reorder(motion, motion_names)
    elements = []
    for c in contacts:
        if c.platform not in by_name:
            raise InputError(
                f"damper.contacts[{c.name}].platform",
                f"names unknown platform {c.platform!r}",
                f"use one of {list(by_name)}",
            )
        a, b = float_array(f"damper.contacts[{c.name}].position", c.position, shape=(2,))
        theta = by_name[c.platform]
        t = np.array([math.cos(theta), math.sin(theta)])
        nrm = np.array([-math.sin(theta), math.cos(theta)])
        G = np.array([[1.0, 0.0, -b], [0.0, 1.0, a]])
        B = np.zeros((2, len(motion_names)))
        j = motion_names.index(f"{c.platform}.x")
        B[:, j : j + 2] = np.vstack([t, nrm])
        elements.append(
            ContactElement(
                name=c.name,
                dof_gather=np.vstack([t @ G, nrm @ G]),
                motion_gather=B,
                tangential_stiffness=c.tangential_stiffness,
                normal_stiffness=c.normal_stiffness,
                friction_coefficient=c.friction_coefficient,
            )
        )
    structure = Structure(mass=np.diag([m, m, J]), dof_names=("x_G", "y_G", "phi"), dof_units=("m", "m", "rad"))
    force = cf * np.array([math.cos(centrifugal_angle), math.sin(centrifugal_angle), 0.0])
    return System(
        structure,
        tuple(elements),
        Excitation(constant_force=force, motion=motion),
        motion_names=motion_names,
        name=name,
    )


def _reorder(signal: Signal, names: tuple[str, ...]) -> Signal:
    """Expand a signal over some motion components onto all of ``names`` (zeros elsewhere)."""
    idx = [names.index(c) for c in signal.components]
    harmonics = []
    for h in signal.harmonics:
        amp, ph = np.zeros(len(names)), np.zeros(len(names))
        amp[idx], ph[idx] = h.amplitude, h.phase
        harmonics.append(Harmonic(h.frequency, amp, ph))
    tables = []
    for tab in signal.tables:
        vals = np.zeros((tab.times.size, len(names)))
        vals[:, idx] = tab.values
        tables.append(Tabulated(tab.times, vals))
    return Signal(names, tuple(harmonics), tuple(tables), signal.ramp_time)
