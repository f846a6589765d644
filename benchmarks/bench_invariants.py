"""Cost of the contact-invariant check (slipstep.methods.invariants, issue 29) against the march it checks.

The check runs once on the rows a march wrote, in NumPy; this prints its time as a ratio of
the kernel time of the same march and of a whole ``slipstep.run`` call (medians of repeated
calls in this process), on the paper case of bench_method1.py (Method 1, one period) and on
Methods 3 and 4.

    python benchmarks/bench_invariants.py [--repeats 7] [--periods 1]
"""

from __future__ import annotations

import argparse
import statistics
import time

import slipstep
from slipstep.methods.invariants import check_outputs
from slipstep.kernels.codes import C_STEPS
from slipstep.methods.simulation import saved_rows


def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--periods", type=float, default=1.0)
    args = parser.parse_args()
    system = slipstep.load_system("paper")
    print(f"paper case, {args.periods:g} period(s), medians of {args.repeats}")
    print(
        f"  {'method':18s} {'steps':>8s} {'kernel':>10s} {'run()':>10s} {'check':>10s} {'check/kernel':>13s} "
        f"{'check/run()':>12s}"
    )
    for method in ("newmark", "piecewise-linear", "quasi-static"):
        sim = slipstep.Simulation(system, method, periods=args.periods, error_estimate=False)
        sim.march()  # compile / warm up
        kernel = _median_time(sim.march, args.repeats)  # march() includes one check: subtract it below
        rows = saved_rows(sim.out, int(sim.out.counters[C_STEPS]))
        check = _median_time(lambda sim=sim, rows=rows: check_outputs(sim.compiled, sim.out, rows), args.repeats)
        kernel -= check
        steps = int(sim.out.counters[C_STEPS])
        wall = _median_time(
            lambda method=method: slipstep.run(system, method, periods=args.periods, error_estimate=False), args.repeats
        )
        print(
            f"  {method:18s} {steps:8d} {kernel * 1e3:8.2f} ms {wall * 1e3:8.2f} ms {check * 1e3:8.3f} ms "
            f"{check / kernel:12.2%} {check / wall:11.2%}"
        )


if __name__ == "__main__":
    main()
