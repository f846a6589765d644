"""How the cost grows with the structure's size and the number of contact points (issue 10).

Two families of structures, each with a harmonic force and Jenkins contacts (constant normal
load by interference) spread evenly over the DOFs:

* ``chain``: a fixed-free chain of N masses (tridiagonal K), the contacts grounding masses;
* ``grid``: a 2D FE-like square grid of masses, springs to the 4 neighbours, clamped on one
  edge (banded K, bandwidth sqrt(N)), the contacts on the free edge and the interior.

For each (N, contact points) the script prints: the set-up time (System build +
Simulation set-up, which includes T_min and the preload), the kernel time of one excitation
period for Methods 1, 3, 2+3 and quasi-static, the steps per period, and the peak memory of
the set-up and march (tracemalloc: numpy's allocations). Then the fitted cost exponents:
the slope of log(time per step) against log N at fixed contacts, and against log(contact
points) at fixed N. A case whose set-up or period takes longer than ``--budget`` seconds is
skipped for the larger sizes of that method (printed as '>budget').

Usage:  python benchmarks/bench_scaling.py [--family chain|grid] [--sizes 100,200,400]
            [--contacts 20] [--contact-sizes 10,20,40] [--contact-n 200] [--methods 1,3,2+3,4]
            [--budget 60] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import time
import tracemalloc

import numpy as np

import slipstep

METHODS = {"1": "newmark", "3": "piecewise-linear", "2+3": "piecewise-linear-adaptive", "4": "quasi-static"}
FREQUENCY_HZ = 40.0
MASS_KG, SPRING_N_PER_M = 0.02, 4e5


def chain(n: int, n_contacts: int) -> slipstep.System:
    """Fixed-free chain: K = k tridiag(-1, 2, -1) with the last diagonal entry k (free end)."""
    K = SPRING_N_PER_M * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    K[-1, -1] = SPRING_N_PER_M
    return _with_contacts(K, np.arange(n), n_contacts, tip=n - 1, name=f"chain-{n}-{n_contacts}")


def grid(n: int, n_contacts: int) -> slipstep.System:
    """Square grid side s = round(sqrt(n)) of masses with springs to the 4 neighbours, the
    column j = 0 clamped (springs to ground)."""
    s = max(2, round(math.sqrt(n)))
    n = s * s
    K = np.zeros((n, n))
    idx = np.arange(n).reshape(s, s)
    for i in range(s):
        for j in range(s):
            a = idx[i, j]
            for di, dj in ((0, 1), (1, 0)):
                if i + di < s and j + dj < s:
                    b = idx[i + di, j + dj]
                    K[a, a] += SPRING_N_PER_M
                    K[b, b] += SPRING_N_PER_M
                    K[a, b] -= SPRING_N_PER_M
                    K[b, a] -= SPRING_N_PER_M
            if j == 0:
                K[a, a] += SPRING_N_PER_M
    return _with_contacts(K, idx[:, 1:].ravel(), n_contacts, tip=int(idx[s // 2, s - 1]), name=f"grid-{n}-{n_contacts}")


def _with_contacts(K: np.ndarray, candidates: np.ndarray, n_contacts: int, tip: int, name: str) -> slipstep.System:
    n = K.shape[0]
    M = np.diag(np.full(n, MASS_KG))
    where = candidates[np.linspace(0, candidates.size - 1, n_contacts).round().astype(int)]
    contacts = []
    for i, dof in enumerate(where):
        A = np.zeros((2, n))
        A[0, dof] = 1.0
        contacts.append(slipstep.ContactElement(f"J{i}", A, 5e5, 5e5, 0.3, normal_offset=2e-5 * (1 + i % 5)))
    amplitude = np.zeros(n)
    amplitude[tip] = 20.0
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(FREQUENCY_HZ, amplitude),))
    structure = slipstep.Structure(M, 2e-5 * K + 2.0 * M, K)
    return slipstep.System(structure, tuple(contacts), slipstep.Excitation(force=force), name=name)


def measure(build, n: int, n_contacts: int, method: str) -> dict:
    """Set-up and one-period kernel time of one (size, contacts, method)."""
    tracemalloc.start()
    start = time.perf_counter()
    system = build(n, n_contacts)
    sim = slipstep.Simulation(system, method, periods=1)
    setup = time.perf_counter() - start
    sim.march()  # first march: the compiled kernel is loaded (and warm caches)
    kernel = sim.kernel_time
    sim.march()
    kernel = min(kernel, sim.kernel_time)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    steps = int(sim.out.counters[0])
    return {
        "n": system.n_dofs,
        "contacts": n_contacts,
        "method": method,
        "setup_s": setup,
        "period_s": kernel,
        "steps": steps,
        "per_step_us": kernel / max(steps, 1) * 1e6,
        "peak_MB": peak / 1e6,
        "status": sim.status.name,
    }


def slope(xs, ys) -> float:
    """Least-squares slope of log y against log x."""
    if len(xs) < 2:
        return math.nan
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def sweep(build, pairs, methods, budget) -> list[dict]:
    rows, over = [], set()
    for n, nc in pairs:
        for label in methods:
            method = METHODS[label]
            if method in over:
                print(f"  N={n:6d} contacts={nc:4d} Method {label:3s}: >budget (skipped)")
                continue
            row = measure(build, n, nc, method)
            row["label"] = label
            rows.append(row)
            print(
                f"  N={row['n']:6d} contacts={nc:4d} Method {label:3s}: set-up {row['setup_s']:8.3f} s, period "
                f"{row['period_s']:8.4f} s, {row['steps']:6d} steps, {row['per_step_us']:9.1f} us/step, "
                f"peak {row['peak_MB']:8.1f} MB, {row['status']}",
                flush=True,
            )
            if row["setup_s"] + row["period_s"] > budget:
                over.add(method)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", choices=("chain", "grid"), default="chain")
    ap.add_argument("--sizes", default="100,200,400")
    ap.add_argument("--contacts", type=int, default=20, help="contact points for the N sweep")
    ap.add_argument("--contact-sizes", default="10,20,40")
    ap.add_argument("--contact-n", type=int, default=200, help="DOFs for the contact-point sweep")
    ap.add_argument("--methods", default="1,3,2+3,4")
    ap.add_argument("--budget", type=float, default=60.0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    build = chain if args.family == "chain" else grid
    methods = args.methods.split(",")
    sizes = [int(s) for s in args.sizes.split(",")]
    contact_sizes = [int(s) for s in args.contact_sizes.split(",")]
    measure(build, 20, 2, METHODS[methods[0]])  # compile/load the kernels outside the timings
    print(f"{args.family}: N sweep at {args.contacts} contacts")
    by_n = sweep(build, [(n, args.contacts) for n in sizes], methods, args.budget)
    print(f"{args.family}: contact sweep at N = {args.contact_n}")
    by_c = sweep(build, [(args.contact_n, c) for c in contact_sizes], methods, args.budget)
    print("fitted exponents of the time per step (log-log slope): in N | in contact points")
    for label in methods:
        rn = [r for r in by_n if r["label"] == label]
        rc = [r for r in by_c if r["label"] == label]
        print(
            f"  Method {label:3s}: {slope([r['n'] for r in rn], [r['per_step_us'] for r in rn]):5.2f} | "
            f"{slope([r['contacts'] for r in rc], [r['per_step_us'] for r in rc]):5.2f}   "
            f"(set-up exponent in N: {slope([r['n'] for r in rn], [r['setup_s'] for r in rn]):5.2f})"
        )
    if args.json:
        from slipstep.io import atomic_path

        with atomic_path(args.json) as tmp:
            tmp.write_text(json.dumps({"by_n": by_n, "by_contacts": by_c}, indent=2))


if __name__ == "__main__":
    main()
