"""Kernel times of two source trees, interleaved (a change's speed against a baseline checkout).

Each round starts one fresh Python process per tree (PYTHONPATH=<tree>/src), alternating the
order, and times ``Simulation.march()`` of every method on the paper case (one period;
quasi-static at 300 steps per period; ``--explicit``: also central difference and RK4 at their
fixed step) after a warm-up, the methods interleaved within the process. Printed per method and tree: the min and median over all rounds, and the ratio of
the second tree to the first (min and median). Noise on a shared machine hits both alike.
``--periods 0.01``: runs of one to three steps, i.e. the fixed cost of a kernel call (argument
unboxing, allocation, setup), which every short run and every sweep case pays.

Usage:  python benchmarks/bench_trees.py BASE_TREE NEW_TREE [--rounds 4] [--repeats 40] [--periods 1] [--explicit]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import textwrap
from pinning import pin_to_one_cpu

SNIPPET = textwrap.dedent("""
    import json, sys, slipstep
    repeats, periods, explicit = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == "1"
    paper = slipstep.load_system("paper")
    methods = [m for m in slipstep.METHODS if not slipstep.METHODS[m].massless]
    sims = {}
    for m in methods:
        opts = {"periods": periods}
        if slipstep.METHODS[m].quasi_static:
            opts["steps_per_period"] = 300
        try:
            sims[m] = slipstep.Simulation(paper, m, **opts)
        except slipstep.InputError:  # a method with a runner of its own (events): no Simulation
            continue
    if explicit:
        from slipstep.integrators import get_integrator

        for scheme in ("central-difference", "rk4"):
            sims[scheme] = get_integrator(scheme).simulation(paper, "fixed", periods=periods)
    for sim in sims.values():
        for _ in range(3):
            sim.march()
    times = {m: [] for m in sims}
    for _ in range(repeats):
        for m, sim in sims.items():
            sim.march()
            times[m].append(sim.kernel_time)
    print(json.dumps(times))
""")


def run_tree(tree: str, repeats: int, periods: float, explicit: bool = False) -> dict:
    env = dict(os.environ, PYTHONPATH=os.path.join(os.path.abspath(tree), "src"))
    done = subprocess.run(
        [sys.executable, "-c", SNIPPET, str(repeats), str(periods), str(int(explicit))],
        env=env,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("base")
    ap.add_argument("new")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=40)
    ap.add_argument("--periods", type=float, default=1.0, help="periods per run (0.01: one to three steps)")
    ap.add_argument("--explicit", action="store_true", help="also the explicit schemes (fixed step)")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    args = ap.parse_args(argv)
    print(pin_to_one_cpu(not args.no_pin))
    trees = [args.base, args.new]
    times: dict = {t: {} for t in trees}
    for k in range(args.rounds):
        for tree in trees if k % 2 == 0 else trees[::-1]:
            for m, ts in run_tree(tree, args.repeats, args.periods, args.explicit).items():
                times[tree].setdefault(m, []).extend(ts)
    print(
        f"kernel time [us] per method, {args.periods:g} period(s) per run, {args.rounds} rounds x "
        f"{args.repeats} repeats, trees interleaved"
    )
    print(
        f"   {'method':28s} {'base min':>9s} {'base med':>9s} {'new min':>9s} {'new med':>9s} {'min ratio':>9s} {'med ratio':>9s}"
    )
    rows = {}
    for m in times[args.base]:
        b, n = times[args.base][m], times[args.new].get(m, [float("nan")])
        row = (min(b), statistics.median(b), min(n), statistics.median(n))
        rows[m] = row
        print(
            f"   {m:28s} {row[0] * 1e6:9.1f} {row[1] * 1e6:9.1f} {row[2] * 1e6:9.1f} {row[3] * 1e6:9.1f}"
            f" {row[2] / row[0]:9.3f} {row[3] / row[1]:9.3f}"
        )
    return rows


if __name__ == "__main__":
    main()
