"""The trust check on many seeded random systems (issue 8): every OK result of Method 1
(newmark), full Newton and Method 3 (piecewise-linear) at their default options must agree
with a tight full-Newton reference on the same grid to 1e-6 of the response range.

    python benchmarks/random_systems.py            # 5,000 systems (about 2-4 min on 2 cores)
    python benchmarks/random_systems.py --n 500 --seed 3 --rtol 1e-4

Prints the failure rate per method (and overall), on the well-conditioned systems and on
all of them (a sensitive system's response moves by more than rtol when its loads are scaled
by 1 + 1e-10: see slipstep.study.verification), and the worst cases.
A failure is a status-OK result that is wrong: it must never happen.

    python benchmarks/random_systems.py --families --n 200     # issue 29: n systems per family

The issue-29 mode: the generators of slipstep.study.verification.family_system (single-stick,
two-on-one, mixed, general, slow-load: 2D laws, harmonic loads and motions, load period tied
to T_min) and, per method and family, the rate of results ending INVARIANT (an OK march that
broke a contact invariant: slipstep.methods.invariants) and, for Method 1, full Newton and Method 3 on
the decidable systems (full Newton and the piecewise-linear solve at 1e-13 agree to 1e-8), the
rate of OK results more than rtol of the range from them.

    python benchmarks/random_systems.py --trust --n 5000   # issue 29 item 3: n systems per generator

The issue-29 item-3 mode: the generators of slipstep.study.trust_systems (stick-1dof, shared-dof,
lever-map, broad), Method 1 ('newmark') at its defaults against full Newton and the piecewise-linear
solve at 1e-13 (study.trust_systems.newmark_check); per generator the decidable systems, the silent
failures (OK, no trust flag, more than rtol of the range off; those whose references are
sensitive, a round-off spread above 1e-12 or a 1e-10 load change moving them by rtol, counted
apart), the silent failures before the load-sensitivity flag (the step audit and the tolerance flag
only), the flagged results (slipstep.methods.invariants.flagged: the step audit, the tolerance flag
or the sensitivity twin: slipstep.methods.sensitivity_twin), the false alarms (flagged, decidable and within rtol), the non-OK
results, the runs whose perturbed twin ran and its CPU share of Method 1's runs.

    python benchmarks/random_systems.py --trust --n 5000 --sensitivity true --dump rows.jsonl

runs the twin on every result (``sensitivity_check=True``) and writes one JSON line per system
(twin_difference, state_change_share, error, ...): the data the flag's threshold and the 'auto'
trigger were chosen from (slipstep.methods.sensitivity_twin).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from slipstep.study.trust_systems import GENERATORS, newmark_check, reference_sensitive, trust_system
from slipstep.study.verification import (
    CHECK_METHODS,
    FAMILIES,
    INVARIANT_METHODS,
    check_system,
    failures,
    family_check,
    family_system,
    random_system,
)


def families(n: int, seed: int, periods: float, rtol: float) -> None:
    """The issue-29 table (module docstring): per family and method, INVARIANT and disagreement rates."""
    start = time.perf_counter()
    print(f"{n} systems per family, seed {seed}, {periods:g} periods, agreement rtol {rtol:g}")
    print("  off: OK and more than rtol of the range from the references; unflagged: off without the step")
    print("  audit's warning (invariants.audit_steps): the failures that must not happen")
    head = f"  {'family':13s} {'method':20s} {'ran':>5s} {'INVARIANT':>11s} {'decidable':>9s} {'off':>5s}"
    print(head + f" {'unflagged':>16s} {'flagged':>8s}  worst")
    for family in FAMILIES:
        # ran, INVARIANT, decidable OK, off, worst, off and unflagged, flagged
        counts = {m: [0, 0, 0, 0, 0.0, 0, 0] for m in INVARIANT_METHODS}
        for i in range(n):
            rows = family_check(family_system(np.random.default_rng([seed, i]), family), periods=periods, rtol=rtol)
            for m in INVARIANT_METHODS:
                c, r = counts[m], rows[m]
                c[0] += r["status"] != "SETUP"
                c[1] += r["status"] == "INVARIANT"
                c[6] += r["flagged"]
                if np.isfinite(r["error"]):
                    c[2] += 1
                    c[3] += not r["error"] <= rtol
                    c[4] = max(c[4], r["error"])
                    c[5] += not r["error"] <= rtol and not r["flagged"]
        for m, (ran, inv, dec, off, worst, silent, flagged) in counts.items():
            agree = ""
            if m in CHECK_METHODS:
                agree = f"{dec:9d} {off:5d} {silent:7d} ({100 * silent / max(dec, 1):4.1f} %) {flagged:8d}  {worst:.2g}"
            print(f"  {family:13s} {m:20s} {ran:5d} {inv:4d} ({100 * inv / max(ran, 1):4.1f} %) {agree}")
    print(f"  {time.perf_counter() - start:.0f} s")


def trust(
    n: int, seed: int, periods: float, rtol: float, method: str = "newmark", sensitivity="auto", dump: str | None = None
) -> None:
    """The issue-29 item-3 table (module docstring): per generator, Method 1's silent failures, with
    the run's ``sensitivity_check`` option ``sensitivity`` ('auto', True or False)."""
    start = time.perf_counter()
    print(
        f"{n} systems per generator, seed {seed}, {periods:g} periods, method {method}, rtol {rtol:g}, "
        f"sensitivity_check={sensitivity!r}"
    )
    print("  silent: OK, unflagged, more than rtol of the range off the two agreeing tight references")
    print("  silent before: the same without the sensitivity twin's flag (the tolerance flag and step audit only)")
    print(
        f"  {'generator':11s} {'systems':>7s} {'decidable':>9s} {'silent':>15s} {'of them sensitive':>17s} "
        f"{'silent before':>13s} {'flagged':>7s} {'false alarms':>12s} {'non-OK':>6s} {'twins':>6s} "
        f"{'twin CPU':>8s}  worst silent, not sensitive"
    )
    total = np.zeros(9, int)
    cpu_total = np.zeros(2)
    out = open(dump, "w") if dump else None  # noqa: SIM115  (one JSON line per system)
    for g, generator in enumerate(GENERATORS):
        # systems, decidable, silent, silent and sensitive, flagged, non-OK, false alarms, silent before, twins
        c = np.zeros(9, int)
        cpu = np.zeros(2)  # Method 1's runs (twins included), the twins
        worst = (0.0, -1)
        for i in range(n):
            system = trust_system(np.random.default_rng([seed, g, i]), generator)
            row = newmark_check(system, method, periods=periods, sensitivity_check=sensitivity)
            if row is None:
                continue
            c[0] += 1
            c[1] += row["decidable"]
            c[4] += row["flagged"]
            c[5] += row["status"] != "OK"
            c[6] += row["flagged"] and row["error"] <= rtol  # a flag on a result that agrees
            c[7] += row["error"] > rtol and not row["flagged_tolerance"]
            c[8] += row["twin_cpu_s"] > 0
            cpu += (row["run_cpu_s"], row["twin_cpu_s"])
            sensitive = None
            if row["error"] > rtol and not row["flagged"]:
                c[2] += 1
                sensitive = reference_sensitive(system, periods=periods, rtol=rtol)
                c[3] += sensitive
                if not sensitive:
                    worst = max(worst, (row["error"], i))
            if out is not None:
                out.write(json.dumps({"generator": generator, "system": i, "sensitive": sensitive, **row}) + "\n")
                out.flush()
        total += c
        cpu_total += cpu
        _trust_row(generator, c, cpu, f"  {worst[0]:.2g} (system {worst[1]})")
    _trust_row("all", total, cpu_total, "")
    if out is not None:
        out.close()
    print(f"  twin CPU: the twins' CPU time / Method 1's runs' (twins included); {time.perf_counter() - start:.0f} s")


def _trust_row(name: str, c, cpu, tail: str) -> None:
    print(
        f"  {name:11s} {c[0]:7d} {c[1]:9d} {c[2]:6d} ({100 * c[2] / max(c[1], 1):5.2f} %) {c[3]:17d} "
        f"{c[7]:13d} {c[4]:7d} {c[6]:12d} {c[5]:6d} {c[8]:6d} {100 * cpu[1] / max(cpu[0], 1e-300):6.1f} %{tail}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5000, help="number of random systems")
    parser.add_argument("--seed", type=int, default=2026, help="seed of the system generator")
    parser.add_argument("--rtol", type=float, default=1e-6, help="agreement required, fraction of the range")
    parser.add_argument("--periods", type=float, default=2.0)
    parser.add_argument(
        "--adaptive", action="store_true", help="also Method 2 against a tight Method 2+3 on their adaptive grid"
    )
    parser.add_argument("--families", action="store_true", help="issue 29: invariants and agreement per family")
    parser.add_argument(
        "--trust", action="store_true", help="issue 29 item 3: Method 1's silent failures per generator"
    )
    parser.add_argument(
        "--sensitivity",
        choices=("auto", "true", "false"),
        default="auto",
        help="--trust: Method 1's sensitivity_check option (the perturbed twin)",
    )
    parser.add_argument("--dump", help="--trust: write one JSON line per system to this file")
    args = parser.parse_args()
    if args.trust:
        sensitivity = {"auto": "auto", "true": True, "false": False}[args.sensitivity]
        trust(args.n, args.seed, args.periods, args.rtol, sensitivity=sensitivity, dump=args.dump)
        return
    if args.families:
        families(args.n, args.seed, args.periods, args.rtol)
        return
    start = time.perf_counter()
    checked = sensitive = skipped = 0
    methods = CHECK_METHODS + (("newmark-adaptive",) if args.adaptive else ())
    failed = {m: 0 for m in methods}
    not_ok = {m: 0 for m in methods}
    any_failed = any_failed_all = 0
    failed_all = {m: 0 for m in methods}
    worst = []
    for i in range(args.n):
        rows = check_system(
            random_system(np.random.default_rng([args.seed, i])),
            periods=args.periods,
            rtol=args.rtol,
            adaptive=args.adaptive,
        )
        if rows is None:
            skipped += 1
            continue
        checked += 1
        sensitive += bool(rows["sensitive"])
        for m in methods:
            not_ok[m] += rows[m]["status"] != "OK"
        bad_all = failures(rows, args.rtol, include_sensitive=True)
        any_failed_all += bool(bad_all)
        for m in bad_all:
            failed_all[m] += 1
        bad = failures(rows, args.rtol)
        any_failed += bool(bad)
        for m in bad:
            failed[m] += 1
            worst.append((rows[m]["error"], i, m))
    elapsed = time.perf_counter() - start
    print(
        f"{checked} systems checked ({skipped} skipped: no static equilibrium or reference failed; "
        f"{sensitive} sensitive, counted apart), seed {args.seed}, {elapsed:.0f} s"
    )
    print(f"failure = status OK but more than {args.rtol:g} of the range from the tight reference")
    good = max(checked - sensitive, 1)
    print(f"  {'':18s} {'well-conditioned':>18s} {'all systems':>18s}  non-OK statuses")
    for m in methods:
        print(
            f"  {m:18s} {failed[m]:7d} ({100 * failed[m] / good:5.2f} %) {failed_all[m]:7d} "
            f"({100 * failed_all[m] / max(checked, 1):5.2f} %)  {not_ok[m]}"
        )
    print(
        f"  {'any method':18s} {any_failed:7d} ({100 * any_failed / good:5.2f} %) {any_failed_all:7d} "
        f"({100 * any_failed_all / max(checked, 1):5.2f} %)"
    )
    for err, i, m in sorted(worst, reverse=True)[:10]:
        print(f"    worst: system {i} {m}: {err:.3g} of the range")


if __name__ == "__main__":
    main()
