"""Frequency responses by marching against shooting (issue 11), measured in one run.

For each case, the same stepped FRF (61 points, each point from the previous one's steady
state, tolerance 1e-6 on the change of the full state over one period) is computed with

* march:  slipstep.steady.march_to_steady at every point (the baseline),
* shoot:  slipstep.steady.shoot (Newton on the one-period map, exact discrete Jacobian),
* and, where the case has DOFs held by contacts only, marching and shooting with the
  quasi-static-dofs method (the damper without inertia inside dynamic blades),

printing the whole-FRF time, the time per point, the periods simulated (total and per point),
the points that reached the steady state, the ratio to marching, and the largest relative
difference of the response amplitude against marching (on the points steady in both) and of
the peak. Compile/caches are warmed first (a 2-point FRF of each variant).

Cases: the examples' Jenkins oscillator and contact chain, and the built-in ``blades`` and
``ring`` cases when present (slipstep.builtin_cases()).

Usage:  python benchmarks/bench_frf.py [--quick] [--points N] [--json FILE] [CASE ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import slipstep
from slipstep.errors import InputError
from slipstep.frequency import frf
from slipstep.methods.registry import METHODS

ROOT = Path(__file__).resolve().parents[1]
CASES = {  # case -> (frequency range [Hz], response DOF or None: the largest)
    str(ROOT / "examples" / "jenkins.toml"): ((250.0, 450.0), "x"),
    str(ROOT / "examples" / "contact_chain.toml"): ((100.0, 600.0), "x3"),
    "blades": ((150.0, 450.0), None),
    "ring": ((150.0, 450.0), None),
}
QS_DAMPER_METHODS = [name for name, m in METHODS.items() if getattr(m, "massless", False)]  # quasi-static-dofs


def variants(case: str):
    out = [("march", dict(solver="march")), ("shoot", dict(solver="shoot"))]
    for name in QS_DAMPER_METHODS:
        out.append((f"march, {name}", dict(solver="march", method=name)))
        out.append((f"shoot, {name}", dict(solver="shoot", method=name)))
    return out


def measure(system, freqs, options, tolerance, max_periods):
    start = time.perf_counter()
    ds = frf(system, freqs, tolerance=tolerance, max_periods=max_periods, **options)
    wall = time.perf_counter() - start
    return ds, wall


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("cases", nargs="*", help="case names or TOML files (default: all available)")
    p.add_argument("--points", type=int, default=61)
    p.add_argument("--quick", action="store_true", help="11 points")
    p.add_argument("--tolerance", type=float, default=1e-6)
    p.add_argument("--max-periods", type=int, default=400)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args(argv)
    points = 11 if args.quick else args.points
    available = set(slipstep.builtin_cases())
    cases = args.cases or [c for c in CASES if Path(c).suffix or c in available]
    rows = []
    for case in cases:
        (f0, f1), response = CASES.get(case, ((150.0, 450.0), None))
        system = slipstep.load_system(case)
        freqs = np.linspace(f0, f1, points)
        name = Path(case).stem if Path(case).suffix else case
        print(
            f"\n{name}: {system.n_dofs} DOFs, {len(system.contacts)} contacts, {points} points "
            f"{f0:g}-{f1:g} Hz, tolerance {args.tolerance:g}",
            flush=True,
        )
        usable = []
        for label, opts in variants(case):  # warm-up: compile and caches
            try:
                measure(system, freqs[:2], opts, args.tolerance, 20)
                usable.append((label, opts))
            except InputError as exc:  # e.g. no massless DOFs in this case
                print(f"  {label:28s} n/a: {exc}")
        base = None
        for label, opts in usable:
            ds, wall = measure(system, freqs, opts, args.tolerance, args.max_periods)
            if response is None:  # the translational DOF with the largest response (the first variant's)
                metres = ds["response"].values[ds["response_unit"].values == "m"]
                response = str(ds["amplitude"].sel(response=metres).max("frequency").idxmax("response").values)
            resp = response
            amp = ds["amplitude"].sel(response=resp).values
            periods = ds["periods_to_steady"].values
            ok_mask = ds["status"].values == "OK"
            ok = int(ok_mask.sum())
            row = {
                "case": name,
                "variant": label,
                "wall_s": wall,
                "per_point_ms": 1e3 * wall / points,
                "periods_total": int(np.nansum(periods)),
                "periods_per_point": float(np.nanmean(periods)),
                "points_ok": ok,
                "points": points,
                "peak_Hz": float(freqs[int(np.nanargmax(amp))]),
                "peak": float(np.nanmax(amp)),
                "response": resp,
            }
            if base is None:
                base = (row, amp, ok_mask)
                row.update(time_ratio=1.0, periods_ratio=1.0, max_rel_diff=0.0, peak_rel_diff=0.0, compared=ok)
            else:
                b, bamp, bok = base
                both = ok_mask & bok  # agreement where both reached the steady state
                diff = np.abs(amp - bamp) / np.abs(bamp)
                row.update(
                    time_ratio=wall / b["wall_s"],
                    periods_ratio=row["periods_total"] / b["periods_total"],
                    max_rel_diff=float(diff[both].max()) if both.any() else float("nan"),
                    peak_rel_diff=abs(row["peak"] - b["peak"]) / b["peak"],
                    compared=int(both.sum()),
                )
            rows.append(row)
            print(
                f"  {label:28s} FRF {wall:7.3f} s  {row['per_point_ms']:8.2f} ms/point  periods "
                f"{row['periods_total']:6d} ({row['periods_per_point']:6.1f}/point)  ok {ok}/{points}  "
                f"time x{row['time_ratio']:.3f}  periods x{row['periods_ratio']:.3f}  "
                f"peak {row['peak']:.4e} at {row['peak_Hz']:.4g} Hz  max |diff| {row['max_rel_diff']:.1e} "
                f"(on {row['compared']} points steady in both)  "
                f"peak diff {row['peak_rel_diff']:.1e}",
                flush=True,
            )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
