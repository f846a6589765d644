"""The mistuning Monte Carlo of issue 27: examples/ring_mistuning.toml (200 mistuned 6-blade
rings with dampers, a 21-point harmonic-balance FRF each) on the default local cluster (one
worker process per core), into a fresh store; prints the time against the 5-minute target,
the per-case split and the load average (the machine may be shared).

    python benchmarks/bench_mistuning.py [--workers N] [--samples S]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ring_mistuning.toml"
TARGET_S = 300.0


def main() -> None:
    from slipstep.sweep import load_spec, open_sweep, run_sweep
    from slipstep.sweep.execute import DaskExecutor

    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--samples", type=int, default=None, help="samples per level (default: the example's)")
    args = ap.parse_args()
    spec = load_spec(EXAMPLE)
    if args.samples is not None:
        import dataclasses

        m = dataclasses.replace(spec.parameters[0], samples=args.samples)
        spec = dataclasses.replace(spec, parameters=(m,))
    folder = Path(tempfile.mkdtemp(prefix="bench_mistuning."))
    try:
        load0 = os.getloadavg()
        start = time.perf_counter()
        report = run_sweep(spec, folder / "ring.zarr", executor=DaskExecutor(workers=args.workers))
        total = time.perf_counter() - start
        load1 = os.getloadavg()
        ds = open_sweep(folder / "ring.zarr")
        n = report["computed"]
        print(f"cases {n}, workers {report['workers']}, status {report['status_counts']}")
        print(
            f"total (client start to store closed) {total:.1f} s  (target {TARGET_S:.0f} s: {'met' if total < TARGET_S else 'NOT met'})"
        )
        print(
            f"  cluster start + warm-up {report['startup_s']:.1f} s, cases {report['elapsed_s']:.1f} s, tuned reference + plan: {total - report['startup_s'] - report['elapsed_s']:.1f} s"
        )
        print(
            f"  per case: {report['mean_case_time_s'] * 1e3:.0f} ms wall, {report['mean_case_cpu_s'] * 1e3:.0f} ms CPU in its worker"
        )
        print(
            f"  throughput {n / report['elapsed_s']:.2f} cases/s = {report['workers'] * report['elapsed_s'] / n:.2f} worker-s per case"
        )
        ok = ds["status"].values.astype(str) == "OK"
        n_blades = len(ds.attrs.get("mistuning_responses", [])) or 6
        whitehead = (1 + n_blades**0.5) / 2
        print(f"OK samples {int(ok.sum())} of {ok.size}; Whitehead limit (1 + sqrt({n_blades}))/2 = {whitehead:.4f}")
        for level in sorted(set(ds["mistuning_level"].values)):
            sel = ok & (ds["mistuning_level"].values == level)
            row = []
            for label, field in (
                ("AF", "amplification_factor"),
                ("stuck AF", "linear_stuck_amplification_factor"),
                ("free AF", "linear_free_amplification_factor"),
            ):
                v = ds[field].values[sel]
                fin = v[np.isfinite(v)]
                row.append(
                    f"{label} mean {fin.mean():.4f} max {fin.max():.4f} ({fin.size} finite)"
                    if fin.size
                    else f"{label}: none finite"
                )
            print(f"  std {level:g}: " + "; ".join(row))
        for name in ("linear_stuck", "linear_free"):
            field = f"{name}_peak_frequency_Hz"
            if field in ds:
                fr = ds[field].values[ok]
                print(f"  {field}: min {np.nanmin(fr):.3f}, max {np.nanmax(fr):.3f} Hz")
        print(
            "  AF of the friction response, per case:", " ".join(f"{v:.12g}" for v in ds["amplification_factor"].values)
        )
        print(
            f"load average 1/5/15 min: before {load0[0]:.2f}/{load0[1]:.2f}/{load0[2]:.2f}, after {load1[0]:.2f}/{load1[1]:.2f}/{load1[2]:.2f} (2 cores)"
        )
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
