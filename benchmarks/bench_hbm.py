"""slipstep's harmonic balance against slipstep's time marching (and shooting, when
slipstep.steady.shoot exists), per frequency point, on the single-DOF Jenkins oscillator of
issue 13 (m 2.5 kg, k 1e7 N/m, C = 40 M, k_t 1e7 N/m, slip force 50 N, 100 N).

Measured in one run, interleaved round-robin, medians of --repeats after a warm-up:

* HBM, Newton at each grid frequency from the previous solution (what tmdsimpy's per-point
  time measures), H = 15 / 256 samples and H = 45 / 1024 samples: time per point;
* HBM along the pseudo-arclength continuation over the same range (time per continuation
  point and per grid point of the whole curve), and with the harmonic-adequacy estimate;
* the periodic steady state by marching (Method 3, 2000 steps per period, to a relative
  periodicity of 1e-6) from the static preload at a few of the grid frequencies (the
  cross-check's slipstep.hbm.crosscheck.steady_reference), and the steady-state FRFs of
  slipstep.frequency.frf by marching and by shooting on the same grid (each point from the
  previous one's state, the same 2000-steps-per-period cap);
* the HBM amplitude and energy against the marched ones at those frequencies.

Reference (issue 13): tmdsimpy's HBM took 0.56 s per point at H = 15 / 256 samples and
1.9 s at H = 45 / 1024 on this machine; the goal is at least 10x faster at equal H.

Usage:  python benchmarks/bench_hbm.py [--quick] [--points N] [--repeats R] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))

from hbm_cases import jenkins_1dof

from slipstep.hbm import HarmonicBalance, frf
from slipstep.hbm.crosscheck import relative_differences, steady_reference
from slipstep.hbm.energy import contact_energy, excitation_work, half_peak_to_peak

TMDSIMPY = {(15, 256): 0.56, (45, 1024): 1.9}


def hbm_grid(hb: HarmonicBalance, freqs) -> tuple[float, list]:
    """Seconds per point of Newton at each frequency from the previous point."""
    pts, Z = [], None
    t = time.perf_counter()
    for f in freqs:
        p = hb.solve(2 * np.pi * f, 1.0, Z)
        Z = p.Y
        pts.append(p)
    return (time.perf_counter() - t) / len(freqs), pts


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--points", type=int, default=19)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    system = jenkins_1dof()
    freqs = np.linspace(150.0, 600.0, args.points)
    check_f = [250.0, 320.0, 350.0] if not args.quick else [350.0]
    results = {}
    warnings.simplefilter("ignore")
    balances = {key: HarmonicBalance(system, key[0], key[1]) for key in TMDSIMPY}
    for key, hb in balances.items():  # warm-up (compile / cache load, imports of the Dataset path)
        hbm_grid(hb, freqs[:2])
    frf(system, freqs[:3], harmonics=3, check="none")
    runs = {key: [] for key in TMDSIMPY}
    for _ in range(repeats):
        for key, hb in balances.items():
            runs[key].append(hbm_grid(hb, freqs)[0])
    for key, hb in balances.items():
        H, N = key
        per_point = statistics.median(runs[key])
        _, pts = hbm_grid(hb, freqs)
        its = np.mean([p.iterations for p in pts])
        t = time.perf_counter()
        ds = frf(system, freqs, harmonics=H, samples=N, check="none", adequacy=False)
        t_cont = time.perf_counter() - t
        t = time.perf_counter()
        frf(system, freqs, harmonics=H, samples=N, continuation=False, check="none", adequacy=True)
        t_adeq = (time.perf_counter() - t) / len(freqs)
        results[f"H{H}_N{N}"] = {
            "hbm_s_per_point": per_point,
            "newton_iterations_per_point": float(its),
            "tmdsimpy_s_per_point": TMDSIMPY[key],
            "speedup_vs_tmdsimpy": TMDSIMPY[key] / per_point,
            "continuation_points": int(ds.frequency.size),
            "continuation_s_per_point": t_cont / ds.frequency.size,
            "continuation_s_per_grid_point": t_cont / len(freqs),
            "with_adequacy_s_per_point": t_adeq,
        }
    # the marched steady state at a few frequencies from the preload, with the HBM difference
    hb = balances[(45, 1024)]
    march_times, rows = [], []
    for f in check_f:
        t = time.perf_counter()
        ref = steady_reference(system, f, 1.0, np.array([0]), tolerance=1e-6, max_periods=400, steps_per_period=2000)
        march_times.append(time.perf_counter() - t)
        p = hb.solve(2 * np.pi * f)
        amp = half_peak_to_peak(hb.h, p.X[:, [0]])
        a, e = relative_differences(amp, contact_energy(hb, p.Z, p.F), ref, excitation_work(hb, p))
        rows.append(
            {
                "frequency_Hz": f,
                "march_s": march_times[-1],
                "march_periods": ref.periods,
                "march_status": ref.status,
                "amplitude_rel_diff": a,
                "energy_rel_diff": e,
            }
        )
    results["march"] = {"s_per_point": statistics.median(march_times), "points": rows}
    # the steady-state FRFs (each point from the previous one's state), same grid, same accuracy cap
    try:
        from slipstep.frequency import frf as frf_steady
    except ImportError:
        frf_steady = None
    if frf_steady is not None:
        grid = freqs if not args.quick else freqs[::4]
        for solver in ("march", "shoot"):
            t = time.perf_counter()
            ds = frf_steady(system, grid, solver=solver, min_steps_per_period=2000, max_periods=400)
            results[f"{solver}_frf"] = {
                "s_per_point": (time.perf_counter() - t) / grid.size,
                "points": int(grid.size),
                "periods_per_point": float(np.nanmean(ds.periods_to_steady.values)),
            }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"single-DOF Jenkins oscillator, {len(freqs)} frequencies 150-600 Hz, median of {repeats}")
    print(f"{'solver':34s} {'s/point':>10s} {'vs tmdsimpy':>12s} {'vs march':>10s} {'vs shoot':>10s}")
    m = results.get("march_frf", results["march"])["s_per_point"]
    sh = results.get("shoot_frf", {}).get("s_per_point", float("nan"))
    for key in TMDSIMPY:
        r = results[f"H{key[0]}_N{key[1]}"]
        print(
            f"{f'HBM H={key[0]} N={key[1]} (Newton per point)':34s} {r['hbm_s_per_point']:10.4f} "
            f"{r['speedup_vs_tmdsimpy']:11.1f}x {m / r['hbm_s_per_point']:9.1f}x {sh / r['hbm_s_per_point']:9.1f}x"
        )
        print(
            f"{'  continuation, per point':34s} {r['continuation_s_per_point']:10.4f}   "
            f"({r['continuation_points']} points; {r['continuation_s_per_grid_point']:.4f} s per grid point)"
        )
        print(f"{'  with the adequacy estimate':34s} {r['with_adequacy_s_per_point']:10.4f}")
        print(f"{'  tmdsimpy (reference)':34s} {r['tmdsimpy_s_per_point']:10.4f}")
    print(f"{'march to steady from the preload':34s} {results['march']['s_per_point']:10.4f}")
    for solver in ("march", "shoot"):
        if f"{solver}_frf" in results:
            r = results[f"{solver}_frf"]
            print(
                f"{f'{solver} FRF (from the previous point)':34s} {r['s_per_point']:10.4f}   "
                f"({r['periods_per_point']:.1f} periods per point)"
            )
    for row in results["march"]["points"]:
        print(
            f"  {row['frequency_Hz']:.0f} Hz: HBM(H=45) vs march: amplitude {row['amplitude_rel_diff']:.2e}, "
            f"energy {row['energy_rel_diff']:.2e} (march {row['march_periods']} periods, {row['march_status']})"
        )


if __name__ == "__main__":
    main()
