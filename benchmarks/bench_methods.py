"""All methods side by side on the paper case (issue 3, "Speed"; the paper's Figure 8).

Two cases, each marched by Methods 1, 2, 3, 2+3 and 4 (quasi-static, 300 steps/period):

* 200 Hz: the built-in ``paper`` case, one period after the preload;
* 100 Hz: the same TOML with the platform motion at 100 Hz, three periods (the paper's
  timing example: 9.46 s -> 5.09 s).

Kernel time = ``Simulation.march()`` (the compiled time loop only), median of repeats after
a warm-up, with the methods interleaved round-robin so machine noise hits all alike. The
ratio is to Method 1 measured in the same run. Printed beside it: the paper's ratio
(Figure 8) and our goal.

Usage:  python benchmarks/bench_methods.py [--quick] [--repeats N] [--json [FILE]]
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import statistics
import time

import slipstep
from slipstep.config import CASES_DIR, build_system, parse_case, read_toml
from slipstep.kernels import march as K

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
        opts = {"periods": periods}
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
    args = ap.parse_args(argv)
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
