"""The quasi-static damper inside dynamic blades (issue 11, item 6) against the fully dynamic
damper, on the built-in ``blades`` case.

For each excitation frequency: Method 3 (piecewise-linear Newmark, the damper with its
inertia: the step is set by the damper's ~10 kHz modes) and quasi-static-dofs (Method 3+4:
the damper without inertia, the step set by the blades' modes and the accuracy cap of 50
steps per period) march from the preload to steady state (``--periods``); printed: kernel
time per period (median of repeats after a warm-up, the two methods interleaved), steps and
solves per period, their ratio, and the steady tip amplitude of blade 1 (the dynamic one
after the zero-phase low-pass filter of the ringing), with the relative difference.

``--steps-per-period N``: both methods with the same fixed step (period / N) instead of their
own step rules: the amplitude difference is then the damper's inertia alone (a converged step
needs about 400 steps per period: Method 3 resolves stick-slip transitions to one step).

Usage:  python benchmarks/bench_massless.py [--quick] [--periods P] [--repeats N] [--frequencies 300,330,360]
                                            [--steps-per-period N]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics

import numpy as np

import slipstep as ss
from slipstep.methods import massless as ML
from slipstep.model.excitation import Harmonic, Signal
from slipstep.post.filtering import filter_dataset

METHODS = ("piecewise-linear", "quasi-static-dofs")


def retuned(system, f):
    sig = system.excitation.force
    h = sig.harmonics[0]
    force = Signal(sig.components, (Harmonic(f, h.amplitude, h.phase),), (), sig.ramp_time)
    return dataclasses.replace(system, excitation=dataclasses.replace(system.excitation, force=force))


def tip_amplitude(ds, dof="blade1.8.x"):
    T = ds.attrs["period_s"]
    x = ds.displacement.sel(dof=dof).sel(time=slice(ds.time[-1] - T, None)).values
    return (x.max() - x.min()) / 2


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--periods", type=float, default=300.0)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--frequencies", default="300,330,360")
    ap.add_argument("--steps-per-period", type=int, default=None)
    args = ap.parse_args()
    repeats = 3 if args.quick else args.repeats
    periods = 100.0 if args.quick else args.periods
    system = ss.load_system("blades")
    internal = float(ML.internal_frequencies(system.compile(), np.ones(3, np.int8), ML.contact_held_dofs(system)).min())
    print(f"blades: {periods:g} periods from the preload, kernel time = median of {repeats} after a warm-up")
    print(
        f"{'f [Hz]':>7} {'method':>18} {'dt [us]':>8} {'steps/T':>8} {'solves/T':>9} {'kernel/T [us]':>14} "
        f"{'speed-up':>9} {'tip amp [um]':>13} {'diff':>8}"
    )
    for f in (float(v) for v in args.frequencies.split(",")):
        step = {} if args.steps_per_period is None else {"dt": 1 / f / args.steps_per_period}
        step = {"step_rule": "t-min", **step}  # the paper's T_min rule: the methods on the same steps
        sims = {m: ss.Simulation(retuned(system, f), m, periods=periods, **step) for m in METHODS}
        for s in sims.values():
            s.march()  # warm-up
        times = {m: [] for m in METHODS}
        for _ in range(repeats):
            for m, s in sims.items():
                s.march()
                times[m].append(s.kernel_time)
        rows = {}
        for m, s in sims.items():
            ds = s.dataset()
            if m == "piecewise-linear":
                ds = filter_dataset(ds, system, internal_Hz=internal)
            rows[m] = (
                s.dt,
                ds.attrs["steps"] / periods,
                ds.attrs["solves"] / periods,
                statistics.median(times[m]) / periods,
                tip_amplitude(ds),
            )
        base = rows["piecewise-linear"]
        for m, (dt, steps, solves, kt, amp) in rows.items():
            print(
                f"{f:7g} {m:>18} {dt * 1e6:8.2f} {steps:8.1f} {solves:9.1f} {kt * 1e6:14.1f} {base[3] / kt:9.2f} "
                f"{amp * 1e6:13.3f} {amp / base[4] - 1:8.2%}"
            )


if __name__ == "__main__":
    main()
