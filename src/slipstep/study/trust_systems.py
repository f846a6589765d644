"""Random systems of the trust check of issue 29 item 3 ("never OK when wrong"), written apart from
``verification.family_system`` so that the two generators check each other:

* ``stick-1dof``: one DOF, one 2D contact gathering it (tangent a x, normal b x), a preload
  holding it closed and a tangential load of 0.2-1.5 mu N0 (long stick phases), damping or none;
* ``shared-dof``: 1-3 DOFs, two contacts whose rows gather the same DOF, pressed from opposite
  sides or side by side (a DOF clamped by two frictional supports);
* ``lever-map``: 2-5 DOFs, every gather row mixing 2-3 DOFs with coefficients of both signs
  over three decades (rotations with lever arms), mass spread 1e3;
* ``broad``: 1-5 DOFs, 1-3 contacts, K SPD, rank-deficient or zero, Rayleigh damping or none,
  gaps and interferences, motions on some.

Every generator: 2D laws, a harmonic load (and motion), the load period 1-100 T_min of full stick
(log-uniform; ``methods.step_control.t_min_of_omega``). ``trust_system(rng, generator)`` draws one.
Used by ``benchmarks/random_systems.py --trust`` and ``tests/test_trust_never_ok_wrong.py``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from slipstep.errors import InputError
from slipstep.methods.eigen import omega_max
from slipstep.methods.step_control import t_min_of_omega
from slipstep.model.contact import ContactElement
from slipstep.model.excitation import Excitation, Harmonic, Signal
from slipstep.model.structure import Structure
from slipstep.model.system import System

GENERATORS = ("stick-1dof", "shared-dof", "lever-map", "broad")


def _spd(rng, n, scale, spread):
    """A random SPD n x n matrix, eigenvalues log-uniform in scale * [1, spread]."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return (Q * (scale * np.exp(rng.uniform(0.0, math.log(spread), n)))) @ Q.T


def _contact(rng, name, A, n_motion):
    return ContactElement(
        name=name,
        dof_gather=A,
        motion_gather=rng.uniform(-1, 1, (2, n_motion)) if n_motion else None,
        normal_stiffness=10 ** rng.uniform(4.5, 7.5),
        tangential_stiffness=(10 ** rng.uniform(4.5, 7.5),),
        friction_coefficient=float(rng.uniform(0.1, 0.9)),
        normal_offset=float(rng.uniform(-5e-6, 2e-5)) if rng.random() < 0.4 else 0.0,
    )


def _gather_rows(rng, generator, n, nc):
    """The 2 x n gather rows (tangent, normal) of each contact."""
    rows = []
    shared = int(rng.integers(0, n))
    side = rng.random() < 0.5  # shared-dof: pressed from opposite sides of the DOF
    for c in range(nc):
        A = np.zeros((2, n))
        if generator == "stick-1dof":
            A[:, 0] = rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0, 2)
        elif generator == "shared-dof":
            A[0, shared] = rng.choice([-1.0, 1.0])
            other = shared if n == 1 or rng.random() < 0.6 else int(rng.integers(0, n))
            A[1, other] = (-1.0 if side and c == 1 else 1.0) * rng.uniform(0.3, 1.0)
        elif generator == "lever-map":
            for r in range(2):
                cols = rng.choice(n, size=min(n, int(rng.integers(2, 4))), replace=False)
                A[r, cols] = rng.choice([-1.0, 1.0], cols.size) * 10 ** rng.uniform(-2, 1, cols.size)
        else:
            A = rng.standard_normal((2, n)) if rng.random() < 0.6 else A
            if not A.any():
                A[0, int(rng.integers(0, n))] = 1.0
                A[1, int(rng.integers(0, n))] = rng.choice([-1.0, 1.0])
        rows.append(A)
    return rows


def trust_system(rng: np.random.Generator, generator: str = "broad") -> System:
    """One random system of ``generator`` (one of GENERATORS; module docstring)."""
    if generator not in GENERATORS:
        raise InputError("generator", f"is {generator!r}", f"use one of {GENERATORS}")
    n = {"stick-1dof": 1, "shared-dof": int(rng.integers(1, 4)), "lever-map": int(rng.integers(2, 6))}.get(
        generator, int(rng.integers(1, 6))
    )
    nc = {"stick-1dof": 1, "shared-dof": 2}.get(generator, int(rng.integers(1, 4)))
    M = _spd(rng, n, 0.01, 1e3 if generator == "lever-map" else 30.0)
    kind = int(rng.integers(0, 3)) if generator == "broad" and n > 1 else 0
    if kind == 0:
        K = _spd(rng, n, 10 ** rng.uniform(3, 6), 100.0)
    elif kind == 1:
        V = rng.standard_normal((n, int(rng.integers(1, n))))
        K = 10 ** rng.uniform(3, 6) * V @ V.T
    else:
        K = np.zeros((n, n))
    n_motion = int(rng.integers(0, 2)) if generator in ("broad", "lever-map") else 0
    motion_names = tuple(f"p{i}" for i in range(n_motion))
    rows = _gather_rows(rng, generator, n, nc)
    contacts = tuple(_contact(rng, f"C{c}", A, n_motion) for c, A in enumerate(rows))
    # constant load pressing every contact closed, plus a little of every DOF
    press = rng.uniform(1.0, 300.0, nc)
    f0 = np.array([A[1] for A in rows]).T @ press + rng.standard_normal(n) * rng.uniform(0, 20)
    system0 = System(Structure(M, None, K), contacts, Excitation(constant_force=f0), motion_names=motion_names)
    cs = system0.compile_dense("the trust check")
    Keff = cs.K.copy()
    for c in range(nc):
        Keff += cs.kn[c] * np.outer(cs.A[cs.normal_row[c]], cs.A[cs.normal_row[c]])
        Keff += cs.kt[c] * np.outer(cs.A[cs.tangential_row[c]], cs.A[cs.tangential_row[c]])
    omega = omega_max(M, Keff)
    C = None
    if rng.random() < 0.5:  # Rayleigh damping: zeta up to 5 % at the top frequency
        zeta = rng.uniform(0.0, 0.05)
        C = (zeta * omega) * M + (zeta / omega) * K if generator != "stick-1dof" else 2 * zeta * omega * M
    frequency = 1.0 / (t_min_of_omega(omega) * 10 ** rng.uniform(0.0, 2.0))
    if generator == "stick-1dof":
        mu, a = contacts[0].friction_coefficient, abs(rows[0][0, 0])
        amplitude = np.array([rng.uniform(0.2, 1.5) * mu * press[0] / a])
    else:
        amplitude = rng.standard_normal(n) * 10 ** rng.uniform(0.0, 2.5)
    force = Signal(tuple(f"x{i}" for i in range(n)), (Harmonic(frequency, amplitude, rng.uniform(0, 6.3, n)),))
    motion = None
    if n_motion:
        motion = Signal(
            motion_names, (Harmonic(frequency, 10 ** rng.uniform(-6.5, -4.5, n_motion), np.zeros(n_motion)),)
        )
    return System(
        Structure(M, C, K),
        contacts,
        Excitation(constant_force=f0, force=force, motion=motion),
        motion_names=motion_names,
        name=f"trust-{generator}",
    )


DECIDABLE_RTOL = 1e-8  # the two tight references agree to this fraction of the range


def newmark_check(system: System, method: str = "newmark", periods: float = 2.0, **options) -> dict | None:
    """Issue 29 item 3 on one system: ``method`` at its defaults (plus ``options``) against full
    Newton at tolerance 1e-13 and the piecewise-linear solve at state tolerance 1e-13 on the same
    grid. Returns {'decidable': the references are OK and agree to DECIDABLE_RTOL of the range,
    'status', 'error': max |x - x_ref| / range (NaN unless decidable and OK), 'flagged': the result
    carries a trust flag (``invariants.flagged``: steps above tolerance, tolerance_over_range,
    twin_difference), 'flagged_tolerance' (the flags but the sensitivity twin's), 'twin_difference'
    (NaN when the twin did not run: the ``sensitivity_check`` option), 'state_change_share' (steps
    that changed a contact state / steps), 'dofs', 'run_cpu_s' (CPU time of the run, twin included),
    'twin_cpu_s' (the twin's), 'steps'}; None when the system cannot be set up (no static
    equilibrium)."""
    import warnings

    from slipstep.errors import SolverError
    from slipstep.methods.invariants import flagged
    from slipstep.methods.simulation import run
    from slipstep.study.verification import agreement_error, tight_references

    options.setdefault("error_estimate", False)
    options.setdefault("step_rule", "t-min")  # the paper's grid for every method (the agreement is on one grid)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ref, pl = tight_references(system, periods)
            cpu = time.process_time()
            ds = run(system, method, periods=periods, **options)
            cpu = time.process_time() - cpu
        except (InputError, SolverError):
            return None
    decidable = ref.attrs["status"] == pl.attrs["status"] == "OK" and agreement_error(pl, ref) <= DECIDABLE_RTOL
    ok = ds.attrs["status"] == "OK"
    a = ds.attrs
    steps = int(a.get("steps", 0))
    return {
        "decidable": bool(decidable),
        "status": a["status"],
        "error": agreement_error(ds, ref) if ok and decidable else math.nan,
        "flagged": bool(flagged(a)),
        "flagged_tolerance": bool(flagged({k: v for k, v in a.items() if k != "twin_difference"})),
        "twin_difference": float(a.get("twin_difference", math.nan)),
        "state_change_share": int(a.get("state_changes", 0)) / max(steps, 1),
        "dofs": int(ds.sizes.get("dof", 0)),
        "run_cpu_s": cpu,
        "twin_cpu_s": float(a.get("twin_time_s", 0.0)),
        "steps": steps,
    }


def reference_sensitive(system: System, periods: float = 2.0, rtol: float = 1e-6) -> bool:
    """The system's tight reference is sensitive (``verification``'s two twins): full Newton at 1e-13
    moves by more than ``rtol`` of the range when the loads are scaled by 1 + 1e-10, or full Newton
    and the piecewise-linear solve at 1e-13 (two round-off paths to one discrete solution) differ by
    more than ROUNDOFF_SPREAD (1e-12) of it: per-step errors are amplified by more than about 1e4."""
    import warnings

    from slipstep.methods.simulation import run
    from slipstep.study.verification import PERTURBATION, ROUNDOFF_SPREAD, agreement_error, perturbed, tight_references

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref, pl = tight_references(system, periods)
        twin = run(
            perturbed(system, PERTURBATION),
            "full-newton",
            periods=periods,
            tolerance=1e-13,
            error_estimate=False,
            sensitivity_check=False,
        )
    return not (agreement_error(pl, ref) <= ROUNDOFF_SPREAD and agreement_error(twin, ref) <= rtol)
