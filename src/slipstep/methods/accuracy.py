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

Default step rule (item 4 of issue 8; README "Methods"; the limits: methods/step_control.py):
    dt0 = min(r T_min(stick) / pi, T / 50, stability limit),  whole steps per period;
    then, while the step-doubling estimate at dt exceeds DEFAULT_TARGET = 0.5 % on the loop
    energy, dt = dt sqrt(DEFAULT_TARGET / estimate) (second order), whole steps per period,
    re-estimated (at most PILOT_ROUNDS = 3 rounds, methods/simulation.py).
A run whose final estimate exceeds WARN_LIMIT = 1 % warns and names the estimate.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from slipstep.errors import InputError, SolverError, Status
from slipstep.kernels.codes import C_FAIL_STEP, C_STEPS
from slipstep.methods.save import Save, contact_columns
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
    from slipstep.methods.simulation import saved_rows

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


def energy_diverged(out, n_steps: int, cs, fe: np.ndarray, motion: np.ndarray) -> int:
    """The first output point where the stored energy has grown beyond everything the loads
    supplied (no source), 0 if it never does:

        E(t) - E(0) > 2 max_{s <= t} max(W(s), 0) + 10 (E(0) + 1e-12 J)   for some t

    E = 1/2 v^T M v + 1/2 x^T K x + contact elastic energy (1/2 N^2/k_n + 1/2 T^2/k_t),
    W = int f_e . dx - int f . B dp (trapezoid rule). A dissipative march has
    E(t) - E(0) <= W(t); an unstable scheme grows exponentially past any such bound."""
    k = n_steps + 1
    x, v = out.x[:k], out.v[:k]
    f = out.f[:k]
    if cs.banded:  # banded backend (issue 10): the quadratic forms on the band, in the kernel's DOF order
        from slipstep.kernels.banded import band_quadratic_forms

        x, v = x[:, cs.dof_order], v[:, cs.dof_order]  # saved columns are in the user's order

        E = np.empty(k)
        ek = np.empty(k)
        band_quadratic_forms(cs.Mb, cs.kl, cs.ku, np.ascontiguousarray(v), E)
        band_quadratic_forms(cs.Kb, cs.kl, cs.ku, np.ascontiguousarray(x), ek)
        E = 0.5 * (E + ek)
    else:
        E = 0.5 * np.einsum("ti,ij,tj->t", v, cs.M, v) + 0.5 * np.einsum("ti,ij,tj->t", x, cs.K, x)
    nrow, trow = np.asarray(cs.normal_row), np.asarray(cs.tangential_row)
    if nrow.size:
        E = E + 0.5 * (f[:, nrow] ** 2 / cs.kn).sum(axis=1) + 0.5 * (f[:, trow] ** 2 / cs.kt).sum(axis=1)
    W = np.concatenate([[0.0], np.cumsum(0.5 * ((fe[1:] + fe[:-1]) * np.diff(x, axis=0)).sum(axis=1))])
    if cs.B.shape[1]:
        fb = f @ cs.B
        W = W - np.concatenate([[0.0], np.cumsum(0.5 * ((fb[1:] + fb[:-1]) * np.diff(motion[:k], axis=0)).sum(axis=1))])
    budget = 2.0 * np.maximum.accumulate(np.maximum(W, 0.0)) + 10.0 * (E[0] + 1e-12)
    over = ~(E - E[0] <= budget)  # NaN counts as over
    return int(np.argmax(over)) if np.any(over) else 0


def check_divergence(runner) -> Status:
    """Set runner.status to DIVERGED when an OK dynamic march's stored energy grew beyond what
    its loads supplied (:func:`energy_diverged`, from the first such point); returns the status."""
    from slipstep.methods.simulation import _force_signal, _motion_signal
    from slipstep.model.excitation import evaluate_compiled

    plan = getattr(runner, "save_plan", None)
    if plan is not None and not (plan.all_dofs and plan.all_contacts and plan.every_step):
        return runner.status  # needs every DOF and contact at every step (not made; NON_FINITE still is)
    if runner.status == Status.OK:
        cs, out = runner.compiled, runner.out
        n = int(out.counters[C_STEPS])
        t = out.t[: n + 1]
        fe = evaluate_compiled(_force_signal(cs), t) + cs.constant_force
        p = evaluate_compiled(_motion_signal(cs), t)
        first = energy_diverged(out, n, cs, fe, p)
        if first:
            runner.status = Status.DIVERGED
            out.counters[C_FAIL_STEP] = first
    return runner.status


def twin(sim, method: str, **changes):
    """A twin march of ``sim`` (same system, scheme and tolerances; the same method when it is
    the partly quasi-static one) with ``changes`` to its options; returns (status, loop energy
    [J], peak force [N]) or None when it cannot run."""
    from slipstep.methods.simulation import Simulation

    opt = sim.options
    base = {
        "scheme": opt.scheme,
        "duration": sim.t_end,
        "tolerance": opt.tolerance,
        "state_tolerance": opt.state_tolerance,
        "singular_tolerance": opt.singular_tolerance,
        "preload_increments": opt.preload_increments,
        "linear_solver": opt.linear_solver,
        "error_estimate": False,
        "max_state_iterations": opt.max_state_iterations,
        "step_ratio": opt.step_ratio,
        "save": Save(dofs="none"),  # the loop energy needs the contacts at every step only
    }
    base.update(changes)
    if sim.method.massless:
        method = sim.method.name
        base["massless_dofs"] = opt.massless_dofs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            other = Simulation(sim.system, method, **base)
        except (InputError, SolverError):
            return None
        status = other.march()
    if status != Status.OK:
        return None
    n = int(other.out.counters[C_STEPS])
    return (status,) + loop_energy(other.out, n, other.compiled, sim.period)


def pilot_step(sim, dt0: float) -> float:
    """The default rule's refinement (module docstring): the step-doubling estimate of the loop
    energy at dt (piecewise-linear twins at dt and 2 dt over PILOT_PERIODS periods); above
    DEFAULT_TARGET the step (and sim.max_step, the cap of adaptive steps) becomes
    dt sqrt(DEFAULT_TARGET / estimate), whole steps per period, re-estimated up to PILOT_ROUNDS times."""
    dt = dt0
    duration = PILOT_PERIODS * sim.period
    for _ in range(PILOT_ROUNDS):
        fine = twin(sim, "piecewise-linear", dt=dt, duration=duration)
        coarse = twin(sim, "piecewise-linear", dt=2 * dt, duration=duration)
        if fine is None or coarse is None:
            return dt
        est = richardson(fine[1], coarse[1])
        if not math.isfinite(est):  # no loop energy at dt (nothing slips): nothing to refine on
            return dt
        if not est > DEFAULT_TARGET:
            if abs(duration - sim.t_end) <= 1e-12 * duration:
                sim._coarse = (2 * dt, coarse)  # reused by the final estimate
            return dt
        sim.max_step = dt * math.sqrt(DEFAULT_TARGET / est)
        dt = sim._fixed_step(sim.dt_limit, sim.max_step)
    return dt


def estimate(sim) -> dict:
    """energy_error_estimate and peak_force_error_estimate (relative, NaN when not available)
    of a finished march by step doubling (module docstring), and error_estimate_method.
    Warns when the loop-energy estimate exceeds WARN_LIMIT (1 %)."""
    nan = {"energy_error_estimate": math.nan, "peak_force_error_estimate": math.nan, "error_estimate_method": "none"}
    if not sim.options.error_estimate or sim.status != Status.OK or sim.period is None:
        return nan
    plan = sim.save_plan
    if not (plan.all_contacts and plan.every == 1 and plan.times is None):
        return dict(nan, error_estimate_method="none (needs every contact at every step: the save option)")
    n = int(sim.out.counters[C_STEPS])
    energy, peak = loop_energy(sim.out, n, sim.compiled, sim.period)
    opt = sim.options
    if sim.method.quasi_static:
        other = twin(sim, "quasi-static", steps_per_period=max(opt.steps_per_period // 2, 1), dt=None)
        how = "step doubling: quasi-static twin at half the steps per period"
    elif sim.method.adaptive or opt.rtol is not None:
        other = twin(
            sim,
            "piecewise-linear-adaptive" if opt.rtol is None else "piecewise-linear",
            step_ratio=2 * opt.step_ratio,
            max_step=2 * sim.max_step,
            rtol=None if opt.rtol is None else min(8 * opt.rtol, 0.2),
        )
        how = (
            "step doubling: piecewise-linear twin with twice the step factor and cap"
            if opt.rtol is None
            else "step doubling: piecewise-linear twin at 8 rtol (twice the step)"
        )
    elif sim._coarse is not None and sim._coarse[0] == 2 * sim.dt:
        other, how = sim._coarse[1], "step doubling: piecewise-linear twin at 2 dt"
    else:
        other, how = twin(sim, "piecewise-linear", dt=2 * sim.dt), "step doubling: piecewise-linear twin at 2 dt"
    if other is None:
        return nan
    ratio = 8.0 ** (1 / 3) if opt.rtol is not None and not sim.method.quasi_static else 2.0
    out = {
        "energy_error_estimate": richardson(energy, other[1], ratio),
        "peak_force_error_estimate": richardson(peak, other[2], ratio),
        "error_estimate_method": how,
    }
    if out["energy_error_estimate"] > WARN_LIMIT:
        warnings.warn(
            f"the estimated time-discretisation error of the dissipated energy per cycle is "
            f"{100 * out['energy_error_estimate']:.2g} % (step doubling): use a smaller step (max_step / "
            f"--steps-per-period) or set rtol (--rtol 1e-3)",
            stacklevel=4,
        )
    return out
