"""Output bytes per step with everything saved and with the default save (issue 10, item 5).

    python benchmarks/bench_save.py [n_dofs]

Two models: the paper case (3 DOFs: the default saves everything) and a fixed-free chain of
``n_dofs`` masses (default 1,000) with 20 Jenkins contacts and a tip force (the default saves the
contacts and the response DOFs). For each: the kernel's output bytes per saved row (allocated
arrays over rows), the rows per step, hence bytes per step, and the Dataset's bytes per step
after a short march, with ``save="all"`` (before) and the default (after); then the memory
estimate of a 100,000-step run of each. Also prints the estimate against the allocated bytes
(they must agree: the estimate is what is checked against max_memory).
"""

from __future__ import annotations

import sys
import time

import numpy as np

import slipstep as ss
from slipstep.methods import memory
from slipstep.methods.simulation import Simulation


def chain(n: int, contacts: int = 20) -> ss.System:
    k = 2e6 * np.eye(n) - 1e6 * (np.eye(n, k=1) + np.eye(n, k=-1))
    k[-1, -1] = 1e6
    names = tuple(f"x{i}" for i in range(n))
    elements = []
    for c in range(contacts):
        gather = np.zeros((2, n))
        gather[0, n - 1 - 5 * c] = 1.0
        elements.append(ss.ContactElement(f"C{c}", gather, 1e6, 1e5, 0.3, normal_offset=1e-6))
    amplitude = np.zeros(n)
    amplitude[-1] = 20.0
    exc = ss.Excitation(force=ss.Signal(names, (ss.Harmonic(100.0, amplitude),)))
    return ss.System(ss.Structure(0.01 * np.eye(n), 1e-5 * k, k, names), tuple(elements), exc, name=f"chain{n}")


def row_bytes(out) -> float:
    rows = out.t.shape[0]
    return sum(a.nbytes for a in out if a.ndim and a.shape[0] == rows) / rows


def measure(system, method: str, save, duration: float) -> dict:
    start = time.perf_counter()
    sim = Simulation(system, method, duration=duration, error_estimate=False, save=save)
    setup = time.perf_counter() - start
    ds = sim.run()
    steps = ds.attrs["steps"]
    plan = sim.save_plan
    per_row = row_bytes(sim.out)
    assert per_row == memory.point_bytes(plan.dofs.size, plan.rows.size, plan.directions.size)
    rows_per_step = ds.sizes["time"] / (steps + 1)
    big = memory.run_bytes(100_000 * rows_per_step, plan.dofs.size, plan.rows.size, plan.directions.size, 0, 0)
    return {
        "save": plan.text,
        "bytes_per_row": per_row,
        "bytes_per_step": per_row * rows_per_step,
        "dataset_bytes_per_step": ds.nbytes / (steps + 1),
        "estimate_100k_steps_MB": big / 1e6,
        "setup_s": setup,
        "steps": steps,
    }


def main(n: int = 1000) -> None:
    cases = [("paper (3 DOFs)", ss.load_system("paper"), "newmark", 0.005)]
    cases.append((f"chain ({n} DOFs, 20 contacts)", chain(n), "piecewise-linear", 0.002))
    measure(*cases[0][1:3], "auto", 0.001)  # compilation
    print(f"{'model':32s} {'save':58s} {'B/row':>8s} {'B/step':>9s} {'Dataset B/step':>15s} {'100k steps':>11s}")
    for label, system, method, duration in cases:
        results = [measure(system, method, save, duration) for save in ("all", "auto")]
        for r in results:
            print(
                f"{label:32s} {r['save'][:58]:58s} {r['bytes_per_row']:8.0f} {r['bytes_per_step']:9.0f} "
                f"{r['dataset_bytes_per_step']:15.0f} {r['estimate_100k_steps_MB']:9.1f} MB"
            )
        print(f"{'':32s} ratio all / default: {results[0]['bytes_per_step'] / results[1]['bytes_per_step']:.1f}x")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)
