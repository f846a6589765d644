"""How the cost grows with the structure's size and the number of contact points (issue 10).

Two families of structures, each with a harmonic force and Jenkins contacts (constant normal
load by interference) spread evenly over the DOFs:

* ``chain``: a fixed-free chain of N masses (tridiagonal K), the contacts grounding masses;
* ``grid``: a 2D FE-like square grid of masses, springs to the 4 neighbours, clamped on one
  edge (banded K, bandwidth sqrt(N)), the contacts on the free edge and the interior;
* ``strip``: a narrow 2D strip of ``--width`` rows (default 4) of N / width masses, springs
  to the 4 neighbours, clamped at one end (bandwidth about ``width`` after the RCM order).

The structures are built as scipy.sparse matrices (``--dense`` builds dense ones, the
pre-issue-10 input); ``--backend`` chooses the linear solver (auto, direct, low-rank,
banded: RunOptions.linear_solver). ``--contact-kind`` jenkins (constant normal load) or 2d
(the paper's 2D law, variable normal load: the normal row on the neighbouring DOF).

For each (N, contact points) the script prints: the set-up time (System build +
Simulation set-up, which includes T_min and the preload), the kernel time of one excitation
period for Methods 1, 3, 2+3 and quasi-static, the steps per period, and the peak memory of
the set-up and march (tracemalloc: numpy's allocations). Then the fitted cost exponents:
the slope of log(time per step) against log N at fixed contacts, and against log(contact
points) at fixed N. A case whose set-up or period takes longer than ``--budget`` seconds is
skipped for the larger sizes of that method (printed as '>budget').

``--mesh`` runs the 3D mesh family instead (issue 26): the bolted beam of
slipstep.model.fe_mesh (scikit-fem hexahedra, a lap joint of one contact point per face
node), marched by Method 3 on the condensed sparse backend: first the coarse beam, sparse
against dense (the largest difference over the range; the time per period of both: the
baseline ratio), then the full beam (``--elements``, default 360 x 6 x 3: 30,240 DOFs,
203 contact points): set-up (model build, plan, factorisation, preload), time per period
(the kernel's, best of two), steps per period, peak memory (tracemalloc and max RSS); then
(unless ``--no-pilot``) the step the 'accuracy' step rule's pilot picks, with its one-period
time and loop-energy error estimate.

Usage:  python benchmarks/bench_scaling.py [--family chain|grid|strip] [--sizes 100,200,400]
            [--contacts 20] [--contact-sizes 10,20,40] [--contact-n 200] [--methods 1,3,2+3,4]
            [--backend auto|direct|low-rank|banded] [--contact-kind jenkins|2d] [--dense]
            [--width 4] [--periods 1] [--no-error-estimate] [--budget 60] [--json FILE]
        python benchmarks/bench_scaling.py --mesh [--elements 360,6,3] [--steps-per-period 50]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import time
import tracemalloc

import numpy as np
import scipy.sparse as sp

import slipstep
from slipstep.model.system import BANDED_MIN_N

METHODS = {"1": "newmark", "3": "piecewise-linear", "2+3": "piecewise-linear-adaptive", "4": "quasi-static"}
FREQUENCY_HZ = 40.0
MASS_KG, SPRING_N_PER_M = 0.02, 4e5


OPTIONS = {"backend": "auto", "kind": "jenkins", "dense": False, "width": 4, "periods": 1.0, "error_estimate": True}


def _springs(n: int, pairs, grounded) -> sp.csr_matrix:
    """K of unit springs SPRING_N_PER_M between DOF pairs and from ``grounded`` DOFs to ground."""
    a, b = np.asarray(pairs).T if len(pairs) else (np.zeros(0, int), np.zeros(0, int))
    rows = np.concatenate([a, b, a, b, grounded])
    cols = np.concatenate([a, b, b, a, grounded])
    vals = np.concatenate([np.ones(2 * a.size), -np.ones(2 * a.size), np.ones(len(grounded))])
    return sp.csr_matrix((SPRING_N_PER_M * vals, (rows, cols)), shape=(n, n))


def chain(n: int, n_contacts: int) -> slipstep.System:
    """Fixed-free chain: K = k tridiag(-1, 2, -1) with the last diagonal entry k (free end)."""
    K = _springs(n, [(i, i + 1) for i in range(n - 1)], [0])
    return _with_contacts(K, np.arange(n - 1), n_contacts, tip=n - 1, name=f"chain-{n}-{n_contacts}")


def grid(n: int, n_contacts: int) -> slipstep.System:
    """Square grid side s = round(sqrt(n)) of masses with springs to the 4 neighbours, the
    column j = 0 clamped (springs to ground)."""
    s = max(2, round(math.sqrt(n)))
    return _plate(s, s, n_contacts, name="grid")


def strip(n: int, n_contacts: int) -> slipstep.System:
    """A strip of ``OPTIONS['width']`` rows and n / width columns, clamped at column 0."""
    rows = OPTIONS["width"]
    return _plate(rows, max(2, round(n / rows)), n_contacts, name="strip")


def _plate(rows: int, cols: int, n_contacts: int, name: str) -> slipstep.System:
    n = rows * cols
    idx = np.arange(n).reshape(rows, cols)
    pairs = [(idx[i, j], idx[i, j + 1]) for i in range(rows) for j in range(cols - 1)]
    pairs += [(idx[i, j], idx[i + 1, j]) for i in range(rows - 1) for j in range(cols)]
    K = _springs(n, pairs, idx[:, 0])
    return _with_contacts(
        K, idx[:, 1:-1].ravel(), n_contacts, tip=int(idx[rows // 2, cols - 1]), name=f"{name}-{n}-{n_contacts}"
    )


def _with_contacts(K, candidates: np.ndarray, n_contacts: int, tip: int, name: str) -> slipstep.System:
    n = K.shape[0]
    M = sp.identity(n, format="csr") * MASS_KG
    where = candidates[np.linspace(0, candidates.size - 1, n_contacts).round().astype(int)]
    contacts = []
    for i, dof in enumerate(where):
        if OPTIONS["kind"] == "2d":  # u on the DOF, the normal approach on its neighbour (variable load)
            A = sp.csr_matrix(([1.0, 0.5], ([0, 1], [dof, dof + 1])), shape=(2, n))
        else:
            A = sp.csr_matrix(([1.0], ([0], [dof])), shape=(2, n))
        contacts.append(slipstep.ContactElement(f"J{i}", A, 5e5, 5e5, 0.3, normal_offset=2e-5 * (1 + i % 5)))
    amplitude = np.zeros(n)
    amplitude[tip] = 20.0
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(FREQUENCY_HZ, amplitude),))
    C = 2e-5 * K + 2.0 * M
    if OPTIONS["dense"]:
        M, C, K = M.toarray(), C.toarray(), K.toarray()
        contacts = [
            slipstep.ContactElement(c.name, c.dense_gather(), 5e5, 5e5, 0.3, normal_offset=c.normal_offset)
            for c in contacts
        ]
    structure = slipstep.Structure(M, C, K)
    return slipstep.System(structure, tuple(contacts), slipstep.Excitation(force=force), name=name)


def _simulation(system, method):
    return slipstep.Simulation(
        system,
        method,
        periods=OPTIONS["periods"],
        linear_solver=OPTIONS["backend"],
        error_estimate=OPTIONS["error_estimate"],
    )


def measure(build, n: int, n_contacts: int, method: str) -> dict:
    """Set-up and one-period kernel time of one (size, contacts, method); then, in a second
    pass under tracemalloc (which slows Python allocations, so not timed), the peak memory of
    the set-up and a march (numpy's allocations), and the process's peak resident set."""
    start = time.perf_counter()
    system = build(n, n_contacts)
    sim = _simulation(system, method)
    setup = time.perf_counter() - start
    sim.march()  # first march: the compiled kernel is loaded (and warm caches)
    kernel = sim.kernel_time
    sim.march()
    kernel = min(kernel, sim.kernel_time)
    steps = int(sim.out.counters[0])
    attrs = sim.method_attrs()
    del sim
    tracemalloc.start()
    again = _simulation(build(n, n_contacts), method)
    again.march()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    del again
    return {
        "n": system.n_dofs,
        "contacts": n_contacts,
        "method": method,
        "setup_s": setup,
        "period_s": kernel,
        "steps": steps,
        "per_step_us": kernel / max(steps, 1) * 1e6,
        "peak_MB": peak / 1e6,
        "rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
        "linear_solver": attrs["linear_solver"],
        "bandwidth": attrs["bandwidth"],
    }


def slope(xs, ys) -> float:
    """Least-squares slope of log y against log x."""
    if len(xs) < 2:
        return math.nan
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def sweep(build, pairs, methods, budget) -> list[dict]:
    rows, over = [], set()
    for n, nc in pairs:
        for label in methods:
            method = METHODS[label]
            if method in over:
                print(f"  N={n:6d} contacts={nc:4d} Method {label:3s}: >budget (skipped)")
                continue
            row = measure(build, n, nc, method)
            row["label"] = label
            rows.append(row)
            print(
                f"  N={row['n']:6d} contacts={nc:4d} Method {label:3s}: set-up {row['setup_s']:8.3f} s, period "
                f"{row['period_s']:8.4f} s, {row['steps']:6d} steps, {row['per_step_us']:9.1f} us/step, "
                f"peak {row['peak_MB']:8.1f} MB (max RSS {row['rss_MB']:7.0f} MB), {row['linear_solver']} "
                f"(b = {row['bandwidth']})",
                flush=True,
            )
            if row["setup_s"] + row["period_s"] > budget:
                over.add(method)
    return rows


def _mesh_run(system, backend: str, steps: int, periods: float = 1.0, **options):
    """A Simulation of Method 3 on ``system`` at ``steps`` fixed steps per period (no pilot)."""
    period = system.period
    return slipstep.Simulation(
        system,
        "piecewise-linear",
        periods=periods,
        dt=period / steps,
        linear_solver=backend,
        error_estimate=False,
        **options,
    )


def _best_period(sim) -> float:
    """The kernel time of one period, best of two marches (the first loads the kernel)."""
    sim.march()
    first = sim.kernel_time
    sim.march()
    return min(first, sim.kernel_time)


def mesh_family(elements: tuple[int, int, int], steps: int, pilot: bool = True) -> dict:
    """The 3D mesh family (module docstring): the coarse beam's sparse-dense equality and
    baseline ratio, then the full beam's set-up, period and memory; ``pilot``: then the step
    the 'accuracy' rule's pilot picks, its period and error estimate."""
    from slipstep.methods import sparse as SB
    from slipstep.model.fe_mesh import BeamSpec, bolted_beam, coarse_spec

    coarse = bolted_beam(coarse_spec(force=800.0, pressure=1e6)).system
    runs = {b: _mesh_run(coarse, b, 200) for b in ("direct", "sparse")}
    times = {b: _best_period(sim) for b, sim in runs.items()}
    ds = {b: sim.dataset() for b, sim in runs.items()}
    worst = 0.0
    for name in ("displacement", "velocity", "normal_force", "tangential_force", "slider"):
        x, y = ds["direct"][name].values, ds["sparse"][name].values
        worst = max(worst, float(np.abs(x - y).max() / max(np.ptp(x), 1e-300)))
    print(
        f"coarse beam ({coarse.n_dofs} DOFs, {len(coarse.contacts)} contact points, 200 steps): sparse vs dense "
        f"max |difference| / range = {worst:.2e}; period dense {times['direct']:.4f} s, sparse "
        f"{times['sparse']:.4f} s (ratio dense / sparse {times['direct'] / times['sparse']:.2f})",
        flush=True,
    )
    SB.forget_factors()
    tracemalloc.start()
    start = time.perf_counter()
    model = bolted_beam(BeamSpec(elements=elements))
    built = time.perf_counter() - start
    sim = _mesh_run(model.system, "auto", steps)  # (the static preload included)
    setup = time.perf_counter() - start
    _, peak_setup = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    factor = sim.marcher.ws.main
    period = _best_period(sim)
    result = sim.dataset()
    states = result["contact_state"].values
    slip = float(np.isin(states, (2, 3)).mean())
    row = {
        "n": model.system.n_dofs,
        "contacts": len(model.system.contacts),
        "linear_solver": result.attrs["linear_solver"],
        "build_s": built,
        "setup_s": setup,
        "factorise_s": SB.TIMING.factorise_s,
        "blocks_s": SB.TIMING.blocks_s,
        "factor_nnz": SB.factor_nnz(factor),
        "period_s": period,
        "steps": int(sim.out.counters[0]),
        "peak_setup_MB": peak_setup / 1e6,
        "rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
        "slip_fraction": slip,
        "coarse_max_diff": worst,
        "coarse_ratio": times["direct"] / times["sparse"],
        "status": result.attrs.get("status_message", ""),
    }
    print(
        f"bolted beam: {row['n']} DOFs, {row['contacts']} contact points, {row['linear_solver']} backend "
        f"(L + U {row['factor_nnz'] / 1e6:.1f} M entries)\n"
        f"  set-up {setup:.2f} s (model build {built:.2f} s, sparse LU {SB.TIMING.factorise_s:.2f} s, contact-space "
        f"blocks {SB.TIMING.blocks_s:.2f} s, {SB.TIMING.factorisations} factorisations)\n"
        f"  Method 3, one period: {period:.3f} s ({row['steps']} steps, {period / row['steps'] * 1e3:.1f} ms/step), "
        f"slip in {100 * slip:.1f} % of the direction-steps; status {row['status']}\n"
        f"  peak memory: set-up {row['peak_setup_MB']:.0f} MB (tracemalloc), max RSS {row['rss_MB']:.0f} MB",
        flush=True,
    )
    del sim, result
    if pilot:  # the step the default accuracy rule picks, and its estimate (the fixed step's check)
        start = time.perf_counter()
        auto = slipstep.Simulation(model.system, "piecewise-linear", periods=1, step_rule="accuracy")
        chosen = time.perf_counter() - start
        ds = auto.run()
        row.update(
            pilot_steps=int(round(model.system.period / auto.dt)),
            pilot_setup_s=chosen,
            pilot_period_s=auto.kernel_time,
            pilot_energy_error=ds.attrs["energy_error_estimate"],
        )
        print(
            f"  step_rule='accuracy' with its step-doubling pilot: {row['pilot_steps']} steps per period "
            f"(set-up with the pilot twins {chosen:.1f} s), one period {auto.kernel_time:.3f} s, loop-energy error "
            f"estimate {100 * row['pilot_energy_error']:.2f} %",
            flush=True,
        )
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", choices=("chain", "grid", "strip"), default="chain")
    ap.add_argument("--backend", choices=("auto", "direct", "low-rank", "banded"), default="auto")
    ap.add_argument("--contact-kind", choices=("jenkins", "2d"), default="jenkins")
    ap.add_argument("--dense", action="store_true", help="dense input matrices (the pre-issue-10 input)")
    ap.add_argument("--width", type=int, default=4, help="rows of the strip family")
    ap.add_argument("--periods", type=float, default=1.0)
    ap.add_argument(
        "--no-error-estimate",
        action="store_true",
        help="no step-doubling pilot twins in the set-up (error_estimate off)",
    )
    ap.add_argument("--sizes", default="100,200,400")
    ap.add_argument("--contacts", type=int, default=20, help="contact points for the N sweep")
    ap.add_argument("--contact-sizes", default="10,20,40")
    ap.add_argument("--contact-n", type=int, default=200, help="DOFs for the contact-point sweep")
    ap.add_argument("--methods", default="1,3,2+3,4")
    ap.add_argument("--budget", type=float, default=60.0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--mesh", action="store_true", help="the 3D mesh family (the bolted beam, sparse backend)")
    ap.add_argument("--elements", default="360,6,3", help="hexahedra along x, y, z of the --mesh beam")
    ap.add_argument("--steps-per-period", type=int, default=50, help="fixed steps per period of --mesh")
    ap.add_argument("--no-pilot", action="store_true", help="--mesh: skip the run with the accuracy rule's pilot")
    args = ap.parse_args()
    if args.mesh:
        row = mesh_family(tuple(int(e) for e in args.elements.split(",")), args.steps_per_period, not args.no_pilot)
        if args.json:
            from slipstep.output.io import atomic_path

            with atomic_path(args.json) as tmp:
                tmp.write_text(json.dumps({"mesh": row}, indent=2))
        return
    OPTIONS.update(
        backend=args.backend,
        kind=args.contact_kind,
        dense=args.dense,
        width=args.width,
        periods=args.periods,
        error_estimate=not args.no_error_estimate,
    )
    build = {"chain": chain, "grid": grid, "strip": strip}[args.family]
    methods = args.methods.split(",")
    sizes = [int(s) for s in args.sizes.split(",")]
    contact_sizes = [int(s) for s in args.contact_sizes.split(",")]
    for warm in (20, BANDED_MIN_N + 10):  # compile/load the kernels (dense and banded) outside the timings
        measure(build, warm, 2, METHODS[methods[0]])
    print(f"{args.family}: N sweep at {args.contacts} contacts")
    by_n = sweep(build, [(n, args.contacts) for n in sizes], methods, args.budget)
    print(f"{args.family}: contact sweep at N = {args.contact_n}")
    by_c = sweep(build, [(args.contact_n, c) for c in contact_sizes], methods, args.budget)
    print("fitted exponents of the time per step (log-log slope): in N | in contact points")
    for label in methods:
        rn = [r for r in by_n if r["label"] == label]
        rc = [r for r in by_c if r["label"] == label]
        print(
            f"  Method {label:3s}: {slope([r['n'] for r in rn], [r['per_step_us'] for r in rn]):5.2f} | "
            f"{slope([r['contacts'] for r in rc], [r['per_step_us'] for r in rc]):5.2f}   "
            f"(set-up exponent in N: {slope([r['n'] for r in rn], [r['setup_s'] for r in rn]):5.2f})"
        )
    if args.json:
        from slipstep.output.io import atomic_path

        with atomic_path(args.json) as tmp:
            tmp.write_text(json.dumps({"by_n": by_n, "by_contacts": by_c}, indent=2))


if __name__ == "__main__":
    main()
