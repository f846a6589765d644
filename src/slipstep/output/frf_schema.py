"""The layout of a frequency-response Dataset, in one place (like ``slipstep.output.results.SCHEMA``).

Every FRF solver (marching to the steady state, shooting, harmonic balance) returns an
``xarray.Dataset`` with these variables, so that curves from different solvers overlay in one
plot. Dimensions:

- ``frequency``: excitation frequencies of the points [Hz], in the order they were computed;
- ``harmonic``: harmonic numbers h = 0..H of the response (0: mean value);
- ``response``: the response DOFs reported (DOF names; coordinate ``response_unit``);
- ``contact``: contact elements (as in the time-domain result).

A sweep computed in both directions is two such Datasets concatenated along ``sweep``
(coordinate values "up", "down"). Values not computed by a solver are NaN (floats) or "" (text).

Response convention: x_j(t) = sum_h A_hj cos(h Omega t + phi_hj), Omega = 2 pi frequency,
t = 0 at the start of the steady-state period.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FrfSolver:
    """One FRF solver: its name (``solver=``), what runs it (``module:function``, loaded by
    pkgutil.resolve_name), whether that is a steady-state solver of one point, called
    ``f(system, initial=..., **options)`` per frequency (slipstep.frequency.response.sweep), and
    what it is in one line (the CLI's ``--solver`` help, the documentation)."""

    name: str
    runs: str
    description: str
    steady: bool = False


#: The one table of the FRF solvers (``solver=`` of slipstep.frequency.frf, ``slipstep frf --solver``,
#: a sweep's ``[outputs.frf] solver``; slipstep.frequency.response derives its STEADY_SOLVERS from it):
#: auto chooses one of the others, march and shoot solve each point's steady state, hbm is harmonic balance.
FRF_SOLVERS: dict[str, FrfSolver] = {
    s.name: s
    for s in (
        FrfSolver(
            "auto",
            "slipstep.frequency.choice:choose",
            "chosen for the system: shoot, or hbm where a time-domain steady state costs minutes; printed with "
            "its reason",
        ),
        FrfSolver("march", "slipstep.steady:march_to_steady", "march each point until its period repeats", True),
        FrfSolver(
            "shoot", "slipstep.steady:shoot", "Newton on the one-period map; reports the Floquet multipliers", True
        ),
        FrfSolver("hbm", "slipstep.hbm.frf:frf", "harmonic balance with continuation through turning points"),
    )
}


def solver_help() -> str:
    """'auto (...), march (...), shoot (...) or hbm (...)': every FRF solver with its description."""
    items = [f"{s.name} ({s.description})" for s in FRF_SOLVERS.values()]
    return ", ".join(items[:-1]) + " or " + items[-1]


FRF_SCHEMA: dict[str, tuple[tuple[str, ...], str, str]] = {
    # name: (dims, units, long_name)
    "amplitude": (
        ("frequency", "response"),
        "m or rad (see response_unit)",
        "half the peak-to-peak response over one steady-state period",
    ),
    "harmonic_amplitude": (
        ("frequency", "harmonic", "response"),
        "m or rad (see response_unit)",
        "amplitude A_h of harmonic h of the response (h = 0: mean)",
    ),
    "harmonic_phase": (
        ("frequency", "harmonic", "response"),
        "rad",
        "phase phi_h of harmonic h: x = sum_h A_h cos(h Omega t + phi_h)",
    ),
    "energy_per_cycle": (("frequency", "contact"), "J", "energy dissipated by friction per cycle in each contact"),
    "excitation_work": (("frequency",), "J", "work of the external forces and prescribed motions per cycle"),
    "viscous_dissipation": (("frequency",), "J", "energy dissipated by the damping matrix C per cycle"),
    "periods_to_steady": (("frequency",), "1", "excitation periods marched before the steady state was reached"),
    "energy_balance_residual": (
        ("frequency",),
        "1",
        "(excitation work - viscous - friction dissipation) / excitation work over the "
        "steady-state period (0 for an exactly periodic orbit)",
    ),
    "steady_change": (
        ("frequency",),
        "1",
        "change of the full state over the last period relative to its amplitude (slipstep.steady.state.period_change)",
    ),
    "point_time": (("frequency",), "s", "wall time spent on the point"),
    "floquet_multiplier_max": (
        ("frequency",),
        "1",
        "largest modulus of the Floquet multipliers (< 1: stable orbit; shooting only)",
    ),
    "linear_free_amplitude": (
        ("frequency", "response"),
        "m or rad (see response_unit)",
        "linear limit with the contacts removed (frequency-domain solution)",
    ),
    "linear_stuck_amplitude": (
        ("frequency", "response"),
        "m or rad (see response_unit)",
        "linear limit with every contact stuck (frequency-domain solution)",
    ),
    "check_amplitude_rel_diff": (
        ("frequency",),
        "1",
        "relative difference of the peak amplitude against the time-marching "
        "cross-check (harmonic balance only; NaN where not checked)",
    ),
    "check_energy_rel_diff": (
        ("frequency",),
        "1",
        "relative difference of the dissipated energy per cycle against the "
        "time-marching cross-check (harmonic balance only; NaN where not checked)",
    ),
    "harmonic_truncation_estimate": (
        ("frequency",),
        "1",
        "estimated relative change of the response amplitude or friction energy "
        "with more harmonics (harmonic balance only: slipstep.hbm.adequacy)",
    ),
    "status": (("frequency",), "1", "status of the point: OK or the name of the failure"),
    "point_kind": (
        ("frequency",),
        "1",
        "asked (a requested frequency), continuation (a point the continuation took between "
        "them) or turning (a continuation point where the branch turns back)",
    ),
    # ---- the error of each point (issue 24: slipstep.frequency.error_estimate) ----
    "error_estimate": (
        ("frequency",),
        "1",
        "estimated relative error of the energy per cycle of the point (march, shoot: step doubling "
        "on the converged orbit; harmonic balance: the harmonic truncation estimate)",
    ),
    "steps_per_period": (
        ("frequency",),
        "1",
        "time steps of the returned steady-state period (march, shoot) or AFT samples per period (harmonic balance)",
    ),
    "time_step": (
        ("frequency",),
        "s",
        "mean time step of the returned period, period / steps_per_period (march, shoot; NaN for harmonic balance)",
    ),
    "step_refinements": (
        ("frequency",),
        "1",
        "times the step was halved beyond the first step doubling because the estimate exceeded rtol (march, shoot)",
    ),
    "status_message": (
        ("frequency",),
        "1",
        "text: why the point is not OK, or that its error estimate exceeds rtol (empty when nothing to say)",
    ),
    "solve_start": (
        ("frequency",),
        "1",
        "text: where the point's steady-state solve started (march, shoot): 'previous orbit' (the previous "
        "point's orbit; the preload at the first point) or 'harmonic balance' (shooting restarted from the "
        "harmonic balance solution continued from the previous frequency, slipstep.frequency.hbm_seed, after the "
        "previous orbit failed)",
    ),
    # ---- end of the error block ----
}

TEXT_VARIABLES = frozenset({"status", "status_message", "point_kind", "solve_start"})
"""Variables of FRF_SCHEMA holding text (one string per point; "" when not set)."""
"""Attributes of an FRF Dataset: ``case``, ``solver`` ("march", "shoot", "hbm", "sine-sweep"),
``sweep`` ("up" or "down"), ``method`` (time-marching method, where one is used),
``harmonics`` (the retained harmonic numbers, HBM), ``steady_tolerance``, ``slipstep_version``,
``rtol`` (the accuracy asked of each point's error estimate), ``error_estimate_method`` (how
``error_estimate`` was obtained, per solver), ``solver_reason`` (why ``solver="auto"`` chose
the solver; "" when it was given)."""
