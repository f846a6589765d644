"""Seeded random systems and the agreement check of the methods against a tight reference.

Every OK result of a method must agree with a tight-tolerance full-Newton reference on the
same time grid (the discrete Newmark solution is the same for every step solver: modified
Newton, full Newton and the piecewise-linear solve all solve the same step equation). Used
by ``tests/test_trust_random.py`` (a few hundred systems) and
``benchmarks/random_systems.py`` (5,000 systems, prints the failure rate).

    rng = np.random.default_rng(7)
    system = random_system(rng)
    row = check_system(system)        # {'newmark': {'status': 'OK', 'error': 3e-10}, ...}

A *failure* is an OK result farther than ``rtol`` of the response range from the reference:
    error = max_t,j |x_j - x_ref,j| / max_j (max_t x_ref,j - min_t x_ref,j)
(a disagreement is allowed only together with a status other than OK).

A *sensitive* system is one where either of two twins of the reference says that a
perturbation of the size a step solved to the default tolerance leaves is amplified beyond
what the check can hold (the twins run only for a system where some method failed): (1) the reference with every load and motion scaled by
1 + ``PERTURBATION`` (1e-10) moves by more than ``rtol`` of the range; (2) the reference
solved along another round-off path to the same discrete solution (the other linear solver:
direct LU against the low-rank update; or the piecewise-linear solve at a tight state
tolerance) differs from it by more than ``ROUNDOFF_SPREAD`` (1e-12: round-off amplified
beyond about 1e4).
These are impacts after long free drifts and chaotic impact oscillators; they are counted
apart (``check_system`` marks them; the benchmark prints both rates).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from slipstep.errors import InputError, SolverError
from slipstep.methods.eigen import omega_max
from slipstep.methods.sensitivity_twin import PERTURBATION, perturbed  # noqa: F401  (re-exported: their former home)
from slipstep.methods.step_control import t_min_of_omega
from slipstep.model.contact import ContactElement
from slipstep.model.excitation import Excitation, Harmonic, Signal
from slipstep.model.structure import Structure
from slipstep.model.system import System

CHECK_METHODS = ("newmark", "full-newton", "piecewise-linear")
ROUNDOFF_SPREAD = 1e-12


def _spd(rng, n, scale, spread):
    """A random symmetric positive definite n x n matrix with eigenvalues in scale * [1, spread]."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    ev = scale * np.exp(rng.uniform(0.0, math.log(spread), n))
    return (Q * ev) @ Q.T


def random_system(rng: np.random.Generator, max_dofs: int = 5, max_contacts: int = 3) -> System:
    """A random small system: 1..max_dofs DOFs, 1..max_contacts contacts (2D or quasi-3D),
    random SPD M, K SPD / zero / rank-deficient, light damping or none, random gather maps,
    preload by constant loads and/or normal interference, harmonic forces and motions."""
    n = int(rng.integers(1, max_dofs + 1))
    nc = int(rng.integers(1, max_contacts + 1))
    M = _spd(rng, n, 1.0, 10.0)
    kind = rng.integers(0, 3)
    if kind == 0:
        K = _spd(rng, n, 1e6, 100.0)
    elif kind == 1 or n == 1:
        K = np.zeros((n, n))
    else:
        rank = int(rng.integers(1, n))
        V = rng.standard_normal((n, rank))
        K = 1e6 * V @ V.T / rank
    C = _spd(rng, n, 1.0, 100.0) * rng.uniform(0, 50) if rng.random() < 0.4 else None
    n_motion = int(rng.integers(0, 3))
    motion_names = tuple(f"p{i}" for i in range(n_motion))
    contacts = []
    for c in range(nc):
        rows = 3 if rng.random() < 0.35 else 2
        A = rng.standard_normal((rows, n))
        B = rng.standard_normal((rows, n_motion)) if n_motion else None
        kn = 10 ** rng.uniform(5.5, 7.5)
        kt = 10 ** rng.uniform(5.5, 7.5, rows - 1)
        contacts.append(
            ContactElement(
                name=f"C{c}",
                dof_gather=A,
                motion_gather=B,
                normal_stiffness=kn,
                tangential_stiffness=tuple(kt),
                friction_coefficient=float(rng.uniform(0.1, 0.8)),
                normal_offset=float(rng.uniform(0.0, 2e-5)) if rng.random() < 0.5 else 0.0,
            )
        )
    # constant load pushing the contacts closed on average (a sum of their normal rows)
    normals = np.array([c.dof_gather[-1] for c in contacts])
    f0 = normals.T @ rng.uniform(0.0, 100.0, nc) + rng.standard_normal(n) * rng.uniform(0, 20)
    # excitation frequency relative to the highest full-stick frequency: 20..400 steps of T_min/pi per period
    system0 = System(Structure(M, C, K), tuple(contacts), Excitation(constant_force=f0), motion_names=motion_names)
    cs = system0.compile_dense("the verification")
    Keff = cs.K.copy()
    for c in range(cs.kn.shape[0]):
        Keff += cs.kn[c] * np.outer(cs.A[cs.normal_row[c]], cs.A[cs.normal_row[c]])
    for d in range(cs.kt.shape[0]):
        Keff += cs.kt[d] * np.outer(cs.A[cs.tangential_row[d]], cs.A[cs.tangential_row[d]])
    wmax = omega_max(M, Keff)  # the largest eigenvalue alone (methods/eigen.py)
    dt_limit = 2.0 / wmax
    frequency = 1.0 / (dt_limit * 10 ** rng.uniform(math.log10(20), math.log10(400)))
    force = motion = None
    if rng.random() < 0.8 or n_motion == 0:
        force = Signal(
            tuple(f"x{i}" for i in range(n)),
            (Harmonic(frequency, rng.standard_normal(n) * rng.uniform(5, 100), rng.uniform(0, 6.3, n)),),
        )
    if n_motion:
        motion = Signal(
            motion_names,
            (Harmonic(frequency, rng.standard_normal(n_motion) * rng.uniform(1e-6, 3e-5), np.zeros(n_motion)),),
        )
    return System(
        Structure(M, C, K),
        tuple(contacts),
        Excitation(constant_force=f0, force=force, motion=motion),
        motion_names=motion_names,
        name="random",
    )


FAMILIES = ("single-stick", "two-on-one", "mixed", "general", "slow-load")


def family_system(rng: np.random.Generator, family: str = "general") -> System:
    """A random system of one of the FAMILIES of issue 29 (2D laws, harmonic loads and motions,
    the load period 1-100 T_min of full stick):

    * ``single-stick``: one DOF, one contact, loads mostly below the friction limit (long sticks);
    * ``two-on-one``: two contacts gathering the same DOF (1-3 DOFs);
    * ``mixed``: 2-5 DOFs, every gather row mixing DOFs (dense random rows);
    * ``general``: 1-5 DOFs, 1-3 contacts, dense or unit gather rows, K SPD or zero, gaps and
      interferences, motions on some;
    * ``slow-load``: ``general`` with a load period of 1e3-3e4 T_min (long quasi-static stretches
      marched by a dynamic method; where Method 3 broke |T| <= mu N before issue 29).
    """
    if family not in FAMILIES:
        raise InputError("family", f"is {family!r}", f"use one of {FAMILIES}")
    n = {"single-stick": 1, "two-on-one": int(rng.integers(1, 4)), "mixed": int(rng.integers(2, 6))}.get(
        family, int(rng.integers(1, 6))
    )
    nc = {"single-stick": 1, "two-on-one": 2}.get(family, int(rng.integers(1, 4)))
    M = _spd(rng, n, 0.1, 100.0)
    K = _spd(rng, n, 1e4, 1e3) if family == "single-stick" or rng.random() < 0.7 else np.zeros((n, n))
    n_motion = int(rng.integers(0, 2))
    motion_names = tuple(f"p{i}" for i in range(n_motion))
    shared = int(rng.integers(0, n))
    contacts = []
    for c in range(nc):
        if family == "mixed" or (family == "general" and rng.random() < 0.7):
            A = rng.standard_normal((2, n))
        else:
            j = shared if family in ("two-on-one", "single-stick") else int(rng.integers(0, n))
            A = np.zeros((2, n))
            A[0, j] = rng.choice([-1.0, 1.0])
            A[1, j if rng.random() < 0.5 else int(rng.integers(0, n))] = rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1)
        contacts.append(
            ContactElement(
                name=f"C{c}",
                dof_gather=A,
                motion_gather=rng.standard_normal((2, n_motion)) if n_motion else None,
                normal_stiffness=10 ** rng.uniform(4, 8),
                tangential_stiffness=(10 ** rng.uniform(4, 8),),
                friction_coefficient=float(rng.uniform(0.05, 1.0)),
                normal_offset=float(rng.uniform(-1e-5, 3e-5)) if rng.random() < 0.5 else 0.0,
            )
        )
    normals = np.array([c.dof_gather[-1] for c in contacts])
    push = rng.uniform(0, 200, nc)
    f0 = normals.T @ push + rng.standard_normal(n) * rng.uniform(0, 50)
    amplitude = (0.3 * push.max() + 1.0) if family == "single-stick" else 10 ** rng.uniform(0, 2.5)
    system0 = System(Structure(M, None, K), tuple(contacts), Excitation(constant_force=f0), motion_names=motion_names)
    cs = system0.compile_dense("the verification")
    Keff = cs.K + sum(cs.kn[c] * np.outer(cs.A[cs.normal_row[c]], cs.A[cs.normal_row[c]]) for c in range(nc))
    Keff = Keff + sum(cs.kt[d] * np.outer(cs.A[cs.tangential_row[d]], cs.A[cs.tangential_row[d]]) for d in range(nc))
    t_min = t_min_of_omega(omega_max(M, Keff))
    frequency = 1.0 / (t_min * 10 ** (rng.uniform(3.0, 4.5) if family == "slow-load" else rng.uniform(0.0, 2.0)))
    force = Signal(
        tuple(f"x{i}" for i in range(n)),
        (Harmonic(frequency, rng.standard_normal(n) * amplitude, rng.uniform(0, 6.3, n)),),
    )
    motion = None
    if n_motion:
        motion = Signal(
            motion_names,
            (Harmonic(frequency, rng.standard_normal(n_motion) * 10 ** rng.uniform(-6, -4), np.zeros(n_motion)),),
        )
    return System(
        Structure(M, None, K),
        tuple(contacts),
        Excitation(constant_force=f0, force=force, motion=motion),
        motion_names=motion_names,
        name=f"random-{family}",
    )


def invariant_check(system: System, method: str, periods: float = 2.0, **options) -> tuple[str, str]:
    """(status, broken invariant text or "") of one run of ``method`` (slipstep.methods.invariants: an
    OK march that breaks one ends with status INVARIANT); ("SETUP", message) when the system
    cannot even be set up (no static equilibrium: not counted)."""
    from slipstep.methods.simulation import run

    options.setdefault("error_estimate", False)
    options.setdefault("sensitivity_check", False)  # the study measures the results, not the run's own check
    options.setdefault("step_rule", "t-min")  # the paper's grid for every method (the agreement is on one grid)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = run(system, method, periods=periods, **options)
        except (InputError, SolverError) as exc:
            return "SETUP", str(exc)
    return ds.attrs["status"], ds.attrs.get("broken_invariant", "")


INVARIANT_METHODS = (
    "newmark",
    "full-newton",
    "piecewise-linear",
    "newmark-adaptive",
    "quasi-static",
    "quasi-static-events",
)
DECIDABLE_RTOL = 1e-8


def tight_references(system, periods):
    """(full Newton at tolerance 1e-13, the piecewise-linear solve at state tolerance 1e-13), both
    on the paper's T_min grid without the error estimate: the two references of an agreement
    check (a system is decidable where they agree to DECIDABLE_RTOL)."""
    from slipstep.methods.simulation import run

    off = {"error_estimate": False, "step_rule": "t-min", "sensitivity_check": False}
    ref = run(system, "full-newton", periods=periods, tolerance=1e-13, **off)
    pl = run(system, "piecewise-linear", periods=periods, state_tolerance=1e-13, **off)
    return ref, pl


def family_check(system: System, methods=INVARIANT_METHODS, periods: float = 2.0, rtol: float = 1e-6) -> dict:
    """Issue 29's check of one system: every method's status and broken invariant (``invariant_check``),
    and for the fixed-step dynamic methods (CHECK_METHODS) the agreement error with full Newton
    at tolerance 1e-13 where the system is *decidable*: full Newton and the piecewise-linear
    solve, both at 1e-13, agree to DECIDABLE_RTOL of the range (else NaN), and whether the
    result was flagged by the step audit (invariants.audit_steps). Returns
    {method: {'status', 'invariant', 'error', 'flagged'}, 'decidable': bool}."""
    from slipstep.methods.invariants import flagged
    from slipstep.methods.simulation import run

    rows: dict = {"decidable": False}
    ref = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ref, pl = tight_references(system, periods)
            rows["decidable"] = (
                ref.attrs["status"] == pl.attrs["status"] == "OK" and agreement_error(pl, ref) <= DECIDABLE_RTOL
            )
        except (InputError, SolverError):
            pass
        for m in methods:
            try:
                ds = run(system, m, periods=periods, error_estimate=False, step_rule="t-min", sensitivity_check=False)
            except (InputError, SolverError) as exc:
                rows[m] = {"status": "SETUP", "invariant": str(exc), "error": math.nan, "flagged": False}
                continue
            ok = ds.attrs["status"] == "OK"
            error = agreement_error(ds, ref) if ok and rows["decidable"] and m in CHECK_METHODS else math.nan
            rows[m] = {
                "status": ds.attrs["status"],
                "invariant": ds.attrs.get("broken_invariant", ""),
                "error": error,
                "flagged": bool(flagged(ds.attrs)),  # invariants.flagged: the step audit, the tolerance flag
            }
    return rows


def agreement_error(ds, ref) -> float:
    """max_t,j |x_j - x_ref,j| / (largest DOF range of the reference); inf if the grids differ."""
    x = ds["displacement"].values
    xr_ = ref["displacement"].values
    if x.shape != xr_.shape or not np.allclose(
        ds.time.values, ref.time.values, rtol=0, atol=1e-12 * ref.time.values[-1]
    ):
        return math.inf
    span = float((xr_.max(axis=0) - xr_.min(axis=0)).max())
    return float(np.abs(x - xr_).max() / max(span, 1e-300))


def check_system(
    system: System,
    methods=CHECK_METHODS,
    periods: float = 2.0,
    reference_tolerance: float = 1e-13,
    rtol: float = 1e-6,
    adaptive: bool = False,
    **options,
) -> dict | None:
    """Run ``methods`` and a full-Newton reference at ``reference_tolerance`` on the same grid;
    returns {method: {'status', 'error'}} (error against the reference, NaN when not OK) and
    'sensitive' (see the module docstring; the twins run only when a method fails), or None
    when the system cannot be set up or the reference itself fails (not counted). The error
    estimate is off (its default-step refinement would change the grid between runs).
    adaptive: also Method 2 ('newmark-adaptive') against Method 2+3 at the tight state
    tolerance on their contact-state grid (error inf when the two grids differ)."""
    from slipstep.methods.simulation import run

    options.setdefault("error_estimate", False)
    options.setdefault("sensitivity_check", False)  # the study measures the results, not the run's own check
    options.setdefault("step_rule", "t-min")  # the paper's grid for every method (the agreement is on one grid)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ref = run(system, "full-newton", periods=periods, tolerance=reference_tolerance, **options)
        except (InputError, SolverError):
            return None
        if ref.attrs["status"] != "OK":
            return None
        rows = {"sensitive": False}
        for m in methods:
            ds = run(system, m, periods=periods, **options)
            ok = ds.attrs["status"] == "OK"
            rows[m] = {"status": ds.attrs["status"], "error": agreement_error(ds, ref) if ok else math.nan}
        if adaptive:
            aref = run(
                system, "piecewise-linear-adaptive", periods=periods, state_tolerance=reference_tolerance, **options
            )
            ds = run(system, "newmark-adaptive", periods=periods, **options)
            ok = ds.attrs["status"] == "OK" and aref.attrs["status"] == "OK"
            rows["newmark-adaptive"] = {
                "status": ds.attrs["status"],
                "error": agreement_error(ds, aref) if ok else math.nan,
            }
        rows["sensitive"] = bool(_failed(rows, rtol)) and _sensitive(
            system, ref, periods, reference_tolerance, rtol, options
        )
    return rows


def _failed(rows: dict, rtol: float) -> list[str]:
    return [m for m, r in rows.items() if m != "sensitive" and r["status"] == "OK" and not r["error"] <= rtol]


def _sensitive(system, ref, periods, reference_tolerance, rtol, options) -> bool:
    """The two sensitivity twins of the module docstring (run only for a system with a failure)."""
    from slipstep.methods.simulation import run

    twin = run(
        perturbed(system, PERTURBATION), "full-newton", periods=periods, tolerance=reference_tolerance, **options
    )
    other = "direct" if ref.attrs["linear_solver"] == "low-rank" else "low-rank"
    try:
        path = run(
            system, "full-newton", periods=periods, tolerance=reference_tolerance, linear_solver=other, **options
        )
        spread = agreement_error(path, ref) if path.attrs["status"] == "OK" else 0.0
    except SolverError:  # the other solver cannot even preload: no second path to compare
        spread = 0.0
    if twin.attrs["status"] != "OK" or not agreement_error(twin, ref) <= rtol or not spread <= ROUNDOFF_SPREAD:
        return True
    path = run(system, "piecewise-linear", periods=periods, state_tolerance=reference_tolerance, **options)
    return path.attrs["status"] == "OK" and not agreement_error(path, ref) <= ROUNDOFF_SPREAD


def failures(rows: dict | None, rtol: float = 1e-6, include_sensitive: bool = False) -> list[str]:
    """The methods whose OK result is farther than rtol of the range from the reference
    (sensitive systems only with include_sensitive)."""
    if rows is None or (rows.get("sensitive") and not include_sensitive):
        return []
    return _failed(rows, rtol)
