"""One forced-response point on large models at the defaults (issue 24, item 7): the unreduced
blade pair of bench_blade_pair.py (999 DOFs, dense, 200 contact points) and the 10,000-DOF chain of
bench_scaling.py (sparse, 100 contact points).

Each model: the solver the ``auto`` rule picks and why, then ``slipstep.frf(system, [f])`` twice
(the first includes compiling), with wall and CPU time of the second, its status and error
estimate. As a baseline measured in the same run, the time of one linear response at the same
frequency (``slipstep.frequency.linear_limits``: one factorisation per harmonic, the floor a
nonlinear point cannot go below); the ratio says how many such solves a point costs.
Target: under 10 s per point on this machine kind.

Usage:  python benchmarks/bench_frf_large.py [--models blade-pair,chain]
"""

from __future__ import annotations

import argparse
import time
import warnings

import bench_blade_pair as bp
import bench_scaling

from slipstep.frequency import linear_limits
from slipstep.frequency.choice import choose_solver
from slipstep.frequency.response import frf


def model(name: str):
    """(system, frequency [Hz]) of a benchmark model."""
    if name == "chain":
        return bench_scaling.chain(10000, 100), 40.0
    full = bp.blade(166)
    f1 = bp.stuck_frequencies(bp.pair(bp.reduced(full, 10), 100, None), 1)[0]
    return bp.pair(full, 100, f1), 0.95 * f1


def timed(fn, *args, **kwargs):
    """(fn(*args, **kwargs), wall [s], CPU [s])."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="blade-pair,chain")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    for name in args.models.split(","):
        system, f = model(name)
        solver, why = choose_solver(system)
        print(f"{name}: {system.n_dofs} DOFs, {len(system.contacts)} contact points; auto: {solver} ({why[:90]}...)")
        frf(system, [f], linear=False)  # compile and warm
        ds, wall, cpu = timed(frf, system, [f], linear=False)
        _, base_wall, _ = timed(linear_limits, system, [f])
        est = float(ds["error_estimate"].values.ravel()[0])
        status = [str(s) for s in ds["status"].values.ravel()]
        print(
            f"  one point at {f:.2f} Hz: {wall:.2f} s wall, {cpu:.2f} s CPU, {status}, error estimate {est:.2g}; "
            f"linear response {base_wall:.2f} s wall: ratio {wall / base_wall:.1f}; target 10 s: "
            f"{'met' if wall < 10 else 'not met'}"
        )


if __name__ == "__main__":
    main()
