"""Design sweeps on dask.distributed (issue 12, "Speed").

1. 10,000 quasi-static variants of the paper case (centrifugal load x platform amplitude x
   friction coefficient, 20 x 25 x 20, 3 periods of 300 steps each) with the default local
   cluster (one worker process per core, loopback); target: under 2 minutes on the 2-core VM.
2. The same kind of sweep on 1 and then 2 workers, in this run: the speed-up (target >= 1.7);
   and on 1 worker with 2 threads (nogil kernels; the set-up and summary hold the GIL).
3. Per-case cost: the kernel (Simulation.march) against the whole case (build the case from
   its TOML dictionary, set up, preload, march, Dataset, summary) measured on the workers,
   and the serial executor in this process as a baseline for dask's own per-task overhead.

Times exclude the cluster's start and a warm-up case per worker (the numba kernels loaded
from the disk cache); both are printed apart. On a shared machine expect 20-50 % scatter.

Usage:  python benchmarks/bench_sweep.py [--quick] [--cases N] [--ratio-cases N] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import tempfile
import time
from pathlib import Path

from slipstep.sweep import DaskExecutor, Parameter, SerialExecutor, SweepSpec, run_sweep
from slipstep.sweep.execute import machine_cores

TARGET_S = 120.0
TARGET_RATIO = 1.7


def paper_sweep(n_cf: int, n_amp: int, n_mu: int) -> SweepSpec:
    return SweepSpec(
        base="paper",
        name=f"bench-{n_cf * n_amp * n_mu}",
        run={"method": "quasi-static", "periods": 3, "steps_per_period": 300},
        parameters=(
            Parameter("damper.centrifugal_force_N", start=100.0, stop=400.0, num=n_cf),
            Parameter("motion.1.amplitude", start=2.0, stop=60.0, num=n_amp, scale="log"),
            Parameter("damper.contacts.*.friction_coefficient", start=0.1, stop=0.6, num=n_mu),
        ),
    )


def shape_for(n: int) -> tuple[int, int, int]:
    """A CF x amplitude x mu grid of about n cases (4 : 5 : 4 like 20 x 25 x 20)."""
    k = (n / 80.0) ** (1 / 3)
    return max(1, round(4 * k)), max(1, round(5 * k)), max(1, round(4 * k))


def timed(spec, store, executor) -> tuple[dict, float]:
    """run_sweep's report plus the client's own CPU time (scheduler thread, store writes) and
    the machine's load average before and after."""
    load = os.getloadavg()[0]
    start, cpu = time.perf_counter(), time.process_time()
    report = run_sweep(spec, store, executor=executor)
    report["client_cpu_s"] = time.process_time() - cpu
    report["load_average"] = (load, os.getloadavg()[0])
    return report, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000 cases and 400 for the ratio")
    parser.add_argument("--cases", type=int, default=None, help="cases of part 1 (default 10,000)")
    parser.add_argument("--ratio-cases", type=int, default=None, help="cases of part 2 (default 2,000)")
    parser.add_argument("--ratio-only", action="store_true", help="part 2 only (1 vs 2 workers)")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    n_big = args.cases or (1000 if args.quick else 10_000)
    n_ratio = args.ratio_cases or (400 if args.quick else 2000)
    root = Path(tempfile.mkdtemp(prefix="slipstep-bench-sweep-"))
    results: dict = {"cores": machine_cores()}
    try:
        if not args.ratio_only:
            big = paper_sweep(*((20, 25, 20) if n_big == 10_000 else shape_for(n_big)))
            report, wall = timed(big, root / "big.zarr", DaskExecutor())
            results["big"] = {**report, "wall_s": wall}
        ratio_spec = paper_sweep(*shape_for(n_ratio))
        one, _ = timed(ratio_spec, root / "one.zarr", DaskExecutor(workers=1))
        two, _ = timed(ratio_spec, root / "two.zarr", DaskExecutor(workers=2))
        results["one_worker"], results["two_workers"] = one, two
        results["speedup"] = one["elapsed_s"] / two["elapsed_s"]
        if not args.ratio_only:
            threads, _ = timed(ratio_spec, root / "threads.zarr", DaskExecutor(workers=1, threads=2))
            results["one_worker_two_threads"] = threads
            small = paper_sweep(*shape_for(min(n_ratio, 400)))
            serial, _ = timed(small, root / "serial.zarr", SerialExecutor())
            results["serial"] = serial
    finally:
        shutil.rmtree(root, ignore_errors=True)
    if args.json:
        print(json.dumps(results))
        return
    _print(results)


def _print(r: dict) -> None:
    print(f"machine: {r['cores']} cores\n")
    if "big" in r:
        _print_big(r)
    _print_ratio(r)
    if "serial" in r:
        _print_costs(r)


def _print_big(r: dict) -> None:
    big = r["big"]
    print(
        f"1. {big['cases']} quasi-static variants of the paper case, default local cluster "
        f"({big['workers']} workers, {big['batch_size']} cases per task)"
    )
    print(
        f"   cases:       {big['elapsed_s']:8.1f} s  ({big['cases_per_s']:.0f} cases/s)   target < {TARGET_S:.0f} s: "
        f"{'met' if big['elapsed_s'] < TARGET_S else 'NOT met'}"
    )
    print(f"   start-up:    {big['startup_s']:8.1f} s  (cluster + one warm-up case per worker)")
    print(
        f"   whole call:  {big['wall_s']:8.1f} s  (plan, store, start-up, cases, shut-down)   "
        f"{'met' if big['wall_s'] < TARGET_S else 'NOT met'} with start-up"
    )
    print(f"   status:      {big['status_counts']}")
    print(
        f"   client CPU:  {big['client_cpu_s']:8.1f} s  ({big['client_cpu_s'] / big['cases'] * 1e3:.2f} ms per case: "
        "scheduler, results, store)"
    )
    print(
        f"   machine load average before / after: {big['load_average'][0]:.1f} / {big['load_average'][1]:.1f} "
        f"(on {r['cores']} cores)\n"
    )


def _print_ratio(r: dict) -> None:
    one, two = r["one_worker"], r["two_workers"]
    print(f"2. {one['cases']} cases on 1 worker and on 2 workers")
    print(f"   1 worker:    {one['elapsed_s']:8.2f} s  ({one['cases_per_s']:.0f} cases/s)")
    print(f"   2 workers:   {two['elapsed_s']:8.2f} s  ({two['cases_per_s']:.0f} cases/s)")
    print(
        f"   load average during the two runs: {one['load_average'][0]:.1f}-{two['load_average'][1]:.1f} "
        f"(other processes take cores from the workers: the ratio needs {r['cores']} idle cores)"
    )
    print(
        f"   speed-up:    {r['speedup']:8.2f} x   target >= {TARGET_RATIO}: "
        f"{'met' if r['speedup'] >= TARGET_RATIO else 'NOT met'}"
    )
    c1, c2 = one["mean_case_cpu_s"], two["mean_case_cpu_s"]
    w1, w2 = one["elapsed_s"] / one["computed"], two["elapsed_s"] / two["computed"]
    print(
        f"   CPU per case on the workers: {c1 * 1e3:.2f} ms (1 worker), {c2 * 1e3:.2f} ms (2 workers); "
        f"CPU share each worker got: {c1 / w1:.0%} (1 worker), {c2 / (2 * w2):.0%} (2 workers)"
    )
    print(
        f"   projection, not a measurement: two idle cores would give {2 * c1 / c2:.2f} x (twice the cases per "
        "CPU-second of one worker; the client's CPU is apart, see part 1)"
    )
    if "one_worker_two_threads" not in r:
        return
    th = r["one_worker_two_threads"]
    print(
        f"   1 worker, 2 threads: {th['elapsed_s']:8.2f} s  ({one['elapsed_s'] / th['elapsed_s']:.2f} x one thread: "
        "the kernels release the GIL, the Python around them does not)\n"
    )


def _print_costs(r: dict) -> None:
    big, one, serial = r["big"], r["one_worker"], r["serial"]
    ms = lambda s: "-" if math.isnan(s) else f"{s * 1e3:.2f} ms"  # noqa: E731
    print("3. per case (means over the cases of part 1, measured on the workers)")
    print(f"   kernel (march):                       {ms(big['mean_kernel_time_s'])}")
    print(f"   whole case (build, run, summary):     {ms(big['mean_case_time_s'])}")
    print(
        f"   overhead outside the kernel:          {ms(big['overhead_per_case_s'])}  "
        f"({big['overhead_per_case_s'] / big['mean_case_time_s'] * 100:.0f} % of the case)"
    )
    per_case_serial = serial["elapsed_s"] / max(serial["computed"], 1)
    per_case_one = one["elapsed_s"] / max(one["computed"], 1)
    print(f"   serial executor, wall per case:       {ms(per_case_serial)}  ({serial['computed']} cases, this process)")
    print(
        f"   1 dask worker, wall per case:         {ms(per_case_one)}  "
        f"(the case itself {ms(one['mean_case_time_s'])}: dask, transfer and store "
        f"{ms(per_case_one - one['mean_case_time_s'])} per case, {one['batch_size']} cases per task)"
    )
    if not math.isfinite(r["speedup"]):
        print("   (no speed-up measured)")


if __name__ == "__main__":
    main()
