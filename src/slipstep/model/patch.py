"""Contact patches: an interface discretised into many point contacts (microslip).

A real interface is a face, not a point. A patch of length L (and out-of-plane width b) is cut
into n equal segments; each segment becomes one spring-slider contact at its centre s_i with
the segment's share of the interface stiffness (midpoint rule, stiffness per unit area k''):

    s_i = s_c + L ((i + 1/2) / n - 1/2),    A_i = b L / n,
    k_n,i = k_n'' A_i,    k_t,i = k_t'' A_i                       (i = 0 .. n-1)

and, for a crowned face of radius R (a curved platform, paper Fig. 2b), the initial normal
offset of each point is the gap of the circle at its distance from the crown s_c:

    g_i = g_c - (s_i - s_c)^2 / (2 R)                             (parabolic approximation)

so that only the points near the crown carry load at small preloads. The preload is not
distributed by hand: each point's normal force comes out of the static equilibrium, i.e. the
pressure distribution that results from the stiffnesses, the offsets and the body's motion.
Under a growing tangential load the least-loaded points slip first (mu N_i is reached first
where N_i is smallest), which is microslip; gross slip is reached when every point slips.

:func:`contact_patch` works for any structure: the caller gives the gather maps of a point
at coordinate s along the face (for an FE interface, the interpolation of its nodes; for a
rigid body, its rigid-body kinematics). :func:`rigid_face_gather` is that map for a point of
a rigid 2D body, and :func:`damper_face_contacts` cuts a face of the rigid underplatform
damper (model/damper.py) into the damper's own contact points.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slipstep.errors import InputError
from slipstep.model.contact import ContactElement
from slipstep.model.damper import DamperContact
from slipstep.model.validate import finite, float_array, positive

MAX_POINTS = 10_000


@dataclass(frozen=True)
class PatchPoints:
    """The discretisation of a face: coordinates s [m] along it, tributary areas [m^2] and
    initial normal offsets g [m] (> 0 interference, < 0 gap) of its n points."""

    s: np.ndarray
    area: np.ndarray
    offset: np.ndarray


def face_points(
    length: float,
    n_points: int,
    *,
    width: float = 1.0,
    centre: float = 0.0,
    crown_radius: float | None = None,
    crown_offset: float = 0.0,
    field: str = "patch",
) -> PatchPoints:
    """Cut a face of ``length`` [m] centred at ``centre`` into ``n_points`` equal segments
    (module docstring); ``width`` [m] is the out-of-plane depth (area = width x length);
    ``crown_radius`` [m] makes the face crowned (gap growing away from the centre), with
    ``crown_offset`` [m] the offset at the crown."""
    L = positive(f"{field}.length", length)
    b = positive(f"{field}.width", width)
    c = finite(f"{field}.centre", centre)
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or not 1 <= n_points <= MAX_POINTS:
        raise InputError(f"{field}.n_points", f"is {n_points!r}", f"give a whole number from 1 to {MAX_POINTS}")
    s = c + L * ((np.arange(n_points) + 0.5) / n_points - 0.5)
    area = np.full(n_points, b * L / n_points)
    g0 = finite(f"{field}.crown_offset", crown_offset)
    if crown_radius is None:
        offset = np.full(n_points, g0)
    else:
        R = positive(f"{field}.crown_radius", crown_radius)
        if R < L / 2:
            raise InputError(
                f"{field}.crown_radius",
                f"is {R:.3g} m, less than half the face length ({L / 2:.3g} m)",
                "give a radius of at least half the face length (the parabola approximates a circle)",
            )
        offset = g0 - (s - c) ** 2 / (2 * R)
    return PatchPoints(s=s, area=area, offset=offset)


def contact_patch(
    name: str,
    points: PatchPoints,
    dof_gather: Callable[[float], np.ndarray],
    *,
    normal_stiffness_per_area: float,
    tangential_stiffness_per_area: float | tuple[float, float],
    friction_coefficient: float,
    motion_gather: Callable[[float], np.ndarray] | None = None,
) -> tuple[ContactElement, ...]:
    """The contact elements of a patch, named ``<name>.<i>``: point i gathers
    ``A_i = dof_gather(s_i)`` (2 rows u, v or 3 rows u1, u2, v, normal last) and
    ``B_i = motion_gather(s_i)``, has k_n = k_n'' A_i and k_t = k_t'' A_i [N/m] and the offset
    g_i of ``points``. Stiffnesses per area in N/m^3 (N/m per m^2)."""
    kn2 = positive(f"{name}.normal_stiffness_per_area", normal_stiffness_per_area)
    kt2 = np.atleast_1d(float_array(f"{name}.tangential_stiffness_per_area", tangential_stiffness_per_area))
    for k in kt2:
        positive(f"{name}.tangential_stiffness_per_area", k)
    elements = []
    for i, (s, area, g) in enumerate(zip(points.s, points.area, points.offset)):
        kt = tuple(float(k * area) for k in kt2)
        elements.append(
            ContactElement(
                name=f"{name}.{i}",
                dof_gather=np.asarray(dof_gather(float(s)), float),
                motion_gather=None if motion_gather is None else np.asarray(motion_gather(float(s)), float),
                tangential_stiffness=kt[0] if len(kt) == 1 else kt,
                normal_stiffness=kn2 * area,
                friction_coefficient=friction_coefficient,
                normal_offset=float(g),
            )
        )
    return tuple(elements)


def rigid_face_gather(
    angle: float,
    origin: tuple[float, float],
    dof_index: tuple[int, int, int],
    n_dofs: int,
) -> Callable[[float], np.ndarray]:
    """The gather map of a point of a rigid 2D body on a face through ``origin`` = (a0, b0) [m]
    (from the body's reference point) with tangent (cos angle, sin angle): the point at s is
    r = origin + s t and moves by G(r) x_b, G = [[1, 0, -b], [0, 1, a]], with x_b = (x, y, phi)
    at ``dof_index`` of an ``n_dofs`` structure; the rows are u = t . G x_b, v = n . G x_b,
    n = (-sin angle, cos angle) (the face's normal, pointing from the body into the face)."""
    t = np.array([math.cos(angle), math.sin(angle)])
    nrm = np.array([-math.sin(angle), math.cos(angle)])
    a0, b0 = float_array("patch.origin", origin, shape=(2,))
    cols = list(dof_index)

    def gather(s: float) -> np.ndarray:
        a, b = a0 + s * t[0], b0 + s * t[1]
        G = np.array([[1.0, 0.0, -b], [0.0, 1.0, a]])
        A = np.zeros((2, n_dofs))
        A[:, cols] = np.vstack([t @ G, nrm @ G])
        return A

    return gather


def damper_face_contacts(
    name: str,
    platform: str,
    angle: float,
    centre: tuple[float, float],
    length: float,
    n_points: int,
    *,
    normal_stiffness_per_area: float,
    tangential_stiffness_per_area: float,
    friction_coefficient: float,
    width: float = 1.0,
) -> list[DamperContact]:
    """A flat damper face on ``platform`` (tangent angle ``angle`` [rad]) centred at ``centre``
    (a, b) [m] from the damper's centre of mass, cut into ``n_points`` contact points for
    :func:`slipstep.model.damper.rigid_damper` (names ``<name>.<i>``, stiffnesses k'' A_i)."""
    pts = face_points(length, n_points, width=width, field=name)
    a0, b0 = float_array(f"{name}.centre", centre, shape=(2,))
    kn2 = positive(f"{name}.normal_stiffness_per_area", normal_stiffness_per_area)
    kt2 = positive(f"{name}.tangential_stiffness_per_area", tangential_stiffness_per_area)
    t = (math.cos(angle), math.sin(angle))
    return [
        DamperContact(
            f"{name}.{i}", platform, (a0 + s * t[0], b0 + s * t[1]), kn2 * area, kt2 * area, friction_coefficient
        )
        for i, (s, area) in enumerate(zip(pts.s, pts.area))
    ]
