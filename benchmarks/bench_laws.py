"""What remains of the piecewise-linear benefit with a coupled friction law (issue 9, item 1).

The shroud pair (examples/shroud_pair.toml) with one isotropic tangential stiffness, marched
with the paper's uncoupled quasi-3D law and with the friction circle ('3d-circle'), whose
slip state has no piecewise-linear form (Methods 3 and 4 solve it by Newton on the
consistent tangent). Prints solves per step and kernel time relative to Method 1 of the same
law (median of interleaved repeats after warming every kernel, slipstep.study.compare.time_kernels).

Usage:  python benchmarks/bench_laws.py [--quick] [--periods P]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from statistics import median

import numpy as np

import slipstep as ss
from slipstep.study.compare import time_kernels

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("newmark", "piecewise-linear", "full-newton", "quasi-static")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--periods", type=float, default=10)
    args = ap.parse_args()
    repeats = 3 if args.quick else 9
    base, _ = ss.load_case(ROOT / "examples" / "shroud_pair.toml")
    print(f"shroud pair, {args.periods:g} periods, k_t = 1.5e7 N/m both directions; median of {repeats} runs")
    print(
        f"{'law':22s} {'method':18s} {'steps':>6s} {'solves':>7s} {'solves/step':>11s} {'max |T|/(mu N)':>14s}"
        f" {'kernel [ms]':>11s} {'ratio':>6s}"
    )
    for law in ("quasi-3d-uncoupled", "3d-circle"):
        contact = dataclasses.replace(base.contacts[0], law=law, tangential_stiffness=1.5e7)
        system = dataclasses.replace(base, contacts=(contact,))
        # the paper's T_min rule: the methods' kernel times on the same steps
        sims = {m: ss.Simulation(system, m, periods=args.periods, step_rule="t-min") for m in METHODS}
        results = {m: sim.run() for m, sim in sims.items()}
        times = {m: median(v) for m, v in time_kernels(sims, repeats).items()}
        for m, ds in results.items():
            a = ds.attrs
            T, N = ds.tangential_force.values, ds.normal_force.values[:, 0]
            ratio = float((np.hypot(T[:, 0], T[:, 1]) / np.where(N > 0, 0.3 * N, np.inf)).max())
            print(
                f"{law:22s} {m:18s} {a['steps']:6d} {a['solves']:7d} {a['mean_solves_per_step']:11.2f} {ratio:14.4f}"
                f" {times[m] * 1e3:11.3f} {times[m] / times['newmark']:6.2f}"
            )


if __name__ == "__main__":
    main()
