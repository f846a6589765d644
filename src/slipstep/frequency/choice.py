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

3. **Harmonic balance** where a time-domain steady state costs minutes
   (:func:`time_domain_cost`): a sparse structure above ``model.structure.DENSE_MAX_N`` DOFs,
   or a dense one whose one-period Jacobian, about N n (3 n + r) (2 n + n_d) multiply-adds
   (N = STEADY_STEPS_PER_PERIOD steps, r contact DOFs, n_d sliders: kernels/sensitivity.py),
   exceeds SHOOTING_MAX_FLOP (about 1 s per Newton iteration here; the unreduced blade pair of
   363 DOFs and 200 contact points needs 1e11). The harmonic balance factorises the dynamic
   stiffness once per harmonic and solves on the contact DOFs (:mod:`slipstep.hbm.linear`);
   its truncation estimate is the point's error.

Elsewhere harmonic balance is not chosen: its contact forces are only as good as the retained
harmonics (its truncation estimate says how good); ask for it with ``solver="hbm"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slipstep.model.system import System
from slipstep.steady.cost import SHOOTING_MAX_FLOP, time_domain_cost  # noqa: F401 (rule 3)

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
    _, costly = time_domain_cost(system)
    if costly:
        return SolverChoice(
            "hbm",
            method,
            f"harmonic balance: {costly}; the balance factorises the dynamic stiffness once per harmonic, "
            "solves on the contact DOFs and reports its harmonic-truncation estimate",
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
