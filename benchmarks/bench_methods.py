"""All methods side by side on the paper case (issue 3, "Speed"; the paper's Figure 8).

Two cases, each marched by Methods 1, 2, 3, 2+3 and 4 (quasi-static, 300 steps/period):

* 200 Hz: the built-in ``paper`` case, one period after the preload;
* 100 Hz: the same TOML with the platform motion at 100 Hz, three periods (the paper's
  timing example: 9.46 s -> 5.09 s).

Kernel time = ``Simulation.march()`` (the compiled time loop only), median of repeats after
a warm-up, with the methods interleaved round-robin so machine noise hits all alike. The
ratio is to Method 1 measured in the same run. Printed beside it: the paper's ratio
(Figure 8) and our goal.

``--per-step``: the cost of one step of Method 4 (quasi-static, 300 steps/period, paper case)
split into its solve and the rest (loads and motions, residual base, compatibility bookkeeping,
outputs, loop control): the solve part is timed by a numba loop written here that repeats exactly
the piecewise-linear solve of one step (the law in the postulated state at q_base, A^T f, the
residual, one LU solve with the cached factorisation, q = q_base + A dx, the compatibility check,
the law at q and A^T f) on the march's own arrays; the rest is the step time minus that. Runs
with any slipstep tree on PYTHONPATH (it uses only kernels/contact.py and kernels/linalg.py).

Usage:  python benchmarks/bench_methods.py [--quick] [--repeats N] [--json [FILE]] [--per-step]
"""

from __future__ import annotations

import argparse
import copy
import inspect
import json
import os
import statistics
import time

import numpy as np
from llvmlite import ir
from numba import njit
from numba.core import cgutils
from numba.extending import intrinsic

import slipstep
from slipstep.casefile.case import CASES_DIR, build_system, parse_case, read_toml
from slipstep.kernels import march as K
from slipstep.kernels.contact import compatible, piecewise_law, scatter
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.settings import contact_table
from pinning import pin_to_one_cpu

# the scatter core takes A since issue 24 (row-wise axpy); trees before it took A^T
_SCATTER_TAKES_A = next(iter(inspect.signature(scatter.py_func).parameters)) == "A"

# (method, label, paper ratio to Method 1 (Figure 8: "at most"), our goal ratio)
METHODS = [
    ("newmark", "1", None, None),
    ("newmark-adaptive", "2", 0.8, None),
    ("piecewise-linear", "3", 0.5, 0.15),
    ("piecewise-linear-adaptive", "2+3", 0.4, 0.12),
    ("quasi-static", "4", 0.1, 0.12),
]
GOAL_M3_ABS_S = 100e-6  # Method 3, one period of the paper case at 200 Hz
QS_STEPS_PER_PERIOD = 300


def paper_system(frequency_hz: float | None = None) -> slipstep.System:
    """The paper case, optionally with the platform motion at another frequency."""
    data = read_toml(CASES_DIR / "paper.toml")
    if frequency_hz is not None:
        data = copy.deepcopy(data)
        for m in data["motion"]:
            m["frequency_Hz"] = frequency_hz
        data["name"] = f"paper-{frequency_hz:g}Hz"
    return build_system(parse_case(data, source="paper.toml (benchmark variant)"))


def bench_case(label: str, system: slipstep.System, periods: float, repeats: int) -> list[dict]:
    sims = []
    for name, paper_label, paper_ratio, goal in METHODS:
        opts = {"periods": periods, "step_rule": "t-min"}  # the paper's steps for every method (Figure 8)
        if name == "quasi-static":
            opts["steps_per_period"] = QS_STEPS_PER_PERIOD
        sim = slipstep.Simulation(system, name, **opts)
        for _ in range(3):  # warm-up: JIT load/compile and caches
            sim.march()
        if sim.status != slipstep.Status.OK:
            print(f"   WARNING: {name} on {label} ended with {sim.status.name}: {sim.status.message}")
        sims.append(sim)
    times = [[] for _ in sims]
    for _ in range(repeats):
        for i, sim in enumerate(sims):
            sim.march()
            times[i].append(sim.kernel_time)
    rows = []
    for (name, paper_label, paper_ratio, goal), sim, ts in zip(METHODS, sims, times):
        c = sim.out.counters
        rows.append(
            {
                "case": label,
                "method": name,
                "paper_method": paper_label,
                "periods": periods,
                "status": sim.status.name,
                "kernel_time_s": statistics.median(ts),
                "kernel_time_min_s": min(ts),
                "steps": int(c[K.C_STEPS]),
                "solves": int(c[K.C_SOLVES]),
                "factorisations": int(c[K.C_FACTORISATIONS]),
                "state_changes": int(c[K.C_STATE_CHANGES]),
                "paper_ratio_max": paper_ratio,
                "goal_ratio_max": goal,
            }
        )
    ref = rows[0]["kernel_time_s"]
    for r in rows:
        r["time_ratio"] = r["kernel_time_s"] / ref
        r["time_per_period_s"] = r["kernel_time_s"] / periods
    return rows


@intrinsic
def _borrowed(typingctx, ary):
    """The array without reference counting (as kernels/borrow.py, repeated here so that the
    floor runs with any slipstep tree)."""

    def codegen(context, builder, signature, args):
        view = cgutils.create_struct_proxy(signature.args[0])(context, builder, value=args[0])
        view.meminfo = ir.Constant(view.meminfo.type, None)
        return view._getvalue()

    return ary(ary), codegen


@njit(cache=True)
def _solve_floor(A, AT, nrow, lcode, lpar, fdir, ndir, trow, kt, lu, piv, qbase, w, st, r0, rtol, L, n_steps):
    """n_steps piecewise-linear step solves in state st (one postulate each, as a compatible step of
    Method 4); the arrays are the arguments (no view or copy is made per step)."""
    A, AT, nrow, lcode, lpar, fdir = (
        _borrowed(A),
        _borrowed(AT),
        _borrowed(nrow),
        _borrowed(lcode),
        _borrowed(lpar),
        _borrowed(fdir),
    )
    ndir, trow, kt, lu, piv = _borrowed(ndir), _borrowed(trow), _borrowed(kt), _borrowed(lu), _borrowed(piv)
    qbase, w, st, r0 = _borrowed(qbase), _borrowed(w), _borrowed(st), _borrowed(r0)
    nq, n = A.shape
    f = np.empty(nq)
    q = np.empty(nq)
    w1 = np.empty(w.shape[0])
    gf = np.empty(n)
    r = np.empty(n)
    dx = np.empty(n)
    ok = 0
    for k in range(n_steps):
        for i in range(nq):
            q[i] = qbase[i]
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, st, q, w, f, w1)
        scatter(A if _SCATTER_TAKES_A else AT, f, gf)
        for i in range(n):
            r[i] = r0[i] - gf[i]
        lu_solve(lu, piv, r, dx)
        for rr in range(nq):
            s = qbase[rr]
            for j in range(n):
                s += A[rr, j] * dx[j]
            q[rr] = s
        ok += compatible(nrow, lcode, lpar, fdir, ndir, trow, kt, st, q, w, rtol, L)
        piecewise_law(nrow, lcode, lpar, fdir, ndir, trow, kt, st, q, w, f, w1)
        scatter(A if _SCATTER_TAKES_A else AT, f, gf)
    return ok


def per_step(repeats: int) -> dict:
    """Method 4 step time, its solve part (the floor loop above) and the rest [s per step]."""
    system = slipstep.load_system("paper")
    sim = slipstep.Simulation(system, "quasi-static", periods=1, steps_per_period=QS_STEPS_PER_PERIOD)
    for _ in range(3):
        sim.march()
    cs = sim.compiled
    n_steps = int(sim.out.counters[K.C_STEPS])
    k = np.arange(n_steps + 1)
    q, w = sim.out.q[k[-1]].copy(), sim.out.w[k[-1]].copy()
    state = sim.out.state[n_steps].copy()
    J = cs.K.copy()
    from slipstep.kernels.contact import add_contact_stiffness

    add_contact_stiffness(cs, state, 1.0, J)
    lu, piv = np.empty_like(J), np.empty(J.shape[0], np.int64)
    lu_factor(J, lu, piv, 1e-13)
    r0 = cs.K @ sim.out.x[k[-1]]
    args = (
        cs.A,
        cs.AT,
        *contact_table(cs),
        lu,
        piv,
        q,
        w,
        state,
        r0,
        sim.options.state_tolerance,
        cs.length_scale,
        n_steps,
    )
    _solve_floor(*args)
    step_times, floor_times = [], []
    for _ in range(repeats):  # interleaved: machine load hits both alike
        sim.march()
        step_times.append(sim.kernel_time / n_steps)
        t0 = time.perf_counter()
        _solve_floor(*args)
        floor_times.append((time.perf_counter() - t0) / n_steps)
    step, solve = min(step_times), min(floor_times)
    row = {
        "steps": n_steps,
        "step_s": step,
        "step_median_s": statistics.median(step_times),
        "solve_s": solve,
        "rest_s": step - solve,
    }
    print(
        f"Method 4 on the paper case ({QS_STEPS_PER_PERIOD} steps/period), min of {repeats} marches "
        f"(slipstep from {os.path.dirname(slipstep.__file__)}):"
    )
    print(
        f"   step {step * 1e9:7.0f} ns (median {row['step_median_s'] * 1e9:.0f}),  of which the solve "
        f"{solve * 1e9:5.0f} ns,  the rest (loads and motions, r0, bookkeeping, outputs) {row['rest_s'] * 1e9:5.0f} ns"
    )
    return row


def fmt_us(s: float) -> str:
    return f"{s * 1e6:10.1f}"


def verdict(ratio: float, bound: float | None) -> str:
    if bound is None:
        return "   -"
    return f"<={bound:<4g} {'ok' if ratio <= bound else 'MISS'}"


def print_table(rows: list[dict], repeats: int) -> None:
    r0 = rows[0]
    print(f"\n{r0['case']}: {r0['periods']:g} period(s), kernel time = median of {repeats} marches")
    head = (
        f"   {'method':27s} {'M':>4s} {'kernel [us]':>11s} {'per period':>11s} {'ratio':>7s} {'steps':>6s}"
        f" {'solves':>7s} {'solves/step':>11s} {'fact.':>6s} {'paper':>10s} {'goal':>10s}"
    )
    print(head)
    print("   " + "-" * (len(head) - 3))
    for r in rows:
        print(
            f"   {r['method']:27s} {r['paper_method']:>4s} {fmt_us(r['kernel_time_s']):>11s}"
            f" {fmt_us(r['time_per_period_s']):>11s} {r['time_ratio']:7.3f} {r['steps']:6d} {r['solves']:7d}"
            f" {r['solves'] / max(r['steps'], 1):11.2f} {r['factorisations']:6d}"
            f" {verdict(r['time_ratio'], r['paper_ratio_max']):>10s} {verdict(r['time_ratio'], r['goal_ratio_max']):>10s}"
            + ("" if r["status"] == "OK" else f"  status {r['status']}")
        )


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats")
    ap.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="repeats per method at 200 Hz (default 300, quick 15); the 100 Hz case uses a third as many",
    )
    ap.add_argument(
        "--json",
        nargs="?",
        const="-",
        default=None,
        metavar="FILE",
        help="dump the results as a JSON list (to FILE, or stdout if no FILE)",
    )
    ap.add_argument("--per-step", action="store_true", help="only the per-step cost split of Method 4")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU")
    args = ap.parse_args(argv)
    print(pin_to_one_cpu(not args.no_pin))
    if args.per_step:
        return [per_step(args.repeats or (30 if args.quick else 200))]
    rep200 = args.repeats or (15 if args.quick else 300)
    rep100 = max(rep200 // 3, 5)

    print(
        f"slipstep {slipstep.__version__}: all methods on the paper case; {os.cpu_count()} CPUs "
        f"(shared: numbers are noisy), {time.strftime('%Y-%m-%d %H:%M')}"
    )
    rows200 = bench_case("paper, 200 Hz", paper_system(), 1, rep200)
    print_table(rows200, rep200)
    m3 = next(r for r in rows200 if r["method"] == "piecewise-linear")
    print(
        f"   Method 3 absolute, one period at 200 Hz: {m3['kernel_time_s'] * 1e6:.1f} us "
        f"(goal < {GOAL_M3_ABS_S * 1e6:.0f} us: {'ok' if m3['kernel_time_s'] < GOAL_M3_ABS_S else 'MISS'})"
    )
    rows100 = bench_case("paper, 100 Hz", paper_system(100.0), 3, rep100)
    print_table(rows100, rep100)
    print("   (paper, 100 Hz 3 periods: Method 1 9.46 s -> Method 3 5.09 s in their MATLAB code, ratio 0.54)")
    print("\npaper = the ratio the paper reports (Figure 8), goal = slipstep's aim; 'ok' = measured ratio within it.")
    rows = rows200 + rows100
    if args.json is not None:
        text = json.dumps(rows, indent=1)
        if args.json == "-":
            print(text)
        else:
            with open(args.json, "w") as fh:
                fh.write(text + "\n")
            print(f"results written to {args.json}")
    return rows


if __name__ == "__main__":
    main()
