"""slipstep side by side with OpenSeesPy and a plain NumPy loop (issue 3).

Two oscillators with Jenkins elements (elastic spring k_t in series with a Coulomb slider
of constant slip force F_s = mu N), harmonic forcing, mass-proportional damping C = alpha M:

* 1-DOF: mass m on a spring k to ground, one Jenkins element to ground, force F sin(2 pi f t).
* 2-DOF: m1 on k1 and a Jenkins element to ground, m2 on k2 and a Jenkins element to m1
  (relative displacement x2 - x1), force on m2.

All three march the same discrete equations (Newmark average acceleration, beta = 1/4,
gamma = 1/2) at the same fixed step dt = T / N, from rest (F(0) = 0, so a(0) = 0):

  (a) slipstep: the Jenkins element is a ContactElement whose tangential row gathers the DOF
      (or DOF difference) and whose normal row is all zero with normal_offset g > 0, so the
      normal load is the constant N = k_n g; method 'piecewise-linear' (Method 3, exact state
      solve) and, for reference, 'newmark' (Method 1, modified Newton, tight tolerance).
  (b) OpenSeesPy: zeroLength elements, uniaxialMaterial Elastic (k) and ElasticPP (k_t,
      yield strain F_s/k_t) in parallel, Rayleigh alpha_M damping, Newmark 0.5 0.25, full
      Newton with a tight NormDispIncr test, ONE analyze(nsteps, dt) call.
  (c) a plain NumPy loop: the same Newmark step with the Jenkins return mapping and full
      Newton iterations (consistent tangent).

Prints steps/s of each (median of repeats; slipstep: the compiled march, and the whole
run() call), the ratio slipstep / OpenSees (goal >= 10x) and the largest differences
between the displacement histories relative to the largest displacement (expected ~1e-9
or better: same discrete equations).

Usage:  python benchmarks/bench_vs_opensees.py [--quick] [--periods P] [--steps-per-period N] [--json]
OpenSeesPy: pip install openseespy (Linux needs Debian's libblas3 liblapack3:
apt-get install -y libblas3 liblapack3). Without it the OpenSees column is skipped.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import tempfile
import time
from dataclasses import dataclass

import numpy as np

import slipstep
from slipstep import ContactElement, Excitation, Harmonic, Signal, Structure, System

try:
    import openseespy.opensees as ops

    OPS_ERROR = None
except Exception as exc:  # ImportError, or RuntimeError when libblas3/liblapack3 are missing
    ops = None
    OPS_ERROR = f"{type(exc).__name__}: {exc}"

KN = 1e6  # normal stiffness of the Jenkins contacts [N/m]; N = KN * g, mu = 1


@dataclass
class Oscillator:
    """M, K [N/m], alpha_M [1/s] (C = alpha_M M), Jenkins elements as (gather row G_j, k_t, F_s),
    force amplitudes per DOF [N] at frequency f [Hz]."""

    name: str
    M: np.ndarray
    K: np.ndarray
    alpha_m: float
    jenkins: list  # [(row (n,), kt, Fs)]
    force: np.ndarray
    frequency: float

    @property
    def n(self) -> int:
        return self.M.shape[0]

    @property
    def period(self) -> float:
        return 1.0 / self.frequency

    def force_at(self, t: float) -> np.ndarray:
        return self.force * math.sin(2.0 * math.pi * self.frequency * t)


def one_dof() -> Oscillator:
    return Oscillator(
        "1-DOF Jenkins oscillator",
        np.array([[1.0]]),
        np.array([[1.0e4]]),
        4.0,
        [(np.array([1.0]), 2.0e4, 10.0)],
        np.array([30.0]),
        10.0,
    )


def two_dof() -> Oscillator:
    k1, k2 = 1.0e4, 5.0e3
    return Oscillator(
        "2-DOF Jenkins oscillator",
        np.diag([1.0, 0.5]),
        np.array([[k1 + k2, -k2], [-k2, k2]]),
        4.0,
        [(np.array([1.0, 0.0]), 2.0e4, 10.0), (np.array([-1.0, 1.0]), 1.0e4, 5.0)],
        np.array([0.0, 20.0]),
        10.0,
    )


# ---------------------------------------------------------------------------------------------
# (a) slipstep
def slipstep_system(osc: Oscillator) -> System:
    names = tuple(f"x{i + 1}" for i in range(osc.n))
    structure = Structure(osc.M, osc.alpha_m * osc.M, osc.K, dof_names=names)
    contacts = []
    for j, (row, kt, fs) in enumerate(osc.jenkins):
        A = np.vstack([row, np.zeros(osc.n)])  # tangential row; normal row on nothing
        contacts.append(
            ContactElement(
                f"J{j + 1}",
                A,
                tangential_stiffness=kt,
                normal_stiffness=KN,
                friction_coefficient=1.0,
                normal_offset=fs / KN,
            )
        )  # N = KN g = F_s
    force = Signal(names, (Harmonic(osc.frequency, osc.force),))
    return System(structure, tuple(contacts), Excitation(force=force), name=osc.name)


def slipstep_simulation(system: System, method: str, dt: float, periods: int, **options) -> slipstep.Simulation:
    """A Simulation whose fixed step is exactly ``dt`` (= period / N).

    slipstep has no ``dt`` option: dt = T / ceil(T / dt_limit), dt_limit = step_ratio *
    step_limit_factor * T_min(all stick); so pick step_ratio to land on N = T / dt."""
    probe = slipstep.Simulation(system, method, periods=1, **options)
    T = system.period
    n_per = round(T / dt)
    ratio = (T / n_per) * (1 + 1e-9) / (probe.options.scheme.step_limit_factor * probe.t_min_stick)
    sim = slipstep.Simulation(system, method, periods=periods, step_ratio=ratio, **options)
    if abs(sim.dt - dt) > 1e-14 * dt:
        raise RuntimeError(f"could not set dt = {dt} exactly (got {sim.dt})")
    return sim


def slipstep_runner(system: System, method: str, dt: float, periods: int, **options):
    """(march, whole_run, result): march() times the compiled kernel only, whole_run() a whole
    slipstep.run() call (set-up, preload, kernel, Dataset)."""
    sim = slipstep_simulation(system, method, dt, periods, **options)
    sim.march()  # warm-up
    ds = sim.dataset()
    if ds.attrs["status"] != "OK":
        raise RuntimeError(f"slipstep {method}: {ds.attrs['status_message']}")
    ratio = sim.options.step_ratio

    def march():
        sim.march()
        return sim.kernel_time

    def whole_run():
        t = time.perf_counter()
        slipstep.run(system, method, periods=periods, step_ratio=ratio, **options)
        return time.perf_counter() - t

    result = {
        "x": ds.displacement.values,
        "t": ds.time.values,
        "steps": int(ds.attrs["steps"]),
        "solves": int(ds.attrs["solves"]),
    }
    return march, whole_run, result


# ---------------------------------------------------------------------------------------------
# (b) OpenSeesPy
def opensees_build(osc: Oscillator, record_to: str | None = None, tol: float = 1e-14) -> None:
    """Nodes 1..n DOFs (node 0 fixed), 1-D model; springs and Jenkins as zeroLength elements."""
    ops.wipe()
    ops.model("basic", "-ndm", 1, "-ndf", 1)
    ops.node(1000, 0.0)
    ops.fix(1000, 1)
    for i in range(osc.n):
        ops.node(i + 1, 0.0)
        ops.mass(i + 1, float(osc.M[i, i]))
    if np.any(osc.M != np.diag(np.diag(osc.M))):
        raise ValueError("OpenSees model: lumped (diagonal) mass only")
    tag = 0
    # linear springs: K of a chain = sum over springs k (e_i - e_j)(e_i - e_j)^T; recover them
    springs = _springs_of(osc.K)
    for i, j, k in springs:
        tag += 1
        ops.uniaxialMaterial("Elastic", tag, float(k))
        ops.element("zeroLength", tag, 1000 if i < 0 else i + 1, j + 1, "-mat", tag, "-dir", 1)
    for row, kt, fs in osc.jenkins:
        nz = np.flatnonzero(row)
        if len(nz) == 1 and row[nz[0]] == 1.0:
            i, j = -1, nz[0]
        elif len(nz) == 2 and row[nz[0]] == -1.0 and row[nz[1]] == 1.0:
            i, j = nz
        else:
            raise ValueError("OpenSees model: Jenkins rows must be e_j or e_j - e_i")
        tag += 1
        ops.uniaxialMaterial("ElasticPP", tag, float(kt), float(fs / kt))
        ops.element("zeroLength", tag, 1000 if i < 0 else int(i) + 1, int(j) + 1, "-mat", tag, "-dir", 1)
    ops.rayleigh(osc.alpha_m, 0.0, 0.0, 0.0)
    ops.timeSeries("Trig", 1, 0.0, 1.0e9, osc.period, "-factor", 1.0)
    ops.pattern("Plain", 1, 1)
    for i in range(osc.n):
        if osc.force[i] != 0.0:
            ops.load(i + 1, float(osc.force[i]))
    if record_to is not None:
        ops.recorder(
            "Node", "-file", record_to, "-time", "-precision", 17, "-node", *range(1, osc.n + 1), "-dof", 1, "disp"
        )
    ops.constraints("Plain")
    ops.numberer("Plain")
    ops.system("FullGeneral")
    ops.test("NormDispIncr", tol, 100, 0)
    ops.algorithm("Newton")
    ops.integrator("Newmark", 0.5, 0.25)
    ops.analysis("Transient")


def _springs_of(K: np.ndarray) -> list:
    """(i, j, k) springs (i = -1: ground) whose assembly is K (chain-like K only)."""
    n = K.shape[0]
    out = []
    for i in range(n):
        for j in range(i + 1, n):
            if K[i, j] != 0.0:
                out.append((i, j, -K[i, j]))
    for i in range(n):
        k_ground = K[i].sum()
        if abs(k_ground) > 1e-12 * abs(K).max():
            out.append((-1, i, k_ground))
    A = np.zeros_like(K)
    for i, j, k in out:
        e = np.zeros(n)
        e[j] = 1.0
        if i >= 0:
            e[i] = -1.0
        A += k * np.outer(e, e)
    assert np.allclose(A, K), "K is not a spring chain"
    return out


def opensees_analyze(osc: Oscillator, dt: float, nsteps: int) -> float:
    """Build the model (not timed), then time ONE analyze(nsteps, dt) call."""
    opensees_build(osc)
    t = time.perf_counter()
    ok = ops.analyze(nsteps, dt)
    elapsed = time.perf_counter() - t
    if ok != 0:
        raise RuntimeError(f"OpenSees analyze failed (code {ok}) at t = {ops.getTime()}")
    ops.wipe()
    return elapsed


def opensees_history(osc: Oscillator, dt: float, nsteps: int) -> tuple[float, dict]:
    """Build + recorder + analyze + read the history back (timed whole, the analogue of run())."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "disp.out")
        t = time.perf_counter()
        opensees_build(osc, record_to=path)
        ok = ops.analyze(nsteps, dt)
        ops.wipe()  # flushes and closes the recorder
        data = np.loadtxt(path, ndmin=2)
        elapsed = time.perf_counter() - t
    if ok != 0:
        raise RuntimeError(f"OpenSees analyze failed (code {ok})")
    # the recorder writes after each step, not the initial state: prepend x(0) = 0, t = 0
    x = np.vstack([np.zeros((1, osc.n)), data[:, 1:]])
    t_rec = np.concatenate([[0.0], data[:, 0]])
    return elapsed, {"x": x, "t": t_rec, "steps": nsteps}


# ---------------------------------------------------------------------------------------------
# (c) plain NumPy
def numpy_march(osc: Oscillator, dt: float, nsteps: int, tol: float = 1e-14) -> dict:
    """Newmark average acceleration + Jenkins return mapping, full Newton on dx = x_{n+1} - x_n:
        r(dx) = F_{n+1} - M a_{n+1} - C v_{n+1} - K (x_n + dx) - G^T T(G (x_n + dx), w_n) = 0,
        a_{n+1} = 4/dt^2 dx - 4/dt v_n - a_n,  v_{n+1} = 2/dt dx - v_n,
        T_j = k_t (u_j - w_j) if |k_t (u_j - w_j)| <= F_s else F_s sign(.) (slip: w_j = u_j - T_j / k_t);
    tangent J = 4/dt^2 M + 2/dt C + K + G^T diag(k_t if stick else 0) G. Stop when max|delta| <= tol * max(1, |x|)."""
    M, K, C = osc.M, osc.K, osc.alpha_m * osc.M
    G = np.array([row for row, _, _ in osc.jenkins])
    kt = np.array([k for _, k, _ in osc.jenkins])
    fs = np.array([f for _, _, f in osc.jenkins])
    Lin = 4.0 / dt**2 * M + 2.0 / dt * C + K
    n = osc.n
    x, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    w = np.zeros(len(kt))
    out = np.zeros((nsteps + 1, n))
    iters = 0
    t = 0.0
    for k in range(1, nsteps + 1):
        t = k * dt
        F1 = osc.force_at(t)
        r0 = F1 + M @ (4.0 / dt * v + a) + C @ v - K @ x
        dx = np.zeros(n)
        for it in range(50):
            u = G @ (x + dx)
            trial = kt * (u - w)
            stick = np.abs(trial) <= fs
            T = np.where(stick, trial, fs * np.sign(trial))
            r = r0 - Lin @ dx - G.T @ T
            J = Lin + G.T @ (np.where(stick, kt, 0.0)[:, None] * G)
            delta = np.linalg.solve(J, r)
            dx += delta
            iters += 1
            if np.abs(delta).max() <= tol * max(1e-3, np.abs(x).max()):
                break
        else:
            raise RuntimeError(f"NumPy Newton did not converge at step {k}")
        u = G @ (x + dx)
        trial = kt * (u - w)
        T = np.clip(trial, -fs, fs)
        w = u - T / kt
        a = 4.0 / dt**2 * dx - 4.0 / dt * v - a
        v = 2.0 / dt * dx - v
        x = x + dx
        out[k] = x
    return {"x": out, "iterations": iters}


# ---------------------------------------------------------------------------------------------
def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    scale = max(np.abs(a).max(), np.abs(b).max(), 1e-300)
    return float(np.abs(a - b).max() / scale)


def run_case(osc: Oscillator, periods: int, n_per: int, repeats: int) -> dict:
    dt = osc.period / n_per
    nsteps = periods * n_per
    system = slipstep_system(osc)
    print(
        f"\n{osc.name}: {osc.n} DOF(s), {len(osc.jenkins)} Jenkins element(s), f = {osc.frequency:g} Hz, "
        f"dt = T/{n_per} = {dt * 1e3:.4g} ms, {periods} periods = {nsteps} steps"
    )
    res = {"case": osc.name, "dt_s": dt, "steps": nsteps}
    m3_march, m3_run, s3 = slipstep_runner(system, "piecewise-linear", dt, periods)
    m1_march, _, s1 = slipstep_runner(system, "newmark", dt, periods, tolerance=1e-12)
    # round-robin repeats so that the (shared, noisy) machine load hits every solver alike
    timers = {"m3": m3_march, "m3_run": m3_run, "m1": m1_march}
    if ops is not None:
        timers["ops"] = lambda: opensees_analyze(osc, dt, nsteps)
        timers["ops_run"] = lambda: opensees_history(osc, dt, nsteps)[0]
    times = {k: [] for k in timers}
    times["numpy"] = []
    npy = None
    for rep in range(repeats):
        for k, fn in timers.items():
            times[k].append(fn())
        if rep % 5 == 0:  # the NumPy loop is slow: fewer repeats
            t = time.perf_counter()
            npy = numpy_march(osc, dt, nsteps)
            times["numpy"].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}
    osr = opensees_history(osc, dt, nsteps)[1] if ops is not None else None
    rows = [
        ("slipstep piecewise-linear (Method 3), kernel", med["m3"], f"{s3['solves']} solves"),
        ("slipstep newmark (Method 1, tol 1e-12), kernel", med["m1"], f"{s1['solves']} solves"),
    ]
    if osr is not None:
        rows.append(("OpenSeesPy: one analyze(nsteps, dt) call", med["ops"], "Newton, NormDispIncr 1e-14"))
    rows.append(("slipstep: whole run() call, Method 3", med["m3_run"], "set-up + preload + kernel + Dataset"))
    if osr is not None:
        rows.append(("OpenSeesPy: build + analyze + recorder + read", med["ops_run"], "17-digit recorder file"))
    rows.append(("plain NumPy loop", med["numpy"], f"{npy['iterations']} Newton solves"))
    print(f"   median of {repeats} interleaved repeats ({len(times['numpy'])} for NumPy)")
    print(f"   {'solver':48s} {'steps':>7s} {'time':>11s} {'steps/s':>11s}  note")
    for name, sec, note in rows:
        print(f"   {name:48s} {nsteps:7d} {sec * 1e3:8.3f} ms {nsteps / sec:11.4g}  {note}")
    res["steps_per_s"] = {name: nsteps / sec for name, sec, _ in rows}
    if osr is not None:
        k_ratio = med["ops"] / med["m3"]
        r_ratio = med["ops_run"] / med["m3_run"]
        print(
            f"   slipstep / OpenSees steps/s: kernel vs analyze() {k_ratio:.1f}x; whole run() vs build+analyze+read "
            f"{r_ratio:.1f}x   (goal >= 10x: {'met' if k_ratio >= 10 else 'NOT met'} on the kernel)"
        )
        res["ratio_kernel_vs_opensees"], res["ratio_run_vs_opensees"] = k_ratio, r_ratio
    print(f"   slipstep / NumPy loop steps/s: kernel {med['numpy'] / med['m3']:.0f}x")
    # histories
    x3, x1, xn = s3["x"], s1["x"], npy["x"]
    if x3.shape != xn.shape:
        raise RuntimeError(f"history shapes differ: slipstep {x3.shape}, NumPy {xn.shape}")
    t_ref = np.arange(nsteps + 1) * dt
    diffs = {
        "slipstep M3 vs NumPy": rel_diff(x3, xn),
        "slipstep M1 vs NumPy": rel_diff(x1, xn),
        "slipstep M3 vs slipstep M1": rel_diff(x3, x1),
    }
    if osr is not None:
        if osr["x"].shape != xn.shape or np.abs(osr["t"] - t_ref).max() > 1e-9 * t_ref[-1]:
            print(
                f"   WARNING: OpenSees history has shape {osr['x'].shape} / times off by "
                f"{np.abs(osr['t'] - t_ref).max() if osr['x'].shape == xn.shape else 'n/a'}"
            )
        else:
            diffs["slipstep M3 vs OpenSees"] = rel_diff(x3, osr["x"])
            diffs["OpenSees vs NumPy"] = rel_diff(osr["x"], xn)
    print(f"   largest displacement difference / largest |x| (max |x| = {np.abs(xn).max() * 1e3:.4g} mm):")
    for k, d in diffs.items():
        print(f"      {k:30s} {d:9.2e}")
    res["max_rel_diff"] = diffs
    res["max_abs_x_m"] = float(np.abs(xn).max())
    return res


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="10 periods, fewer repeats")
    ap.add_argument("--periods", type=int, default=None, help="forcing periods (default 50, quick 10)")
    ap.add_argument("--steps-per-period", type=int, default=200, help="N in dt = T / N (default 200)")
    ap.add_argument("--repeats", type=int, default=None, help="slipstep kernel repeats (default 20, quick 6)")
    ap.add_argument("--json", action="store_true", help="also print the results as JSON")
    args = ap.parse_args(argv)
    periods = args.periods or (10 if args.quick else 50)
    repeats = args.repeats or (6 if args.quick else 20)
    print(
        f"slipstep {slipstep.__version__} vs OpenSeesPy vs NumPy: Newmark average acceleration, fixed dt; "
        f"{os.cpu_count()} CPUs (shared: noisy), {time.strftime('%Y-%m-%d %H:%M')}"
    )
    if ops is None:
        print(
            f"OpenSeesPy is not available ({OPS_ERROR}): its column is SKIPPED. Install with "
            "`pip install openseespy` (+ `apt-get install -y libblas3 liblapack3` on Debian/Ubuntu)."
        )
    results = [run_case(osc, periods, args.steps_per_period, repeats) for osc in (one_dof(), two_dof())]
    if args.json:
        print(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
