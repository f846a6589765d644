"""The banded backend (issue 10): banded LU and products against scipy / dense numpy, the
contact stiffness in band storage and T_min against the dense path, sparse input end to end,
and whole marches of the banded backend equal to the dense one (Methods 1, 2, 3, 2+3, 4)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

import slipstep
from slipstep.errors import InputError
from slipstep.kernels import banded as BD
from slipstep.kernels.contact import add_contact_stiffness
from slipstep.kernels.settings import contact_table
from slipstep.methods.step_control import state_omega2, state_t_min
from slipstep.model.system import kernel_dofs, to_user_order


# ---- band storage and the banded LU ---------------------------------------------------------
def to_band(A, kl, ku):
    n = A.shape[0]
    ab = np.zeros((n, kl + ku + 1))
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            ab[j, ku + i - j] = A[i, j]
    return ab


def random_banded(rng, n, kl, ku, symmetric=False):
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            A[i, j] = rng.standard_normal()
    if symmetric:
        A = A + A.T
    return A


def well_conditioned(A, kl, ku):
    """A plus a diagonal that keeps it far from singular (random triangular bands are not)."""
    return A + (kl + ku + 1) * np.eye(A.shape[0])


@pytest.mark.parametrize(
    "n, kl, ku, symmetric",
    [(1, 0, 0, False), (6, 1, 1, True), (40, 3, 2, False), (50, 0, 4, False), (60, 4, 0, False), (120, 6, 6, True)],
)
def test_banded_lu_solves_like_scipy(n, kl, ku, symmetric):
    rng = np.random.default_rng(n + kl)
    A = well_conditioned(random_banded(rng, n, kl, ku, symmetric), kl, ku)
    if symmetric:
        kl = ku = max(kl, ku)
    ab = to_band(A, kl, ku)
    x = rng.standard_normal(n)
    y = np.empty(n)
    BD.band_matvec(ab, kl, ku, x, y)
    np.testing.assert_allclose(y, A @ x, rtol=0, atol=1e-13 * np.abs(A).sum())
    lu = np.zeros((n, 2 * kl + ku + 1))
    BD.band_to_lu_storage(ab, kl, ku, lu)
    piv = np.zeros(n, np.int64)
    assert BD.band_lu_factor(lu, kl, ku, piv, 1e-14)
    b = rng.standard_normal(n)
    out = np.empty(n)
    BD.band_lu_solve(lu, kl, ku, piv, b, out)
    # scipy's banded solver (LAPACK gbsv) takes the LAPACK layout: the transpose of ours
    lapack = np.zeros((kl + ku + 1, n))
    for j in range(n):
        for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
            lapack[ku + i - j, j] = A[i, j]
    expected = scipy.linalg.solve_banded((kl, ku), lapack, b)
    np.testing.assert_allclose(out, expected, rtol=1e-9, atol=1e-11 * np.abs(expected).max())
    np.testing.assert_allclose(A @ out, b, atol=1e-10 * np.abs(b).max())


def test_banded_lu_pivots_where_the_diagonal_is_zero():
    """A zero diagonal needs the row interchanges (partial pivoting), as LAPACK gbtrf does."""
    rng = np.random.default_rng(3)
    n, kl, ku = 30, 2, 1
    A = random_banded(rng, n, kl, ku)
    A[np.arange(n), np.arange(n)] = 0.0
    lu = np.zeros((n, 2 * kl + ku + 1))
    BD.band_to_lu_storage(to_band(A, kl, ku), kl, ku, lu)
    piv = np.zeros(n, np.int64)
    assert BD.band_lu_factor(lu, kl, ku, piv, 1e-14)
    assert np.any(piv != np.arange(n))
    b = rng.standard_normal(n)
    out = np.empty(n)
    BD.band_lu_solve(lu, kl, ku, piv, b, out)
    np.testing.assert_allclose(out, np.linalg.solve(A, b), rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("eps, singular", [(0.0, True), (1e-15, True), (1e-6, False)])
def test_banded_lu_detects_near_singular_matrices(eps, singular):
    """A tridiagonal matrix with a null vector (a free-free chain), shifted by eps: singular
    below the relative pivot threshold 1e-12, regular above it (the rule of kernels/linalg.py)."""
    n = 25
    A = 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    A[0, 0] = A[-1, -1] = 1.0
    A += eps * np.eye(n)
    lu = np.zeros((n, 4))
    BD.band_to_lu_storage(to_band(A, 1, 1), 1, 1, lu)
    assert BD.band_lu_factor(lu, 1, 1, np.zeros(n, np.int64), 1e-12) == (not singular)


# ---- systems ------------------------------------------------------------------------------
K_SPRING, MASS = 4e5, 0.02


def chain_system(n, nc, kind="jenkins", offset=2e-5, sparse=True, law=None):
    K = sp.diags([np.full(n, 2.0), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="lil") * K_SPRING
    K[n - 1, n - 1] = K_SPRING
    return _system(K.tocsr(), np.linspace(1, n - 3, nc).round().astype(int), kind, offset, sparse, n - 1, law)


def grid_system(side, nc, kind="2d", offset=3e-5, sparse=True):
    """A side x side grid, springs to the 4 neighbours, column 0 clamped (bandwidth ~ side)."""
    n = side * side
    idx = np.arange(n).reshape(side, side)
    K = sp.lil_matrix((n, n))
    for i in range(side):
        for j in range(side):
            for di, dj in ((0, 1), (1, 0)):
                if i + di < side and j + dj < side:
                    a, b = idx[i, j], idx[i + di, j + dj]
                    K[a, a] += K_SPRING
                    K[b, b] += K_SPRING
                    K[a, b] -= K_SPRING
                    K[b, a] -= K_SPRING
            if j == 0:
                K[idx[i, j], idx[i, j]] += K_SPRING
    where = idx[:, 1:-1].ravel()[np.linspace(0, side * (side - 2) - 1, nc).round().astype(int)]
    return _system(K.tocsr(), where, kind, offset, sparse, int(idx[side // 2, -1]))


def _system(K, where, kind, offset, sparse, tip, law=None):
    n = K.shape[0]
    M = sp.identity(n, format="csr") * MASS
    contacts = []
    for i, d in enumerate(where):
        if kind == "jenkins":
            A = sp.csr_matrix(([1.0], ([0], [d])), shape=(2, n))
        elif kind == "2d":
            A = sp.csr_matrix(([1.0, 0.5], ([0, 1], [d, d + 1])), shape=(2, n))
        else:  # quasi-3D: two tangential directions, the normal on the next DOF
            A = sp.csr_matrix(([1.0, 0.4, 0.5], ([0, 1, 2], [d, d - 1, d + 1])), shape=(3, n))
        contacts.append(
            slipstep.ContactElement(
                f"P{i}", A if sparse else A.toarray(), 5e5, 5e5, 0.3, normal_offset=offset * (1 + i % 3), law=law
            )
        )
    amp = np.zeros(n)
    amp[tip] = 20.0
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(40.0, amp),))
    C = 2e-5 * K + 2.0 * M
    mats = (M, C, K) if sparse else (M.toarray(), C.toarray(), K.toarray())
    return slipstep.System(slipstep.Structure(*mats), tuple(contacts), slipstep.Excitation(force=force), name="b")


# ---- compile: order, band, gathers --------------------------------------------------------
def test_compile_orders_the_dofs_and_keeps_the_band_narrow():
    system = grid_system(8, 10)
    cs = system.compile("banded")
    dense = system.compile("dense")
    assert cs.banded and not dense.banded
    n = system.n_dofs
    assert sorted(cs.dof_order) == list(range(n))
    assert cs.kl == cs.ku <= 2 * 8  # RCM of a grid: about its side
    assert cs.M.shape == (n, 0) and cs.A.shape == (dense.A.shape[0], 0)  # placeholders keep n and nq
    order, inv = np.asarray(cs.dof_order), kernel_dofs(cs, np.arange(n))
    np.testing.assert_array_equal(order[inv], np.arange(n))
    # every band entry is the dense matrix's entry at the reordered position
    for name in ("M", "C", "K"):
        ab = getattr(cs, name + "b")
        D = getattr(dense, name)[np.ix_(order, order)]
        np.testing.assert_array_equal(ab, to_band(D, cs.kl, cs.ku))
    A = sp.csr_matrix((cs.A_val, cs.A_idx, cs.A_ptr), shape=(dense.A.shape[0], n)).toarray()
    np.testing.assert_array_equal(A, dense.A[:, order])
    np.testing.assert_array_equal(np.asarray(cs.constant_force), np.asarray(dense.constant_force)[order])
    np.testing.assert_array_equal(to_user_order(cs, np.asarray(cs.force_sin).T).T, dense.force_sin)


@pytest.mark.parametrize("kind", ["jenkins", "2d", "q3"])
def test_contact_stiffness_and_t_min_equal_the_dense_path(kind):
    """J(S)'s contact part assembled into the band equals the dense A^T K(S) A (reordered), and
    T_min per state (Arnoldi on the band) equals the dense eigen-solve, slip states included
    (their k_uv makes K_D(S) unsymmetric)."""
    system = grid_system(7, 8, kind=kind) if kind != "jenkins" else chain_system(80, 12)
    cs, dense = system.compile("banded"), system.compile("dense")
    order = np.asarray(cs.dof_order)
    n, kl, ku = system.n_dofs, cs.kl, cs.ku
    rng = np.random.default_rng(7)
    nd = cs.kt.shape[0]
    for _ in range(4):
        owner = np.asarray(cs.direction_contact)
        lift = rng.random(len(system.contacts)) < 0.2
        state = rng.choice([1, 2, 3], nd).astype(np.int8)
        state[lift[owner]] = 0
        Kd = np.zeros((n, n))
        add_contact_stiffness(dense, state, 1.0, Kd)
        lu = np.zeros((n, 2 * kl + ku + 1))
        BD.band_contact_stiffness(
            *contact_table(cs),
            cs.A_ptr, cs.A_idx, cs.A_val, state, np.empty(0), np.empty(0), 1.0, lu, kl + ku,
        )  # fmt: skip
        expected = to_band(Kd[np.ix_(order, order)], kl, ku)
        np.testing.assert_allclose(lu[:, kl:], expected, rtol=0, atol=1e-9 * np.abs(Kd).max())
        t_dense = state_t_min(dense, state)
        t_band = state_t_min(cs, state)
        assert t_band == pytest.approx(t_dense, rel=1e-10)


def test_lambda_max_of_a_large_chain_is_on_the_safe_side():
    """Beyond LANCZOS_FULL DOFs: LANCZOS_STEPS Arnoldi steps plus the residual bound; never
    below the exact largest eigenvalue (dt never above the rule) and within 1e-6 of it."""
    system = chain_system(1200, 20)
    cs = system.compile("banded")
    K = sp.diags([np.full(1200, 2.0), -np.ones(1199), -np.ones(1199)], [0, 1, -1]).toarray() * K_SPRING
    K[-1, -1] = K_SPRING
    Kd = np.zeros_like(K)
    stick = np.ones(cs.kt.shape[0], np.int8)
    add_contact_stiffness(system.compile("dense"), stick, 1.0, Kd)
    exact = scipy.linalg.eigvalsh(K + Kd, subset_by_index=(1199, 1199))[0] / MASS
    omega2 = state_omega2(cs, stick)
    assert omega2 >= exact * (1 - 1e-12)
    assert omega2 == pytest.approx(exact, rel=1e-6)


# ---- sparse input ------------------------------------------------------------------------
def test_a_large_sparse_structure_is_validated_without_dense_matrices():
    n = 20000
    K = sp.diags([np.full(n, 2.0), -np.ones(n - 1), -np.ones(n - 1)], [0, 1, -1], format="csr")
    s = slipstep.Structure(sp.identity(n, format="csr"), None, K)
    assert s.sparse and sp.issparse(s.mass) and sp.issparse(s.damping) and s.damping.nnz == 0
    with pytest.raises(InputError, match="structure.stiffness.*not symmetric"):
        slipstep.Structure(sp.identity(n, format="csr"), None, K + sp.csr_matrix(([1.0], ([0], [5])), shape=(n, n)))
    with pytest.raises(InputError, match="structure.stiffness.*negative eigenvalue"):
        slipstep.Structure(sp.identity(n, format="csr"), None, -K)
    with pytest.raises(InputError, match="structure.mass.*not positive definite"):
        slipstep.Structure(sp.diags(np.r_[1.0, np.zeros(n - 1)], format="csr"), None, K)


def test_dense_only_features_refuse_a_large_sparse_model():
    system = chain_system(2500, 4)
    with pytest.raises(InputError, match="harmonic balance needs dense"):
        system.compile_dense("harmonic balance")
    with pytest.raises(InputError, match="quasi-static-events needs the dense backend"):
        slipstep.Simulation(system, "quasi-static-events", periods=1)
    with pytest.raises(InputError, match="central-difference needs the dense backend"):
        from slipstep.integrators import get_integrator

        get_integrator("central-difference").simulation(system, periods=0.1)


# ---- whole marches: banded equals dense -----------------------------------------------------
def _pair(system, method, **opt):
    opt.setdefault("error_estimate", False)
    d = slipstep.Simulation(system, method, linear_solver="direct", **opt).run()
    b = slipstep.Simulation(system, method, linear_solver="banded", **opt).run()
    assert d.attrs["status"] == b.attrs["status"] == "OK"
    assert (b.attrs["linear_solver"], d.attrs["linear_solver"]) == ("banded", "direct")
    assert b.attrs["bandwidth"] >= 1 and d.attrs["bandwidth"] == -1
    assert d.attrs["steps"] == b.attrs["steps"]
    return d, b


def _max_difference(d, b):
    """max |banded - dense| relative to the response range, over displacements and forces."""
    out = 0.0
    for name in ("displacement", "tangential_force", "normal_force", "slider"):
        ref = d[name].values
        out = max(out, np.abs(b[name].values - ref).max() / max(np.ptp(ref), 1e-300))
    return out


CASES = [
    ("chain-jenkins", lambda: chain_system(120, 12), ["newmark", "newmark-adaptive", "piecewise-linear",
                                                      "piecewise-linear-adaptive", "quasi-static"]),
    ("chain-2d", lambda: chain_system(150, 15, "2d", offset=6e-5), ["newmark", "piecewise-linear", "quasi-static"]),
    ("grid-2d", lambda: grid_system(9, 10, "2d"), ["newmark", "piecewise-linear", "quasi-static"]),
    ("grid-q3", lambda: grid_system(8, 8, "q3"), ["piecewise-linear", "newmark-adaptive"]),
    ("chain-circle", lambda: chain_system(60, 6, "q3", offset=6e-5, law="3d-circle"), ["piecewise-linear"]),
]  # fmt: skip


@pytest.mark.parametrize("label, build, methods", CASES, ids=[c[0] for c in CASES])
def test_banded_march_equals_dense(label, build, methods):
    system = build()
    for method in methods:
        d, b = _pair(system, method, periods=0.5)
        assert _max_difference(d, b) < 1e-9, (label, method, _max_difference(d, b))


def test_banded_result_keeps_the_energy_balance_and_the_user_dof_order():
    """The results come back in the user's DOF order (the energy balance of
    slipstep.post.energy, computed from the user's sparse matrices, closes); the tip DOF the
    force drives moves most."""
    from slipstep.post.energy import energy_balance

    system = chain_system(400, 20, "2d", offset=6e-5)
    ds = slipstep.run(system, "piecewise-linear", periods=1, error_estimate=False, save="all")
    assert ds.attrs["linear_solver"] == "banded"  # auto: sparse and n >= BANDED_MIN_N
    assert energy_balance(ds, system).attrs["relative_residual"] < 1e-8
    amplitude = np.ptp(ds["displacement"].values, axis=0)
    assert int(np.argmax(amplitude)) == system.n_dofs - 1
    # the default save of a large model: the response DOFs (those the contacts see and the
    # forced tip), named in the user's order, equal to the same columns of the full save
    auto = slipstep.run(system, "piecewise-linear", periods=1, error_estimate=False)
    seen = {
        system.structure.dof_names[j] for c in system.contacts for j in np.flatnonzero(c.dense_gather().any(axis=0))
    }
    names = list(auto["dof"].values)
    assert set(names) == seen | {system.structure.dof_names[-1]}
    assert names == sorted(names, key=system.structure.dof_names.index)
    np.testing.assert_array_equal(auto["displacement"].values, ds["displacement"].sel(dof=names).values)


def test_steady_state_by_marching_on_the_banded_backend_equals_the_dense_one():
    """Issue 24 item 7 (in part): march_to_steady runs on the banded backend (the marcher keeps
    states in the user's DOF order) and gives the dense backend's periodic orbit to round-off;
    shooting, whose period Jacobian is dense in 2 n + nd unknowns, marches a sparse structure
    densely (the same orbit), refuses the banded backend when asked for it, and refuses a sparse
    structure above DENSE_MAX_N naming harmonic balance."""
    from slipstep.steady import march_to_steady, shoot

    system = chain_system(120, 4)
    orbits = {}
    for backend in ("banded", "direct"):
        st = march_to_steady(system, linear_solver=backend, max_periods=400, tolerance=1e-8)
        assert st.ok and st.period.attrs["linear_solver"] == backend
        orbits[backend] = st.period["displacement"].values
    span = np.ptp(orbits["direct"])
    assert span > 0 and np.abs(orbits["banded"] - orbits["direct"]).max() <= 1e-9 * span
    shot = shoot(system, tolerance=1e-8)
    assert shot.ok and shot.period.attrs["linear_solver"] == "direct"
    assert np.abs(shot.period["displacement"].values - orbits["direct"]).max() <= 1e-6 * span
    with pytest.raises(InputError, match="shooting's period Jacobian needs the dense matrices"):
        shoot(system, linear_solver="banded")
    from slipstep.model.structure import DENSE_MAX_N

    with pytest.raises(InputError, match="solver='hbm'"):
        shoot(chain_system(DENSE_MAX_N + 10, 4))
