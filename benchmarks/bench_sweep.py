"""Design sweeps on dask.distributed (issue 12, "Speed").

1. 10,000 quasi-static variants of the paper case (centrifugal load x platform amplitude x
   friction coefficient, 20 x 25 x 20, 3 periods of 300 steps each) with the default local
   cluster (one worker process per core, loopback); target: under 15 s on the 2-core VM (issue 27;
   issue 12 asked for 2 minutes).
2. The same kind of sweep on 1 and then 2 workers, in this run: the speed-up (target >= 1.7);
   and on 1 worker with 2 threads (nogil kernels; the set-up and summary hold the GIL).
3. Per-case cost: the kernel (Simulation.march) against the whole case (the worker's runner,
   slipstep.sweep.runner: patch, plan, preload, march, invariants, summary) measured on the
   workers, and the serial executor in this process as a baseline for dask's own per-task overhead.
4. The CPU split of a case in this process (thread CPU time, less noisy than wall time on a
   shared machine): the runner's stages against the case-format path (execute.run_case).

Times exclude the cluster's start and a warm-up case per worker (the numba kernels loaded
from the disk cache); both are printed apart. On a shared machine expect 20-50 % scatter.

Usage:  python benchmarks/bench_sweep.py [--quick] [--cases N] [--ratio-cases N] [--split-only] [--json]
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

TARGET_S = 15.0  # issue 27 (issue 12: 120 s)
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
    parser.add_argument("--split-only", action="store_true", help="part 4 only (the CPU split of a case)")
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object")
    args = parser.parse_args()
    if args.split_only:
        split = cpu_split()
        print(json.dumps({"split": split}) if args.json else _split_text(split))
        return
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
            results["split"] = cpu_split()
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
    if "split" in r:
        print(_split_text(r["split"]))


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


def cpu_split(n: int = 500) -> dict:
    """CPU time per case [s] (time.thread_time, this process) of the runner's stages over n
    cases of the 10,000-case sweep (every 10,000 / n-th): patch and plan (CaseRunner.plan_for,
    Marcher.retarget), preload (methods.start.static_equilibrium), march (Marcher.advance: the
    kernel call and its few tens of us of Python), invariants (methods.invariants.check_march),
    record and summary (post.summary.record_of, summarise_record); the whole CaseRunner.run and
    the case-format path execute.run_case on the same cases; the kernel's own wall time."""
    from slipstep.methods.invariants import check_march
    from slipstep.methods.simulation import Simulation
    from slipstep.methods.start import static_equilibrium
    from slipstep.post.summary import record_of, summarise_record
    from slipstep.sweep.execute import payload_of, run_case
    from slipstep.sweep.run import plan_of
    from slipstep.sweep.runner import CaseRunner

    plan = plan_of(paper_sweep(20, 25, 20))
    payload = payload_of(plan)
    cases = [[float(v) for v in plan.values[i]] for i in range(0, plan.n_cases, max(plan.n_cases // n, 1))]
    runner = CaseRunner(payload)
    for values in cases[:3]:  # built, checked against the case format, kernels loaded
        runner.run(values)
    split = dict.fromkeys(("patch_and_plan", "preload", "march", "invariants", "record_and_summary"), 0.0)
    kernel_wall = 0.0
    clock = time.thread_time
    for values in cases:
        t0 = clock()
        plan_i = runner.plan_for(values)
        runner.marcher.retarget(plan_i)
        sim = Simulation.from_plan(plan_i, runner.marcher)
        t1 = clock()
        sim.start = static_equilibrium(plan_i, runner.marcher.ws)
        t2 = clock()
        segment = runner.marcher.advance(sim.start)
        sim.segment, sim.status, sim.kernel_time = segment, segment.status, segment.kernel_time_s
        t3 = clock()
        check_march(sim)
        t4 = clock()
        summarise_record(record_of(sim), runner.interfaces)
        t5 = clock()
        for key, dt in zip(split, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
            split[key] += dt
        kernel_wall += segment.kernel_time_s
    out = {key: value / len(cases) for key, value in split.items()}
    for name, run in (("runner_run", runner.run), ("run_case", lambda v: run_case(payload, v))):
        t0 = clock()
        for values in cases:
            run(values)
        out[name] = (clock() - t0) / len(cases)
    out["kernel_wall"] = kernel_wall / len(cases)
    out["patching"] = bool(runner.patching)
    out["cases"] = len(cases)
    out["load_average"] = os.getloadavg()[0]
    return out


def _split_text(s: dict) -> str:
    ms = lambda x: f"{x * 1e3:6.3f} ms"  # noqa: E731
    lines = [
        f"4. CPU per case in this process ({s['cases']} cases, thread CPU time; load average {s['load_average']:.1f})"
    ]
    for key in ("patch_and_plan", "preload", "march", "invariants", "record_and_summary"):
        lines.append(f"   {key.replace('_', ' '):24s} {ms(s[key])}")
    lines.append(f"   whole case, runner:      {ms(s['runner_run'])}  (patching: {s['patching']})")
    lines.append(
        f"   outside the march:       {ms(s['runner_run'] - s['march'])}  (target < 1 ms; the kernel's wall time "
        f"{ms(s['kernel_wall'])})"
    )
    lines.append(
        f"   case-format path:        {ms(s['run_case'])}  (execute.run_case: {s['run_case'] / s['runner_run']:.1f} x)"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
