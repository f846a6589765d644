"""Contact patches (model/patch.py): the discretisation, the pressure that results from the
static equilibrium (analytic for a rigid block on a flat face), microslip order, and the
limit of a vanishing face (the paper's point contacts)."""

import math

import numpy as np
import pytest

import slipstep as ss
from slipstep.errors import InputError
from slipstep.model.damper import Platform, rigid_damper
from slipstep.model.excitation import Excitation, Signal, Tabulated
from slipstep.model.patch import contact_patch, damper_face_contacts, face_points, rigid_face_gather
from slipstep.model.structure import Structure
from slipstep.model.system import System

KN2, KT2, MU, L, WIDTH = 2.0e13, 1.5e13, 0.4, 4e-3, 2e-3  # N/m^3, -, m, m


def _block(n, P, M_z, force=None, crown_radius=None):
    """A rigid block (x, y, phi) pressed by P [N] and the moment M_z [N m] onto a flat face
    (tangent X, normal +Y) cut into n points."""
    pts = face_points(L, n, width=WIDTH, crown_radius=crown_radius)
    contacts = contact_patch(
        "face",
        pts,
        rigid_face_gather(0.0, (0.0, 0.0), (0, 1, 2), 3),
        normal_stiffness_per_area=KN2,
        tangential_stiffness_per_area=KT2,
        friction_coefficient=MU,
    )
    structure = Structure(mass=np.diag([0.01, 0.01, 1e-7]), dof_names=("x", "y", "phi"), dof_units=("m", "m", "rad"))
    exc = Excitation(constant_force=np.array([0.0, P, M_z]), force=force)
    return System(structure, contacts, exc, name="block"), pts


def test_face_points_midpoint_rule_and_crown():
    pts = face_points(L, 8, width=WIDTH, centre=1e-3)
    assert pts.s.size == 8 and np.isclose(pts.area.sum(), L * WIDTH)
    assert np.allclose(np.diff(pts.s), L / 8) and np.isclose(pts.s.mean(), 1e-3)
    assert np.allclose(pts.offset, 0.0)
    crowned = face_points(L, 9, crown_radius=0.05, crown_offset=1e-6)
    assert crowned.offset.max() == pytest.approx(1e-6) and crowned.offset[4] == pytest.approx(1e-6)
    assert np.allclose(crowned.offset, 1e-6 - crowned.s**2 / 0.1)


@pytest.mark.parametrize("n", [4, 21])
def test_preload_pressure_of_a_rigid_block_is_linear(n):
    """Rigid block: v_i = y + s_i phi, so N_i = P/n + M s_i / sum s_j^2 (equal k_n,i)."""
    P, Mz = 300.0, 0.05
    system, pts = _block(n, P, Mz, force=None)
    ds = ss.run(system, "quasi-static", duration=1e-3, steps_per_period=2)
    N = ds.normal_force.isel(time=0).values
    expected = P / n + Mz * pts.s / np.sum(pts.s**2)
    assert np.all(expected > 0)
    np.testing.assert_allclose(N, expected, rtol=1e-9)
    assert N.sum() == pytest.approx(P, rel=1e-12)
    kn = np.array([c.normal_stiffness for c in system.contacts])
    assert kn.sum() == pytest.approx(KN2 * L * WIDTH, rel=1e-12)


def test_microslip_least_loaded_points_slip_first():
    """A tangential force growing to 0.9 mu P on the tilted block: points enter slip in the
    order of their normal force (smallest first); the total |T| stays the applied force and
    |T_i| <= mu N_i throughout; part of the face still sticks at the end (microslip)."""
    n, P, Mz = 12, 300.0, 0.1
    F_end = 0.9 * MU * P
    table = Tabulated(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [F_end, 0.0, 0.0]]))
    system, pts = _block(n, P, Mz, force=Signal(("x", "y", "phi"), tables=(table,)))
    ds = ss.run(system, "quasi-static", duration=1.0, steps_per_period=400)
    assert ds.attrs["status"] == "OK"
    N0 = ds.normal_force.isel(time=0).values
    state = ds.contact_state.values
    slipping = (state == 2) | (state == 3)
    first_slip = np.array([np.argmax(slipping[:, i]) if slipping[:, i].any() else state.shape[0] for i in range(n)])
    assert 0 < slipping[-1].sum() < n
    order_by_load = np.argsort(N0, kind="stable")
    assert np.all(np.diff(first_slip[order_by_load]) >= 0)
    T, N = ds.tangential_force.values, ds.normal_force.values
    assert np.all(np.abs(T) <= MU * N * (1 + 1e-9) + 1e-9)
    applied = np.interp(ds.time.values, [0.0, 1.0], [0.0, F_end])
    np.testing.assert_allclose(T.sum(axis=1), applied, atol=1e-9 * P)


def test_vanishing_damper_faces_reproduce_the_point_contacts():
    """Each of the paper's three point contacts replaced by a 1 um face of 5 points of the
    same total stiffness: the preload forces per original point agree to 1e-4 of CF."""
    paper = ss.load_system("paper")
    spec = {
        "P1": ("left", 45.0, (-3.914e-3, -0.414e-3), 13e6, 0.40),
        "P2": ("left", 45.0, (-1.086e-3, 2.414e-3), 13e6, 0.40),
        "P3": ("right", -45.0, (2.5e-3, 1.0e-3), 26e6, 0.25),
    }
    length, width = 1e-6, 1e-3
    contacts = []
    for name, (platform, angle, centre, k, mu) in spec.items():
        contacts += damper_face_contacts(
            name,
            platform,
            math.radians(angle),
            centre,
            length,
            5,
            normal_stiffness_per_area=k / (length * width),
            tangential_stiffness_per_area=k / (length * width),
            friction_coefficient=mu,
            width=width,
        )
    platforms = [Platform("left", math.radians(45.0)), Platform("right", math.radians(-45.0))]
    system = rigid_damper(0.012, 1.2e-7, platforms, contacts, 200.0)
    ref = ss.run(paper, "quasi-static", periods=1, steps_per_period=1)
    ds = ss.run(system, "quasi-static", duration=1e-3, steps_per_period=2)
    N = ds.normal_force.isel(time=0).values.reshape(3, 5).sum(axis=1)
    T = ds.tangential_force.isel(time=0).values.reshape(3, 5).sum(axis=1)
    np.testing.assert_allclose(N, ref.normal_force.isel(time=0).values, atol=2e-2)
    np.testing.assert_allclose(T, ref.tangential_force.isel(time=0).values, atol=2e-2)


def test_bad_patch_input_names_the_field():
    with pytest.raises(InputError, match="face.n_points"):
        face_points(L, 0, field="face")
    with pytest.raises(InputError, match="face.length"):
        face_points(-1.0, 3, field="face")
    with pytest.raises(InputError, match="crown_radius"):
        face_points(L, 3, crown_radius=L / 4, field="face")
    with pytest.raises(InputError, match="face.normal_stiffness_per_area"):
        contact_patch(
            "face",
            face_points(L, 3),
            rigid_face_gather(0.0, (0, 0), (0, 1, 2), 3),
            normal_stiffness_per_area=float("nan"),
            tangential_stiffness_per_area=1.0,
            friction_coefficient=0.3,
        )


def test_definiteness_checks_without_eigen_decomposition():
    """Structure's checks (Cholesky / sparse diagonal-pivot LU): a 400-DOF banded chain is
    accepted; one negative stiffness entry, a zero mass, and an indefinite coupling are refused
    with the smallest eigenvalue in the message, on both the dense and the sparse path."""
    from slipstep.model.structure import Structure

    for n in (50, 400):  # dense path, sparse path
        K = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
        M = np.diag(np.full(n, 0.02))
        Structure(M, 2e-5 * K, K)
        Structure(M, None, np.zeros((n, n)))  # K = 0 (a free body) is semi-definite
        free = K.copy()
        free[0, 0] = 4e5  # fixed-free -> free-free: singular, still semi-definite
        Structure(M, None, free)
        bad = K.copy()
        bad[5, 5] = -1e3
        with pytest.raises(InputError, match="structure.stiffness.*negative eigenvalue"):
            Structure(M, None, bad)
        zero_mass = M.copy()
        zero_mass[3, 3] = 0.0
        with pytest.raises(InputError, match="structure.mass.*not positive definite"):
            Structure(zero_mass)
        coupled = M.copy()
        coupled[1, 2] = coupled[2, 1] = 0.03  # |m12| > sqrt(m11 m22): indefinite
        with pytest.raises(InputError, match="structure.mass"):
            Structure(coupled)
