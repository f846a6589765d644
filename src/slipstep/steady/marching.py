"""Periodic steady state by time marching: march one excitation period at a time, each from
the state the previous one ended in, until the change of the full state (x, v and the
sliders w) over one period falls below ``tolerance`` relative to its amplitude
(:func:`slipstep.steady.state.period_change`), or ``max_periods`` have been marched.
"""

from __future__ import annotations

import math
import time

import numpy as np

from slipstep.methods import save as SV
from slipstep.errors import InputError, Status
from slipstep.kernels.codes import C_STEPS
from slipstep.kernels.codes import PIECEWISE_LINEAR
from slipstep.methods.registry import Method, get_method
from slipstep.methods.options import RunOptions
from slipstep.methods.simulation import Simulation
from slipstep.steady.state import (
    State,
    SteadyState,
    as_state,
    period_change,
    period_scales,
)
from slipstep.model.system import System


#: the steady states' fixed step T / N of the piecewise-linear Newmark methods (see period_simulation)
STEADY_STEPS_PER_PERIOD = 256

#: run options that set the step themselves (the steady step rule then leaves it to them)
STEP_OPTIONS = ("dt", "max_step", "step_ratio", "rtol")


def period_simulation(
    system: System, method, min_steps_per_period: int | None, run_options: dict, initial=None
) -> Simulation:
    """A Simulation that marches exactly one excitation period per call of ``march()``; when
    ``initial`` is a SteadyState carrying its marcher (the FRF point before), on that marcher
    with its plan retuned (:func:`reused_simulation`: no compile, eigenvalue problem, allocation
    or preload per point).

    The step: the piecewise-linear Newmark methods (Method 3, quasi-static-dofs) solve each step
    without iterating, so neither Newton's convergence nor the T_min rule of the paper bounds
    their step; the trapezoidal rule is unconditionally stable. Their steady states march with
    the fixed step dt = T / N, N = ``steps_per_period`` of the run options (default
    STEADY_STEPS_PER_PERIOD; at least ``min_steps_per_period``): accuracy alone sets it (phase
    error about (Omega dt)^2 / 12, amplified near a resonance by its quality factor; the FRF's
    error estimate says how large). A fixed step also keeps the discrete period map the same
    function of the start from one Newton iteration to the next. The other methods (Newton
    iterations, adaptive steps, quasi-static) keep the run options' step rule, with
    ``min_steps_per_period`` capping the step at T / N; so do the piecewise-linear methods when
    a step option (dt, max_step, step_ratio, rtol) is given."""
    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    T = system.period
    if T is None:
        raise InputError(
            "excitation",
            "has no period (tables only): a periodic steady state needs one",
            "give a harmonic force or motion, or period_s",
        )
    for key in ("periods", "duration"):
        if key in run_options:
            raise InputError(
                key, "is set by the steady-state solver (one period per march)", "use max_periods and tolerance instead"
            )
    opts = dict(run_options)
    # one-period continued marches (the default rule's step-doubling refinement pilots a run from
    # the preload: issue 8)
    opts.setdefault("error_estimate", False)
    if min_steps_per_period is not None:
        if (
            isinstance(min_steps_per_period, bool)
            or not isinstance(min_steps_per_period, (int, np.integer))
            or min_steps_per_period < 2
        ):
            raise InputError("min_steps_per_period", f"is {min_steps_per_period!r}", "give a whole number >= 2")
    spec = method if isinstance(method, Method) else get_method(method)
    fixed = spec.solver == PIECEWISE_LINEAR and not spec.adaptive and not spec.quasi_static
    if fixed and not any(opts.get(key) is not None for key in STEP_OPTIONS):
        n_steps = opts.pop("steps_per_period", STEADY_STEPS_PER_PERIOD)
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 2:
            raise InputError("steps_per_period", f"is {n_steps!r}", "give a whole number >= 2 (e.g. 256)")
        opts["dt"] = T / max(int(n_steps), min_steps_per_period or 0)
    elif min_steps_per_period is not None:
        opts["max_step"] = min(opts.get("max_step") or math.inf, T / min_steps_per_period)
    opts.setdefault("save", "all")  # the period change and the shooting replay read every DOF at every step
    sim = reused_simulation(initial, system, method, opts)
    if sim is None:
        sim = Simulation(system, method, periods=1.0, **opts)
    sim.marcher.keep_factorisations = True  # each period (Newton iterate) revisits the states of the one before
    SV.needs(
        sim.save_plan, "every_step", "the periodic steady state (march_to_steady, shooting)", "drop the save option"
    )
    return sim


def reused_simulation(initial, system: System, method, opts: dict) -> Simulation | None:
    """The one-period Simulation of ``system`` on the marcher of ``initial`` (a SteadyState of
    the same method): its plan retuned to the new frequency and options (RunPlan.retuned),
    the marcher retargeted (or a new one when the layout differs); None without such a marcher.
    The numbers are those of a new Simulation: the start is the given state, never the preload."""
    marcher = getattr(initial, "_marcher", None)
    if marcher is None or set(opts) - set(RunOptions.__dataclass_fields__):
        return None
    old = marcher.plan
    spec = method if isinstance(method, Method) else get_method(method)
    if spec.name != old.method.name:
        return None
    new = RunOptions(periods=1.0, **opts)
    changes = {
        k: getattr(new, k)
        for k in RunOptions.__dataclass_fields__
        if not _same(getattr(new, k), getattr(old.options, k))
    }
    plan = old.retuned(1.0 / system.period, system=system, **changes)
    try:
        marcher.retarget(plan)
    except ValueError:  # another array layout
        return Simulation.from_plan(plan)
    return Simulation.from_plan(plan, marcher)


def _same(a, b) -> bool:
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # arrays inside
        return a is b


def check_tolerance(tolerance: float, max_periods: int) -> None:
    if not (isinstance(tolerance, (int, float)) and 0 < tolerance < 1):
        raise InputError("tolerance", f"is {tolerance!r}", "give a relative tolerance between 0 and 1 (e.g. 1e-6)")
    if isinstance(max_periods, bool) or not isinstance(max_periods, (int, np.integer)) or max_periods < 1:
        raise InputError("max_periods", f"is {max_periods!r}", "give a whole number >= 1")


def start(sim: Simulation, state: State | None, t_start: float) -> None:
    """Set the state the next march starts from (None: the current start, the preload unless
    set otherwise) at time t_start."""
    state = sim.start if state is None else state
    sim.start_from(state.x, state.v, state.a, state.w, state.contact_state, t_start=t_start)


def march_one_period(sim: Simulation, check: bool = True):
    """March one period from the set start; (status, start state, end state, change e).
    ``check`` False: without the contact invariants (Simulation.march), for an iterate whose
    period is not kept."""
    quasi = sim.method.quasi_static
    s0 = sim.start
    status = sim.march(check=check)
    end = sim.segment.end_state
    if status != Status.OK:
        return status, s0, end, math.inf
    n_steps = int(sim.out.counters[C_STEPS])
    scales = period_scales(sim.out, n_steps, sim.compiled, sim.system.structure.dof_units, quasi)
    return status, s0, end, period_change(s0, end, scales, quasi)


def march_periods(sim: Simulation, first_index: int, tolerance: float, max_periods: int):
    """March periods first_index, first_index + 1, ... (each from the end of the previous,
    the first from the start already set) until the change is <= tolerance or max_periods
    have been marched. Returns (status, periods marched, changes, end state, kernel time)."""
    T = sim.period
    changes: list[float] = []
    kernel = 0.0
    end = None
    status = Status.OK
    for k in range(max_periods):
        status, _, end, e = march_one_period(sim)
        kernel += sim.kernel_time
        changes.append(e)
        if status != Status.OK:
            return status.name, k + 1, changes, end, kernel
        if e <= tolerance:
            return "OK", k + 1, changes, end, kernel
        if k + 1 < max_periods:
            start(sim, end, (first_index + k + 1) * T)
    return "NOT_STEADY", max_periods, changes, end, kernel


def march_to_steady(
    system: System,
    method="piecewise-linear",
    *,
    tolerance: float = 1e-6,
    max_periods: int = 200,
    initial=None,
    min_steps_per_period: int | None = None,
    **run_options,
) -> SteadyState:
    """Periodic steady state by marching (see the module docstring).

    method: a time-marching method (slipstep.methods.registry); run_options: those of
    slipstep.RunOptions except periods/duration; initial: a SteadyState or State to start
    from (default: the static preload at t = 0). Status "NOT_STEADY" when max_periods were
    marched without reaching the tolerance (the last period is returned all the same)."""
    wall = time.perf_counter()
    check_tolerance(tolerance, max_periods)
    sim = period_simulation(system, method, min_steps_per_period, run_options, initial)
    n, nd = sim.compiled.M.shape[0], sim.compiled.kt.shape[0]
    if initial is not None:
        start(sim, as_state(initial, n, nd), 0.0)
    status, periods, changes, end, kernel = march_periods(sim, 0, tolerance, max_periods)
    return finish(sim, status, periods, changes, end, kernel, wall, "march")


def finish(
    sim: Simulation, status: str, periods: int, changes, end: State, kernel: float, wall: float, solver: str, **extra
) -> SteadyState:
    """Wrap the last marched period (in sim.out) as a SteadyState."""
    ds = sim.dataset()
    e = changes[-1] if changes else math.inf
    if status == "OK":
        message = f"steady after {periods} period(s): change over the last period {e:.2e}"
    elif status == "NOT_STEADY":
        message = (
            f"not steady after {periods} period(s): change over the last period {e:.2e} above the "
            "tolerance; raise max_periods or the tolerance"
        )
    else:
        message = ds.attrs.get("status_message", status)
    ds.attrs.update(steady_status=status, steady_change=e, periods_to_steady=periods)
    return SteadyState(
        period=ds,
        periods=periods,
        status=status,
        message=message,
        final_state=end,
        change=e,
        solver=solver,
        method=sim.method.name,
        changes=list(changes),
        kernel_time_s=kernel,
        wall_time_s=time.perf_counter() - wall,
        _marcher=sim.marcher,
        **extra,
    )
