"""The time per step of each structure backend, and the one linear_solver='auto' picks (issue 26).

Method 3 (piecewise-linear) at a fixed step (``--steps`` per period, one period, no pilot) on a
family of structures: bench_scaling's chains (narrow band), grids (band sqrt(n)) and strips,
the blade pair of bench_blade_pair (full: 363 DOFs; reduced: 31 DOFs; both dense input), and
the 3D bolted beam of slipstep.model.fe_mesh at three sizes. For each structure and each
backend (direct, low-rank, banded, sparse; '-' where it refuses or, for the dense ones, above
DENSE_LIMIT DOFs) the CPU time of the march (best of two: the first loads the kernel) is
divided by the steps. Then the backend 'auto' takes (a separate run), the ratio of that
backend's time (its column) to the fastest one's (1.00: 'auto' picked the fastest; single
measurements on a shared machine vary by up to 2x), nnz(L + U) of the sparse factor over the
cost model's estimate (methods.sparse.step_costs), and the reason 'auto' gives (the result
attribute ``linear_solver_reason``: its estimated us per step of each backend). Columns:

    case, n, nq, band (RCM of M + C + K), us per step per backend, auto, auto/best, LU/est, reason

Usage: python benchmarks/bench_backends.py [--steps 200] [--quick] [--cases chain-2000,...] [--json FILE]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import pathlib
import sys
import time

import numpy as np

import slipstep
from slipstep.methods import sparse as SB

HERE = pathlib.Path(__file__).resolve().parent
BACKENDS = ("direct", "low-rank", "banded", "sparse")
DENSE_LIMIT = 3000  # the dense backends beyond this many DOFs take seconds per step: skipped


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def cases(quick: bool) -> dict:
    """name -> a function building the System."""
    scaling = _load("bench_scaling")
    blade = _load("bench_blade_pair")
    from slipstep.model.fe_mesh import BeamSpec, bolted_beam, coarse_spec

    def blade_pair(full: bool):
        sub = blade.blade(60)
        if not full:
            sub = blade.reduced(sub, 10)
        probe = blade.pair(sub, 50, None)
        f1 = blade.stuck_frequencies(probe, 1)[0]
        return blade.pair(sub, 50, 0.9 * f1)

    def strip(n, nc, width):
        scaling.OPTIONS["width"] = width
        return scaling.strip(n, nc)

    out = {
        "blade-reduced": lambda: blade_pair(False),
        "blade-full": lambda: blade_pair(True),
        "chain-200-20": lambda: scaling.chain(200, 20),
        "chain-1000-100": lambda: scaling.chain(1000, 100),
        "chain-5000-500": lambda: scaling.chain(5000, 500),
        "grid-400-40": lambda: scaling.grid(400, 40),
        "grid-2500-100": lambda: scaling.grid(2500, 100),
        "strip8-2000-200": lambda: strip(2000, 200, 8),
        "beam-coarse": lambda: bolted_beam(coarse_spec(force=800.0, pressure=1e6)).system,
        "beam-60x3x2": lambda: bolted_beam(BeamSpec(elements=(60, 3, 2), force=800.0, pressure=1e6)).system,
    }
    if not quick:
        out["chain-2000-1000"] = lambda: scaling.chain(2000, 1000)
        out["grid-4900-200"] = lambda: scaling.grid(4900, 200)
        out["beam-120x4x2"] = lambda: bolted_beam(BeamSpec(elements=(120, 4, 2), force=800.0, pressure=1e6)).system
    return out


def per_step(system, backend: str, steps: int):
    """(CPU seconds per step of Method 3, the dataset, the Simulation) or (nan, None, None) when
    the backend refuses."""
    try:
        sim = slipstep.Simulation(
            system,
            "piecewise-linear",
            periods=1.0,
            dt=system.period / steps,
            linear_solver=backend,
            error_estimate=False,
        )
    except slipstep.errors.InputError:
        return math.nan, None, None
    best = math.inf
    for _ in range(2):  # CPU time (the machine is shared: wall time is not the cost)
        c0 = time.process_time()
        sim.march()
        best = min(best, time.process_time() - c0)
    ds = sim.dataset()
    return best / max(int(ds.attrs["steps"]), 1), ds, sim


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200, help="fixed steps per period")
    ap.add_argument("--quick", action="store_true", help="leave out the largest cases")
    ap.add_argument("--cases", default=None, help="comma-separated case names (default: all)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    table = cases(args.quick)
    names = args.cases.split(",") if args.cases else list(table)
    print(
        f"{'case':>16} {'n':>6} {'nq':>5} {'band':>5} "
        + " ".join(f"{b + ' us':>12}" for b in BACKENDS)
        + f" {'auto':>9} {'auto/best':>9} {'LU/est':>6}  reason"
    )
    rows = []
    for name in names:
        system = table[name]()
        n = system.n_dofs
        nq = sum(c.dof_gather.shape[0] for c in system.contacts)
        band = SB.structure_bandwidth(system.structure)
        times, lu = {}, 0
        for b in BACKENDS:
            if b in ("direct", "low-rank") and n > DENSE_LIMIT:
                times[b] = math.nan
                continue
            SB.forget_factors()
            times[b], _, sim = per_step(system, b, args.steps)
            if b == "sparse" and sim is not None:
                lu = SB.factor_nnz(sim.marcher.ws.main)
        SB.forget_factors()
        t0 = time.perf_counter()
        t_auto, ds, _ = per_step(system, "auto", args.steps)
        est = SB.step_costs(system)
        chosen = ds.attrs["linear_solver"] if ds is not None else "-"
        reason = ds.attrs.get("linear_solver_reason", "") if ds is not None else ""
        best = min(t for t in times.values() if np.isfinite(t))
        print(
            f"{name:>16} {n:6d} {nq:5d} {band:5d} "
            + " ".join(f"{t * 1e6:12.1f}" if np.isfinite(t) else f"{'-':>12}" for t in times.values())
            + f" {chosen:>9} {times.get(chosen, t_auto) / best:9.2f} {lu / est.lu_entries:6.2f}  {reason}",
            flush=True,
        )
        rows.append(
            {
                "case": name,
                "n": n,
                "nq": nq,
                "band": band,
                "per_step_s": times,
                "auto": chosen,
                "auto_per_step_s": t_auto,
                "reason": reason,
                "estimate_s": est.seconds,
                "lu_entries": lu,
                "lu_estimate": est.lu_entries,
                "auto_wall_s": time.perf_counter() - t0,
            }
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
