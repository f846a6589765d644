"""The `blades` case by harmonic balance and by time marching, on one plot.

    python examples/hbm_blades.py [--harmonics 15] [--points 13] [--output-dir slipstep-out]

Computes the HBM FRF of the tip of blade 1 over 300-420 Hz (pseudo-arclength continuation;
the time-marching cross-check at the peak and at 330 and 400 Hz), the marched FRF on the same
grid when slipstep.frequency.frf is available (the steady state per point by marching, each
from the previous one), writes both into one figure and prints the cross-check numbers and
the time per point of each.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import slipstep as ss
from slipstep.hbm import frf
from slipstep.hbm.plot import plot_frf

RESPONSE = "blade1.8.x"


def compute(harmonics=15, points=13, check_frequencies=(330.0, 400.0), march=True):
    """(HBM Dataset, marched Dataset or None, timings dict)."""
    system = ss.load_system("blades")
    freqs = np.linspace(300.0, 420.0, points)
    t = time.perf_counter()
    hbm = frf(
        system,
        freqs,
        harmonics=harmonics,
        responses=[RESPONSE],
        check="peak",
        check_frequencies=list(check_frequencies),
    )
    timings = {"hbm_s": time.perf_counter() - t, "hbm_solve_s_per_point": hbm.attrs["time_per_point_s"]}
    marched = None
    if march:
        try:
            from slipstep.frequency import frf as frf_march
        except ImportError:
            frf_march = None
        if frf_march is not None:
            t = time.perf_counter()
            marched = frf_march(system, freqs, solver="march", responses=[RESPONSE])
            timings["march_s_per_point"] = (time.perf_counter() - t) / points
    return hbm, marched, timings


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--harmonics", type=int, default=15)
    ap.add_argument("--points", type=int, default=13)
    ap.add_argument("--output-dir", type=Path, default=Path("slipstep-out"))
    args = ap.parse_args(argv)
    hbm, marched, timings = compute(args.harmonics, args.points)
    args.output_dir.mkdir(parents=True, exist_ok=True)
    path = args.output_dir / "blades_hbm_vs_march.png"
    plot_frf([hbm] + ([marched] if marched is not None else []), path, response=RESPONSE)
    print(f"figure: {path}")
    print(
        f"HBM: {hbm.frequency.size} continuation points, {timings['hbm_solve_s_per_point'] * 1e3:.1f} ms per point; "
        f"harmonic truncation estimate (max) {hbm.attrs['max_harmonic_truncation_estimate']:.2e}"
    )
    if "march_s_per_point" in timings:
        print(f"march: {timings['march_s_per_point']:.2f} s per point")
    for row in json.loads(hbm.attrs["check_summary"]):
        print(
            f"  {row['frequency_Hz']:.1f} Hz: HBM vs march amplitude {row['amplitude_rel_diff']:.2e}, "
            f"energy {row['energy_rel_diff']:.2e} ({row['march_status']}, {row['march_periods']} periods)"
        )


if __name__ == "__main__":
    main()
