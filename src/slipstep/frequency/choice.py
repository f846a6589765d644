"""The ``solver="auto"`` rule of :func:`slipstep.frequency.frf`: which steady-state solver (and,
when no method is given, which time-marching method) converges on a system, and why.

The rule:

1. **Shooting** (Newton on the one-period map, :func:`slipstep.steady.shoot`) for every system
   with a period. Marching to the steady state waits for every free vibration to die out: a
   stuck rigid damper rings undamped at its internal frequencies (8-12 kHz in the built-in
   ``blades``; 1,000 periods were not enough), while Newton finds the orbit in a few periods
   whatever the damping and reports its Floquet multipliers.
2. **The method**, when none is given: ``quasi-static-dofs`` (the contact-held DOFs without
   inertia, the rest dynamic) where the advisor (:func:`slipstep.study.advise.advise`, its
   quasi-static-DOFs analysis, paper Remark 3) says it applies: their internal frequencies are
   far above the excitation, so their inertia only adds the ringing (on ``ring`` the dynamic
   damper leaves an orbit unconverged at 300 Hz); else ``quasi-static`` for a system without
   mass, else ``piecewise-linear`` (Method 3).

3. **Harmonic balance** for a sparse structure above ``model.structure.DENSE_MAX_N`` DOFs:
   shooting's Jacobian is dense over 2n unknowns there, while the harmonic balance factorises
   the sparse dynamic stiffness once per harmonic and solves on the contact coordinates
   (:mod:`slipstep.hbm.linear`); its truncation estimate is the point's error.

Elsewhere harmonic balance is not chosen: its contact forces are only as good as the retained
harmonics (its truncation estimate says how good); ask for it with ``solver="hbm"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slipstep.model.structure import DENSE_MAX_N
from slipstep.model.system import System

DEFAULT_METHOD = "piecewise-linear"


@dataclass(frozen=True)
class SolverChoice:
    """The solver, the time-marching method and the reason in plain words."""

    solver: str
    method: object  # a method name or object (slipstep.methods.registry)
    reason: str


def choose_method(system: System) -> tuple[str, str]:
    """(method, why) of rule 2 in the module docstring."""
    cs = system.compile_dense("the solver choice")
    if not np.any(cs.M):
        return "quasi-static", "the system has no mass: the quasi-static method"
    from slipstep.study.advise import advise

    partial = advise(system, run_cases=False, max_states=0).massless
    if partial is not None and partial["applies"]:
        return "quasi-static-dofs", (
            f"method quasi-static-dofs: {', '.join(partial['dofs'][:4])}{' ...' if len(partial['dofs']) > 4 else ''} "
            f"without inertia, the rest dynamic (the advisor: {partial['why']}; give method='piecewise-linear' to "
            "keep their inertia)"
        )
    return DEFAULT_METHOD, f"method {DEFAULT_METHOD} (Method 3, every DOF dynamic)"


def choose(system: System, method: str | None = None) -> SolverChoice:
    """The auto rule (module docstring); ``method`` given: kept."""
    from slipstep.errors import InputError

    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    if system.structure.sparse and system.n_dofs > DENSE_MAX_N:
        return SolverChoice(
            "hbm",
            method,
            f"harmonic balance: the structure is sparse with {system.n_dofs} DOFs (above {DENSE_MAX_N}), where "
            "shooting's Jacobian would be dense over 2n unknowns; the balance factorises the sparse dynamic "
            "stiffness once per harmonic and reports its harmonic-truncation estimate",
        )
    if method is None:
        method, why = choose_method(system)
    else:
        why = f"method {method} (given)"
    reason = (
        "shooting (Newton on the one-period map) reaches the periodic orbit in a few periods where marching "
        "waits for the undamped ringing of stuck contacts to die out, and reports the Floquet multipliers; " + why
    )
    return SolverChoice("shoot", method, reason)


def choose_solver(system: System) -> tuple[str, str]:
    """(solver name, reason) of the auto rule (module docstring)."""
    c = choose(system)
    return c.solver, c.reason
