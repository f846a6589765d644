"""The exact event-driven method ``events`` against Method 3 (piecewise-linear) at equal
accuracy (issue 28, item 5): the friction energy dissipated over the last excitation period of
a run from the static preload, within ``--accuracies`` (default 1e-6 and 1e-3) relative to the
exact one.

Per case: the exact run's time, its events and contact states; then Method 3 at fixed steps
T / N, N doubling from its first N until its energy per cycle (the trapezoid sum of T dw over
the last period, slipstep.post.energy) is within the strictest accuracy; per accuracy the
first N that reaches it, its time and the ratio Method 3 / events. Times are the whole ``ss.run`` (preload, march, Dataset), the best of
``--repeats`` after a warm-up, so every kernel is compiled. The cases: the Jenkins oscillator
of issue 24 at 350 Hz (20 periods: a few events per period, long stick and slip phases), the
paper case (3 periods: about 50 events per period, 3 contacts, undamped ringing at 8-12 kHz),
and the `ring` case (36 DOFs, 2 periods: many distinct contact states, each an
eigendecomposition of a 72 x 72 first-order matrix).

``--frf``: instead, the exact steady state of the Jenkins oscillator at the 11 frequencies of
tests/frf_accuracy.py (250-500 Hz; steady/exact_orbit.exact_frf) against the independent
reference of tests/jenkins_reference.py (DOP853 + fsolve, started from the exact orbit): the
relative differences of the friction energy and excitation work per cycle, the time per point.

``--recontact``: instead, Method 3's displacement error against the exact solution before and
after the first re-contact on the random systems of tests/test_exact_events.py (seeds 1-3).

Usage:  python benchmarks/bench_exact_events.py [--accuracies 1e-6,1e-3] [--quick] [--frf] [--recontact] [--json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

import sys

import slipstep as ss
from slipstep.methods.exact_events import ExactEventRun, energy_balance
from slipstep.post.energy import friction_energy_per_period

ROOT = Path(__file__).resolve().parents[1]


def best_time(fn, repeats: int):
    best, value = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - start)
    return best, value


def exact(system, periods: float, repeats: int) -> dict:
    def once():
        run = ExactEventRun(system, periods=periods)
        run.march()
        run.dataset()
        return run

    seconds, run = best_time(once, repeats)
    T, t_end = run.plan.period, run.plan.t_end
    energy = energy_balance(run.trajectory, t_from=t_end - T, t_to=t_end)["friction_dissipation"]
    return {
        "time_s": seconds,
        "events": run.trajectory.events,
        "states": len(run.model.states),
        "energy_J": energy,
        "status": run.trajectory.status.name,
    }


def method3(system, periods: float, reference: float, accuracy: float, n0: int, n_max: int, repeats: int) -> dict:
    period = system.period
    n, rows = n0, []
    while n <= n_max:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")

            def once(n=n):
                return ss.run(system, "piecewise-linear", periods=periods, dt=period / n, error_estimate=False)

            ds = once()  # warm-up (compile or cache load)
            seconds, ds = best_time(once, repeats)
        energy = float(friction_energy_per_period(ds).sum())
        error = abs(energy - reference) / abs(reference)
        rows.append({"steps_per_period": n, "time_s": seconds, "error": error})
        if error <= accuracy:
            break
        n *= 2
    return {"rows": rows, "reached": rows[-1]["error"] <= accuracy}


def case(name: str, system, periods: float, accuracies, n0: int, n_max: int, repeats: int) -> dict:
    exact(system, periods, 1)  # warm-up
    ev = exact(system, periods, repeats)
    m3 = method3(system, periods, ev["energy_J"], min(accuracies), n0, n_max, repeats)
    at = {}
    for accuracy in accuracies:
        row = next((r for r in m3["rows"] if r["error"] <= accuracy), None)
        at[accuracy] = {**(row or m3["rows"][-1]), "reached": row is not None}
        at[accuracy]["ratio"] = at[accuracy]["time_s"] / ev["time_s"]
    return {"case": name, "periods": periods, "events": ev, "method3": m3, "at": at}


def text(results) -> str:
    lines = [
        f"{'case':8} {'periods':>7} {'events':>6} {'states':>6} {'events [s]':>10} {'accuracy':>8} "
        f"{'M3 N/period':>11} {'M3 error':>9} {'M3 [s]':>8} {'M3 / events':>11}"
    ]
    for r in results:
        ev = r["events"]
        for accuracy, row in r["at"].items():
            ratio = ("" if row["reached"] else "> ") + f"{row['ratio']:.2g}"
            lines.append(
                f"{r['case']:8} {r['periods']:7g} {ev['events']:6d} {ev['states']:6d} {ev['time_s']:10.3f} "
                f"{accuracy:8.0e} {row['steps_per_period']:11d} {row['error']:9.1e} {row['time_s']:8.3f} {ratio:>11}"
            )
    lines.append("")
    lines.append("Method 3's path to the accuracy (steps per period: error, time):")
    for r in results:
        path = ", ".join(
            f"{x['steps_per_period']}: {x['error']:.1e}, {x['time_s']:.3f} s" for x in r["method3"]["rows"]
        )
        lines.append(f"  {r['case']}: {path}")
    return "\n".join(lines)


def frf_check() -> list[dict]:
    """The exact Jenkins FRF against the independent reference (module docstring)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import frf_accuracy as FA
    from jenkins_reference import periodic_orbit_energies

    from slipstep.steady.exact_orbit import exact_frf

    system = FA.system()
    exact_frf(system, FA.FREQUENCIES[:1])  # warm-up
    rows, guess = [], None
    for f in FA.FREQUENCIES:
        start = time.perf_counter()
        (orbit,) = exact_frf(system, [f]) if guess is None else [_orbit_from(system, f, guess)]
        seconds = time.perf_counter() - start
        guess = (orbit.x0, orbit.v0, orbit.w0)
        mode = int(orbit.trajectory.phases[0].sm.state[0])
        ref = periodic_orbit_energies(*FA.PARAMETERS, f, orbit.x0[0], orbit.v0[0], orbit.w0[0], mode)
        rows.append(
            {
                "frequency_Hz": f,
                "friction_energy_J": orbit.friction_energy,
                "friction_rel_diff": abs(orbit.friction_energy / ref["friction_energy"] - 1),
                "work_rel_diff": abs(orbit.excitation_work / ref["excitation_work"] - 1),
                "amplitude_m": float(orbit.amplitude[0]),
                "amplitude_rel_diff": abs(orbit.amplitude[0] / ref["amplitude"] - 1),
                "newton_iterations": orbit.iterations,
                "max_multiplier": float(np.abs(orbit.multipliers).max()),
                "time_s": seconds,
            }
        )
    return rows


def _orbit_from(system, f, guess):
    from slipstep.steady.exact_orbit import periodic_orbit

    return periodic_orbit(system, f, guess=guess)


def frf_text(rows) -> str:
    lines = [
        "exact Jenkins steady state (Newton on the exact period map, each point from the previous orbit) "
        "against tests/jenkins_reference.py",
        f"{'f [Hz]':>7} {'E [mJ]':>9} {'dE/E':>8} {'dW/W':>8} {'amp [um]':>9} {'damp/amp':>8} {'Newton':>6} "
        f"{'|mult|max':>9} {'time [s]':>8}",
    ]
    for r in rows:
        lines.append(
            f"{r['frequency_Hz']:7.1f} {r['friction_energy_J'] * 1e3:9.5f} {r['friction_rel_diff']:8.1e} "
            f"{r['work_rel_diff']:8.1e} {r['amplitude_m'] * 1e6:9.4f} {r['amplitude_rel_diff']:8.1e} "
            f"{r['newton_iterations']:6d} {r['max_multiplier']:9.3f} {r['time_s']:8.3f}"
        )
    return "\n".join(lines)


def recontact_check(steps=(4000, 16000, 64000, 256000)) -> list[dict]:
    """Method 3 against the exact solution before / after the first re-contact (module docstring)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_exact_events import random_system

    from slipstep.kernels.codes import LIFT

    rows = []
    for seed in (1, 2, 3):
        system = random_system(np.random.default_rng(seed))
        run = ExactEventRun(system, periods=1)
        run.march()
        phases, period = run.trajectory.phases, run.plan.period
        t_rc = next(
            (b.t0 for a, b in zip(phases, phases[1:]) if np.any((a.sm.state == LIFT) & (b.sm.state != LIFT))), None
        )
        for n in steps:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ds = ss.run(system, "piecewise-linear", periods=1, dt=period / n, error_estimate=False)
            ref = run.trajectory.evaluate(ds.time.values)["x"]
            err = np.abs(ds.displacement.values - ref).max(axis=1) / np.abs(ref).max()
            t = ds.time.values
            before = float(err[t < t_rc].max()) if t_rc is not None else float(err.max())
            after = float(err[t > t_rc].max()) if t_rc is not None else float("nan")
            rows.append(
                {
                    "seed": seed,
                    "recontact_t_over_T": (t_rc or np.nan) / period,
                    "steps_per_period": n,
                    "before": before,
                    "after": after,
                }
            )
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--accuracies", default="1e-6,1e-3", help="relative errors of the energy per cycle")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="Jenkins and paper only, one repeat")
    parser.add_argument("--frf", action="store_true", help="the exact Jenkins FRF against the reference instead")
    parser.add_argument("--recontact", action="store_true", help="Method 3's error around re-contacts instead")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if args.recontact:
        rows = recontact_check()
        if args.json:
            print(json.dumps(rows))
        else:
            print(
                "Method 3 against the exact solution: largest relative displacement error before / after the first re-contact"
            )
            for r in rows:
                print(
                    f"seed {r['seed']} (re-contact at t/T = {r['recontact_t_over_T']:.4f}) N = {r['steps_per_period']:6d}: "
                    f"before {r['before']:.1e}, after {r['after']:.1e}"
                )
        return 0
    if args.frf:
        rows = frf_check()
        print(json.dumps(rows) if args.json else frf_text(rows))
        return 0
    accuracies = sorted((float(a) for a in args.accuracies.split(",")), reverse=True)
    repeats = 1 if args.quick else args.repeats
    results = [
        case("jenkins", ss.load_system(ROOT / "examples" / "jenkins.toml"), 20, accuracies, 50, 2**17, repeats),
        case("paper", ss.load_system("paper"), 3, accuracies, 200, 2**18, repeats),
    ]
    if not args.quick:
        results.append(case("ring", ss.load_system("ring"), 2, accuracies, 50, 2**17, 1))
    if args.json:
        print(json.dumps(results, default=float))
        return 0
    print("events against Method 3 (piecewise-linear, fixed step) at equal accuracy of the friction energy per cycle")
    print(text(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
