"""The largest eigenvalue of M^-1 K without a full eigen-decomposition (issue 10 item 2).

omega_max^2 = max |lambda|, lambda the eigenvalues of M^-1 K_eff, K_eff = K + K_D(S) (paper Eq. 8),
for M and K_eff dense (numpy) or sparse (scipy.sparse), symmetric or not (the slip tangent of a
contact with variable normal load couples mu k_n into the tangential rows):

* n <= DENSE_LIMIT: ``numpy.linalg.eigvals(solve(M, K))`` (LAPACK; ARPACK cannot run for n < 3
  and is slower up to about this size: ``benchmarks/bench_eigen.py`` measures the crossover);
* larger: ARPACK with k = 1, which = 'LM' (``scipy.sparse.linalg.eigsh`` for a symmetric K_eff,
  ``eigs`` otherwise) on the operator L^-1 K_eff L^-T (M = L L^T diagonal or Cholesky: the same
  eigenvalues as M^-1 K_eff, symmetric when K_eff is), to ARPACK_RTOL relative.

Massless DOFs (zero rows of M, :mod:`slipstep.methods.massless`) are condensed first:
K* = K_dd - K_dm K_mm^-1 K_md, omega^2 = eig(M_dd^-1 K*) (dense Schur complement below
DENSE_LIMIT, a LinearOperator with a sparse LU of K_mm above).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slipstep.errors import InputError
from slipstep.kernels import banded as BD
from slipstep.kernels.settings import contact_table

#: at most this many DOFs: the dense eigenvalue problem (measured crossover, bench_eigen.py)
DENSE_LIMIT = 64
#: relative accuracy asked of ARPACK (its residual test |K x - lambda M x| <= tol |lambda|)
ARPACK_RTOL = 1e-12
#: ARPACK's Krylov basis size (its default max(2k + 1, 20) restarts far more often on chains)
ARPACK_NCV = 40


def largest_eigenvalue(M, K) -> complex:
    """The eigenvalue of largest modulus of M^-1 K (module docstring); M, K dense or sparse,
    M symmetric positive semi-definite with zero rows marking DOFs without mass."""
    n = M.shape[0]
    if n == 0:
        return 0.0
    massless = _massless(M)
    if massless.any():
        return _condensed_largest(M, K, np.flatnonzero(massless), np.flatnonzero(~massless))
    if n <= DENSE_LIMIT:
        ev = np.linalg.eigvals(np.linalg.solve(_dense(M), _dense(K)))
        return ev[np.argmax(np.abs(ev))]
    return _arpack_largest(M, K)


def omega_max(M, K) -> float:
    """omega_max = sqrt(max |eig(M^-1 K)|) [rad/s] (paper Eq. 8)."""
    return math.sqrt(abs(largest_eigenvalue(M, K)))


def is_symmetric(K, rtol: float = 1e-12) -> bool:
    """|K - K^T| <= rtol max |K| entrywise (dense or sparse)."""
    if sp.issparse(K):
        scale = abs(K).max() if K.nnz else 0.0
        d = abs(K - K.T)
        return (d.max() if d.nnz else 0.0) <= rtol * scale
    K = np.asarray(K)
    return bool(np.abs(K - K.T).max(initial=0.0) <= rtol * np.abs(K).max(initial=0.0))


def _dense(A) -> np.ndarray:
    return A.toarray() if sp.issparse(A) else np.asarray(A, float)


def _massless(M) -> np.ndarray:
    """True where M has a zero row."""
    if sp.issparse(M):
        return ~(np.asarray(abs(sp.csr_matrix(M)).sum(axis=1)).ravel() > 0)
    return ~np.any(np.asarray(M) != 0.0, axis=1)


def _scaled_operator(M, K):
    """(operator B = L^-1 K L^-T, symmetric) with M = L L^T: L = sqrt(diag M) for a diagonal M,
    else the Cholesky factor (dense, or scipy's LU of M for sparse M, then B = M^-1 K)."""
    n = M.shape[0]
    symmetric = is_symmetric(K)
    if sp.issparse(M):
        diag = M.diagonal()
        off = M - sp.diags(diag)
        diagonal = not (off.count_nonzero() if sp.issparse(off) else 0)
    else:
        diag = np.diag(M).copy()
        diagonal = not np.any(M - np.diag(diag))
    if diagonal:
        s = 1.0 / np.sqrt(diag)
        if sp.issparse(K):
            B = sp.diags(s) @ sp.csr_matrix(K) @ sp.diags(s)
        else:
            B = s[:, None] * np.asarray(K) * s[None, :]
        return B, symmetric
    if sp.issparse(M) or sp.issparse(K):
        lu = spla.splu(sp.csc_matrix(M))
        Ks = sp.csr_matrix(K)
        op = spla.LinearOperator((n, n), matvec=lambda x: lu.solve(Ks @ x), dtype=float)
        return op, False  # M^-1 K is not symmetric in the Euclidean product: Arnoldi
    L = np.linalg.cholesky(np.asarray(M, float))
    B = sla.solve_triangular(L, sla.solve_triangular(L, np.asarray(K, float).T, lower=True).T, lower=True)
    return 0.5 * (B + B.T) if symmetric else B, symmetric


def _arpack_largest(M, K) -> complex:
    """ARPACK, k = 1, which = 'LM', on the scaled operator of :func:`_scaled_operator`."""
    B, symmetric = _scaled_operator(M, K)
    n = M.shape[0]
    ncv = min(n - 1, ARPACK_NCV)
    v0 = np.random.default_rng(12345).standard_normal(n)
    if symmetric:
        return float(spla.eigsh(B, k=1, which="LM", tol=ARPACK_RTOL, ncv=ncv, v0=v0, return_eigenvectors=False)[0])
    return complex(spla.eigs(B, k=1, which="LM", tol=ARPACK_RTOL, ncv=ncv, v0=v0, return_eigenvectors=False)[0])


def _condensed_largest(M, K, m: np.ndarray, d: np.ndarray) -> complex:
    """Largest eigenvalue of M_dd^-1 (K_dd - K_dm K_mm^-1 K_md) (module docstring)."""
    if d.size <= DENSE_LIMIT and not (sp.issparse(K) and d.size + m.size > DENSE_LIMIT):
        Kd = _dense(K)
        Ks = Kd[np.ix_(d, d)] - Kd[np.ix_(d, m)] @ np.linalg.solve(Kd[np.ix_(m, m)], Kd[np.ix_(m, d)])
        ev = np.linalg.eigvals(np.linalg.solve(_dense(M)[np.ix_(d, d)], Ks))
        return ev[np.argmax(np.abs(ev))] if ev.size else 0.0
    Kc = sp.csr_matrix(K)
    Kmm = spla.splu(sp.csc_matrix(Kc[m][:, m]))
    Kdd, Kdm, Kmd = Kc[d][:, d], Kc[d][:, m], Kc[m][:, d]
    Md = spla.splu(sp.csc_matrix(sp.csr_matrix(M)[d][:, d]))
    op = spla.LinearOperator(
        (d.size, d.size), matvec=lambda x: Md.solve(Kdd @ x - Kdm @ Kmm.solve(Kmd @ x)), dtype=float
    )
    v0 = np.random.default_rng(12345).standard_normal(d.size)
    ncv = min(d.size - 1, ARPACK_NCV)
    return complex(spla.eigs(op, k=1, which="LM", tol=ARPACK_RTOL, ncv=ncv, v0=v0, return_eigenvectors=False)[0])


def mass_factor(M) -> np.ndarray:
    """L with M = L L^T on the DOFs with mass (lower Cholesky factor, dense n x n) and zero rows
    and columns on the massless ones: the factorisation the march's eigenvalue routine uses
    (slipstep.kernels.eigen; a zero pivot marks a DOF without mass)."""
    M = _dense(M)
    n = M.shape[0]
    L = np.zeros((n, n))
    d = np.flatnonzero(~_massless(M))
    if d.size:
        L[np.ix_(d, d)] = np.linalg.cholesky(M[np.ix_(d, d)])
    return L


# ---- the banded backend (issue 10): M, K in band storage, kernel DOF order ----------------
def banded_lambda_max(cs, state: np.ndarray) -> float:
    """omega_max^2 of a contact state for the banded backend (kernels.banded.band_lambda_max)."""
    n, kl, ku = cs.Mb.shape[0], cs.kl, cs.ku
    keff = np.zeros((n, 2 * kl + ku + 1))
    BD.band_to_lu_storage(cs.Kb, kl, ku, keff)
    BD.band_contact_stiffness(
        *contact_table(cs),
        cs.A_ptr,
        cs.A_idx,
        cs.A_val,
        np.asarray(state, np.int8),
        np.empty(0),
        np.empty(0),
        1.0,
        keff,
        kl + ku,
    )
    mlu, mpiv = band_mass_lu(cs)
    return float(BD.band_lambda_max(cs.Mb, keff, kl, ku, mlu, mpiv, bool(BD.band_is_diagonal(cs.Mb, ku))))


def band_mass_lu(cs) -> tuple[np.ndarray, np.ndarray]:
    """The banded LU of M (banded backend): (lu, piv)."""
    n, kl, ku = cs.Mb.shape[0], cs.kl, cs.ku
    lu = np.zeros((n, 2 * kl + ku + 1))
    piv = np.zeros(n, np.int64)
    BD.band_to_lu_storage(cs.Mb, kl, ku, lu)
    if not BD.band_lu_factor(lu, kl, ku, piv, 1e-14):
        raise InputError("structure.mass", "is singular", "give every DOF a positive mass/inertia")
    return lu, piv
