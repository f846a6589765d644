"""The time of one FRF point by shooting (and by marching) on the built-in ``blades`` case, two
source trees interleaved: the set-up a point pays besides its periods (plan, compile, T_min,
allocation, preload) shows as the difference.

Each round starts one fresh Python process per tree (PYTHONPATH=<tree>/src), warms the caches
with a 2-point sweep, then times a sweep of ``--points`` points (each from the point before, as
slipstep.frequency.frf does) and prints, per tree, the median and min point time of the points
after the first (``point_time`` of the FRF Dataset), the periods per point and the ratio new/base.

Usage:  python benchmarks/bench_frf_point.py BASE_TREE NEW_TREE [--rounds 2] [--points 8] [--solver shoot]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import textwrap

SNIPPET = textwrap.dedent("""
    import json, sys, warnings
    import numpy as np
    import slipstep as ss
    from slipstep.frequency import frf
    warnings.simplefilter("ignore")
    points, solver = int(sys.argv[1]), sys.argv[2]
    blades = ss.load_system("blades")
    frf(blades, [290.0, 295.0], solver=solver, linear=False)
    ds = frf(blades, np.linspace(280.0, 320.0, points), solver=solver, linear=False)
    print(json.dumps({"time": ds.point_time.values[1:].tolist(),
                      "periods": ds.periods_to_steady.values[1:].tolist(),
                      "status": [str(s) for s in ds.status.values]}))
""")


def run_tree(tree: str, points: int, solver: str) -> dict:
    env = dict(os.environ, PYTHONPATH=os.path.join(os.path.abspath(tree), "src"))
    done = subprocess.run([sys.executable, "-c", SNIPPET, str(points), solver], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("base")
    ap.add_argument("new")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--points", type=int, default=8)
    ap.add_argument("--solver", default="shoot")
    args = ap.parse_args(argv)
    trees = [args.base, args.new]
    times: dict = {t: [] for t in trees}
    periods: dict = {t: [] for t in trees}
    for k in range(args.rounds):
        for tree in trees if k % 2 == 0 else trees[::-1]:
            got = run_tree(tree, args.points, args.solver)
            times[tree] += got["time"]
            periods[tree] += got["periods"]
            print(f"  {tree}: status {got['status']}", file=sys.stderr)
    print(f"FRF point time [ms] on blades, solver {args.solver}, {args.rounds} rounds x {args.points - 1} points")
    for label, tree in (("base", args.base), ("new", args.new)):
        t = times[tree]
        print(
            f"   {label:5s} median {1e3 * statistics.median(t):8.1f}  min {1e3 * min(t):8.1f}  "
            f"periods per point {statistics.mean(periods[tree]):.1f}"
        )
    b, n = times[args.base], times[args.new]
    print(f"   ratio new/base: median {statistics.median(n) / statistics.median(b):.3f}, min {min(n) / min(b):.3f}")


if __name__ == "__main__":
    main()
