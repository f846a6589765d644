"""T_min from the largest eigenvalue alone (issue 10 item 2): times and accuracy.

1. The crossover of slipstep.methods.eigen: dense LAPACK eigvals(solve(M, K)) against ARPACK
   (k = 1, which = 'LM') on chains and random non-symmetric systems of n DOFs (sets DENSE_LIMIT).
2. Sparse chains of 1,000 and 10,000 DOFs (K tridiagonal, M diagonal), symmetric and with a
   non-symmetric slip coupling: methods.eigen.largest_eigenvalue against LAPACK's tridiagonal
   eigenvalue (stebz) for the symmetric one.
3. The march's routine (kernels/eigen.py, dense K_eff and mass factor: LAPACK on B up to its
   DENSE_LIMIT, the Krylov routine above) and the Krylov routine alone, against the dense
   eigvals(M^-1 K_eff) the march used before, per contact state.

Times: min (median) of R repeats, the contenders interleaved in the same run.

    python benchmarks/bench_eigen.py [--repeats R] [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numba import njit

from slipstep.kernels.eigen import (
    DENSE_LIMIT,
    EIG_RTOL,
    MAX_BASIS,
    MAX_RESTARTS,
    krylov_largest_modulus,
    largest_eigenvalue_modulus,
)
from slipstep.methods import eigen


@njit(cache=True)
def former_kernel(Minv, Keff):
    """The march's T_min before issue 10: eigvals of the dense M^-1 K_eff (complex LAPACK)."""
    ev = np.linalg.eigvals(np.dot(Minv, Keff).astype(np.complex128))
    best = 0.0
    for i in range(ev.shape[0]):
        best = max(best, abs(ev[i]))
    return best


def chain(n: int, sparse: bool):
    K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1]).tolil() * 1e6
    K[n - 1, n - 1] = 1e6
    M = sp.diags(np.linspace(1.0, 2.0, n))
    return (M.tocsr(), K.tocsr()) if sparse else (M.toarray(), K.toarray())


def random_nonsymmetric(n: int, rng):
    A = rng.standard_normal((n, n))
    K = A @ A.T + n * np.eye(n) + 0.3 * np.sqrt(n) * rng.standard_normal((n, n))
    B = rng.standard_normal((n, n))
    return B @ B.T / n + np.eye(n), K


def timed(funcs: dict, repeats: int) -> dict:
    """{name: (min, median)} of interleaved repeats."""
    times = {k: [] for k in funcs}
    for _ in range(repeats):
        for name, f in funcs.items():
            t0 = time.perf_counter()
            f()
            times[name].append(time.perf_counter() - t0)
    return {k: (min(v), statistics.median(v)) for k, v in times.items()}


def ms(t) -> str:
    return f"{t[0] * 1e3:8.2f} ({t[1] * 1e3:.2f})"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="2 repeats")
    args = ap.parse_args()
    if args.quick:
        args.repeats = 2
    rng = np.random.default_rng(2026)
    largest_eigenvalue_modulus(np.eye(3), np.eye(3), EIG_RTOL, MAX_BASIS, MAX_RESTARTS)  # compile
    krylov_largest_modulus(np.eye(3), np.eye(3), EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
    former_kernel(np.eye(3), np.eye(3))

    print("1. dense eigvals against ARPACK, ms: min (median); DENSE_LIMIT =", eigen.DENSE_LIMIT)
    print(f"{'n':>5} {'system':>8} {'dense':>18} {'ARPACK':>18} {'ratio':>6}")
    for n in (16, 32, 48, 64, 96, 128, 200, 400):
        for label, (M, K) in (("chain", chain(n, False)), ("random", random_nonsymmetric(n, rng))):
            t = timed(
                {
                    "dense": lambda M=M, K=K: np.linalg.eigvals(np.linalg.solve(M, K)),
                    "arpack": lambda M=M, K=K: eigen._arpack_largest(M, K),
                },
                args.repeats,
            )
            print(f"{n:5d} {label:>8} {ms(t['dense'])} {ms(t['arpack'])} {t['dense'][0] / t['arpack'][0]:6.2f}")

    print("\n2. sparse chains (methods.eigen.largest_eigenvalue), ms: min (median)")
    for n in (1000, 10000):
        M, K = chain(n, True)
        K2 = K.tolil()
        K2[0, 5] = 3e5  # a slip coupling: non-symmetric (eigs)
        K2 = K2.tocsr()
        s = 1.0 / np.sqrt(M.diagonal())
        B = sp.diags(s) @ K @ sp.diags(s)
        ref = sla.eigvalsh_tridiagonal(B.diagonal(), B.diagonal(1), select="i", select_range=(n - 1, n - 1))[0]
        t = timed(
            {
                "sym": lambda M=M, K=K: eigen.largest_eigenvalue(M, K),
                "nonsym": lambda M=M, K2=K2: eigen.largest_eigenvalue(M, K2),
                "stebz": lambda B=B, n=n: sla.eigvalsh_tridiagonal(
                    B.diagonal(), B.diagonal(1), select="i", select_range=(n - 1, n - 1)
                ),
            },
            max(1, args.repeats // 2),
        )
        err = abs(eigen.largest_eigenvalue(M, K) - ref) / ref
        print(
            f"  n = {n:6d}: symmetric (eigsh) {ms(t['sym'])} ms, relative error {err:.1e} against stebz "
            f"({ms(t['stebz'])} ms); non-symmetric (eigs) {ms(t['nonsym'])} ms"
        )

    print(f"\n3. the march's routine (LAPACK on B up to {DENSE_LIMIT} DOFs, Krylov above) and the Krylov")
    print("   routine alone, against the former kernel's complex eigvals(M^-1 K_eff), per state, ms: min (median)")
    for n in (3, 20, 48, 64, 100, 300, 1000):
        for label, (M, K) in (("chain", chain(n, False)), ("random", random_nonsymmetric(n, rng))):
            L = eigen.mass_factor(M)
            Minv = np.linalg.inv(M)
            ref = np.abs(np.linalg.eigvals(Minv @ K)).max()
            got = largest_eigenvalue_modulus(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
            kry = krylov_largest_modulus(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS)
            reps = args.repeats if n <= 300 else 1
            t = timed(
                {
                    "former": lambda Minv=Minv, K=K: former_kernel(Minv, K),
                    "march": lambda K=K, L=L: largest_eigenvalue_modulus(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS),
                    "krylov": lambda K=K, L=L: krylov_largest_modulus(K, L, EIG_RTOL, MAX_BASIS, MAX_RESTARTS),
                },
                reps,
            )
            print(
                f"  n = {n:5d} {label:>7}: former {ms(t['former'])}  march {ms(t['march'])}  "
                f"Krylov {ms(t['krylov'])}  former/march {t['former'][0] / t['march'][0]:5.2f}  "
                f"relative difference {abs(got - ref) / ref:.1e} (Krylov {abs(kry - ref) / ref:.1e})"
            )


if __name__ == "__main__":
    main()
