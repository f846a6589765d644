"""A Craig-Bampton-reduced blade pair with a meshed underplatform damper (issue 10, item 6).

Two cantilever frame blades (``--elements`` Euler-Bernoulli frame elements each, 3 DOFs per
node) with a rigid underplatform damper between their platforms; each of the damper's two
flat faces is cut into ``--points`` contact points (model/patch.py: stiffness per unit area,
the preload shared by the resulting pressure), so the damper carries 2 x points contacts
(2D: a tangential and a normal coordinate each). Blade 1 is driven at its tip by a harmonic
force at ``--frequency`` (default: 90 % of the first stuck bending mode).

Each blade is reduced by Craig-Bampton (model/substructure.py) onto its platform node (x, y,
rz) and its tip x plus ``--modes`` fixed-interface modes, so the assembled model has
2 (4 + modes) + 3 DOFs and 4 x points contact coordinates: the industrial shape of few
DOFs and many contact coordinates.

Printed:
* the model: DOFs of the full and reduced models, contact points, reduction time;
* accuracy of the reduction: the lowest stuck natural frequencies of the reduced and the
  full assembly (linear, all contacts stuck) and their relative difference;
* per method (1, 3, 2+3, quasi-static-dofs): set-up time, kernel time of one period
  (median of repeats after a warm-up, methods interleaved), steps and solves per period,
  ratio to Method 1, and the tip amplitude of blade 1 over the last marched period
  (the methods must agree: printed as the largest relative difference to Method 1);
* with ``--full``: the same march on the unreduced assembly (Method 3), as an independent
  check of the reduction on the nonlinear response (tip amplitude difference).

With ``--frf`` (issue 24: the designer's job at the designer's size): the forced response
between 0.7 and 1.1 times the first stuck frequency on ``--frf-points`` frequencies, side by
side for the solvers a user would pick, each timed on the same model in the same run:
* shoot (slipstep.frequency.frf, solver "shoot", at its defaults: each point with its step-doubling
  error estimate) and shoot-plain (rtol=None: the points as solved): every point, its status
  and Floquet stability;
  the one-period Jacobian's cost split (free unknowns only, as shooting builds it, against all
  sliders as unknowns: the pre-issue-24 column count) and the arithmetic floor of its matrix
  products (one per step, and the solve with J(S) per change of state) at the dgemm rate
  measured in this run;
* hbm (slipstep.hbm.frf at H = ``--harmonics``, without the marching cross-check): every point;
* march (solver "march", the steady state by marching): on ``--march-points`` points only
  (it needs hundreds of periods per point where the stuck damper rings undamped);
and the largest amplitude difference between the solvers at the common points. The figures of
the issue (this machine kind, before): shoot 487 s for 61 points, HBM unfinished after 1,500 s.

Usage:  python benchmarks/bench_blade_pair.py [--quick] [--elements 60] [--points 50]
            [--modes 10] [--periods 3] [--repeats 5] [--full] [--json FILE]
        python benchmarks/bench_blade_pair.py --frf [--elements 166 --points 100 --modes 10]
            [--frf-points 61] [--harmonics 7] [--march-points 3] [--solvers shoot,shoot-plain,hbm,march]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

import numpy as np

import slipstep as ss
from slipstep.kernels.contact import add_contact_stiffness
from slipstep.model.assembly import DamperLink, HarmonicForce, PlatformLink, assemble
from slipstep.model.patch import damper_face_contacts
from slipstep.model.substructure import Substructure, craig_bampton, frame_blade

E, RHO, L, B, H = 2.0e11, 7800.0, 0.12, 0.02, 0.0045  # steel blade 120 x 20 x 4.5 mm
PLATFORM_FRACTION = 0.25  # platform node at a quarter of the blade length
DAMPER_MASS, DAMPER_INERTIA, CENTRIFUGAL_N = 0.012, 1.2e-7, 200.0
FACE_LENGTH_M, FACE_WIDTH_M = 4e-3, 10e-3
KN_PER_AREA, KT_PER_AREA, MU = 3e11, 3e11, 0.4  # N/m per m^2 of face
FORCE_N = 20.0
METHODS = (
    ("1", "newmark"),
    ("3", "piecewise-linear"),
    ("2+3", "piecewise-linear-adaptive"),
    ("3+4", "quasi-static-dofs"),
)


def blade(n_elements: int) -> Substructure:
    pnode = max(1, round(PLATFORM_FRACTION * n_elements))
    return frame_blade(
        "blade",
        L,
        n_elements,
        E,
        RHO,
        B * H,
        B * H**3 / 12,
        platform_node=pnode,
        platform_mass=0.02,
        modal_damping_ratio=0.002,
    )


def reduced(full: Substructure, n_modes: int) -> Substructure:
    pnode = full.points["platform"].dofs["x"].split(".")[0]
    tip = full.points["tip"].dofs["x"]
    return craig_bampton(full, [f"{pnode}.x", f"{pnode}.y", f"{pnode}.rz", tip], n_modes)


def pair(sub: Substructure, n_points: int, frequency_hz: float | None) -> ss.System:
    b1 = Substructure(
        "blade1", sub.mass, sub.stiffness, sub.dof_names, sub.dof_units, points=sub.points, modal_damping_ratio=0.002
    )
    b2 = Substructure(
        "blade2", sub.mass, sub.stiffness, sub.dof_names, sub.dof_units, points=sub.points, modal_damping_ratio=0.002
    )
    faces = []
    for platform, angle, centre in (
        ("left", math.radians(45), (-2.5e-3, 1.0e-3)),
        ("right", math.radians(-45), (2.5e-3, 1.0e-3)),
    ):
        faces += damper_face_contacts(
            platform,
            platform,
            angle,
            centre,
            FACE_LENGTH_M,
            n_points,
            width=FACE_WIDTH_M,
            normal_stiffness_per_area=KN_PER_AREA,
            tangential_stiffness_per_area=KT_PER_AREA,
            friction_coefficient=MU,
        )
    damper = DamperLink(
        "damper",
        DAMPER_MASS,
        DAMPER_INERTIA,
        CENTRIFUGAL_N,
        (PlatformLink("left", math.radians(45), "blade1"), PlatformLink("right", math.radians(-45), "blade2")),
        tuple(faces),
    )
    tip = "blade1." + sub.points["tip"].dofs["x"]
    forces = [HarmonicForce(tip, FORCE_N, frequency_hz or 1.0)]
    return assemble([b1, b2], [damper], forces=forces, name=f"blade-pair-{n_points}")


def stuck_frequencies(system: ss.System, k: int) -> np.ndarray:
    """Lowest k natural frequencies [Hz] of the assembly with every contact stuck."""
    cs = system.compile()
    Kst = np.array(cs.K, copy=True)
    add_contact_stiffness(cs, np.ones(cs.kt.shape[0], np.int8), 1.0, Kst)
    import scipy.linalg

    w2 = scipy.linalg.eigh(Kst, cs.M, eigvals_only=True, subset_by_index=[0, k - 1])
    return np.sqrt(np.clip(w2, 0, None)) / (2 * math.pi)


def tip_amplitude(ds, dof: str) -> float:
    T = ds.attrs["period_s"]
    x = ds.displacement.sel(dof=dof).sel(time=slice(float(ds.time[-1]) - T, None)).values
    return float((x.max() - x.min()) / 2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20 points per face, 2 periods, 3 repeats")
    ap.add_argument("--elements", type=int, default=60)
    ap.add_argument("--points", type=int, default=50, help="contact points per damper face (2 faces)")
    ap.add_argument("--modes", type=int, default=10)
    ap.add_argument("--periods", type=float, default=3.0)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--frequency", type=float, default=None, help="Hz (default 0.9 x first stuck mode)")
    ap.add_argument("--full", action="store_true", help="also march the unreduced assembly (Method 3)")
    ap.add_argument("--full-solver", default="sparse", help="linear_solver of the unreduced march (auto: sparse here)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--frf", action="store_true", help="time the forced response by shoot, hbm and march")
    ap.add_argument("--frf-points", type=int, default=61)
    ap.add_argument("--harmonics", type=int, default=7)
    ap.add_argument("--march-points", type=int, default=3)
    ap.add_argument(
        "--solvers", default="shoot,shoot-plain,hbm,march", help="shoot-plain: shooting without the error estimate"
    )
    args = ap.parse_args()
    if args.frf:
        return frf_benchmark(args)
    if args.quick:
        args.points, args.periods, args.repeats = 20, 2.0, 3

    full = blade(args.elements)
    t0 = time.perf_counter()
    cb = reduced(full, args.modes)
    t_cb = time.perf_counter() - t0
    probe = pair(cb, args.points, None)
    f_cb = stuck_frequencies(probe, 4)
    freq = args.frequency or 0.9 * f_cb[0]
    system = pair(cb, args.points, freq)
    cs = system.compile()
    print(
        f"blade: {full.n_dofs} DOFs full -> {cb.n_dofs} reduced (CB {t_cb * 1e3:.0f} ms); assembly {cs.M.shape[0]}"
        f" DOFs, {len(system.contacts)} contact points ({cs.A.shape[0]} contact coordinates); force {freq:.1f} Hz"
    )
    rows = {
        "model": {
            "full_blade_dofs": full.n_dofs,
            "reduced_blade_dofs": cb.n_dofs,
            "dofs": cs.M.shape[0],
            "contact_points": len(system.contacts),
            "contact_coordinates": cs.A.shape[0],
            "frequency_Hz": freq,
            "craig_bampton_s": t_cb,
        }
    }
    full_system = pair(full, args.points, freq)
    f_full = stuck_frequencies(full_system, 4)
    print(
        "stuck frequencies [Hz]  reduced: "
        + ", ".join(f"{f:.2f}" for f in f_cb)
        + "   full: "
        + ", ".join(f"{f:.2f}" for f in f_full)
        + f"   max rel. diff {np.max(np.abs(f_cb / f_full - 1)):.2e}"
    )
    rows["stuck_frequencies_Hz"] = {"reduced": f_cb.tolist(), "full": f_full.tolist()}

    tip = "blade1." + cb.points["tip"].dofs["x"]
    sims, setup = {}, {}
    for label, method in METHODS:
        t0 = time.perf_counter()
        # the paper's T_min rule for every method: their kernel times compared on the same steps
        sims[label] = ss.Simulation(system, method, periods=args.periods, step_rule="t-min")
        setup[label] = time.perf_counter() - t0
        for _ in range(2):
            sims[label].march()
    times = {label: [] for label in sims}
    for _ in range(args.repeats):
        for label, sim in sims.items():
            sim.march()
            times[label].append(sim.kernel_time)
    amps = {}
    print(
        f"{'method':>6} {'setup s':>8} {'period ms':>10} {'ratio':>6} {'steps/T':>8} {'solves/T':>9} {'tip amp um':>11}"
    )
    ref = statistics.median(times["1"])
    for label, sim in sims.items():
        ds = sim.dataset()
        amps[label] = tip_amplitude(ds, tip)
        per = statistics.median(times[label]) / args.periods
        steps = int(ds.attrs["steps"]) / args.periods
        solves = float(ds.attrs["solves"]) / args.periods
        print(
            f"{label:>6} {setup[label]:8.2f} {per * 1e3:10.2f} {per / (ref / args.periods):6.2f} {steps:8.0f}"
            f" {solves:9.0f} {amps[label] * 1e6:11.3f}  {ds.attrs['status']}"
        )
        rows[label] = {
            "setup_s": setup[label],
            "period_s": per,
            "steps_per_period": steps,
            "solves_per_period": solves,
            "tip_amplitude_m": amps[label],
            "status": ds.attrs["status"],
        }
    spread = max(abs(a / amps["1"] - 1) for a in amps.values())
    print(f"largest tip-amplitude difference to Method 1: {spread:.2e}")
    if args.full:
        t0, c0 = time.perf_counter(), time.process_time()
        # Method 3's default step rule, 'accuracy' (issue 26): the frame's axial modes make T_min
        # tiny, the piecewise-linear solve does not need it (step_rule="t-min" took 622 s here).
        # 'auto' takes the sparse backend here by its estimated cost per step (methods.sparse.step_costs;
        # the dense one, which it took before by size alone, is 4x slower: 33 s CPU against 7.9 s)
        ds = ss.run(full_system, "piecewise-linear", periods=args.periods, linear_solver=args.full_solver)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        amp = tip_amplitude(ds, "blade1." + full.points["tip"].dofs["x"])
        print(
            f"full model ({full_system.structure.n_dofs} DOFs), Method 3 (step_rule {ds.attrs['step_rule']},"
            f" {ds.attrs['linear_solver']} backend, {int(ds.attrs['steps'])} steps, dt {ds.attrs['dt_s']:.3g} s):"
            f" {wall:.1f} s wall, {cpu:.1f} s CPU, tip amplitude {amp * 1e6:.3f} um,"
            f" reduced/full - 1 = {amps['3'] / amp - 1:.2e}"
        )
        rows["full"] = {
            "dofs": full_system.structure.n_dofs,
            "tip_amplitude_m": amp,
            "status": ds.attrs["status"],
            "step_rule": ds.attrs["step_rule"],
            "wall_s": wall,
            "cpu_s": cpu,
        }
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


def jacobian_split(system: ss.System, frequency_hz: float) -> dict:
    """The one-period Jacobian of shooting on a converged orbit: time with the free unknowns
    (x, v and the sliders that leave stick) against every slider as an unknown, and the floor
    of its matrix products per step (kernels/sensitivity.py) at the dgemm rate of a product of
    the same shape measured here."""
    from slipstep.model.retune import retune
    from slipstep.steady import shoot
    from slipstep.steady.marching import march_one_period, period_simulation, start
    from slipstep.steady.shooting import moving_sliders, period_jacobian

    system_f = retune(system, frequency_hz)
    steady = shoot(system_f)
    sim = period_simulation(system_f, "piecewise-linear", None, {})
    start(sim, steady.final_state, 0.0)
    march_one_period(sim)
    n, nd = system_f.n_dofs, len(system_f.direction_names())
    free = moving_sliders(sim)
    steps = int(sim.dataset().attrs["steps"])
    timing = {}
    for label, sliders in (("free", free), ("all", None)):
        period_jacobian(sim, sliders)
        t = []
        for _ in range(3):
            t0 = time.perf_counter()
            period_jacobian(sim, sliders)
            t.append(time.perf_counter() - t0)
        timing[label] = min(t)
    na = free.size
    nc = int(np.count_nonzero(np.abs(system_f.compile().A).sum(axis=0)))  # the contact DOFs
    cols = 2 * n + na
    states = sim.out.state[1 : steps + 1]
    changes = 1 + int(np.count_nonzero((states[1:] != states[:-1]).any(axis=1)))  # new (dt, S): the first step too
    # the kernel's products (kernels/sensitivity.py), m = cols columns: per step P_s Z (n x 3n);
    # per change of (dt, S) Q h (n x nc) and the solve with J(S) of 3n + nc right-hand sides
    flops = 2.0 * (steps * cols * 3 * n * n + changes * (cols * n * nc + n * n * (3 * n + nc)))
    a, b = np.random.default_rng(0).random((n, 3 * n)), np.random.default_rng(1).random((3 * n, cols))
    reps = 400
    t0 = time.perf_counter()
    for _ in range(reps):
        a @ b
    rate = reps * 2.0 * n * 3 * n * cols / (time.perf_counter() - t0)
    return {
        "steps_per_period": steps,
        "state_changes": changes,
        "moving_sliders": int(na),
        "contact_dofs": nc,
        "sliders": nd,
        "jacobian_free_s": timing["free"],
        "jacobian_all_sliders_s": timing["all"],
        "dgemm_flops_per_s": rate,
        "jacobian_floor_s": flops / rate,
        "march_period_s": float(sim.kernel_time),
    }


def frf_benchmark(args) -> None:
    """The --frf comparison (module docstring)."""
    from slipstep.frequency.response import frf
    from slipstep.hbm import frf as hbm_frf

    cb = reduced(blade(args.elements), args.modes)
    f1 = stuck_frequencies(pair(cb, args.points, None), 1)[0]
    system = pair(cb, args.points, f1)
    cs = system.compile()
    freqs = np.linspace(0.7 * f1, 1.1 * f1, args.frf_points)
    tip = "blade1." + cb.points["tip"].dofs["x"]
    print(
        f"blade pair: {cs.M.shape[0]} DOFs after Craig-Bampton ({args.elements} elements per blade), "
        f"{len(system.contacts)} contact points ({cs.A.shape[0]} contact coordinates); first stuck mode "
        f"{f1:.2f} Hz; {args.frf_points} points {freqs[0]:.1f}-{freqs[-1]:.1f} Hz"
    )
    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    rows, amps = {}, {}
    frf(system, freqs[:1], solver="shoot", linear=False, responses=[tip])  # compile outside the timings
    for name in solvers:
        grid = (
            freqs if name != "march" else freqs[:: max(1, len(freqs) // max(args.march_points, 1))][: args.march_points]
        )
        t0, c0 = time.perf_counter(), time.process_time()
        if name == "hbm":
            ds = hbm_frf(system, grid, harmonics=args.harmonics, responses=[tip], check="none", asked_only=True)
        elif name == "shoot-plain":  # the points as solved, without the step doubling's error estimate
            ds = frf(system, grid, solver="shoot", responses=[tip], linear=False, rtol=None)
        else:
            ds = frf(system, grid, solver=name, responses=[tip], linear=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        status = [str(s) for s in ds["status"].values.ravel()]
        ok = sum(s == "OK" for s in status)
        f_out = ds["frequency"].values
        amp = ds["amplitude"].sel(response=tip).values.ravel()
        amps[name] = dict(zip(np.round(f_out, 9), amp))
        extra = ""
        estimate = "harmonic_truncation_estimate" if name == "hbm" else "error_estimate"
        if estimate in ds and name not in ("shoot-plain", "march") and np.isfinite(ds[estimate].values).any():
            est = ds[estimate].values.ravel()
            extra += f", error estimate median {np.nanmedian(est):.1e} max {np.nanmax(est):.1e}"
        if "floquet_multiplier_max" in ds and name.startswith("shoot"):
            fm = ds["floquet_multiplier_max"].values.ravel()
            extra += f", stable {int(np.sum(fm < 1))} of {fm.size} (|Floquet| max {np.nanmax(fm):.4f})"
        print(
            f"{name:>6}: {len(f_out):3d} points in {wall:7.1f} s, {cpu:7.1f} s CPU ({wall / max(len(f_out), 1):6.3f} s "
            "per point), "
            f"{ok} OK{extra}"
        )
        rows[name] = {
            "points": len(f_out),
            "wall_s": wall,
            "cpu_s": cpu,
            "per_point_s": wall / max(len(f_out), 1),
            "ok": ok,
        }
    if "shoot" in amps:
        peak = max(amps["shoot"], key=amps["shoot"].get)
        for name in amps:
            common = [f for f in amps[name] if f in amps["shoot"]]
            if name != "shoot" and common:
                d = max(abs(amps[name][f] / amps["shoot"][f] - 1) for f in common)
                print(f"  {name} against shoot: largest relative amplitude difference {d:.2e} at {len(common)} points")
        split = jacobian_split(system, float(peak))
        print(
            f"  shooting at the peak ({peak:.2f} Hz): {split['steps_per_period']} steps per period, "
            f"{split['moving_sliders']} of {split['sliders']} sliders leave stick, {split['state_changes']} "
            "changes of state; period march "
            f"{split['march_period_s'] * 1e3:.1f} ms; Jacobian {split['jacobian_free_s'] * 1e3:.1f} ms over the free "
            f"unknowns, {split['jacobian_all_sliders_s'] * 1e3:.1f} ms with every slider as an unknown, floor "
            f"{split['jacobian_floor_s'] * 1e3:.1f} ms ({split['jacobian_free_s'] / split['jacobian_floor_s']:.1f}x) "
            f"at {split['dgemm_flops_per_s'] / 1e9:.1f} GFLOP/s"
        )
        rows["jacobian"] = split
    print("issue 24 (before): shoot 487 s for 61 points (8 s per point); hbm not finished after 1,500 s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
