"""Bit-for-bit equality of the results of two source trees (a refactoring must not change a number).

Each tree runs in a fresh Python process (PYTHONPATH=<tree>/src) and stores, for the paper case:
every registered method (``slipstep.run``, its default options: pilot step rule and step-doubling
estimate included, 2 periods), the explicit schemes (rk4, central difference, fixed and adaptive),
a periodic steady state by marching and by shooting, frequency responses by marching and by
shooting (4 points: each point starts from the one before), the harmonic balance's preload and the
linear limit's stuck state. Every array of every result and every numeric attribute (except wall and
kernel times) is compared with ``numpy.array_equal`` (NaN equal to NaN); the script prints the
number of arrays and attributes compared and every difference, and exits 1 on any.

Usage:  python benchmarks/same_results.py BASE_TREE NEW_TREE [--save-base FILE]
(a tree may also be a FILE saved by --save-base: the base tree's results, not run again)
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import textwrap

import numpy as np

SNIPPET = textwrap.dedent("""
    import pickle, sys, warnings
    import numpy as np
    import slipstep as ss
    from slipstep.integrators import get_integrator
    from slipstep.steady import march_to_steady, shoot
    from slipstep.hbm.residual import preload_sliders
    from slipstep.steady.linear import stuck_state

    TIMES = ("wall_time_s", "kernel_time_s", "point_time", "twin_time_s")
    paper = ss.load_system("paper")
    found = {}

    def keep(label, ds):
        for name, var in ds.variables.items():
            if name in TIMES:
                continue
            found[f"{label}/{name}"] = np.asarray(var.values)
        for key, value in ds.attrs.items():
            if key not in TIMES and isinstance(value, (int, float, np.number, str)):
                found[f"{label}@{key}"] = value

    warnings.simplefilter("ignore")
    for method in ss.METHODS:
        try:
            keep(method, ss.run(paper, method, periods=2))
        except ss.InputError as err:
            found[f"{method}!"] = str(err)
    for scheme in ("rk4", "central-difference"):
        for variant in ("fixed", "adaptive"):
            keep(f"{scheme}-{variant}", get_integrator(scheme).simulation(paper, variant, periods=0.5).run())
    for label, result in (
        ("march_to_steady", march_to_steady(paper, max_periods=30)),
        ("shoot", shoot(paper, tolerance=1e-8)),
        ("shoot-quasi", shoot(paper, method="quasi-static", tolerance=1e-8)),
    ):
        keep(label, result.period)
        for field in ("x", "v", "a", "w"):
            found[f"{label}.final_state.{field}"] = np.asarray(getattr(result.final_state, field))
        found[f"{label}.final_state.states"] = np.asarray(result.final_state.states)
        found[f"{label}.periods"] = result.periods
        found[f"{label}.changes"] = np.asarray(result.changes)
        if result.floquet_multipliers is not None:
            found[f"{label}.floquet"] = np.asarray(result.floquet_multipliers)
    from slipstep.frequency import frf

    for solver in ("march", "shoot"):
        keep(f"frf-{solver}", frf(paper, np.linspace(150.0, 240.0, 4), solver=solver))
    x, w = preload_sliders(paper)
    found["preload_sliders.x"], found["preload_sliders.w"] = x, w
    found["stuck_state"] = stuck_state(paper)
    with open(sys.argv[1], "wb") as fh:
        pickle.dump(found, fh)
""")


def results(tree: str) -> dict:
    if tree.endswith(".pkl"):
        with open(tree, "rb") as f:
            return pickle.load(f)
    env = dict(os.environ, PYTHONPATH=os.path.join(os.path.abspath(tree), "src"))
    with tempfile.NamedTemporaryFile(suffix=".pkl") as fh:
        done = subprocess.run([sys.executable, "-c", SNIPPET, fh.name], env=env, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{tree}: {done.stderr[-3000:]}")
        with open(fh.name, "rb") as f:
            return pickle.load(f)


def same(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("base")
    ap.add_argument("new")
    ap.add_argument("--save-base", help="store the base tree's results in this file")
    args = ap.parse_args(argv)
    base = results(args.base)
    if args.save_base:
        with open(args.save_base, "wb") as f:
            pickle.dump(base, f)
    new = results(args.new)
    differ = [k for k in base if k not in new or not same(base[k], new[k])]
    extra = [k for k in new if k not in base]
    arrays = sum(1 for k in base if "@" not in k)
    print(f"compared {arrays} arrays and {len(base) - arrays} attributes: {len(differ)} differ, {len(extra)} new")
    for k in differ + extra:
        print(f"  {k}: base {str(base.get(k))[:80]!s} new {str(new.get(k))[:80]!s}")
    return 1 if differ or extra else 0


if __name__ == "__main__":
    sys.exit(main())
