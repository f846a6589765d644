"""Substructures and assemblies (issue 11, items 1-2): the frame blade against Euler-Bernoulli,
Craig-Bampton against the full model, npz/mtx round trips, DOF prefixes, the damper between two
blades against a hand-assembled stiffness, engine-order phases, the ring's cyclic symmetry, and
bad TOML input naming the key."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

import slipstep as ss
from slipstep.casefile.case import CASES_DIR, read_toml
from slipstep.kernels.contact import add_contact_stiffness
from slipstep.model.assembly import (
    DamperLink,
    HarmonicForce,
    PlatformLink,
    assemble,
    blade_chain,
    engine_order_forces,
)
from slipstep.model.damper import DamperContact
from slipstep.model.substructure import (
    Substructure,
    cantilever_frequencies,
    craig_bampton,
    frame_blade,
    load_mtx,
    load_npz,
    save_mtx,
    save_npz,
)

E, RHO, L, B, H = 2.0e11, 7800.0, 0.12, 0.02, 0.0045
AREA, SECOND = B * H, B * H**3 / 12
MM = 1e-3
PAPER_CONTACTS = (
    DamperContact("P1", "left", (-3.914 * MM, -0.414 * MM), 13e6, 13e6, 0.4),
    DamperContact("P2", "left", (-1.086 * MM, 2.414 * MM), 13e6, 13e6, 0.4),
    DamperContact("P3", "right", (2.5 * MM, 1.0 * MM), 26e6, 26e6, 0.25),
)


def blade(n=8, **kw):
    return frame_blade("b", L, n, E, RHO, AREA, SECOND, **kw)


def stick(cs):
    return np.ones(cs.kt.shape[0], np.int8)


def stuck_stiffness(system):
    cs = system.compile()
    K = cs.K.copy()
    add_contact_stiffness(cs, stick(cs), 1.0, K)
    return cs, K


# ---- item 1: substructures ----------------------------------------------------------------
def test_frame_blade_converges_to_euler_bernoulli_bending_and_axial():
    bend, axial = cantilever_frequencies(L, E, RHO, AREA, SECOND, 3)
    errors, axial_errors = [], []
    for n in (2, 4, 8):
        f = blade(n).frequencies()
        # the in-plane spectrum holds the bending and the axial families: pick the closest
        got = np.array([f[np.argmin(abs(f - ref))] for ref in bend])
        errors.append(abs(got / bend - 1))
        axial_errors.append(abs(f[np.argmin(abs(f - axial[0]))] / axial[0] - 1))
    errors = np.array(errors)
    # linear axial elements with consistent mass converge as h^2 from above
    assert axial_errors[-1] < 2e-3 and axial_errors[1] / axial_errors[2] > 3.5
    assert np.all(np.diff(errors[:, 1:], axis=0) < 0)  # modes 2, 3 converge with elements
    assert errors[-1, 0] < 1e-5 and errors[-1, 1] < 1e-4 and errors[-1, 2] < 1e-3  # 8 elements
    # cubic-Hermite elements converge as h^4 on the second mode
    assert errors[1, 1] / errors[2, 1] > 10


def test_frame_blade_layout_and_points():
    b = blade(4, platform_node=1, platform_mass=0.05, modal_damping_ratio=0.01)
    assert b.dof_names[:3] == ("1.x", "1.y", "1.rz") and b.dof_units[:3] == ("m", "m", "rad") and b.n_dofs == 12
    assert b.points["platform"].dofs == {"x": "1.x", "y": "1.y", "rz": "1.rz"}
    assert np.allclose(b.points["tip"].position, (0.0, L))
    # the lumped platform mass: total translational mass = rho A L + 0.05 (x direction of every node)
    rigid_x = np.zeros(12)
    rigid_x[0::3] = 1
    assert rigid_x @ b.mass @ rigid_x == pytest.approx(RHO * AREA * L * (1 - 0.5 / 4 * 0) + 0.05, rel=0.2)
    # modal damping: every mode gets zeta = 1 %: phi^T C phi = 2 zeta omega (mass-normalised)
    w2, phi = scipy.linalg.eigh(b.stiffness, b.mass)
    modal = phi.T @ b.damping_matrix() @ phi
    assert np.allclose(np.diag(modal), 2 * 0.01 * np.sqrt(w2), rtol=1e-8)
    assert abs(modal - np.diag(np.diag(modal))).max() < 1e-8 * modal.max()


def test_craig_bampton_matches_full_model_lowest_frequencies():
    full = blade(16, platform_node=4)
    f_full = full.frequencies(5)
    cb = craig_bampton(full, ["4.x", "4.y", "4.rz", "16.x"], 6)
    f_cb = cb.frequencies()
    assert cb.dof_names == ("4.x", "4.y", "4.rz", "16.x", "mode1", "mode2", "mode3", "mode4", "mode5", "mode6")
    assert np.all(f_cb[:5] >= f_full * (1 - 1e-9))  # a Rayleigh-Ritz reduction: upper bounds
    assert np.allclose(f_cb[:4], f_full[:4], rtol=2e-3)
    assert f_cb[0] == pytest.approx(f_full[0], rel=2e-6) and f_cb[1] == pytest.approx(f_full[1], rel=1e-4)
    # more modes, closer (the reduction converges to the full model)
    f_more = craig_bampton(full, ["4.x", "4.y", "4.rz", "16.x"], 12).frequencies()
    assert np.all(abs(f_more[:4] / f_full[:4] - 1) <= abs(f_cb[:4] / f_full[:4] - 1) + 1e-12)
    # the kept point, and a reduction where the platform's y/rz are interior
    assert cb.points["platform"].dofs == {"x": "4.x", "y": "4.y", "rz": "4.rz"}
    assert craig_bampton(full, ["4.x", "16.x"], 1).points["platform"].dofs == {"x": "4.x"}


def test_craig_bampton_of_sparse_input_stays_sparse_and_agrees():
    full = blade(12, platform_node=3)
    sparse = Substructure(
        "s", sp.csr_matrix(full.mass), sp.csr_matrix(full.stiffness), full.dof_names, full.dof_units, points=full.points
    )
    assert sparse.sparse and sp.issparse(sparse.mass)
    a = craig_bampton(full, ["3.x", "12.x"], 3)
    b = craig_bampton(sparse, ["3.x", "12.x"], 3)  # splu + eigsh (shift-invert)
    assert np.allclose(a.frequencies(), b.frequencies(), rtol=1e-9)
    assert np.allclose(np.abs(a.stiffness), np.abs(b.stiffness), rtol=1e-7, atol=1e-9 * abs(a.stiffness).max())
    assert np.allclose(sparse.frequencies(3), full.frequencies(3), rtol=1e-9)


@pytest.mark.parametrize("sparse", [False, True])
def test_npz_and_mtx_round_trip(tmp_path, sparse):
    b = blade(3, rayleigh=(1.0, 1e-6))
    conv = sp.csr_matrix if sparse else np.asarray
    sub = Substructure(
        "blade", conv(b.mass), conv(b.stiffness), b.dof_names, b.dof_units, damping=conv(b.damping_matrix())
    )
    save_npz(sub, tmp_path / "blade.npz")
    back = load_npz(tmp_path / "blade.npz", "blade")
    paths = save_mtx(sub, tmp_path)
    back2 = load_mtx(paths["mass"], paths["stiffness"], "blade", damping=paths["damping"], dofs_file=paths["dofs"])
    for r in (back, back2):
        assert r.sparse == sparse
        assert r.dof_names == b.dof_names and r.dof_units == b.dof_units
        for got, want in ((r.mass, b.mass), (r.stiffness, b.stiffness), (r.damping, b.damping_matrix())):
            got = got.toarray() if sp.issparse(got) else got
            assert np.allclose(got, want, rtol=1e-15, atol=0)


def test_import_errors_name_the_field(tmp_path):
    np.savez(tmp_path / "bad.npz", K=np.eye(2))
    with pytest.raises(ss.InputError, match="^file: .*holds no 'M' or 'mass'"):
        load_npz(tmp_path / "bad.npz", "b")
    with pytest.raises(ss.InputError, match=r"substructures\[b\].stiffness: is not symmetric"):
        Substructure("b", np.eye(2), [[1.0, 2.0], [0.0, 1.0]])
    with pytest.raises(ss.InputError, match=r"substructures\[b\].reduction|boundary_dofs: names unknown DOF"):
        craig_bampton(blade(2), ["9.x"], 1)


# ---- item 2: assembly -------------------------------------------------------------------
def pair(mu=(0.4, 0.4, 0.25)):
    b = craig_bampton(blade(8, platform_node=2, platform_mass=0.05), ["2.x", "8.x"], 1)
    b1 = Substructure("blade1", b.mass, b.stiffness, b.dof_names, b.dof_units, points=b.points)
    b2 = Substructure("blade2", b.mass, b.stiffness, b.dof_names, b.dof_units, points=b.points)
    contacts = tuple(
        DamperContact(c.name, c.platform, c.position, c.normal_stiffness, c.tangential_stiffness, m)
        for c, m in zip(PAPER_CONTACTS, mu)
    )
    d = DamperLink(
        "damper",
        0.012,
        1.2e-7,
        200.0,
        (PlatformLink("left", math.radians(45), "blade1"), PlatformLink("right", math.radians(-45), "blade2")),
        contacts,
    )
    return b, assemble([b1, b2], [d], forces=[HarmonicForce("blade1.8.x", 1.0, 300.0)], name="pair")


def test_assembled_dof_names_are_prefixed_and_matrices_block_diagonal():
    b, system = pair()
    names = system.structure.dof_names
    assert names == (
        "blade1.2.x",
        "blade1.8.x",
        "blade1.mode1",
        "blade2.2.x",
        "blade2.8.x",
        "blade2.mode1",
        "damper.x_G",
        "damper.y_G",
        "damper.phi",
    )
    assert system.contact_names == ("damper.P1", "damper.P2", "damper.P3")
    M, K = system.structure.mass, system.structure.stiffness
    assert np.array_equal(M[:4, :4][:3, :3], b.mass) and np.array_equal(K[3:6, 3:6], b.stiffness)
    assert not M[:3, 3:].any() and not K[:6, 6:].any()
    assert np.allclose(np.diag(M)[6:], [0.012, 0.012, 1.2e-7])
    assert np.allclose(system.excitation.constant_force[6:], [0.0, 200.0, 0.0])
    assert system.motion_names == ()


def test_stuck_blade_pair_matches_hand_assembled_linear_system():
    b, system = pair()
    cs, K_stuck = stuck_stiffness(system)
    # by hand: contact c of platform P at angle theta: u = t.(G_c x_d - x_P e_X), v = n.(...)
    K = scipy.linalg.block_diag(b.stiffness, b.stiffness, np.zeros((3, 3)))
    for c in PAPER_CONTACTS:
        th = math.radians(45 if c.platform == "left" else -45)
        t, nrm = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
        a_, b_ = c.position
        G = np.array([[1, 0, -b_], [0, 1, a_]])
        P = 0 if c.platform == "left" else 3  # the platform X DOF of blade1 / blade2
        for vec, k in ((t, c.tangential_stiffness), (nrm, c.normal_stiffness)):
            row = np.zeros(9)
            row[6:] = vec @ G
            row[P] -= vec[0]
            K += k * np.outer(row, row)
    assert np.allclose(K_stuck, K, rtol=1e-13, atol=1e-6)
    # the frequency response of the stuck pair equals the hand-assembled one
    w = 2 * math.pi * 300
    F = np.zeros(9)
    F[1] = 1.0
    X1 = np.linalg.solve(K_stuck - w * w * cs.M, F)
    X2 = np.linalg.solve(K - w * w * scipy.linalg.block_diag(b.mass, b.mass, np.diag([0.012, 0.012, 1.2e-7])), F)
    assert np.allclose(X1, X2, rtol=1e-10)


def test_platform_rotation_offset_enters_the_gather():
    full = blade(4, platform_node=2)
    b1 = Substructure("blade1", full.mass, full.stiffness, full.dof_names, full.dof_units, points=full.points)
    b2 = Substructure("blade2", full.mass, full.stiffness, full.dof_names, full.dof_units, points=full.points)
    off = (0.01, -0.002)
    d = DamperLink(
        "d",
        0.012,
        1.2e-7,
        200.0,
        (
            PlatformLink("left", math.radians(45), "blade1", offset=off),
            PlatformLink("right", math.radians(-45), "blade2"),
        ),
        PAPER_CONTACTS,
    )
    s = assemble([b1, b2], [d])
    A = s.contacts[0].dof_gather  # P1 on blade1's platform (node 2: DOFs 3, 4, 5)
    t = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4)])
    lx, ly = off[0] + PAPER_CONTACTS[0].position[0], off[1] + PAPER_CONTACTS[0].position[1]
    assert np.allclose(A[0, 3:6], -(t @ np.array([[1, 0, -ly], [0, 1, lx]])))
    # a rigid translation of everything moves no contact
    rigid = np.array([1.0 if n.endswith((".x", "x_G")) else 0.0 for n in s.structure.dof_names])
    assert np.allclose(np.vstack([c.dof_gather for c in s.contacts]) @ rigid, 0.0, atol=1e-15)


def test_engine_order_phases():
    forces = engine_order_forces([f"blade{j + 1}" for j in range(6)], "8.x", 2.0, 300.0, 2)
    assert [f.dof for f in forces] == [f"blade{j + 1}.8.x" for j in range(6)]
    assert np.allclose([f.phase for f in forces], [-2 * math.pi * 2 * j / 6 for j in range(6)])
    system = ss.load_system("ring")
    h = system.excitation.force.harmonics[0]
    tips = [system.structure.dof_names.index(f"blade{j + 1}.8.x") for j in range(6)]
    assert np.allclose(h.amplitude[tips], 3.0) and np.count_nonzero(h.amplitude) == 6
    lag = np.angle(np.exp(1j * (h.phase[tips[0]] - h.phase[tips])))  # blade j lags by 2 pi EO j / N
    assert np.allclose(np.mod(lag, 2 * math.pi), np.mod(2 * math.pi * np.arange(6) / 6, 2 * math.pi))


def test_ring_cyclic_symmetry_travelling_wave_and_mode_pairs():
    system = ss.load_system("ring")
    names = system.structure.dof_names
    assert len([n for n in names if n.endswith(".x_G")]) == 6 and len(system.contacts) == 18
    cs, K = stuck_stiffness(system)
    f = np.sort(np.sqrt(np.abs(scipy.linalg.eigvals(K, cs.M).real))) / (2 * math.pi)
    low = f[:6]  # the first bending family: ND 0, 1, 1, 2, 2, 3
    assert low[1] == pytest.approx(low[2], rel=1e-9) and low[3] == pytest.approx(low[4], rel=1e-9)
    assert low[2] < low[3] * (1 - 1e-3) and low[0] < low[1] * (1 - 1e-3)
    # stuck linear steady state of the EO 1 travelling wave: equal tip amplitudes, lags 2 pi j / 6
    h = system.excitation.force.harmonics[0]
    F = h.amplitude * np.exp(1j * h.phase)
    for freq in (300.0, low[1]):
        w = 2 * math.pi * freq
        X = np.linalg.solve(K - w * w * cs.M + 1j * w * cs.C, F)
        tips = X[[names.index(f"blade{j + 1}.8.x") for j in range(6)]]
        assert np.allclose(abs(tips), abs(tips[0]), rtol=1e-9)
        assert np.allclose(tips[1:] / tips[:-1], np.exp(-1j * 2 * math.pi / 6), rtol=1e-9)


def test_blade_chain_builder_matches_the_toml_case():
    system = ss.load_system("blades")
    b = craig_bampton(blade(8, platform_node=2, platform_mass=0.05, modal_damping_ratio=0.005), ["2.x", "8.x"], 1)
    d = DamperLink(
        "damper",
        0.012,
        1.2e-7,
        200.0,
        (PlatformLink("left", math.radians(45), ""), PlatformLink("right", math.radians(-45), "")),
        PAPER_CONTACTS,
    )
    chain = blade_chain(b, 2, d, force_dof="8.x", force_amplitude=3.0, frequency=300.0, engine_order=1)
    for attr in ("stiffness", "mass", "damping"):
        want = getattr(system.structure, attr)
        assert np.allclose(getattr(chain.structure, attr), want, rtol=1e-9, atol=1e-12 * abs(want).max())
    assert np.allclose(
        np.vstack([c.dof_gather for c in chain.contacts]), np.vstack([c.dof_gather for c in system.contacts])
    )
    assert chain.structure.dof_names[:3] == ("blade1.2.x", "blade1.8.x", "blade1.mode1")


# ---- the built-in cases ----------------------------------------------------------------
def test_blades_case_damper_is_the_paper_damper_and_modes_in_range():
    paper = read_toml(CASES_DIR / "paper.toml")["damper"]
    d = read_toml(CASES_DIR / "blades.toml")["dampers"][0]
    for key in ("mass_kg", "inertia_kg_m2", "centrifugal_force_N"):
        assert d[key] == paper[key]
    assert [(p["name"], p["angle_deg"]) for p in d["platforms"]] == [
        (p["name"], p["angle_deg"]) for p in paper["platforms"]
    ]
    assert d["contacts"] == paper["contacts"]
    system = ss.load_system("blades")
    cs, K = stuck_stiffness(system)
    n = 6  # blade DOFs
    removed = np.sort(np.sqrt(scipy.linalg.eigvals(cs.K[:n, :n], cs.M[:n, :n]).real)) / (2 * math.pi)
    stuck = np.sort(np.sqrt(np.abs(scipy.linalg.eigvals(K, cs.M).real))) / (2 * math.pi)
    assert 150 < removed[0] < 600 and 150 < stuck[1] < 600 and stuck[1] > 1.2 * removed[0]
    assert stuck[-1] > 8e3  # the damper's internal modes (paper: about 10 kHz)


# ---- bad TOML input -------------------------------------------------------------------------
BLADES = (CASES_DIR / "blades.toml").read_text()
RING = (CASES_DIR / "ring.toml").read_text()


@pytest.mark.parametrize(
    "text, old, new, field",
    [
        (BLADES, "length_mm = 120.0", "lenght_mm = 120.0", "substructures[blade1].lenght_mm"),
        (BLADES, "length_mm = 120.0\n", "", "substructures[blade1].length_mm"),
        (BLADES, "length_mm = 120.0", "length_mm = -1.0", "substructures[blade1].length_mm"),
        (BLADES, "elements = 8", 'elements = "8"', "substructures[blade1].elements"),
        (
            BLADES,
            'boundary_dofs = ["2.x", "8.x"]',
            'boundary_dofs = ["2.x", "9.x"]',
            "substructures[blade1].reduction.boundary_dofs",
        ),
        (BLADES, 'copy_of = "blade1"', 'copy_of = "blade7"', "substructures[blade2].copy_of"),
        (BLADES, "mass_kg = 0.012", "mass_kg = -0.012", "dampers[damper].mass_kg"),
        (BLADES, 'substructure = "blade2"', 'substructure = "blade3"', "dampers[damper].platforms[right].substructure"),
        (BLADES, 'point = "platform"', 'point = "root"', "dampers[damper].platforms[left].point"),
        (
            BLADES,
            "normal_stiffness_N_per_um = 26.0",
            "normal_stiffness_N_per_um = 0.0",
            "dampers[damper].contacts[P3].normal_stiffness_N_per_um",
        ),
        (BLADES, 'dof = "8.x"', 'dof = "9.x"', "engine_order_force[0].dof"),
        (BLADES, "engine_order = 1", "engine_order = 1.5", "engine_order_force.0.engine_order"),
        (RING, "blades = 6", "blades = 2", "chain.blades"),
        (RING, 'blade = "blade"', 'blade = "vane"', "chain.blade"),
    ],
)
def test_bad_toml_names_the_key(tmp_path, text, old, new, field):
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ss.InputError) as err:
        ss.load_system(path)
    assert err.value.field.startswith(field.split("[0]")[0].split(".0.")[0]), str(err.value)
    assert field.replace("[0]", "").replace(".0.", ".") in str(err.value).replace("[0]", "").replace(".0.", "."), str(
        err.value
    )


def test_matrices_substructure_from_files(tmp_path):
    b = craig_bampton(blade(8, platform_node=2, platform_mass=0.05), ["2.x", "8.x"], 1)
    save_npz(b, tmp_path / "blade.npz")
    text = BLADES.replace('kind = "frame_blade"', 'kind = "matrices"\nfile = "blade.npz"')
    for key in (
        "length_mm = 120.0",
        "elements = 8",
        "youngs_modulus_GPa = 200.0",
        "density_kg_per_m3 = 7800.0",
        "area_mm2 = 90.0",
        "second_moment_mm4 = 151.875",
        "platform_node = 2",
        "platform_mass_kg = 0.05",
    ):
        text = text.replace(key, "", 1)
    text = text.replace(
        '[substructures.reduction]\nboundary_dofs = ["2.x", "8.x"]   # platform X, tip X\nmodes = 1',
        '[[substructures.points]]\nname = "platform"\nx = "2.x"',
    )
    (tmp_path / "case.toml").write_text(text)
    system = ss.load_system(tmp_path / "case.toml")  # relative file path: beside the case
    ref = ss.load_system("blades")
    assert system.structure.dof_names == ref.structure.dof_names
    for attr in ("stiffness", "mass", "damping"):
        want = getattr(ref.structure, attr)
        assert np.allclose(getattr(system.structure, attr), want, rtol=1e-9, atol=1e-12 * abs(want).max())


def test_toml_link_contact_between_tips_preload_is_analytic(tmp_path):
    """A contact on named DOFs between the two tips (normal along X, interference g) whose
    tangential row holds blade1's platform: the static preload gives N = k_n g / (1 + k_n (c1 +
    c2)), c_i the tips' static compliances (blade1's with the stuck tangential spring)."""
    text = (
        BLADES.split("[[dampers]]")[0]
        + """
[[contacts]]
name = "tips"
dofs = ["blade1.8.x", "blade2.8.x", "blade1.2.x"]
dof_gather = [[0.0, 0.0, 1.0], [1.0, -1.0, 0.0]]
normal_stiffness_N_per_m = 1.0e6
tangential_stiffness_N_per_m = 1.0e5
friction_coefficient = 0.3
normal_offset_m = 2.0e-5

[[force]]
component = "blade1.8.x"
amplitude = 0.1
frequency_Hz = 300.0
"""
    )
    path = tmp_path / "tips.toml"
    path.write_text(text)
    system = ss.load_system(path)
    assert system.contact_names == ("tips",) and system.n_dofs == 6
    A = system.contacts[0].dof_gather
    names = system.structure.dof_names
    assert A[1, names.index("blade1.8.x")] == 1 and A[1, names.index("blade2.8.x")] == -1 and A[0, 0] == 1
    sim = ss.Simulation(system, "piecewise-linear", periods=1)
    K1 = system.structure.stiffness[:3, :3].copy()
    c2 = np.linalg.inv(K1)[1, 1]
    K1[0, 0] += 1e5  # blade1's platform is held by the stuck tangential spring (row u)
    c1 = np.linalg.inv(K1)[1, 1]
    T, N = sim.f0
    assert N == pytest.approx(1e6 * 2e-5 / (1 + (c1 + c2) * 1e6), rel=1e-9)
    assert abs(T) < 0.3 * N and T == pytest.approx(1e5 * sim.preload_state[0][0], rel=1e-9)
    # constant forces by DOF name
    loaded = tmp_path / "loaded.toml"
    loaded.write_text(text.replace('name = "blades"', 'name = "blades"\nconstant_force_N = {"blade2.8.x" = 0.5}'))
    assert ss.load_system(loaded).excitation.constant_force[names.index("blade2.8.x")] == 0.5
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('"blade1.2.x"]', '"blade3.2.x"]'))
    with pytest.raises(ss.InputError, match=r"^contacts\[tips\]\.dofs: names unknown DOF 'blade3.2.x'"):
        ss.load_system(bad)


def test_readme_assembly_example_builds_the_ring_case(monkeypatch):
    """The case-file guide's Python assembly example runs and builds exactly the built-in `ring`."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "case_files.md").read_text()
    start = text.index("```python", text.index("Blades and dampers (issue 11)")) + len("```python")
    code = text[start : text.index("```", start)].replace("periods=50", "periods=1")
    ns: dict = {}
    exec(compile(code, "case_files.md", "exec"), ns)  # noqa: S102 (the guide example is our own text)
    ring = ss.load_system("ring")
    got = ns["ring"]
    assert got.structure.dof_names == ring.structure.dof_names
    for attr in ("mass", "stiffness", "damping"):
        want = getattr(ring.structure, attr)
        assert np.allclose(getattr(got.structure, attr), want, rtol=1e-9, atol=1e-12 * abs(want).max())
    assert np.allclose(
        np.vstack([c.dof_gather for c in got.contacts]), np.vstack([c.dof_gather for c in ring.contacts])
    )
    assert ns["ds"].attrs["status"] == "OK"


def test_large_frame_blade_is_sparse_and_its_craig_bampton_reduction_stays_accurate():
    big = frame_blade("big", L, 1000, E, RHO, AREA, SECOND, platform_node=250)  # 3000 DOFs, CSR
    assert big.sparse and sp.issparse(big.mass) and big.mass.nnz < 30 * big.n_dofs
    bend, _ = cantilever_frequencies(L, E, RHO, AREA, SECOND, 3)
    cb = craig_bampton(big, ["250.x", "1000.x"], 4)
    f = cb.frequencies()
    assert np.allclose(f[:3], bend, rtol=5e-3) and f[0] == pytest.approx(bend[0], rel=1e-5)
    small = blade(8, platform_node=2)
    assert not small.sparse  # small blades stay dense
    assert np.allclose(
        frame_blade("b", L, 8, E, RHO, AREA, SECOND, platform_node=2, sparse=True).mass.toarray(),
        small.mass,
        rtol=1e-14,
        atol=0,
    )
