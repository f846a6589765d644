"""The largest |eigenvalue| of M^-1 K_eff inside the march (numba; issue 10 item 2):
omega_max^2 of a contact state, T_min = 2 pi / omega_max (paper Eq. 8), without a dense
eigen-decomposition and without the dense inverse of M.

Operator. With M = L L^T (Cholesky, ``L = mass_factor``; a diagonal M gives a diagonal L),
M^-1 K_eff is similar to B = L^-1 K_eff L^-T (B = L^T (M^-1 K_eff) L^-T): the same eigenvalues,
and B is symmetric whenever K_eff is, so the Rayleigh-Ritz values below are real and certified
in that case. A zero pivot L_jj = 0 marks a DOF without mass: its coordinate is held at 0 (a
zero row and column of B, eigenvalue 0), as the former M^-1 with zero rows did. The operator is
one function, :func:`apply_operator` (dense K_eff and L here; a banded version only needs
another body).

Algorithm: Krylov-Rayleigh-Ritz with thick restarts (Arnoldi for any K_eff, Lanczos when it is
symmetric; Wu & Simon 2000, Stathopoulos & Saad 1998 for the restart). The basis V (orthonormal,
classical Gram-Schmidt twice per vector) grows by B v_last; the projection H = V^T (B V) is
formed explicitly from the stored W = B V; at MAX_BASIS vectors (or n) the Ritz pairs
(theta, y = V s) of H are taken. Stop when the Ritz value of largest modulus has the residual

    ||B y - theta y|| <= rtol |theta|,   ||y|| = 1.

For a symmetric B this certifies (Bauer-Fike, B normal) an eigenvalue within rtol |theta| of
theta, and theta <= lambda_max (Ritz values lie inside the spectrum); for a non-symmetric one it
is the same test up to the eigenvector condition number (ARPACK's test). Otherwise restart with
the MAX_BASIS // 2 Ritz vectors of largest |theta| (real and imaginary parts of complex ones),
the largest last, so the next vector B y continues the Krylov space from its residual.
Small systems (n <= DENSE_LIMIT): B is formed (scaled by the diagonal of a lumped mass, else
two triangular solves) and its eigenvalues taken by LAPACK (the symmetric solver when K_eff is
symmetric), faster there than the Krylov routine (benchmarks/bench_eigen.py); both are exact to
round-off (the former dense eigvals of M^-1 K_eff to 1e-15 on the paper case). Why not power iteration: its error falls
like (lambda_2/lambda_1)^k, hopeless for the clustered top spectra of chains (lambda_2/lambda_1 =
1 - 7e-6 at 1,000 DOFs); Krylov methods converge like a Chebyshev polynomial in sqrt of the gap.

Not converged after MAX_RESTARTS restarts: |theta| + ||r|| is returned (an eigenvalue lies within
||r|| of theta for a symmetric B), a larger omega_max, so a shorter, safe step.
"""

import numpy as np
from numba import njit

#: at most this many DOFs: the eigenvalues of the dense n x n B by LAPACK (3-6x faster than the
#: Krylov routine up to here, 1x at about 100 DOFs, 2.5-4x slower at 300-1000: bench_eigen.py)
DENSE_LIMIT = 64
#: relative residual of the Ritz pair at which the largest |eigenvalue| is accepted
EIG_RTOL = 1e-10
#: Krylov basis size (memory: 2 MAX_BASIS n numbers)
MAX_BASIS = 48
#: thick restarts at most (each: MAX_BASIS / 2 operator applications)
MAX_RESTARTS = 400


@njit(cache=True, nogil=True, error_model="numpy")
def lower_solve(L, b, out):
    """out = L^-1 b (forward substitution); a zero pivot L_jj = 0 sets out_j = 0 (no mass)."""
    n = b.shape[0]
    for i in range(n):
        if L[i, i] == 0.0:
            out[i] = 0.0
            continue
        s = b[i]
        for j in range(i):
            s -= L[i, j] * out[j]
        out[i] = s / L[i, i]


@njit(cache=True, nogil=True, error_model="numpy")
def upper_solve(L, b, out):
    """out = L^-T b (back substitution on the transpose); a zero pivot sets out_j = 0."""
    n = b.shape[0]
    for i in range(n - 1, -1, -1):
        if L[i, i] == 0.0:
            out[i] = 0.0
            continue
        s = b[i]
        for j in range(i + 1, n):
            s -= L[j, i] * out[j]
        out[i] = s / L[i, i]


@njit(cache=True, nogil=True, error_model="numpy")
def apply_operator(Keff, L, x, y, tmp):
    """y = L^-1 K_eff L^-T x: M^-1 K_eff in the coordinates z = L^T x (M = L L^T), tmp scratch (n)."""
    n = x.shape[0]
    upper_solve(L, x, tmp)
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += Keff[i, j] * tmp[j]
        y[i] = s
    for i in range(n):
        tmp[i] = y[i]
    lower_solve(L, tmp, y)


@njit(cache=True, nogil=True, error_model="numpy")
def _next_random(seed, u):
    """Fill u with deterministic pseudo-random numbers in [-1, 1) (64-bit LCG); returns the seed."""
    for i in range(u.shape[0]):
        seed = (seed * 6364136223846793005 + 1442695040888963407) & 0x7FFFFFFFFFFFFFFF
        u[i] = 2.0 * ((seed >> 11) / 4503599627370496.0) - 1.0
    return seed


@njit(cache=True, nogil=True, error_model="numpy")
def _orthogonalise(V, j, u):
    """u -= V[:j]^T (V[:j] u), twice (classical Gram-Schmidt with re-orthogonalisation); returns ||u||."""
    n = u.shape[0]
    for _ in range(2):
        for i in range(j):
            c = 0.0
            for k in range(n):
                c += V[i, k] * u[k]
            for k in range(n):
                u[k] -= c * V[i, k]
    s = 0.0
    for k in range(n):
        s += u[k] * u[k]
    return np.sqrt(s)


@njit(cache=True, nogil=True, error_model="numpy")
def _dot(a, b):
    s = 0.0
    for k in range(a.shape[0]):
        s += a[k] * b[k]
    return s


@njit(cache=True, nogil=True, error_model="numpy")
def scaled_matrix(Keff, L):
    """B = L^-1 K_eff L^-T as a dense n x n matrix (zero rows and columns for zero pivots):
    B_ij = K_ij / (L_ii L_jj) for a diagonal L (a lumped mass), else two triangular solves per
    column (:func:`lower_solve`; n <= DENSE_LIMIT here, and no LAPACK wrapper to compile)."""
    n = Keff.shape[0]
    diagonal = True
    for i in range(n):
        for j in range(i):
            if L[i, j] != 0.0:
                diagonal = False
    B = np.empty((n, n))
    if diagonal:
        d = np.empty(n)
        for i in range(n):
            d[i] = 1.0 / L[i, i] if L[i, i] != 0.0 else 0.0
        for i in range(n):
            for j in range(n):
                B[i, j] = Keff[i, j] * d[i] * d[j]
        return B
    X = np.empty((n, n))
    col = np.empty(n)
    out = np.empty(n)
    for c in range(n):  # X = L^-1 K_eff, column by column
        for i in range(n):
            col[i] = Keff[i, c]
        lower_solve(L, col, out)
        for i in range(n):
            X[i, c] = out[i]
    for r in range(n):  # B = X L^-T: row r of B is L^-1 (row r of X)
        lower_solve(L, X[r], out)
        for j in range(n):
            B[r, j] = out[j]
    return B


@njit(cache=True, nogil=True, error_model="numpy")
def dense_largest_modulus(B):
    """max |eig(B)| by LAPACK: the symmetric solver (dsyevd) when B is symmetric to 1e-13 of its
    largest entry (the part 1e-13 off is round-off of K_eff's assembly), else the general one."""
    n = B.shape[0]
    scale = 0.0
    asym = 0.0
    for i in range(n):
        for j in range(n):
            scale = max(scale, abs(B[i, j]))
            asym = max(asym, abs(B[i, j] - B[j, i]))
    best = 0.0
    if asym <= 1e-13 * scale:
        S = np.empty((n, n))
        for i in range(n):
            for j in range(n):
                S[i, j] = 0.5 * (B[i, j] + B[j, i])
        ev = np.linalg.eigvalsh(S)
        for i in range(n):
            best = max(best, abs(ev[i]))
        return best
    evc = np.linalg.eigvals(B.astype(np.complex128))
    for i in range(n):
        best = max(best, abs(evc[i]))
    return best


@njit(cache=True, nogil=True, error_model="numpy")
def largest_eigenvalue_modulus(Keff, L, rtol, max_basis, max_restarts):
    """max |eig(M^-1 K_eff)| to the relative residual rtol (module docstring), M = L L^T:
    LAPACK on the dense B up to DENSE_LIMIT DOFs, the thick-restart Krylov routine above."""
    n = Keff.shape[0]
    if n == 0:
        return 0.0
    if n <= DENSE_LIMIT:
        return dense_largest_modulus(scaled_matrix(Keff, L))
    return krylov_largest_modulus(Keff, L, rtol, max_basis, max_restarts)


@njit(cache=True, nogil=True, error_model="numpy")
def krylov_largest_modulus(Keff, L, rtol, max_basis, max_restarts):
    """max |eig(L^-1 K_eff L^-T)| by the thick-restart Krylov-Rayleigh-Ritz iteration of the
    module docstring, to the relative residual rtol (any n)."""
    n = Keff.shape[0]
    if n == 0:
        return 0.0
    m = min(n, max_basis)
    V = np.zeros((m, n))
    W = np.zeros((m, n))
    H = np.zeros((m, m))
    u = np.empty(n)
    tmp = np.empty(n)
    seed = _next_random(np.int64(20261201), u)  # np.int64: one specialisation, not one per literal
    for i in range(n):
        u[i] += 1.5  # a component along every direction, whatever the LCG gives
    nrm = np.sqrt(_dot(u, u))
    for k in range(n):
        V[0, k] = u[k] / nrm
    apply_operator(Keff, L, V[0], W[0], tmp)
    H[0, 0] = _dot(V[0], W[0])
    j = 1
    best = 0.0
    for restart in range(max_restarts + 1):
        # ---- expand the basis by B v_last (a new random direction on breakdown) ----
        while j < m:
            for k in range(n):
                u[k] = W[j - 1, k]
            ref = np.sqrt(_dot(u, u))
            nrm = _orthogonalise(V, np.int64(j), u)
            tries = 0
            while not nrm > 1e-10 * ref and tries < 3:  # invariant subspace found: a fresh direction
                seed = _next_random(seed, u)
                ref = np.sqrt(_dot(u, u))
                nrm = _orthogonalise(V, np.int64(j), u)
                tries += 1
            if not nrm > 1e-10 * ref:
                break
            for k in range(n):
                V[j, k] = u[k] / nrm
            apply_operator(Keff, L, V[j], W[j], tmp)
            for i in range(j + 1):
                H[i, j] = _dot(V[i], W[j])
                H[j, i] = _dot(V[j], W[i])
            j += 1
        # ---- Rayleigh-Ritz: the Ritz value of largest modulus and its residual ----
        theta, S = np.linalg.eig(H[:j, :j].astype(np.complex128))
        order = np.argsort(-np.abs(theta))
        top = order[0]
        t = theta[top]
        res2 = 0.0
        for k in range(n):
            r = 0.0 + 0.0j
            for i in range(j):
                r += S[i, top] * (W[i, k] - t * V[i, k])
            res2 += r.real * r.real + r.imag * r.imag
        res = np.sqrt(res2)
        best = abs(t)
        if j >= n or res <= rtol * best:
            return best
        if restart == max_restarts:
            return best + res
        # ---- thick restart: keep the real span of the p Ritz vectors of largest |theta| ----
        p = max(1, m // 2)
        C = np.zeros((p, j))  # coefficient vectors of the kept vectors, orthonormal in R^j
        c = np.empty(j)
        count = 0
        for idx in range(j):
            if count == p:
                break
            col = order[idx]
            for part in range(2):
                if count == p:
                    break
                for i in range(j):
                    c[i] = S[i, col].real if part == 0 else S[i, col].imag
                cn = _orthogonalise(C, np.int64(count), c)
                if cn > 1e-8:
                    for i in range(j):
                        C[count, i] = c[i] / cn
                    count += 1
        # the top Ritz vector's real part last (the next expansion continues from B y_top)
        Vn = np.zeros((count, n))
        Wn = np.zeros((count, n))
        for a in range(count):
            row = count - 1 - a
            for i in range(j):
                ci = C[a, i]
                if ci != 0.0:
                    for k in range(n):
                        Vn[row, k] += ci * V[i, k]
                        Wn[row, k] += ci * W[i, k]
        for a in range(count):
            for k in range(n):
                V[a, k] = Vn[a, k]
                W[a, k] = Wn[a, k]
        for a in range(count):
            for b in range(count):
                H[a, b] = _dot(V[a], W[b])
        j = count
    return best
