"""The largest eigenvalue of M^-1 K_eff without a full decomposition (issue 10 item 2):
methods/eigen.py (dense / ARPACK, dense or sparse input, massless DOFs) and kernels/eigen.py
(the march's thick-restart Krylov routine), each against the dense eigenvalues."""

import math

import numpy as np
import pytest
import scipy.sparse as sp

import slipstep as ss
from slipstep.kernels.eigen import (
    DENSE_LIMIT,
    EIG_RTOL,
    MAX_BASIS,
    MAX_RESTARTS,
    apply_operator,
    krylov_largest_modulus,
    largest_eigenvalue_modulus,
)
from slipstep.methods import eigen, step_control


def random_system(n, symmetric, rng, massless=0):
    """M SPD (massless: that many zero rows/columns at the end), K SPD, plus a non-symmetric
    part of the size of a slip coupling when not symmetric."""
    A = rng.standard_normal((n, n))
    K = A @ A.T + n * np.eye(n)
    if not symmetric:
        K = K + 0.3 * math.sqrt(n) * rng.standard_normal((n, n))
    B = rng.standard_normal((n, n))
    M = B @ B.T / n + np.eye(n)
    if massless:
        M[n - massless :, :] = 0.0
        M[:, n - massless :] = 0.0
    return M, K


def dense_reference(M, K):
    """max |eig(M^-1 K)| with DOFs without mass condensed (Schur complement), dense."""
    m = np.flatnonzero(~np.any(M != 0, axis=1))
    d = np.setdiff1d(np.arange(M.shape[0]), m)
    if m.size:
        K = K[np.ix_(d, d)] - K[np.ix_(d, m)] @ np.linalg.solve(K[np.ix_(m, m)], K[np.ix_(m, d)])
        M = M[np.ix_(d, d)]
    return float(np.abs(np.linalg.eigvals(np.linalg.solve(M, K))).max())


def chain(n, sparse=True):
    """Fixed-free chain: K tridiagonal (k = 1e6 N/m), M diagonal 1..2 kg."""
    K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tolil() * 1e6
    K[n - 1, n - 1] = 1e6
    M = sp.diags(np.linspace(1.0, 2.0, n))
    return (M.tocsr(), K.tocsr()) if sparse else (M.toarray(), K.toarray())


@pytest.mark.parametrize("n", [1, 2, 3, 10, eigen.DENSE_LIMIT, eigen.DENSE_LIMIT + 1, 150])
@pytest.mark.parametrize("symmetric", [True, False])
@pytest.mark.parametrize("sparse", [False, True])
def test_python_largest_eigenvalue_matches_dense(n, symmetric, sparse):
    rng = np.random.default_rng(1000 * n + 10 * symmetric + sparse)
    M, K = random_system(n, symmetric, rng)
    ref = dense_reference(M, K)
    args = (sp.csr_matrix(M), sp.csr_matrix(K)) if sparse else (M, K)
    got = abs(eigen.largest_eigenvalue(*args))
    assert got == pytest.approx(ref, rel=1e-9)
    assert eigen.omega_max(*args) == pytest.approx(math.sqrt(ref), rel=1e-9)


@pytest.mark.parametrize("n", [6, 90])
@pytest.mark.parametrize("sparse", [False, True])
def test_python_largest_eigenvalue_condenses_massless_dofs(n, sparse):
    rng = np.random.default_rng(n)
    M, K = random_system(n, True, rng, massless=2)
    ref = dense_reference(M, K)
    args = (sp.csr_matrix(M), sp.csr_matrix(K)) if sparse else (M, K)
    assert abs(eigen.largest_eigenvalue(*args)) == pytest.approx(ref, rel=1e-9)


def test_python_sparse_chain_against_the_tridiagonal_eigenvalue():
    """1,000-DOF chain, sparse (ARPACK on D^-1/2 K D^-1/2): the largest eigenvalue of the
    symmetric tridiagonal by LAPACK's stebz."""
    import scipy.linalg as sla

    M, K = chain(1000)
    s = 1.0 / np.sqrt(M.diagonal())
    B = sp.diags(s) @ K @ sp.diags(s)
    ref = sla.eigvalsh_tridiagonal(B.diagonal(), B.diagonal(1), select="i", select_range=(999, 999))[0]
    assert eigen.largest_eigenvalue(M, K) == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize("n", [1, 2, 3, 10, MAX_BASIS, MAX_BASIS + 1, DENSE_LIMIT + 1, 120])
@pytest.mark.parametrize("symmetric", [True, False])
@pytest.mark.parametrize("routine", [largest_eigenvalue_modulus, krylov_largest_modulus])
def test_kernel_largest_eigenvalue_matches_dense(n, symmetric, routine):
    """Both paths of the march's routine (dense B up to DENSE_LIMIT, Krylov above) and the
    Krylov routine itself at every size (full basis for n <= MAX_BASIS, restarts above)."""
    rng = np.random.default_rng(7 * n + symmetric)
    M, K = random_system(n, symmetric, rng)
    got = routine(K, eigen.mass_factor(M), EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
    assert got == pytest.approx(dense_reference(M, K), rel=1e-8)


def test_kernel_largest_eigenvalue_on_a_clustered_chain_with_restarts():
    """A 150-DOF chain: the top eigenvalues 1e-4 apart, three times the basis size."""
    M, K = chain(150, sparse=False)
    got = largest_eigenvalue_modulus(K, eigen.mass_factor(M), EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
    assert got == pytest.approx(dense_reference(M, K), rel=1e-8)


def test_kernel_krylov_unconverged_returns_a_larger_bound():
    """Out of restarts: |theta| + ||r|| (a shorter, safe step). On this symmetric chain one basis
    of 48 vectors gives theta 7e-15 below lambda_max with a residual of 2e-8 > EIG_RTOL: the
    returned bound is above lambda_max and within the residual of it."""
    M, K = chain(300, sparse=False)
    L = eigen.mass_factor(M)
    exact = dense_reference(M, K)
    early = krylov_largest_modulus(K, L, EIG_RTOL, MAX_BASIS, 0)
    assert exact <= early <= exact * (1 + 1e-6)
    assert krylov_largest_modulus(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS) == pytest.approx(exact, rel=1e-8)


def test_kernel_massless_dofs_are_held_at_zero():
    """A zero pivot of the mass factor: the operator's row and column vanish, as the former
    M^-1 with zero rows gave: max |eig(M_dd^-1 K_dd)|."""
    rng = np.random.default_rng(3)
    M, K = random_system(8, True, rng, massless=3)
    L = eigen.mass_factor(M)
    assert np.all(np.diag(L)[5:] == 0)
    d = np.arange(5)
    ref = np.abs(np.linalg.eigvals(np.linalg.solve(M[np.ix_(d, d)], K[np.ix_(d, d)]))).max()
    for routine in (largest_eigenvalue_modulus, krylov_largest_modulus):
        assert routine(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS) == pytest.approx(ref, rel=1e-10)


def test_operator_is_m_inverse_k_in_scaled_coordinates():
    """y = L^-1 K L^-T x is similar to M^-1 K: L^-T y = M^-1 K (L^-T x)."""
    rng = np.random.default_rng(5)
    M, K = random_system(7, False, rng)
    L = eigen.mass_factor(M)
    x = rng.standard_normal(7)
    y, tmp = np.empty(7), np.empty(7)
    apply_operator(K, L, x, y, tmp)
    z = np.linalg.solve(L.T, x)
    assert np.allclose(np.linalg.solve(L.T, y), np.linalg.solve(M, K @ z), rtol=1e-12, atol=0)


@pytest.mark.parametrize("method", ["newmark-adaptive", "piecewise-linear-adaptive"])
def test_march_t_min_per_state_equals_the_dense_one(method):
    """Every T_min the adaptive march cached equals the dense eigenvalue problem's."""
    system = ss.load_system("paper")
    sim = ss.Simulation(system, method, periods=1, error_estimate=False)
    assert sim.march() == ss.Status.OK
    ws = sim.ws
    used = np.flatnonzero(ws.tmin_used)
    assert used.size >= 3  # stick and the slip / lift-off states it visited
    for slot in used:
        state = ws.tmin_keys[slot]
        ev = np.linalg.eigvals(np.linalg.solve(sim.compiled.M, step_control.effective_stiffness(sim.compiled, state)))
        ref = 2 * math.pi / math.sqrt(np.abs(ev).max())
        assert ws.tmin_value[slot] == pytest.approx(ref, rel=1e-12)
        assert step_control.state_t_min(sim.compiled, state) == pytest.approx(ref, rel=1e-12)
