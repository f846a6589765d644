"""The step rule's accuracy side: the step-doubling estimate of the time-discretisation
error, the default rule's refinement of the step, and the divergence test.

Error estimate (step doubling, Richardson). Newmark / HHT / generalised alpha are second
order, also across stick-slip transitions for the loop energy (measured: the loop-energy
error falls 3.6-4.4x per halved step on the oscillator of tests/test_trust_accuracy.py), so
for a quantity Q computed with step dt and with 2 dt

    err(Q_dt) ~ (Q_dt - Q_2dt) / (2^2 - 1)

The coarse march uses the piecewise-linear solve (the same discrete equations as every
implicit step solver, and no convergence limit, so 2 dt is allowed). Estimated: the
dissipated energy per cycle (friction, last period, all contacts) and the peak contact
force over the last period, both relative. Explicit schemes cannot double their step
(stability): their twin halves it, err ~ (Q_dt - Q_dt/2) * 4/3.

Default step rule (item 4 of issue 8; docs/guide/method_details.md; the limits: methods/step_control.py):
    dt0 = min(r T_min(stick) / pi, T / 50, stability limit),  whole steps per period;
    then, while the step-doubling estimate at dt exceeds DEFAULT_TARGET = 0.5 % on the loop
    energy, dt = dt sqrt(DEFAULT_TARGET / estimate) (second order), whole steps per period,
    re-estimated (at most PILOT_ROUNDS = 3 rounds): :func:`pilot_plan`, a refined RunPlan.
A run whose final estimate exceeds WARN_LIMIT = 1 % warns and names the estimate.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from slipstep.errors import InputError, SolverError, Status
from slipstep.kernels.codes import C_STEPS
from slipstep.methods.buffers import saved_rows
from slipstep.methods.divergence import check_divergence, energy_diverged  # noqa: F401  (re-exported)
from slipstep.methods.marcher import Marcher
from slipstep.methods.plan import RunPlan, plan_run
from slipstep.methods.save import Save, contact_columns
from slipstep.methods.start import static_equilibrium
from slipstep.methods.step_control import highest_frequency  # noqa: F401  (re-exported)

DEFAULT_TARGET = 0.005
WARN_LIMIT = 0.01
#: refinements of the default step rule at most (each: two piecewise-linear twin marches of
#: PILOT_PERIODS periods, whatever the run's length: the step does not depend on it)
PILOT_ROUNDS = 3
PILOT_PERIODS = 3


def loop_energy(out, n_steps: int, cs, period: float | None) -> tuple[float, float]:
    """(friction energy dissipated over the last period [J], peak |contact force| over it [N])
    from kernel outputs: D = sum_d int T_d dw_d (trapezoid rule, interpolated at the start
    of the period, as slipstep.post.energy.friction_energy_per_period). ``out`` must hold
    every contact at every step of the last period (``saved_rows`` rows: slipstep.methods.save)."""
    k = saved_rows(out, n_steps)
    t = out.t[:k]
    if period is None or t[-1] - t[0] < period * (1 - 1e-9):
        period = t[-1] - t[0]
    T = out.f[:k][:, contact_columns(out, cs)[0]]
    w = out.w[:k]
    inc = (0.5 * (T[1:] + T[:-1]) * np.diff(w, axis=0)).sum(axis=1)
    cum = np.concatenate([[0.0], np.cumsum(inc)])
    start = t[-1] - period
    energy = cum[-1] - np.interp(start, t, cum)
    last = t >= start - 1e-12 * period
    peak = float(np.abs(out.f[:k][last]).max(initial=0.0))
    return float(energy), peak


def richardson(fine: float, coarse: float, ratio: float = 2.0, order: int = 2) -> float:
    """Relative error estimate of ``fine`` from a twin whose step is ``ratio`` times larger
    (ratio < 1: a finer twin): |fine - coarse| / |ratio^order - 1| / |fine|."""
    scale = abs(fine)
    if scale == 0.0:
        return 0.0 if coarse == 0.0 else math.inf
    if ratio > 1:
        return abs(fine - coarse) / (ratio**order - 1.0) / scale
    # finer twin: the twin is the better value, err(fine) ~ |fine - twin| r^-p / (r^-p - 1)
    q = ratio**-order
    return abs(fine - coarse) * q / (q - 1.0) / scale


def twin(plan: RunPlan, method: str, **changes):
    """A twin march of ``plan`` (same system, scheme and tolerances; the same method when it is
    the partly quasi-static one) with ``changes`` to its options, from its own static
    equilibrium; returns (status, loop energy [J], peak force [N]) or None when it cannot run."""
    opt = plan.options
    base = {
        "scheme": opt.scheme,
        "duration": plan.t_end,
        "tolerance": opt.tolerance,
        "state_tolerance": opt.state_tolerance,
        "singular_tolerance": opt.singular_tolerance,
        "preload_increments": opt.preload_increments,
        "linear_solver": opt.linear_solver,
        "error_estimate": False,
        "max_state_iterations": opt.max_state_iterations,
        "step_ratio": opt.step_ratio,
        "step_rule": plan.step_rule,
        "save": Save(dofs="none"),  # the loop energy needs the contacts at every step only
    }
    base.update(changes)
    if plan.method.massless:
        method = plan.method.name
        base["massless_dofs"] = opt.massless_dofs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            other = plan_run(plan.system, method, **base)
            marcher = Marcher(other)
            start = static_equilibrium(other, marcher.ws)
        except (InputError, SolverError):
            return None
        segment = marcher.advance(start)
    if segment.status != Status.OK:
        return None
    return (segment.status,) + loop_energy(marcher.out, segment.trace.n_steps, other.compiled, plan.period)


def pilot_step(plan: RunPlan, dt0: float) -> tuple[float, float, tuple | None]:
    """The default rule's refinement (module docstring): the step-doubling estimate of the loop
    energy at dt (piecewise-linear twins at dt and 2 dt over PILOT_PERIODS periods); above
    DEFAULT_TARGET the step (and max_step, the cap of adaptive steps) becomes
    dt sqrt(DEFAULT_TARGET / estimate), whole steps per period, re-estimated up to PILOT_ROUNDS
    times. Returns (dt, max_step, coarse): coarse = (2 dt, the twin's result) when the pilot
    ran over the whole run (reused by :func:`estimate`), else None."""
    dt, max_step = dt0, plan.max_step
    duration = PILOT_PERIODS * plan.period
    for _ in range(PILOT_ROUNDS):
        fine = twin(plan, "piecewise-linear", dt=dt, duration=duration)
        coarse = twin(plan, "piecewise-linear", dt=2 * dt, duration=duration)
        if fine is None or coarse is None:
            return dt, max_step, None
        est = richardson(fine[1], coarse[1])
        if not math.isfinite(est):  # no loop energy at dt (nothing slips): nothing to refine on
            return dt, max_step, None
        if not est > DEFAULT_TARGET:
            whole = abs(duration - plan.t_end) <= 1e-12 * duration
            return dt, max_step, ((2 * dt, coarse) if whole else None)
        max_step = dt * math.sqrt(DEFAULT_TARGET / est)
        dt = plan.fixed_step(max_step)
    return dt, max_step, None


def pilot_plan(plan: RunPlan) -> RunPlan:
    """``plan`` with the step of the default rule's refinement (:func:`pilot_step`)."""
    dt, max_step, coarse = pilot_step(plan, plan.dt)
    return plan.with_step(dt, max_step, coarse)


def no_estimate(why: str = "none") -> dict:
    """The estimate attrs when there is none (``why``: error_estimate_method)."""
    return {"energy_error_estimate": math.nan, "peak_force_error_estimate": math.nan, "error_estimate_method": why}


def estimate(plan: RunPlan, status: Status, out) -> dict:
    """energy_error_estimate and peak_force_error_estimate (relative, NaN when not available)
    of a finished march of ``plan`` from its static equilibrium (``out``: its outputs) by step
    doubling (module docstring), and error_estimate_method. Warns when the loop-energy
    estimate exceeds WARN_LIMIT (1 %)."""
    nan = no_estimate()
    if not plan.options.error_estimate or status != Status.OK or plan.period is None:
        return nan
    save = plan.save_plan
    if not (save.all_contacts and save.every == 1 and save.times is None):
        return no_estimate("none (needs every contact at every step: the save option)")
    n = int(out.counters[C_STEPS])
    energy, peak = loop_energy(out, n, plan.compiled, plan.period)
    opt = plan.options
    if plan.method.quasi_static:
        other = twin(plan, "quasi-static", steps_per_period=max(opt.steps_per_period // 2, 1), dt=None)
        how = "step doubling: quasi-static twin at half the steps per period"
    elif plan.method.adaptive or opt.rtol is not None:
        other = twin(
            plan,
            "piecewise-linear-adaptive" if opt.rtol is None else "piecewise-linear",
            step_ratio=2 * opt.step_ratio,
            max_step=2 * plan.max_step,
            rtol=None if opt.rtol is None else min(8 * opt.rtol, 0.2),
        )
        how = (
            "step doubling: piecewise-linear twin with twice the step factor and cap"
            if opt.rtol is None
            else "step doubling: piecewise-linear twin at 8 rtol (twice the step)"
        )
    elif plan.coarse is not None and plan.coarse[0] == 2 * plan.dt:
        other, how = plan.coarse[1], "step doubling: piecewise-linear twin at 2 dt"
    else:
        other, how = twin(plan, "piecewise-linear", dt=2 * plan.dt), "step doubling: piecewise-linear twin at 2 dt"
    if other is None:
        return nan
    ratio = 8.0 ** (1 / 3) if opt.rtol is not None and not plan.method.quasi_static else 2.0
    result = {
        "energy_error_estimate": richardson(energy, other[1], ratio),
        "peak_force_error_estimate": richardson(peak, other[2], ratio),
        "error_estimate_method": how,
    }
    if result["energy_error_estimate"] > WARN_LIMIT:
        warnings.warn(
            f"the estimated time-discretisation error of the dissipated energy per cycle is "
            f"{100 * result['energy_error_estimate']:.2g} % (step doubling): use a smaller step (max_step / "
            f"--steps-per-period) or set rtol (--rtol 1e-3)",
            stacklevel=4,
        )
    return result
