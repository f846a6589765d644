"""Dense LU factorisation with partial pivoting, kept so a factorisation can be cached and
reused (numba's np.linalg.solve refactorises on every call).

    P A = L U,   solve A x = b  by  L y = P b,  U x = y.
"""

from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def lu_factor(A, lu, piv, singular_rtol):
    """Factorise A into ``lu`` (L below the diagonal, unit diagonal implied; U on and above)
    and row pivots ``piv`` (``lu`` may be ``A`` itself: in place). Returns False if a pivot is
    below ``singular_rtol * max|A|``."""
    n = A.shape[0]
    scale = 0.0
    for i in range(n):
        for j in range(n):
            lu[i, j] = A[i, j]
            if abs(A[i, j]) > scale:
                scale = abs(A[i, j])
    if scale == 0.0:
        return False
    for k in range(n):
        p = k
        big = abs(lu[k, k])
        for i in range(k + 1, n):
            if abs(lu[i, k]) > big:
                big = abs(lu[i, k])
                p = i
        piv[k] = p
        if big <= singular_rtol * scale:
            return False
        if p != k:
            for j in range(n):
                tmp = lu[k, j]
                lu[k, j] = lu[p, j]
                lu[p, j] = tmp
        inv = 1.0 / lu[k, k]
        for i in range(k + 1, n):
            lu[i, k] *= inv
            lik = lu[i, k]
            if lik != 0.0:
                for j in range(k + 1, n):
                    lu[i, j] -= lik * lu[k, j]
    return True


@njit(cache=True, error_model="numpy", inline="always")
def lu_solve(lu, piv, b, x):
    """Solve with a factorisation from :func:`lu_factor`; ``x`` and ``b`` must be distinct."""
    n = lu.shape[0]
    for i in range(n):
        x[i] = b[i]
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = x[k]
            x[k] = x[p]
            x[p] = tmp
    for i in range(n):
        s = x[i]
        for j in range(i):
            s -= lu[i, j] * x[j]
        x[i] = s
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= lu[i, j] * x[j]
        x[i] = s / lu[i, i]


@njit(cache=True, error_model="numpy", inline="always")
def lu_solve_rows(lu, piv, B):
    """Solve A X = B in place for the columns of B (n x r, row-major) with a factorisation from
    :func:`lu_factor`: the row swaps of P, then L Y = P B and U X = Y a row of B at a time, so
    the inner loop runs along a contiguous row of r right-hand sides."""
    n, r = B.shape
    for k in range(n):
        p = piv[k]
        if p != k:
            for j in range(r):
                tmp = B[k, j]
                B[k, j] = B[p, j]
                B[p, j] = tmp
    for i in range(n):
        for k in range(i):
            lik = lu[i, k]
            if lik != 0.0:
                for j in range(r):
                    B[i, j] -= lik * B[k, j]
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            uik = lu[i, k]
            if uik != 0.0:
                for j in range(r):
                    B[i, j] -= uik * B[k, j]
        inv = 1.0 / lu[i, i]
        for j in range(r):
            B[i, j] *= inv
