"""The accuracy of slipstep.frequency.frf at its defaults (issue 24, item 4), not its speed: the
single-DOF Jenkins oscillator (m 2.5 kg, k 1e7 N/m, C = 40 M, k_t 1e7 N/m, slip force 50 N,
F = 100 N) at 11 frequencies between 250 and 500 Hz by each solver (march, shoot, hbm, auto),
against the exact continuous periodic orbit of tests/jenkins_reference.py.

Per point: the friction energy per cycle, the reference's, the true relative error of the
energies per cycle (tests/frf_accuracy.py: as the estimate is defined), the point's
error_estimate, their ratio, the steps per period (AFT samples for hbm) and whether it warns.
The issue's figures (before): the marched and shot FRFs at 50 steps per period off by up to
2.6 % with no warning; HBM at H = 5 within 0.4 %, its estimate within about 3x of the error.

Usage:  python benchmarks/bench_frf_accuracy.py [--quick] [--rtol R] [--steps-per-period N] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import frf_accuracy as FA  # noqa: E402


def table(solver: str, frequencies, rtol: float, steps: int | None) -> dict:
    start = time.perf_counter()
    extra = {} if steps is None or solver == "hbm" else {"steps_per_period": steps}
    ds, warned = FA.frf_at_defaults(solver, frequencies, rtol=rtol, **extra)
    wall = time.perf_counter() - start
    rows = FA.rows(ds)
    return {"solver": solver, "wall_time_s": wall, "summary_warnings": len(warned), "points": rows}


def _text(result: dict, rtol: float) -> str:
    lines = [
        f"{result['solver']}: {len(result['points'])} points in {result['wall_time_s']:.2f} s "
        f"(the reference orbits excluded), {result['summary_warnings']} summary warning(s)",
        f"{'f [Hz]':>8} {'E [mJ]':>9} {'E_ref [mJ]':>10} {'true err':>9} {'estimate':>9} {'est/err':>8} "
        f"{'steps':>6} {'warns':>5}  status",
    ]
    for r in result["points"]:
        ratio = r["error_estimate"] / r["true_error"] if r["true_error"] > 0 else math.nan
        lines.append(
            f"{r['frequency_Hz']:8.1f} {r['friction_energy_J'] * 1e3:9.4f} {r['reference_J'] * 1e3:10.4f} "
            f"{r['true_error']:9.2e} {r['error_estimate']:9.2e} {ratio:8.2f} {r['steps_per_period']:6.0f} "
            f"{'yes' if r['status_message'] else 'no':>5}  {r['status']}"
        )
    worst = max(r["true_error"] for r in result["points"])
    silent = [r for r in result["points"] if r["true_error"] > rtol and not r["status_message"]]
    lines.append(f"largest true error {worst:.2e}; points above rtol {rtol:g} without a warning: {len(silent)}")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="5 frequencies instead of 11")
    parser.add_argument("--rtol", type=float, default=1e-2, help="the FRF's rtol (default 1e-2)")
    parser.add_argument(
        "--steps-per-period",
        type=int,
        default=None,
        help="march/shoot: the first solve's steps per period (default: the steady default, 256; the issue's was 50)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    freqs = FA.FREQUENCIES[::2] if args.quick else FA.FREQUENCIES
    start = time.perf_counter()
    for f in freqs:
        FA.reference(f)
    ref_time = time.perf_counter() - start
    FA.frf_at_defaults("shoot", freqs[:1])  # warm-up: compile or cache load
    results = [table(s, freqs, args.rtol, args.steps_per_period) for s in ("march", "shoot", "hbm", "auto")]
    if args.json:
        print(json.dumps({"reference_time_s": ref_time, "rtol": args.rtol, "solvers": results}, allow_nan=False))
        return 0
    print(f"Jenkins oscillator, exact reference at {len(freqs)} frequencies ({ref_time:.1f} s), rtol {args.rtol:g}")
    for r in results:
        print()
        print(_text(r, args.rtol))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
