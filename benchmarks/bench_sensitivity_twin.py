"""The cost of the sensitivity twin (slipstep.methods.sensitivity_twin) on the paper case: the CPU time
of ``slipstep.run`` at its defaults (sensitivity_check='auto': the twin runs, 19 % of the steps change
contact state) against the same run with sensitivity_check=False, measured in the same process.

    python benchmarks/bench_sensitivity_twin.py            # 21 runs of each, Methods 1 and 3
    python benchmarks/bench_sensitivity_twin.py --repeats 51

Prints per method the median CPU time of each, their ratio, the twin's own CPU time (twin_time_s)
and twin_difference. The random-system share is printed by ``benchmarks/random_systems.py --trust``.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import slipstep as ss


def median_cpu(system, method: str, repeats: int, **options) -> tuple[float, dict]:
    times, ds = [], None
    for _ in range(repeats):
        cpu = time.process_time()
        ds = ss.run(system, method, **options)
        times.append(time.process_time() - cpu)
    return float(np.median(times)), dict(ds.attrs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=21)
    args = parser.parse_args()
    system = ss.load_system("paper")
    warnings.simplefilter("ignore")
    print(f"paper case, default options, median CPU of {args.repeats} runs each")
    print(f"  {'method':18s} {'no twin [ms]':>12s} {'auto [ms]':>10s} {'ratio':>6s} {'twin [ms]':>9s}  twin_difference")
    for method in ("newmark", "piecewise-linear"):
        median_cpu(system, method, 2)  # warm up (numba cache, imports)
        off, _ = median_cpu(system, method, args.repeats, sensitivity_check=False)
        auto, attrs = median_cpu(system, method, args.repeats)
        twin = attrs.get("twin_time_s", float("nan"))
        print(
            f"  {method:18s} {1e3 * off:12.2f} {1e3 * auto:10.2f} {auto / off:6.2f} {1e3 * twin:9.2f}  "
            f"{attrs.get('twin_difference', float('nan')):.2g}"
        )


if __name__ == "__main__":
    main()
