"""Banded linear algebra of the banded backend (issue 10): band storage, a banded LU with
partial pivoting (LAPACK gbtf2/gbtrs), band mat-vecs, sparse (CSR) gather and scatter, the
assembly of the contact stiffness A^T K(S) A into band storage, and omega_max^2 = max |eig(M^-1 K_eff)|
by Arnoldi (Lanczos in a symmetric state).

Band storage (the transpose of LAPACK's, so that a column is contiguous in a C-order array):
an n x n matrix with kl sub- and ku superdiagonals is held as ``ab`` of shape (n, kl + ku + 1),

    A[i, j] = ab[j, ku + i - j]        for max(0, j - ku) <= i <= min(n - 1, j + kl),

and its LU factorisation as ``lu`` of shape (n, 2 kl + ku + 1) (kl extra superdiagonals for the
fill-in of the row interchanges, as LAPACK gbtrf):

    A[i, j] = lu[j, kl + ku + i - j] before the factorisation;  P A = L U after it.

Costs: factorisation O(n kl (kl + ku)), solve and mat-vec O(n (kl + ku)); so a step of the
march is linear in n for a fixed bandwidth. Gather maps are CSR: (indptr, indices, data).
"""

import numpy as np
from numba import njit

from slipstep.kernels import laws
from slipstep.kernels.borrow import borrowed

#: Lanczos runs to convergence (n steps, full reorthogonalisation) up to this size, else LANCZOS_STEPS
LANCZOS_FULL = 400
LANCZOS_STEPS = 40


# ---- band storage ----------------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def band_matvec_sub(ab, kl, ku, x, out):
    """out -= A x, A in band storage ab (n, kl + ku + 1)."""
    n = x.shape[0]
    for j in range(n):
        xj = x[j]
        if xj == 0.0:
            continue
        i0 = max(0, j - ku)
        i1 = min(n - 1, j + kl)
        off = ku - j
        for i in range(i0, i1 + 1):
            out[i] -= ab[j, off + i] * xj


@njit(cache=True, nogil=True, error_model="numpy")
def band_matvec(ab, kl, ku, x, out):
    """out = A x, A in band storage."""
    for i in range(out.shape[0]):
        out[i] = 0.0
    band_matvec_sub(ab, kl, ku, x, out)
    for i in range(out.shape[0]):
        out[i] = -out[i]


@njit(cache=True, nogil=True, error_model="numpy")
def band_combine(ca, a, cb, b, cc, c, out):
    """out = ca a + cb b + cc c, elementwise on three band arrays of one shape (Lin per dt)."""
    for j in range(out.shape[0]):
        for t in range(out.shape[1]):
            out[j, t] = ca * a[j, t] + cb * b[j, t] + cc * c[j, t]


@njit(cache=True, nogil=True, error_model="numpy")
def band_diagonal(ab, ku, out):
    """out = diag A."""
    for j in range(out.shape[0]):
        out[j] = ab[j, ku]


@njit(cache=True, nogil=True, error_model="numpy")
def band_to_lu_storage(ab, kl, ku, lu):
    """Copy A from band storage (n, kl + ku + 1) into factorisation storage (n, 2 kl + ku + 1)
    (the kl fill-in rows zeroed)."""
    n = ab.shape[0]
    w = kl + ku + 1
    for j in range(n):
        for t in range(kl):
            lu[j, t] = 0.0
        for t in range(w):
            lu[j, kl + t] = ab[j, t]


# ---- banded LU (LAPACK gbtf2 / gbtrs) ---------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def band_lu_factor(lu, kl, ku, piv, singular_rtol):
    """In-place P A = L U of A held in factorisation storage ``lu`` (n, 2 kl + ku + 1), row
    pivots ``piv`` (LAPACK gbtf2: for each column the largest of the kl + 1 candidates is the
    pivot, the rows are swapped over the columns the band reaches, then the rank-1 update of
    the trailing kl x (kl + ku) block). Returns False when a pivot is below
    ``singular_rtol * max|A|`` (the threshold of kernels/linalg.py)."""
    n = lu.shape[0]
    kv = kl + ku
    scale = 0.0
    for j in range(n):
        for t in range(kl, lu.shape[1]):
            if abs(lu[j, t]) > scale:
                scale = abs(lu[j, t])
    if scale == 0.0:
        return False
    ju = 0  # the last column reached by the row interchanges so far
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        big = abs(lu[j, kv])
        for t in range(1, km + 1):
            if abs(lu[j, kv + t]) > big:
                big = abs(lu[j, kv + t])
                jp = t
        piv[j] = j + jp
        if big <= singular_rtol * scale:
            return False
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:  # swap rows j and j + jp over the columns j..ju
            for c in range(j, ju + 1):
                a = kv + j - c
                tmp = lu[c, a]
                lu[c, a] = lu[c, a + jp]
                lu[c, a + jp] = tmp
        if km > 0:
            inv = 1.0 / lu[j, kv]
            for t in range(1, km + 1):
                lu[j, kv + t] *= inv
            for c in range(j + 1, ju + 1):
                a = kv + j - c
                ujc = lu[c, a]
                if ujc != 0.0:
                    for t in range(1, km + 1):
                        lu[c, a + t] -= lu[j, kv + t] * ujc
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def band_lu_solve(lu, kl, ku, piv, b, x):
    """x = A^-1 b with the factorisation of :func:`band_lu_factor` (LAPACK gbtrs, no transpose):
    L y = P b column by column, then the upper band U (kl + ku superdiagonals) x = y.
    ``x`` and ``b`` may be the same array."""
    n = lu.shape[0]
    kv = kl + ku
    for i in range(n):
        x[i] = b[i]
    for j in range(n - 1):
        p = piv[j]
        if p != j:
            tmp = x[j]
            x[j] = x[p]
            x[p] = tmp
        xj = x[j]
        if xj != 0.0:
            for t in range(1, min(kl, n - 1 - j) + 1):
                x[j + t] -= lu[j, kv + t] * xj
    for j in range(n - 1, -1, -1):
        xj = x[j] / lu[j, kv]
        x[j] = xj
        if xj != 0.0:
            for i in range(max(0, j - kv), j):
                x[i] -= lu[j, kv + i - j] * xj


# ---- sparse gather / scatter ------------------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def csr_gather(ptr, idx, val, base, x, out):
    """out = base + A x, A in CSR (one row per local coordinate)."""
    for r in range(out.shape[0]):
        s = base[r]
        for k in range(ptr[r], ptr[r + 1]):
            s += val[k] * x[idx[k]]
        out[r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def csr_matvec(ptr, idx, val, x, out):
    """out = A x, A in CSR."""
    for r in range(out.shape[0]):
        s = 0.0
        for k in range(ptr[r], ptr[r + 1]):
            s += val[k] * x[idx[k]]
        out[r] = s


@njit(cache=True, nogil=True, error_model="numpy")
def csr_abs_max(ptr, idx, val, x):
    """max_r |(A x)_r| (0 without rows)."""
    m = 0.0
    for r in range(ptr.shape[0] - 1):
        s = 0.0
        for k in range(ptr[r], ptr[r + 1]):
            s += val[k] * x[idx[k]]
        m = max(m, abs(s))
    return m


# ---- contact stiffness in band storage ---------------------------------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def _band_add_outer(lu, off, factor, ptr, idx, val, r1, r2):
    """lu += factor A[r1]^T A[r2] into storage whose diagonal is at column ``off``
    (A[i, j] = lu[j, off + i - j]): the outer product of two sparse rows."""
    for k1 in range(ptr[r1], ptr[r1 + 1]):
        i = idx[k1]
        a = factor * val[k1]
        for k2 in range(ptr[r2], ptr[r2 + 1]):
            j = idx[k2]
            lu[j, off + i - j] += a * val[k2]


@njit(cache=True, nogil=True, error_model="numpy")
def band_contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, ptr, idx, val, state, q, w_old, factor, lu, off):
    """lu += factor K_D(S), K_D(S) = A^T K(S) A (paper Eq. 7), into band storage with the
    diagonal at column ``off`` (off = ku for band storage, kl + ku for factorisation storage),
    A in CSR: per contact the outer products of its few rows with the local stiffness of
    kernels.laws.stiffness (as kernels.contact.contact_stiffness)."""
    cl = borrowed((nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old))  # no counting per contact
    nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old = cl
    for c in range(nrow.shape[0]):
        ks, ra, rb = laws.stiffness(c, nrow, lcode, lpar, fdir, ndir, trow, kt, state, q, w_old)
        for i in range(len(ks)):
            if ks[i] != 0.0:
                _band_add_outer(lu, off, factor * ks[i], ptr, idx, val, ra[i], rb[i])


# ---- lambda_max of K phi = lambda M phi (T_min, paper Eq. 8) --------------------------------
@njit(cache=True, nogil=True, error_model="numpy")
def _start_vector(n, seed):
    """A deterministic vector with components in every direction (no symmetry of the
    structure can make it orthogonal to the top mode, as a constant vector could)."""
    v = np.empty(n)
    for i in range(n):
        v[i] = 0.5 + np.sin(12.9898 * (i + 1) + 78.233 * seed) * 43758.5453 % 1.0
    return v


@njit(cache=True, nogil=True, error_model="numpy")
def band_lambda_max(Mb, Klu, kl, ku, mlu, mpiv, m_diagonal):
    """omega_max^2 = max |eig(M^-1 K_eff)| (paper Eq. 8) by Arnoldi in the M inner product on
    the operator M^-1 K_eff (M^-1 by its banded LU (mlu, mpiv), or a division where M is
    diagonal), with full reorthogonalisation. K_eff = K + K_D(S) is given in factorisation
    storage ``Klu`` (diagonal at column kl + ku, not factorised), M in band storage. K_D(S)
    of a slip state with variable normal load is not symmetric (k_uv couples u to v), so the
    Hessenberg matrix H of the Arnoldi relation is eigen-solved in complex arithmetic, as the
    dense path does; in a symmetric state H is tridiagonal (Lanczos). Up to LANCZOS_FULL DOFs
    it runs n steps (exact up to round-off: the dense eigen-solve's value); beyond, LANCZOS_STEPS
    steps and the estimate |theta| + h_{k+1,k} |y_k| (the Ritz value of largest modulus plus its
    residual, on the safe side of a converging estimate)."""
    n = Mb.shape[0]
    kv = kl + ku
    steps = n if n <= LANCZOS_FULL else LANCZOS_STEPS
    Q = np.zeros((steps, n))
    MQ = np.zeros((steps, n))
    H = np.zeros((steps, steps))
    w = _start_vector(n, 0)
    mw = np.empty(n)
    kq = np.empty(n)
    band_matvec(Mb, kl, ku, w, mw)
    nrm = np.sqrt(max(np.dot(w, mw), 1e-300))
    k_done = 0
    seed = 1
    rest = 0.0
    for k in range(steps):
        for i in range(n):
            Q[k, i] = w[i] / nrm
            MQ[k, i] = mw[i] / nrm
        for i in range(n):  # kq = K_eff q_k
            kq[i] = 0.0
        for j in range(n):
            qj = Q[k, j]
            if qj != 0.0:
                for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
                    kq[i] += Klu[j, kv + i - j] * qj
        if m_diagonal:  # w = M^-1 K_eff q_k
            for i in range(n):
                w[i] = kq[i] / Mb[i, ku]
        else:
            band_lu_solve(mlu, kl, ku, mpiv, kq, w)
        k_done = k + 1
        for rep in range(2):  # Gram-Schmidt in the M inner product, twice (full reorthogonalisation)
            for t in range(k + 1):
                c = np.dot(MQ[t], w)
                H[t, k] += c
                for i in range(n):
                    w[i] -= c * Q[t, i]
        band_matvec(Mb, kl, ku, w, mw)
        b = np.sqrt(max(np.dot(w, mw), 0.0))
        if k + 1 == steps:
            rest = b
            break
        hk = 0.0
        for t in range(k + 1):
            hk = max(hk, abs(H[t, k]))
        if b <= 1e-10 * max(hk, 1e-300):  # an invariant subspace: go on with a fresh direction
            w = _start_vector(n, seed)
            seed += 1
            for rep in range(2):
                for t in range(k + 1):
                    c = np.dot(MQ[t], w)
                    for i in range(n):
                        w[i] -= c * Q[t, i]
            band_matvec(Mb, kl, ku, w, mw)
            nrm = np.sqrt(max(np.dot(w, mw), 1e-300))
        else:
            H[k + 1, k] = b
            nrm = b
    Hc = np.zeros((k_done, k_done), dtype=np.complex128)
    for i in range(k_done):
        for j in range(k_done):
            Hc[i, j] = H[i, j]
    ev, vec = np.linalg.eig(Hc)
    top = 0.0
    at = 0
    for i in range(k_done):
        if abs(ev[i]) > top:
            top = abs(ev[i])
            at = i
    if k_done < n:  # not run to the end: add the residual of the top Ritz pair (|y| = 1)
        nv = 0.0
        for i in range(k_done):
            nv += abs(vec[i, at]) ** 2
        top += rest * abs(vec[k_done - 1, at]) / np.sqrt(max(nv, 1e-300))
    return top


@njit(cache=True, nogil=True, error_model="numpy")
def band_is_diagonal(ab, ku):
    """True if the band storage holds a diagonal matrix."""
    for j in range(ab.shape[0]):
        for t in range(ab.shape[1]):
            if t != ku and ab[j, t] != 0.0:
                return False
    return True


@njit(cache=True, nogil=True, error_model="numpy")
def band_quadratic_forms(ab, kl, ku, X, out):
    """out[t] = X[t]^T A X[t] for every row of X (nt, n), A in band storage: O(nt n (kl + ku))."""
    n = X.shape[1]
    for t in range(X.shape[0]):
        s = 0.0
        for j in range(n):
            xj = X[t, j]
            if xj == 0.0:
                continue
            acc = 0.0
            for i in range(max(0, j - ku), min(n - 1, j + kl) + 1):
                acc += X[t, i] * ab[j, ku + i - j]
            s += acc * xj
        out[t] = s
