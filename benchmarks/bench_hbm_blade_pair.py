"""Harmonic balance on the Craig-Bampton blade pair of bench_blade_pair.py (issue 24, item 2).

The model of issue 24: ``--elements 166 --modes 10 --points 100`` (31 DOFs after the
reduction, 200 contact points, 400 contact coordinates, the contacts on the damper's and the
platforms' 9 rigid-body DOFs); the grid of ``--count`` points (default 61) between 0.7 and
1.1 times the first stuck frequency; H = ``--harmonics`` (default 7: harmonics 0..7).

Measured in one run:

* baseline, the balance on the contact coordinates (``condense="contacts"``, the path of
  issue 13: n_coef x 400 unknowns, dense products and solve): one Newton iteration (residual,
  Jacobian, solve) at the first grid frequency, against the same iteration of the balance on
  the gathered DOFs (``condense="dofs"``, n_coef x 9 unknowns), and their ratio; with
  ``--baseline-point`` also a whole point of each from the static preload;
* the FRF over the grid at the defaults (continuation, truncation estimate at the asked
  points): wall time, time per asked point and per computed point, the points by kind, the
  largest truncation estimate of the asked points;
* with ``--check``: the time-marching cross-check at the FRF peak (hbm/crosscheck.py: the
  marched periodic steady state of the same System from the HBM state): amplitude and
  friction-energy differences against the point's truncation estimate.

Usage:  python benchmarks/bench_hbm_blade_pair.py [--quick] [--count 61] [--harmonics 7] [--check]
            [--baseline-point] [--elements 166] [--points 100] [--modes 10] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from bench_blade_pair import blade, pair, reduced, stuck_frequencies

from slipstep.hbm import HarmonicBalance, frf
from slipstep.hbm.residual import blas_threads


def newton_iteration(hb: HarmonicBalance, omega: float) -> float:
    """Seconds of one Newton iteration (residual, Jacobian, solve) from the static preload."""
    with blas_threads(hb.size):
        Y = hb.initial_guess()
        hb.linear.at(omega, 1.0)
        t = time.perf_counter()
        R, J, _, _ = hb.evaluate(Y, omega, 1.0, refactor=False)
        np.linalg.solve(J, -R)
        return time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--elements", type=int, default=166)
    ap.add_argument("--modes", type=int, default=10)
    ap.add_argument("--points", type=int, default=100, help="contact points per damper face (2 faces)")
    ap.add_argument("--count", type=int, default=61, help="grid points between 0.7 and 1.1 x the first stuck mode")
    ap.add_argument("--harmonics", type=int, default=7)
    ap.add_argument("--check", action="store_true", help="cross-check the peak by time marching")
    ap.add_argument("--baseline-point", action="store_true", help="also solve one whole point by each path")
    ap.add_argument("--quick", action="store_true", help="21 grid points (the same model)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    if args.quick:
        args.count = 21

    cb = reduced(blade(args.elements), args.modes)
    f1 = float(stuck_frequencies(pair(cb, args.points, None), 1)[0])
    system = pair(cb, args.points, f1)
    freqs = np.linspace(0.7 * f1, 1.1 * f1, args.count)
    cs = system.compile()
    print(
        f"model: {cs.M.shape[0]} DOFs, {len(system.contacts)} contact points, {cs.A.shape[0]} contact coordinates;"
        f" first stuck mode {f1:.2f} Hz; grid {freqs[0]:.1f}..{freqs[-1]:.1f} Hz, {freqs.size} points;"
        f" H = {args.harmonics} (harmonics 0..{args.harmonics})"
    )
    rows = {"model": {"dofs": cs.M.shape[0], "contact_coordinates": cs.A.shape[0], "first_stuck_Hz": f1}}

    omega0 = 2 * np.pi * freqs[0]
    fast = HarmonicBalance(system, args.harmonics, condense="dofs")
    old = HarmonicBalance(system, args.harmonics, condense="contacts")
    newton_iteration(fast, omega0)  # warm-up (numba, caches)
    t_fast = min(newton_iteration(fast, omega0) for _ in range(3))
    t_old = newton_iteration(old, omega0)
    print(
        f"one Newton iteration: contact coordinates ({old.size} unknowns) {t_old:.3f} s,"
        f" gathered DOFs ({fast.size} unknowns) {t_fast * 1e3:.2f} ms, ratio {t_old / t_fast:.0f}x"
    )
    rows["newton_iteration_s"] = {"contacts": t_old, "dofs": t_fast, "ratio": t_old / t_fast}
    if args.baseline_point:
        for label, hb in (("contacts", old), ("dofs", fast)):
            t = time.perf_counter()
            pt = hb.solve(omega0)
            dt = time.perf_counter() - t
            print(f"one point at {freqs[0]:.1f} Hz by {label}: {dt:.2f} s, {pt.iterations} iterations, {pt.converged}")
            rows[f"point_{label}_s"] = dt

    t = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = frf(system, freqs, harmonics=args.harmonics, check="peak" if args.check else "none")
    wall = time.perf_counter() - t
    kind = ds.point_kind.values
    asked = kind == "asked"
    est = ds.harmonic_truncation_estimate.values[asked]
    n_kinds = {k: int(np.sum(kind == k)) for k in ("asked", "continuation", "turning")}
    print(
        f"FRF: {wall:.1f} s wall, of which {ds.attrs['solve_time_s']:.1f} s solve + estimate:"
        f" {ds.attrs['solve_time_s'] / freqs.size:.2f} s per asked point, {ds.attrs['solve_time_s'] / kind.size:.3f} s"
        f" per computed point; points {n_kinds};"
        f" status {dict(zip(*np.unique(ds.status.values, return_counts=True)))}; asked frequencies exact:"
        f" {bool(np.array_equal(ds.frequency.values[asked], freqs))}"
    )
    finite = est[np.isfinite(est)]
    print(
        f"truncation estimate at the asked points: median {np.median(finite):.2e}, max {finite.max():.2e}"
        f" ({int(np.sum(~np.isfinite(est)))} without an extended solution); {len(caught)} warning(s)"
    )
    rows["frf"] = {
        "wall_s": wall,
        "per_asked_point_s": ds.attrs["solve_time_s"] / freqs.size,
        "solve_s": ds.attrs["solve_time_s"],
        "points": n_kinds,
        "truncation_estimate_max": float(finite.max()),
        "truncation_estimate_nonfinite": int(np.sum(~np.isfinite(est))),
    }
    if args.check:
        summary = json.loads(ds.attrs["check_summary"])[0]
        i = summary["index"]
        e = float(ds.harmonic_truncation_estimate.values[i])
        print(
            f"peak {summary['frequency_Hz']:.3f} Hz ({kind[i]}): marched ({summary['march_status']},"
            f" {summary['march_periods']} periods) vs HBM: amplitude {summary['amplitude_rel_diff']:.2e},"
            f" energy {summary['energy_rel_diff']:.2e}; truncation estimate {e:.2e};"
            f" layout and cross-check {ds.attrs['wall_time_s'] - ds.attrs['solve_time_s']:.1f} s"
        )
        rows["check"] = {**summary, "truncation_estimate": e}
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2, default=float)


if __name__ == "__main__":
    main()
