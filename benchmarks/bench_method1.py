"""Speed of Method 1 (standard Newmark, modified Newton) on one period of the paper case.

Issue 2, "Speed". Prints, with the targets beside them:

1. numba compile time: the first march in a fresh Python process with an EMPTY on-disk
   cache (a private NUMBA_CACHE_DIR, so the shared cache is not touched), then a second
   fresh process on the same cache directory (must load, not recompile: numba's dispatcher
   stats report cache hits / misses of the march kernel).
2. kernel time per period (median of repeated ``Simulation.march()`` calls after warm-up),
   steps/s, iterations/s, time per iteration.
3. the "arithmetic floor": a small numba kernel, written here, that does exactly what one
   modified-Newton iteration needs (q = A x - B p + g, contact law, A^T f, residual, one
   LU solve with a prefactorised matrix) N times; the ratio (time per real iteration) /
   (time per floor iteration) says how far the real kernel is from the floor.
4. the wall time of a whole ``slipstep.run(system, 'newmark', periods=1)`` call (median).

Usage:  python benchmarks/bench_method1.py [--quick] [--no-compile] [--repeats N] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

import slipstep
from slipstep.kernels import march as K
from slipstep.kernels.contact import contact_law, generalised_force, local_displacement
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.contact import add_contact_stiffness
from pinning import pin_to_one_cpu

TARGET_KERNEL_S = 1e-3  # one period of the paper case
TARGET_RUN_S = 50e-3  # a whole slipstep.run call for one period

# Snippet run in a fresh interpreter: import, build, first march; report times and numba cache stats.
FRESH_SNIPPET = textwrap.dedent("""
    import json, time
    def other_misses():
        # cache misses of every other compiled dispatcher in slipstep.kernels (e.g. a preload kernel)
        import sys as _s
        n = 0
        for name, mod in list(_s.modules.items()):
            if name.startswith("slipstep.kernels"):
                for obj in vars(mod).values():
                    st = getattr(obj, "stats", None)
                    if st is not None and hasattr(st, "cache_misses") and obj is not kernel:
                        n += sum(st.cache_misses.values())
        return n
    t0 = time.perf_counter()
    import slipstep
    from slipstep.kernels import march as K
    kernel = K.implicit_kernel(0) if hasattr(K, "implicit_kernel") else K.march  # the dense march (older trees: one)
    t1 = time.perf_counter()
    sim = slipstep.Simulation(slipstep.load_system("paper"), "newmark", periods=1)
    t2 = time.perf_counter()
    sim.march()
    t3 = time.perf_counter()
    st = kernel.stats
    print(json.dumps({"import_s": t1 - t0, "setup_and_preload_s": t2 - t1, "first_march_s": t3 - t2,
                      "total_s": t3 - t0, "march_cache_hits": sum(st.cache_hits.values()),
                      "march_cache_misses": sum(st.cache_misses.values()),
                      "other_kernel_cache_misses": other_misses(),
                      "status": sim.status.name}))
""")


def source_stamp() -> tuple:
    """(path, mtime, size) of every slipstep source file: numba's cache index is keyed on these."""
    root = os.path.dirname(slipstep.__file__)
    out = []
    for dirpath, _, files in os.walk(root):
        for name in sorted(files):
            if name.endswith(".py"):
                st = os.stat(os.path.join(dirpath, name))
                out.append((os.path.join(dirpath, name), st.st_mtime_ns, st.st_size))
    return tuple(sorted(out))


def fresh_process(cache_dir: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", FRESH_SNIPPET], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"fresh process failed:\n{proc.stderr}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process_wall_s"] = wall
    return out


# The contact evaluation of the floor: the explicit-array cores when the kernels have them
# (what the march's hot path calls), else the CompiledSystem wrappers named in issue 2.
try:
    import inspect

    from slipstep.kernels.contact import gather as _g_core, law as _l_core, scatter as _s_core

    # the cores take A^T for a gather and A for a scatter since issue 24 (column-wise products);
    # trees before it took A and A^T
    _COLUMNWISE = next(iter(inspect.signature(_g_core.py_func).parameters)) == "AT"

    @njit(inline="always")
    def _gather(sys, x, p, q):
        _g_core(sys.AT if _COLUMNWISE else sys.A, sys.B, sys.g, x, p, q)

    @njit(inline="always")
    def _law(sys, q, w_old, f, w_new, state):
        _l_core(
            sys.normal_row,
            sys.law,
            sys.law_par,
            sys.first_direction,
            sys.n_directions,
            sys.tangential_row,
            sys.kt,
            q,
            w_old,
            f,
            w_new,
            state,
        )

    @njit(inline="always")
    def _scatter(sys, f, out):
        _s_core(sys.A if _COLUMNWISE else sys.AT, f, out)

    FLOOR_FUNCTIONS = "contact.gather + contact.law + contact.scatter + linalg.lu_solve"
except ImportError:  # older kernels
    _gather, _law, _scatter = local_displacement, contact_law, generalised_force
    FLOOR_FUNCTIONS = "contact.local_displacement + contact_law + generalised_force + linalg.lu_solve"


def _borrow_value(context, builder, ty, value):
    if isinstance(ty, types.Array):
        view = cgutils.create_struct_proxy(ty)(context, builder, value=value)
        view.meminfo = ir.Constant(view.meminfo.type, None)
        return view._getvalue()
    if isinstance(ty, types.BaseTuple):
        for i, member in enumerate(ty.types):
            item = _borrow_value(context, builder, member, builder.extract_value(value, i))
            value = builder.insert_value(value, item, i)
    return value


@intrinsic
def _borrowed(typingctx, value):
    """The arrays of value without reference counting (as kernels/borrow.py, repeated here so
    that the floor is the same loop whatever slipstep tree is on the path)."""

    def codegen(context, builder, signature, args):
        return _borrow_value(context, builder, signature.args[0], args[0])

    return value(value), codegen


@njit(cache=False)
def floor_kernel(sys, lu, piv, Lin, x0, p, w_old, r0, n_iter, q, f, w_new, state, gf, r, delta, dx):
    """q_base = A x0 - B p + g once; then n_iter times: q = q_base + A dx; f = law(q, w_old);
    gf = A^T f; r = r0 - gf - Lin dx; delta = J^-1 r (prefactorised); dx = 1e-9 delta (a tiny
    drift so nothing is hoisted and each iteration depends on the last, as in Newton). The
    arguments are borrowed (no reference counting, as in the march kernels)."""
    sys, lu, piv, Lin, x0, p, w_old, r0 = _borrowed((sys, lu, piv, Lin, x0, p, w_old, r0))
    q, f, w_new, state, gf, r, delta, dx = _borrowed((q, f, w_new, state, gf, r, delta, dx))
    n = x0.shape[0]
    A = sys.A
    nq = A.shape[0]
    qbase = np.empty(nq)
    _gather(sys, x0, p, qbase)
    for i in range(n):
        dx[i] = 0.0
    acc = 0.0
    for it in range(n_iter):
        for rr in range(nq):
            s = qbase[rr]
            for j in range(n):
                s += A[rr, j] * dx[j]
            q[rr] = s
        _law(sys, q, w_old, f, w_new, state)
        _scatter(sys, f, gf)
        for i in range(n):
            s = r0[i] - gf[i]
            for j in range(n):
                s -= Lin[i, j] * dx[j]
            r[i] = s
        lu_solve(lu, piv, r, delta)
        for i in range(n):
            dx[i] = 1e-9 * delta[i]
        acc += delta[0]
    return acc


def floor_timer(sim: slipstep.Simulation, n_iter: int):
    """A function timing one call of the floor kernel (n_iter iterations) on the paper case's
    matrices: J(all stick) factorised once, the preload state, platforms moved by 1 um."""
    cs = sim.compiled
    n = cs.M.shape[0]
    nq = cs.A.shape[0]
    nd = cs.kt.shape[0]
    dt = sim.dt
    beta = sim.options.scheme.beta
    Lin = cs.M / (beta * dt * dt) + sim.options.scheme.gamma / (beta * dt) * cs.C + cs.K
    J = Lin.copy()
    add_contact_stiffness(cs, np.full(nd, 1, np.int8), 1.0, J)
    lu, piv = np.zeros((n, n)), np.zeros(n, np.int64)
    assert lu_factor(J, lu, piv, 1e-12)
    x0, w_old = sim.preload_state[0].copy(), sim.preload_state[5].copy()
    p = np.full(cs.B.shape[1], 1e-6)  # platforms moved: some contacts stick, some slip
    r0 = sim.preload_state[4].copy()  # about the size of the contact forces
    args = (
        np.zeros(nq),
        np.zeros(nq),
        np.zeros(nd),
        np.zeros(nd, np.int8),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
    )
    floor_kernel(cs, lu, piv, Lin, x0, p, w_old, r0, 10, *args)  # compile

    def timed() -> float:
        t = time.perf_counter()
        floor_kernel(cs, lu, piv, Lin, x0, p, w_old, r0, n_iter, *args)
        return time.perf_counter() - t

    return timed


def fmt_time(s: float) -> str:
    if s < 1e-6:
        return f"{s * 1e9:8.1f} ns"
    if s < 1e-3:
        return f"{s * 1e6:8.2f} us"
    if s < 1.0:
        return f"{s * 1e3:8.2f} ms"
    return f"{s:8.2f} s "


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, no cold-compile measurement")
    ap.add_argument("--no-compile", action="store_true", help="skip the fresh-process compile measurement")
    ap.add_argument("--compile", action="store_true", help="measure the cold compile even with --quick")
    ap.add_argument("--repeats", type=int, default=None, help="kernel repeats (default 200, quick 30)")
    ap.add_argument("--json", action="store_true", help="also print the results as one JSON object")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    args = ap.parse_args(argv)
    print(pin_to_one_cpu(not args.no_pin))
    repeats = args.repeats or (30 if args.quick else 200)
    results: dict = {"machine_cpus": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M")}

    print(f"slipstep {slipstep.__version__}: Method 1 (newmark, modified Newton) on one period of the paper case")
    print(
        f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPUs (shared: numbers are noisy)\n"
    )

    # -- 1. compile time in fresh processes ------------------------------------------------
    do_compile = not args.no_compile and (not args.quick or args.compile)
    if do_compile:
        print("1. numba compile (fresh processes, private NUMBA_CACHE_DIR; the shared cache is untouched)")
        before = source_stamp()
        with tempfile.TemporaryDirectory(prefix="slipstep_numba_cache_") as cache_dir:
            cold = fresh_process(cache_dir)
            mid = source_stamp()
            warm = fresh_process(cache_dir)
        after = source_stamp()
        changed = (
            [p for (p, *st), (_, *st2) in zip(before, mid) if st != st2]
            if len(before) == len(mid)
            else ["(files added/removed)"]
        )
        rows = [("cold (empty cache)", cold), ("warm (cache from the cold run)", warm)]
        print(
            f"   {'process':32s} {'import':>10s} {'setup+preload':>14s} {'first march':>12s} {'process wall':>13s}"
            f" {'march cache hits/misses':>24s} {'other kernels misses':>21s}"
        )
        for name, r in rows:
            print(
                f"   {name:32s} {fmt_time(r['import_s']):>10s} {fmt_time(r['setup_and_preload_s']):>14s}"
                f" {fmt_time(r['first_march_s']):>12s} {fmt_time(r['process_wall_s']):>13s}"
                f" {r['march_cache_hits']:>11d} / {r['march_cache_misses']:<10d} {r['other_kernel_cache_misses']:>21d}"
            )
        compile_s = cold["total_s"] - warm["total_s"]
        recompiled = warm["march_cache_misses"] > 0 or warm["other_kernel_cache_misses"] > 0
        print(f"   compile time (cold - warm, import to first march): {compile_s:.1f} s")
        print(
            f"   second process recompiled the march kernel: {'YES (cache not used!)' if recompiled else 'no (loaded from the on-disk cache)'}"
        )
        if recompiled and (changed or mid != after):
            print(
                "   NOTE: slipstep source files changed between the two processes (numba keys its cache on each source\n"
                f"   file's timestamp, so this recompile is expected): {changed}; rerun when the code is still."
            )
        print()
        results["compile"] = {"cold": cold, "warm": warm, "compile_s": compile_s, "warm_recompiled": recompiled}
    else:
        print("1. numba compile: skipped (--quick or --no-compile; use --compile to force)\n")

    # -- 2. warm kernel ----------------------------------------------------------------------
    system = slipstep.load_system("paper")
    sim = slipstep.Simulation(system, "newmark", periods=1)
    for _ in range(3):
        sim.march()  # warm-up (loads or compiles the kernel in this process)
    if sim.status != slipstep.Status.OK:
        raise SystemExit(f"march failed: {sim.status.message}")
    solves = int(sim.out.counters[K.C_SOLVES])
    floor_call = floor_timer(sim, solves)
    times, floor_times = [], []
    for _ in range(repeats):  # kernel and floor interleaved: machine load hits both alike
        sim.march()
        times.append(sim.kernel_time)
        floor_times.append(floor_call())
    kernel = statistics.median(times)
    c = sim.out.counters
    steps, solves, laws = int(c[K.C_STEPS]), int(c[K.C_SOLVES]), int(c[K.C_LAW_CALLS])
    per_iter = kernel / solves
    print(
        f"2. kernel, one period ({steps} steps, {solves} modified-Newton iterations = solves, "
        f"{laws} contact-law calls, {solves / steps:.2f} iterations/step); median of {repeats} marches"
    )
    q25, q75 = np.percentile(times, [25, 75])
    print(
        f"   {'kernel time per period':30s} {fmt_time(kernel)}   (IQR {fmt_time(q25).strip()} - {fmt_time(q75).strip()}; "
        f"min {fmt_time(min(times)).strip()})   target < {fmt_time(TARGET_KERNEL_S).strip()}: "
        f"{'MET' if kernel < TARGET_KERNEL_S else 'not met'} ({kernel / TARGET_KERNEL_S:.2f} x target)"
    )
    print(f"   {'steps/s':30s} {steps / kernel:11.3g}")
    print(f"   {'iterations/s':30s} {solves / kernel:11.3g}")
    print(f"   {'time per iteration':30s} {fmt_time(per_iter)}")
    print(f"   {'time per step':30s} {fmt_time(kernel / steps)}\n")
    results["kernel"] = {
        "steps": steps,
        "solves": solves,
        "law_calls": laws,
        "kernel_time_s": kernel,
        "kernel_time_min_s": min(times),
        "steps_per_s": steps / kernel,
        "iterations_per_s": solves / kernel,
        "time_per_iteration_s": per_iter,
        "target_s": TARGET_KERNEL_S,
    }

    # -- 3. arithmetic floor -----------------------------------------------------------------
    floor = statistics.median(floor_times) / solves
    print("3. arithmetic floor: one iteration = q = q_base + A dx, contact law, A^T f, residual, one 3x3 LU solve")
    print(f"   ({FLOOR_FUNCTIONS}, in a numba loop written in this script, {solves} iterations per call)")
    print(
        f"   {'floor time per iteration':30s} {fmt_time(floor)}   ({solves} of them = {fmt_time(floor * solves).strip()} per period)"
    )
    print(f"   {'real / floor':30s} {per_iter / floor:8.2f} x   (1 = the kernel does nothing but the arithmetic)\n")
    results["floor"] = {
        "time_per_iteration_s": floor,
        "floor_per_period_s": floor * solves,
        "real_over_floor": per_iter / floor,
    }

    # -- 4. whole run() --------------------------------------------------------------------
    n_run = 10 if args.quick else 40
    slipstep.run(system, "newmark", periods=1)
    walls = []
    for _ in range(n_run):
        t = time.perf_counter()
        ds = slipstep.run(system, "newmark", periods=1)
        walls.append(time.perf_counter() - t)
    wall = statistics.median(walls)
    t = time.perf_counter()
    for _ in range(n_run):
        slipstep.Simulation(system, "newmark", periods=1)
    setup = (time.perf_counter() - t) / n_run
    print(f"4. slipstep.run(system, 'newmark', periods=1), median of {n_run} (status {ds.attrs['status']})")
    print(
        f"   {'run() wall time':30s} {fmt_time(wall)}   target < {fmt_time(TARGET_RUN_S).strip()}: "
        f"{'MET' if wall < TARGET_RUN_S else 'not met'} ({wall / TARGET_RUN_S:.2f} x target)"
    )
    print(f"   {'  of which Simulation() set-up':30s} {fmt_time(setup)}   (compile arrays, T_min, allocate, preload)")
    print(f"   {'  of which kernel':30s} {fmt_time(kernel)}")
    print(f"   {'  rest (Dataset, etc.)':30s} {fmt_time(max(wall - setup - kernel, 0.0))}")
    results["run"] = {"wall_s": wall, "setup_s": setup, "target_s": TARGET_RUN_S}

    print("\nSummary")
    print(f"   {'measure':34s} {'measured':>12s} {'target':>12s}  met")
    print(
        f"   {'kernel, one period':34s} {fmt_time(kernel):>12s} {fmt_time(TARGET_KERNEL_S):>12s}  {'yes' if kernel < TARGET_KERNEL_S else 'NO'}"
    )
    print(
        f"   {'run() call, one period':34s} {fmt_time(wall):>12s} {fmt_time(TARGET_RUN_S):>12s}  {'yes' if wall < TARGET_RUN_S else 'NO'}"
    )
    print(f"   {'iteration / arithmetic floor':34s} {per_iter / floor:10.2f} x {'':>12s}")
    if "compile" in results:
        print(
            f"   {'compile (cold - warm process)':34s} {results['compile']['compile_s']:10.1f} s "
            f"{'':>12s}  {'cached' if not results['compile']['warm_recompiled'] else 'RECOMPILED'}"
        )
    if args.json:
        print(json.dumps(results, indent=1, default=float))
    return results


if __name__ == "__main__":
    main()
