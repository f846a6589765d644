"""The Python face of a time march: validate options, compile, allocate, preload, call the
kernel, wrap the arrays in a Dataset. No numerics here beyond set-up (T_min, dt).

    sim = Simulation(system, "piecewise-linear", periods=3)
    ds = sim.run()            # preload + march + Dataset
    sim.march()               # re-march from the stored preload (for timing)
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numba
import numpy as np

from slipstep.errors import InputError, Interrupted, SolverError, Status
from slipstep.live import call_kernel
from slipstep.methods import memory
from slipstep.kernels import banded as BD
from slipstep.kernels import march as K
from slipstep.kernels import explicit as E
from slipstep.kernels.arguments import KernelArguments, pack_arguments
from slipstep.kernels.events import event_arguments, event_march, event_march_packed
from slipstep.kernels.quasi_static import quasi_static_march, quasi_static_march_packed
from slipstep.kernels.state_solve import LowRank
from slipstep.methods import accuracy
from slipstep.methods import save as SV
from slipstep.methods.accuracy import check_divergence  # noqa: F401  (re-exported for the explicit runner)
from slipstep.invariants import check_march
from slipstep.kernels.contact import STICK, contact_law, generalised_force, local_displacement
from slipstep.methods import massless as ML
from slipstep.methods import step_control as SC
from slipstep.methods.eigen import band_mass_lu, mass_factor
from slipstep.methods.step_control import default_max_step, state_t_min  # noqa: F401  (re-exported)
from slipstep.methods.registry import Method, get_method
from slipstep.methods.schemes import Scheme, newmark
from slipstep.model.excitation import CompiledSignal, evaluate_compiled
from slipstep.model.validate import positive
from slipstep.results import STATE_NAMES, build_dataset
from slipstep.system import CompiledSystem, System

#: the values of RunOptions.linear_solver
LINEAR_SOLVERS = ("auto", "direct", "low-rank", "banded")

#: rtol -> local error bound rtol * RTOL_LOCAL_FACTOR * L (calibrated: loop energy within rtol on the paper case)
RTOL_LOCAL_FACTOR = 0.1

SOLVER_NAMES = {
    K.MODIFIED_NEWTON: "modified-newton",
    K.FULL_NEWTON: "full-newton",
    K.PIECEWISE_LINEAR: "piecewise-linear",
    K.MODIFIED_NEWTON_STATE: "modified-newton-state",
    K.EVENTS: "events",
}


@dataclass(frozen=True)
class RunOptions:
    """Options of a run; every field is validated in :meth:`validated`.

    periods / duration: simulated time after the preload (duration [s] wins if given).
    step_ratio: r in dt = r * T_min / (2 pi sqrt(beta)) (dynamic methods).
    steps_per_period: quasi-static step count per excitation period.
    tolerance: Newton stop (modified and full Newton), both tests at once (kernels/march.py):
        increment: theta/(1-theta) eta <= 1, eta = max(max |A delta| / (tol L), max_j |delta_j| /
        (tol L_j)), L_j = L / max_r |A_rj|, theta the larger of the last two contraction ratios; and
        residual: max |r| <= tol * (the step's largest force term). Default 1e-11: with 1e-8 and
        the increment test alone, Method 1 left 28 % of random small systems more than 1e-6 of
        their range from the converged solution (benchmarks/random_systems.py).
    state_tolerance: relative tolerance of the compatibility check (physics.md 3).
    max_step: accuracy cap of dynamic steps, fixed and adaptive [s] (default: period / 50).
    dt: an exact fixed step [s] for the fixed-step methods (overrides step_ratio/steps_per_period).
    linear_solver: 'direct' (an n x n LU per contact state), 'low-rank' (one LU of J(stick) and
        an nq x nq capacitance matrix per state: kernels/state_solve.py), 'banded' (the DOFs
        reordered by reverse Cuthill-McKee, a banded LU per contact state: slipstep.system,
        kernels/banded.py) or 'auto' (banded for a sparse structure of at least
        slipstep.system.BANDED_MIN_N DOFs with a narrow band, else low-rank when the contact
        coordinates are at most half the DOFs, else direct).
    rtol: accuracy the user sets (dynamic methods): the step follows the local error estimate
        of each step (kernels/march.py, "accuracy control") so that the loop energy per cycle is
        within about rtol; it never exceeds the contact-state / convergence rule of Newton
        methods, nor the stability limit; the piecewise-linear solve obeys only the latter.
    error_estimate: compute the step-doubling error estimate (attrs energy_error_estimate,
        peak_force_error_estimate; one coarse piecewise-linear twin march) and let the default
        step rule refine the step when the estimate exceeds 0.5 % (methods/accuracy.py).
    max_memory: the memory a run may take [bytes] (estimate checked before any allocation,
        slipstep.methods.memory); default: half of the available memory.
    massless_dofs: the DOFs the quasi-static-dofs method treats without inertia: DOF names or
        shell patterns ('damper*'), or 'auto' (the DOFs held by contacts only: methods/massless.py).
    save: what the march stores (methods/save.py): 'auto' (everything for at most
        save.FULL_SAVE_MAX_DOFS DOFs, else the contacts and the response DOFs, every step), 'all',
        a slipstep.Save or a dict of its keys (dofs, contacts, every, last_periods, times, response).
    """

    periods: float = 3.0
    duration: float | None = None
    step_ratio: float = 1.0
    steps_per_period: int = 300
    scheme: Scheme = field(default_factory=newmark)
    tolerance: float = 1e-11
    state_tolerance: float = 1e-9
    singular_tolerance: float = 1e-12
    max_iterations: int = 500
    max_state_iterations: int = 20
    max_redo: int = 4
    max_step: float | None = None
    preload_increments: int = 45
    fallback: bool = True
    dt: float | None = None
    linear_solver: str = "auto"
    rtol: float | None = None
    error_estimate: bool = True
    max_memory: float | None = None
    massless_dofs: object = "auto"
    save: object = "auto"

    def validated(self) -> "RunOptions":
        positive("periods", self.periods)
        if self.duration is not None:
            positive("duration", self.duration)
        r = positive("step_ratio", self.step_ratio)
        if r > 50:
            raise InputError(
                "step_ratio",
                f"is {r}: the step would be {r} times the stability/convergence limit",
                "use a ratio of about 1 (below 1 for more accuracy)",
            )
        for name in ("steps_per_period", "max_iterations", "max_state_iterations", "preload_increments"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InputError(name, f"is {value!r}", "give a whole number >= 1")
            if value > 10**9:  # an int64 in the kernel settings (issue 29: OverflowError before)
                raise InputError(name, f"is {value!r}, beyond any useful count", "give a whole number of at most 1e9")
        for name in ("tolerance", "state_tolerance", "singular_tolerance"):
            value = positive(name, getattr(self, name))
            if value >= 1:
                raise InputError(name, f"is {value}", "give a small relative tolerance (e.g. 1e-6)")
        if self.max_step is not None:
            positive("max_step", self.max_step)
        if self.dt is not None:
            positive("dt", self.dt)
        if self.rtol is not None:
            value = positive("rtol", self.rtol)
            if not 1e-8 <= value <= 0.2:
                raise InputError("rtol", f"is {value}", "give a relative accuracy between 1e-8 and 0.2 (e.g. 1e-3)")
        if self.max_memory is not None:
            memory.parse_size("max_memory", self.max_memory)
        if self.linear_solver not in LINEAR_SOLVERS:
            raise InputError(
                "linear_solver", f"is {self.linear_solver!r}", "use 'auto', 'direct', 'low-rank' or 'banded'"
            )
        SV.as_save(self.save)
        if not isinstance(self.scheme, Scheme):
            raise InputError("scheme", f"is {self.scheme!r}", "use slipstep.newmark(), hht() or generalized_alpha()")
        return self


class Runner:
    """What every march runner shares: run(), the Dataset and the failure report.

    Subclasses set system, compiled, options, out (kernels.march.Outputs), status,
    kernel_time, dt, t_min_stick, t_end, period, and implement march(), method_attrs()
    (method, paper_method, solver, adaptive_step, quasi_static, scheme, ...) and
    _visited_states() (the contact states tried at a failure, as text)."""

    failure_hint = ""
    _kernel = None
    _packed = None  # (sys, ws, out, q0, f0, their KernelArguments): :meth:`_packed_arguments`
    progress = False  # draw a progress bar on stderr for runs longer than a second (the CLI sets it)
    keep_interrupted = False  # Ctrl-C: return the partial result (True) or raise Interrupted carrying it

    def accuracy_attrs(self) -> dict:
        """The time-discretisation error estimate attrs (see Simulation.accuracy_attrs)."""
        return {}

    def kernel_arguments(self) -> tuple:
        """The march kernel's arguments (sys, settings, ws, out, q0, f0)."""
        return (self.compiled, self.settings, self.ws, self.out, self.q0, self.f0)

    def _packed_arguments(self, args: tuple) -> tuple:
        """(KernelArguments, settings) of the kernel arguments (sys, settings, ws, out, q0, f0):
        the arrays unboxed once, when first seen (kernels/arguments.py), and again only when the
        runner replaces one of them."""
        sys, settings, ws, out, q0, f0 = args
        held = (sys, ws, out, q0, f0)
        if self._packed is None or any(a is not b for a, b in zip(self._packed, held)):
            self._packed = (*held, pack_arguments(*held))
        return self._packed[-1], settings

    def _run_kernel(self, dispatcher) -> Status:
        """Time one call of the march kernel on this runner's arrays; after the first call the
        compiled overload is called directly (no type dispatch). Sets status and kernel_time."""
        self.out.counters[:] = 0
        reset_outputs(self.out)
        args = self.kernel_arguments()
        twin = PACKED_TWINS.get(dispatcher)
        if twin is not None:
            dispatcher, args = twin, self._packed_arguments(args)
        layout = args[0]._type if twin is not None else None  # a new KernelArguments may hold other layouts
        known = self._kernel is not None and self._kernel[0] is dispatcher and self._kernel[2] == layout
        kernel = self._kernel[1] if known else dispatcher  # _kernel: (dispatcher, compiled entry, layout)
        # a long run marches in a worker thread: Ctrl-C stops it (INTERRUPTED), progress is shown
        plan = getattr(self, "save_plan", None)
        times = self.out.t  # the progress bar reads the time of step k from row k
        if plan is not None and not plan.every_step and self.progress:  # rows are not steps: t ~ k dt
            cap = int(self.out.plan[K.S_CAPACITY])
            times = self.settings.t_start + np.minimum(np.arange(cap + 1) * self.dt, self.t_end)
        status, self.kernel_time = call_kernel(
            kernel, args, self.out.counters, times, self.t_end, int(self.out.plan[K.S_CAPACITY]) + 1, self.progress
        )
        if not known:
            self._kernel = (dispatcher, compiled_entry(dispatcher, args), layout)
        self.status = Status(status)
        if self.status == Status.INTERRUPTED and not self.keep_interrupted:
            partial = self.dataset()
            raise Interrupted(partial.attrs["status_message"], partial)
        return self.status

    def run(self, raise_on_failure: bool = False):
        """Preloaded march + Dataset. On failure the Dataset holds every step done before it."""
        start = time.perf_counter()
        self.march()
        ds = self.dataset()
        ds.attrs["wall_time_s"] = time.perf_counter() - start
        if raise_on_failure and self.status != Status.OK:
            raise SolverError(ds.attrs["status_message"], ds)
        return ds

    def failure_report(self) -> dict:
        if self.status in (None, Status.OK):
            return {}
        step = int(self.out.counters[K.C_FAIL_STEP])
        t_fail = float(self.out.times[K.S_FAIL])
        if not math.isfinite(t_fail):  # interrupted: the time of the last step done
            t_fail = float(self.out.t[max(saved_rows(self.out, int(self.out.counters[K.C_STEPS])) - 1, 0)])
        report = {"failed_at_step": step, "failed_at_time_s": t_fail}
        visited = self._visited_states() if self.status != Status.INTERRUPTED else ""
        if visited:
            report["states_visited"] = visited
        if getattr(self, "broken_invariant", None) is not None:  # Status.INVARIANT (slipstep.invariants)
            report["broken_invariant"] = self.broken_invariant.text()
        return report

    def dataset(self):
        if self.status is None:
            raise RuntimeError("call march() first")
        c = self.out.counters
        n_steps = int(c[K.C_STEPS])
        plan = getattr(self, "save_plan", None)
        rows = saved_rows(self.out, n_steps)
        grid = None if plan is None or plan.times is None else plan.times
        if grid is not None:  # the given times the march reached
            grid = grid[grid <= self.out.t[rows - 1] * (1 + 1e-15) + 1e-300]
        t = self.out.t[:rows] if grid is None else grid
        motion = evaluate_compiled(_motion_signal(self.compiled), t)
        failure = self.failure_report()
        message = self.status.message
        if self.status == Status.CAPACITY:  # which buffer: the steps, or the saved rows (methods/save.py)
            rows_full = n_steps < int(self.out.plan[K.S_CAPACITY])
            message += " (out of output rows of the save plan)" if rows_full else " (out of step capacity)"
        if failure:
            message = (
                f"{self.status.name}: {message}; stopped at step {failure['failed_at_step']}, "
                f"t = {failure['failed_at_time_s']:.6g} s"
            )
            if "states_visited" in failure:
                message += f", states tried {failure['states_visited']}"
            if "broken_invariant" in failure:
                message += f"; {failure['broken_invariant']}"
            message += self.failure_hint if self.status == Status.NON_FINITE else ""
        solves = int(self.out.solves[1:rows].sum()) if rows == n_steps + 1 else int(c[K.C_SOLVES])
        method = self.method_attrs()
        attrs = {"title": f"slipstep result: {self.system.name}, {method['method']}", "case": self.system.name}
        attrs.update(method)
        attrs.update(
            {
                "status": self.status.name,
                "status_message": message,
                "steps": n_steps,
                "solves": solves,
                "iterations": solves,
                "mean_solves_per_step": solves / max(n_steps, 1),
                "factorisations": int(c[K.C_FACTORISATIONS]),
                "law_calls": int(c[K.C_LAW_CALLS]),
                "redone_steps": int(c[K.C_REDOS]),
                "state_changes": int(c[K.C_STATE_CHANGES]),
                "dt_s": self.dt,
                "t_min_s": self.t_min_stick,
                "t_end_s": self.t_end,
                "period_s": self.period,
                "step_ratio": self.options.step_ratio,
                "max_step_s": self.max_step,
                "kernel_time_s": self.kernel_time,
                "length_scale_m": self.compiled.length_scale,
            }
        )
        attrs.update(failure)
        attrs.update(getattr(self, "step_audit", {}))  # slipstep.invariants.audit_steps (issue 29)
        attrs.update(self.accuracy_attrs())
        if plan is not None:
            attrs.update(plan.attrs())
        return build_dataset(
            self.system,
            self.out,
            rows - 1,
            motion,
            attrs,
            dynamic=not method["quasi_static"],
            compiled=self.compiled,
            plan=plan,
            grid=grid,
            gamma=None if method["quasi_static"] else self.options.scheme.gamma,
        )


class Simulation(Runner):
    """One system marched by one method with one set of options."""

    _event_arguments = None  # (compiled, ws, the event kernel's slim tuples of them), kernel_arguments

    def __init__(self, system: System, method: str | Method = "newmark", **options):
        if not isinstance(system, System):
            raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
        unknown = set(options) - set(RunOptions.__dataclass_fields__)
        if unknown:
            raise InputError(
                "options", f"unknown option(s) {sorted(unknown)}", f"use only {sorted(RunOptions.__dataclass_fields__)}"
            )
        self.system = system
        self.method = method if isinstance(method, Method) else get_method(method)
        self.options = RunOptions(**options).validated()
        self.compiled = cs = system.compile(compile_backend(self.options.linear_solver))
        if cs.banded:
            check_banded_method(self.method)
        if self.method.solver == K.EVENTS:
            check_event_case(system, cs)
        nd = cs.kt.shape[0]
        self.stick = np.full(nd, STICK, np.int8)
        self.massless = ML.select_massless(system, self.options.massless_dofs) if self.method.massless else None
        if self.massless is not None:  # those DOFs without inertia; T_min of the dynamic part
            self.compiled = cs = ML.inertia_free(cs, self.massless)
        else:
            if self.options.massless_dofs != "auto":
                raise InputError(
                    "massless_dofs",
                    f"is only used by the quasi-static-dofs method, not {self.method.name}",
                    "use method quasi-static-dofs or drop the option",
                )
        self.t_min_stick = state_t_min(cs, self.stick)  # massless DOFs (zero rows of M) condensed
        period = system.period
        opt = self.options
        if opt.duration is not None:
            t_end = opt.duration
        elif period is not None:
            t_end = opt.periods * period
        else:
            raise InputError(
                "duration",
                "is not set and the excitation has no period (tables only)",
                "give duration (seconds) or a harmonic excitation",
            )
        self.period, self.t_end = period, t_end
        self.save_plan = SV.resolve(self.options.save, system, cs, 0.0, t_end, period)
        scheme = opt.scheme
        self._accuracy = None
        self._coarse = None
        self.dt_limit, self.dt_stability = self._step_limits(scheme)
        self.max_step = opt.max_step if opt.max_step is not None else default_max_step(period, self.dt_limit)
        _check_time_scales(t_end, self.dt_limit, self.max_step, opt)
        dt = self._fixed_step(self.dt_limit, self.max_step)
        if opt.dt is not None and opt.dt > self.dt_stability * (1 + 1e-12):
            raise InputError(
                "dt",
                f"is {opt.dt:.4g} s, beyond the stability limit {self.dt_stability:.4g} s of the "
                f"scheme {scheme.name} (Omega_crit = {scheme.omega_crit:.4g})",
                "give a smaller dt or use an unconditionally stable scheme (2 beta >= gamma)",
            )
        if self._pilot_allowed():
            dt = self._pilot_step(dt)
        if dt > t_end * (1 + 1e-12):
            field_name = "duration" if opt.duration is not None else "periods"
            raise InputError(
                field_name,
                f"gives {t_end:.3g} s, shorter than one time step ({dt:.3g} s)",
                "simulate longer or use a smaller step",
            )
        self.dt = dt
        dt_max = self.max_step
        capacity = SC.capacity(
            t_end,
            dt,
            self.dt_limit,
            dt_max,
            self.method.adaptive,
            None if self.method.quasi_static else opt.rtol,
            self.t_min_stick,
        )
        # the event-driven kernel factorises J(S) (n x n) itself: its cache must be n x n (issue 29: a low-rank
        # cache of nq x nq was written out of bounds)
        self.low_rank = use_low_rank(cs, opt.linear_solver) and self.method.solver != K.EVENTS
        self.memory_estimate = check_memory(
            cs, capacity, opt, self.method.quasi_static, self.low_rank, self.save_plan, t_end
        )
        accuracy_on = opt.rtol is not None and not self.method.quasi_static
        self.settings = K.march_settings(
            beta=scheme.beta,
            gamma=scheme.gamma,
            alpha_m=scheme.alpha_m,
            alpha_f=scheme.alpha_f,
            dt=dt,
            step_factor=SC.kernel_step_factor(scheme, opt.step_ratio),
            dt_max=min(dt_max, self.dt_stability),
            tol=opt.tolerance,
            state_rtol=opt.state_tolerance,
            singular_rtol=opt.singular_tolerance,
            t_start=0.0,
            t_end=t_end,
            rtol=opt.rtol if accuracy_on else 0.0,
            err_scale=RTOL_LOCAL_FACTOR * cs.length_scale if accuracy_on else 0.0,
            solver=self.method.solver,
            adaptive=self.method.adaptive,
            inertia=not self.method.quasi_static,
            max_iter=opt.max_iterations,
            max_state_iter=opt.max_state_iterations,
            max_redo=opt.max_redo,
            fallback=opt.fallback,
            signals=True,
            preload=0,
            structure=K.BANDED if cs.banded else (K.LOW_RANK if self.low_rank else K.DENSE),
        )
        self.ws = _allocate_workspace(cs, opt.max_state_iterations, self.low_rank)
        self.out = _allocate_outputs(cs, capacity, self.options.max_memory, self.save_plan, t_end)
        self.status = None
        self.kernel_time = math.nan
        self._preload()

    # -- the step rule (README "Methods"; methods/step_control.py, methods/accuracy.py) ------
    def _step_limits(self, scheme) -> tuple[float, float]:
        """(dt_limit, dt_stability): :func:`slipstep.methods.step_control.step_limits`."""
        opt = self.options
        iterates = not (opt.rtol is not None and self.method.solver == K.PIECEWISE_LINEAR)
        return SC.step_limits(
            self.compiled,
            scheme,
            self.t_min_stick,
            opt.step_ratio,
            self.method.quasi_static,
            iterates,
            opt.dt is not None,
        )

    def _fixed_step(self, limit: float, max_step: float) -> float:
        """The fixed step: :func:`slipstep.methods.step_control.fixed_step`."""
        opt = self.options
        spp = opt.steps_per_period if self.method.quasi_static else None
        return SC.fixed_step(limit, max_step, self.period, self.t_end, opt.dt, spp)

    def _pilot_allowed(self) -> bool:
        opt = self.options
        return (
            opt.error_estimate
            and not self.method.quasi_static
            and self.period is not None
            and opt.dt is None
            and opt.max_step is None
            and opt.rtol is None
        )

    def _twin(self, method: str, **changes):
        return accuracy.twin(self, method, **changes)

    def _pilot_step(self, dt0: float) -> float:
        return accuracy.pilot_step(self, dt0)

    def _check_divergence(self) -> Status:
        """A march that ends OK but whose energy grew without a source is DIVERGED."""
        if not self.method.quasi_static:
            accuracy.check_divergence(self)
        return self.status

    def accuracy_attrs(self) -> dict:
        """energy_error_estimate, peak_force_error_estimate, error_estimate_method: see
        :func:`slipstep.methods.accuracy.estimate` (computed once per Simulation)."""
        if self._accuracy is not None:
            return self._accuracy
        result = accuracy.estimate(self)
        if self.status == Status.OK:
            self._accuracy = result
        return result

    # -- set-up ---------------------------------------------------------------------------
    def _preload(self):
        """Static equilibrium under the constant loads and contact offsets: ramp the loads
        quasi-statically from x = 0, w = 0 (offsets applied from the first increment),
        postulating full stick. Without loads or offsets x = 0 is the equilibrium."""
        cs, ws = self.compiled, self.ws
        for arr in (ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w):
            arr[:] = 0.0
        ws.state[:] = STICK
        _reset_cache(ws)
        settings = K.replace_settings(
            self.settings,
            inertia=False,
            signals=False,
            solver=K.PIECEWISE_LINEAR,
            adaptive=False,
            fallback=True,
            preload=self.options.preload_increments,
        )
        nq = cs.A.shape[0]
        q, f = np.zeros(nq), np.zeros(nq)
        ramp = _allocate_outputs(cs, self.options.preload_increments)
        if np.any(cs.constant_force != 0) or np.any(cs.g != 0):
            status = K.march(cs, settings, ws, ramp, q, f)
            counters = ramp.counters
            q[:], f[:] = ramp.q[counters[K.C_STEPS]], ramp.f[counters[K.C_STEPS]]
        else:
            status = K.OK
            local_displacement(cs, ws.x, np.zeros(cs.B.shape[1]), q)
            contact_law(cs, q, ws.w.copy(), f, ws.w, ws.state)
        if status != K.OK:
            states = ", ".join(f"{d}={STATE_NAMES[s]}" for d, s in zip(self.system.direction_names(), ws.state1))
            raise SolverError(
                f"static preload failed at increment {ramp.counters[K.C_FAIL_STEP]} of "
                f"{self.options.preload_increments}: {Status(status).message} (states: {states})"
            )
        # initial point of the march: p(0), f_e(0), consistent acceleration
        p0 = evaluate_compiled(_motion_signal(cs), np.zeros(1))[0]
        fe0 = evaluate_compiled(_force_signal(cs), np.zeros(1))[0] + cs.constant_force
        if np.abs(p0).max(initial=0.0) > 1e-6 * cs.length_scale and not self.method.quasi_static:
            warnings.warn(
                "the prescribed motion does not start from zero (p(0) != 0): a dynamic run receives it "
                "as an impulse and rings at the internal frequencies for as long as nothing damps them. "
                "Start motions from zero (sine phase) or set ramp_time.",
                stacklevel=3,
            )
        if self.method.quasi_static and (np.any(p0 != 0) or np.any(fe0 != cs.constant_force)):
            q[:], f[:] = self._static_start(settings)
        else:
            w_pre = ws.w.copy()
            local_displacement(cs, ws.x, p0, q)
            contact_law(cs, q, w_pre, f, ws.w, ws.state)
            generalised_force(cs, f, ws.gf)
        ws.fe[:] = fe0
        if not self.method.quasi_static:
            ws.a[:] = mass_solve(cs, fe0 - structure_product(cs, "K", ws.x) - ws.gf)
        self.preload_state = tuple(a.copy() for a in (ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w, ws.state))
        self.q0, self.f0 = q.copy(), f.copy()

    def _static_start(self, settings: K.MarchSettings) -> tuple[np.ndarray, np.ndarray]:
        """Quasi-static runs start from the static equilibrium at p(0), f_e(0): one
        piecewise-linear quasi-static step from the preload (x, w) to t = 0 (K x + A^T f(q, w)
        = f_e(0) with q = A x - B p(0) + g, the sliders moved by that solve). Returns (q, f)."""
        cs, ws = self.compiled, self.ws
        delta = 1e-9 * (self.period if self.period is not None else self.t_end)
        settings = K.replace_settings(settings, t_start=-delta, t_end=0.0, dt=delta, rtol=0.0, signals=True, preload=0)
        out = _allocate_outputs(cs, 1)
        nq = cs.A.shape[0]
        q, f = np.zeros(nq), np.zeros(nq)
        local_displacement(cs, ws.x, np.zeros(cs.B.shape[1]), q)
        contact_law(cs, q, ws.w.copy(), f, np.empty_like(ws.w), np.empty_like(ws.state))
        status = K.march(cs, settings, ws, out, q, f)
        if status != K.OK:
            raise SolverError(f"the static equilibrium at t = 0 (p(0), f_e(0)) failed: {Status(status).message}")
        _reset_cache(ws)
        return out.q[1].copy(), out.f[1].copy()

    def start_from(self, x, v=None, a=None, w=None, state=None, t_start: float = 0.0) -> None:
        """Start the following marches from a given state at time ``t_start`` [s] instead of the
        preload (continuation of a steady state, shooting). The march then covers
        [t_start, t_start + duration]. ``v`` defaults to 0 (dynamic methods), ``w`` to the
        preload sliders, ``state`` to the law's states at (x, w); ``a`` defaults to the
        consistent acceleration a = M^-1 (f_e - C v - K x - A^T f(x, w)), with the contact
        force in elastic form T = k_t (u - w), N = k_n v for v > 0 (0 in lift-off)."""
        cs = self.compiled
        n, nd = cs.M.shape[0], cs.kt.shape[0]
        order = np.asarray(cs.dof_order)  # user order -> kernel order (the banded backend reorders)
        x = np.array(x, float).reshape(n)[order]
        v = np.zeros(n) if v is None or self.method.quasi_static else np.array(v, float).reshape(n)[order]
        if a is not None:
            a = np.array(a, float).reshape(n)[order]
        w = self.preload_state[5].copy() if w is None else np.array(w, float).reshape(nd)
        p0 = evaluate_compiled(_motion_signal(cs), np.array([t_start]))[0]
        fe0 = evaluate_compiled(_force_signal(cs), np.array([t_start]))[0] + cs.constant_force
        q = np.empty(cs.A.shape[0])
        local_displacement(cs, x, p0, q)
        f = elastic_contact_force(cs, q, w)
        if state is None:
            state = np.empty(nd, np.int8)
            contact_law(cs, q, w.copy(), np.empty_like(q), np.empty(nd), state)
        gf = np.empty(n)
        generalised_force(cs, f, gf)
        if self.method.quasi_static:
            a = np.zeros(n)
        elif a is None:
            a = mass_solve(cs, fe0 - structure_product(cs, "C", v) - structure_product(cs, "K", x) - gf)
        self.preload_state = (x, v, np.array(a, float).reshape(n), fe0, gf, w, np.asarray(state, np.int8).copy())
        self.q0, self.f0 = q, f
        self.settings = K.replace_settings(self.settings, t_start=t_start, t_end=t_start + self.t_end)
        self.out.times[K.S_FROM] = t_start + self.save_plan.t_from  # the last periods of this march
        # the step-doubling twins march from the preload: no estimate for a continued march
        self._accuracy = {
            "energy_error_estimate": math.nan,
            "peak_force_error_estimate": math.nan,
            "error_estimate_method": "none (started from a given state)",
        }

    # -- marching -------------------------------------------------------------------------
    def kernel_arguments(self) -> tuple:
        """The kernel's arguments; the event-driven kernel takes the slim system and workspace
        tuples of kernels.events.event_arguments (fewer arrays to unbox or pass per call)."""
        if self.method.solver != K.EVENTS:
            return super().kernel_arguments()
        built = self._event_arguments  # built once per (compiled, ws)
        if built is None or built[0] is not self.compiled or built[1] is not self.ws:
            built = self._event_arguments = (self.compiled, self.ws, event_arguments(self.compiled, self.ws))
        sys, ws = built[2]
        return (sys, self.settings, ws, self.out, self.q0, self.f0)

    def march(self, kernel=None) -> Status:
        """Run the method's kernel (:func:`march_kernel`; or ``kernel``, another kernel of the same
        arguments, as tests/test_quasi_static.py does) from the preload state; returns the status
        (also in self.status)."""
        ws = self.ws
        for dst, src in zip((ws.x, ws.v, ws.a, ws.fe, ws.gf, ws.w, ws.state), self.preload_state):
            dst[:] = src
        _reset_cache(ws)
        self._run_kernel(march_kernel(self.method) if kernel is None else kernel)
        self._check_divergence()
        return check_march(self)

    # -- results --------------------------------------------------------------------------
    def _visited_states(self) -> str:
        c = self.out.counters
        names = self.system.direction_names()
        visited = self.ws.visited[: max(int(c[K.C_N_VISITED]), 1)]
        return " -> ".join(
            "(" + ", ".join(f"{d}={STATE_NAMES[s]}" for d, s in zip(names, row)) + ")" for row in visited
        )

    def method_attrs(self) -> dict:
        return {
            "method": self.method.name,
            "paper_method": self.method.paper_label,
            "solver": SOLVER_NAMES[self.method.solver],
            "adaptive_step": self.method.adaptive,
            "quasi_static": self.method.quasi_static,
            "scheme": "quasi-static" if self.method.quasi_static else self.options.scheme.name,
            "fallback_steps": int(self.out.counters[K.C_FALLBACKS]),
            "steps_per_period": self.options.steps_per_period if self.method.quasi_static else None,
            "tolerance": self.options.tolerance,
            "state_tolerance": self.options.state_tolerance,
            "rtol": math.nan if self.options.rtol is None else float(self.options.rtol),
            "linear_solver": "banded" if self.compiled.banded else ("low-rank" if self.low_rank else "direct"),
            "bandwidth": int(self.compiled.kl) if self.compiled.banded else -1,
            **(
                {}
                if self.massless is None
                else {"massless_dofs": ", ".join(self.system.structure.dof_names[i] for i in self.massless)}
            ),
        }


#: each march kernel's twin taking a kernels.arguments.KernelArguments (its arrays unboxed once,
#: not on every call); Runner._run_kernel calls the twin of a kernel that has one
PACKED_TWINS = {
    K.march: K.march_packed,
    quasi_static_march: quasi_static_march_packed,
    event_march: event_march_packed,
    E.explicit_march: E.explicit_march_packed,
}


def march_kernel(method: Method):
    """The kernel that marches ``method`` after the preload: the event-driven march
    (kernels/events.py), the quasi-static march of Method 4 (kernels/quasi_static.py: no
    inertia, fixed step, piecewise-linear solve) or the implicit march (kernels/march.py)."""
    if method.solver == K.EVENTS:
        return event_march
    if method.quasi_static and method.solver == K.PIECEWISE_LINEAR and not method.adaptive:
        return quasi_static_march
    return K.march


def check_banded_method(method: Method) -> None:
    """The banded backend (sparse structures) runs the implicit march's methods; the
    event-driven march and the partly quasi-static method need the dense matrices."""
    if method.solver == K.EVENTS or method.massless:
        raise InputError(
            "method",
            f"{method.name} needs the dense backend; this sparse structure compiles to the banded one",
            "use newmark, piecewise-linear, their adaptive variants or quasi-static, or give dense matrices "
            "(linear_solver='direct' for a small model)",
        )


def check_event_case(system: System, cs: CompiledSystem) -> None:
    """The event-driven method needs phases that are linear in known harmonic functions of time."""
    if cs.force_table_time.size or cs.motion_table_time.size:
        raise InputError(
            "method",
            "quasi-static-events needs harmonic loads and motions, the case has tables",
            "use method 'quasi-static' for tabulated signals",
        )
    if cs.force_ramp > 0 or cs.motion_ramp > 0:
        raise InputError(
            "ramp_time",
            "is set: quasi-static-events needs unramped harmonic signals",
            "remove ramp_time or use method 'quasi-static'",
        )
    circles = [c.name for c in system.contacts if c.law == "3d-circle"]
    if circles:
        raise InputError(
            "method",
            f"quasi-static-events needs piecewise-linear contact laws; {circles} use '3d-circle'",
            "use method 'quasi-static' for friction-circle contacts",
        )


def _check_time_scales(t_end: float, dt_limit: float, max_step: float, opt: RunOptions) -> None:
    """Refuse end times and step limits whose ratio no march can cover (before any step count
    is computed from them): a non-finite end time, or more than 1e15 steps."""
    field_name = "duration" if opt.duration is not None else "periods"
    if not math.isfinite(t_end):
        raise InputError(field_name, f"gives an end time of {t_end} s", "give a finite duration or number of periods")
    limit = min(dt_limit, max_step)
    if not limit > 0 or t_end / limit > 1e15:
        raise InputError(
            field_name,
            f"would need more than 1e15 steps ({t_end:.3g} s with steps of {limit:.3g} s)",
            "check the units of the masses and stiffnesses, or simulate a shorter time",
        )


def elastic_contact_force(cs: CompiledSystem, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Local contact forces from (q, w) in elastic form: T_d = k_t (u_d - w_d), N = k_n v for a
    contact with v > 0, all zero in lift-off (in stick and in slip alike, since a slipping
    slider sits at w = u - T / k_t)."""
    f = np.zeros(cs.A.shape[0])
    v = q[cs.normal_row]
    closed = v > 0.0
    f[cs.normal_row] = np.where(closed, cs.kn * v, 0.0)
    d_closed = closed[cs.direction_contact]
    f[cs.tangential_row] = np.where(d_closed, cs.kt * (q[cs.tangential_row] - w), 0.0)
    return f


def compiled_entry(dispatcher, args):
    """The compiled overload of a numba dispatcher for these argument types, callable without
    the per-call type dispatch (about 6 us for our tuples of arrays); the dispatcher itself
    if no such overload is found. numba.typeof of our nested tuples costs about 1.7 ms, so the
    overload is cached by :func:`_layout_key`, the part of the arguments their numba types
    depend on (a sweep's cases and the accuracy rule's pilot runs share one look-up)."""
    key = (dispatcher, _layout_key(args))
    entry = _ENTRY_CACHE.get(key)
    if entry is None:
        signature = tuple(numba.typeof(a) for a in args)
        overload = dispatcher.overloads.get(signature)
        if overload is None:
            return dispatcher
        entry = _ENTRY_CACHE[key] = overload.entry_point
    return entry


_ENTRY_CACHE: dict = {}


def _layout_key(value):
    """What the numba type of an argument is made of: per array its dtype, rank, layout and
    flags; per tuple its class and items; per scalar its Python type."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        return (value.dtype.str, value.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable, flags.aligned)
    if isinstance(value, tuple):
        return (type(value), tuple(_layout_key(item) for item in value))
    if isinstance(value, KernelArguments):
        return value._type  # its numba type: the layout of every array it holds
    return type(value)


def _motion_signal(cs: CompiledSystem) -> CompiledSignal:
    return CompiledSignal(
        cs.motion_frequency, cs.motion_sin, cs.motion_cos, cs.motion_table_time, cs.motion_table_value, cs.motion_ramp
    )


def _force_signal(cs: CompiledSystem) -> CompiledSignal:
    return CompiledSignal(
        cs.force_frequency, cs.force_sin, cs.force_cos, cs.force_table_time, cs.force_table_value, cs.force_ramp
    )


def _reset_cache(ws: K.Workspace) -> None:
    """Forget the factorisations (every march pays for its own). T_min per state is a property
    of the system and is kept for the life of the Simulation (cleared at allocation)."""
    ws.cache_used[:] = False
    ws.lr.base_used[:] = False
    ws.lin_dt[0] = np.nan


def structure_product(cs: CompiledSystem, which: str, x: np.ndarray) -> np.ndarray:
    """M x, C x or K x (``which`` 'M', 'C', 'K') in the kernel DOF order, dense or banded."""
    if not cs.banded:
        return getattr(cs, which) @ x
    out = np.empty(cs.Mb.shape[0])
    BD.band_matvec(getattr(cs, which + "b"), cs.kl, cs.ku, np.ascontiguousarray(x, dtype=float), out)
    return out


def mass_solve(cs: CompiledSystem, rhs: np.ndarray) -> np.ndarray:
    """a = M^-1 rhs on the DOFs with inertia (methods/massless.py), dense or banded."""
    if not cs.banded:
        return ML.initial_acceleration(cs.M, rhs)
    lu, piv = band_mass_lu(cs)
    out = np.empty(rhs.shape[0])
    BD.band_lu_solve(lu, cs.kl, cs.ku, piv, np.ascontiguousarray(rhs, dtype=float), out)
    return out


def compile_backend(linear_solver: str) -> str:
    """The System.compile backend a linear_solver option asks for."""
    return {"banded": "banded", "direct": "dense", "low-rank": "dense"}.get(linear_solver, "auto")


def use_low_rank(cs: CompiledSystem, linear_solver: str) -> bool:
    """The low-rank (Woodbury) state solve pays when the contact coordinates are few against
    the DOFs (kernels/state_solve.py): 'auto' takes it when 2 nq <= n (never with the banded
    backend, whose banded LU per state is already O(n b^2))."""
    if cs.banded:
        return False
    n, nq = cs.M.shape[0], cs.A.shape[0]
    if linear_solver == "auto":
        return 0 < nq and 2 * nq <= n
    return linear_solver == "low-rank" and nq > 0


def check_memory(
    cs: CompiledSystem,
    capacity: int,
    opt: RunOptions,
    quasi_static: bool,
    low_rank: bool,
    plan: SV.Plan | None = None,
    t_end: float = 0.0,
) -> float:
    """The memory estimate of a march of ``capacity`` steps saving ``plan`` (None: everything;
    slipstep.methods.memory) checked against the limit before anything is allocated; returns
    it [bytes]."""
    n, nq, nd, m = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.B.shape[1]
    field_name = "duration" if opt.duration is not None else "periods"
    fixes = "simulate fewer periods (or a shorter duration)" + (
        ", use fewer steps_per_period" if quasi_static else ", raise the step ratio"
    )
    points = capacity + 1
    if plan is not None:
        n, nq, nd = plan.dofs.size, plan.rows.size, plan.directions.size
        points = SV.rows_needed(plan, capacity, 0.0, t_end)
        fixes = "save less (save: fewer dofs, every k-th step or the last periods; --save-dofs, --save-every), " + fixes
    limit = None if opt.max_memory is None else memory.parse_size("max_memory", opt.max_memory)
    return memory.check(
        points, n, nq, nd, m, _workspace_bytes(cs, opt.max_state_iterations, low_rank), limit, field_name, fixes
    )


def _cache_capacities(n: int, nq: int, low_rank: bool, band_width: int = 0) -> tuple[int, int, int]:
    """(matrix size factorised per state, state cache slots, low-rank base slots): at most
    about 200 MB of factorisations each. ``band_width`` > 0 (the banded backend: 2 kl + ku + 1
    columns per row of a banded LU): the slots of n x band_width LUs."""
    if band_width > 0:
        cap = int(min(512, max(8, 2e8 // (8 * n * (band_width + 1) + 1))))
        return n, cap, 1
    size = nq if low_rank else n  # the matrix factorised per state: C(S) (nq) or J(S) (n)
    cap = int(min(512, max(8, 2e8 // (8 * size * size + 1))))
    capb = int(min(64, max(2, 2e8 // (8 * (n * n + 2 * n * nq) + 1)))) if low_rank else 1
    return size, cap, capb


def _lu_width(cs: CompiledSystem) -> int:
    """Columns of a banded LU (2 kl + ku + 1), 0 for the dense backend."""
    return 2 * cs.kl + cs.ku + 1 if cs.banded else 0


def _workspace_bytes(cs: CompiledSystem, max_state_iter: int, low_rank: bool) -> int:
    """Bytes of :func:`_allocate_workspace` (its largest arrays)."""
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    width = _lu_width(cs)
    size, cap, capb = _cache_capacities(n, nq, low_rank, width)
    if width:  # banded: LUs (cap + 2) x n x (width + 1 pivots), Lin, J, M's LU, T_min Lanczos basis
        lanczos = 2 * min(n, BD.LANCZOS_FULL if n <= BD.LANCZOS_FULL else BD.LANCZOS_STEPS) * n
        return int(8 * ((cap + 2) * n * (width + 1) + 4 * n * width + lanczos + 20 * (n + nq + nd)) + 2 * cap * nd)
    nb, nqb = (n, nq) if low_rank else (1, 1)
    return int(
        8
        * (
            (cap + 2) * size * (size + 1)
            + (capb + 1) * (nb * nb + nb + nb * nqb + nqb * nqb)
            + 4 * n * n
            + 20 * (n + nq + nd)
        )
        + 2 * cap * nd
        + nd * (max_state_iter + 1)
    )


def _allocate_workspace(cs: CompiledSystem, max_state_iter: int, low_rank: bool) -> K.Workspace:
    n, nq, nd, m = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.B.shape[1]
    width = _lu_width(cs)
    size, cap, capb = _cache_capacities(n, nq, low_rank, width)
    nb, nqb = (n, nq) if low_rank else (1, 1)
    z = lambda *shape: np.zeros(shape)
    i8 = lambda *shape: np.zeros(shape, np.int8)
    if width:  # banded backend: band storage for Lin (kl + ku + 1) and the LUs (2 kl + ku + 1); M's LU
        lin, jac, lus = z(n, cs.kl + cs.ku + 1), z(n, width), z(cap + 2, n, width)
        mfac, mpiv = band_mass_lu(cs)  # the banded LU of M (kernels/banded.py band_lambda_max)
    else:
        lin, jac, lus = z(n, n), z(n, n), z(cap + 2, size, size)
        mfac, mpiv = mass_factor(cs.M), np.zeros(0, np.int64)
    lr = LowRank(
        base_keys=i8(capb, nd),
        base_used=np.zeros(capb, np.bool_),
        base_ok=np.zeros(capb + 1, np.bool_),
        base_lu=z(capb + 1, nb, nb),
        base_piv=np.zeros((capb + 1, nb), np.int64),
        Z=z(capb + 1, nb, nqb),
        AZ=z(capb + 1, nqb, nqb),
        slot_base=np.zeros(cap + 2, np.int64),
        slot_identity=np.zeros(cap + 2, np.bool_),
        Ay=z(nq),
        t=z(nq),
        s=z(nq),
        col=z(n),
        zc=z(n),
    )
    return K.Workspace(
        x=z(n),
        v=z(n),
        a=z(n),
        fe=z(n),
        gf=z(n),
        w=z(nd),
        state=i8(nd),
        fe1=z(n),
        gf1=z(n),
        f1=z(nq),
        q1=z(nq),
        w1=z(nd),
        state1=i8(nd),
        dx=z(n),
        delta=z(n),
        r0=z(n),
        r=z(n),
        p=z(m),
        qbase=z(nq),
        Lin=lin,
        J=jac,
        mass_factor=mfac,
        key=i8(2 * nd),
        dt_state=i8(nd),
        stick=np.full(nd, STICK, np.int8),
        cache_keys=i8(cap, 2 * nd),
        cache_used=np.zeros(cap, np.bool_),
        cache_ok=np.zeros(cap + 2, np.bool_),
        cache_lu=lus,
        cache_piv=np.zeros((cap + 2, size), np.int64),
        tmin_keys=i8(cap, nd),
        tmin_used=np.zeros(cap, np.bool_),
        tmin_value=z(cap),
        lin_dt=np.full(1, np.nan),
        visited=i8(max_state_iter + 1, nd),
        basis=z(4, cs.force_frequency.shape[0] + cs.motion_frequency.shape[0]),
        clock=z(4),
        mpiv=mpiv,
        lr=lr,
    )


def _allocate_outputs(
    cs: CompiledSystem, capacity: int, max_memory: float | None = None, plan: SV.Plan | None = None, t_end: float = 0.0
) -> K.Outputs:
    """The output buffers of a march of at most ``capacity`` steps saving ``plan`` (None: every
    DOF and contact at every step); a buffer beyond the memory limit (default: half of the
    available memory) is refused first (runners check it earlier with a better message)."""
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    if plan is None:
        dofs, rows, dirs = np.arange(n, dtype=np.int64), np.arange(nq, dtype=np.int64), np.arange(nd, dtype=np.int64)
        ip, times = np.array([capacity, 1, 0, -1, 0, 0], np.int64), np.array([-math.inf, math.nan, math.inf])
        k = capacity + 3
    else:
        dofs, rows, dirs, ip, times = SV.kernel_arrays(plan, cs, capacity)
        k = SV.rows_needed(plan, capacity, 0.0, t_end)
    ns, nqs, nds = dofs.size, rows.size, dirs.size
    if k > 100_000:
        limit = None if max_memory is None else memory.parse_size("max_memory", max_memory)
        memory.check(k, ns, nqs, nds, cs.B.shape[1], 0, limit, "duration", "simulate a shorter time or save less")
    return K.Outputs(
        t=np.zeros(k),
        dt=np.zeros(k),
        x=np.zeros((k, ns)),
        v=np.zeros((k, ns)),
        a=np.zeros((k, ns)),
        q=np.zeros((k, nqs)),
        f=np.zeros((k, nqs)),
        w=np.zeros((k, nds)),
        state=np.zeros((k, nds), np.int8),
        solves=np.zeros(k, np.int64),
        counters=np.zeros(K.N_COUNTERS, np.int64),
        step=np.full(k, -1, np.int64),
        dofs=dofs,
        rows=rows,
        dirs=dirs,
        plan=ip,
        times=times,
    )


def reset_outputs(out: K.Outputs) -> None:
    """Set the save plan's running entries before a march (the kernel's _store keeps them):
    no row kept, no step kept, the first given time, the first multiple of every; no failure."""
    out.plan[[K.S_ROWS, K.S_LAST, K.S_GRID, K.S_NEXT]] = 0, -1, 0, 0
    out.times[K.S_FAIL] = math.nan


def saved_rows(out: K.Outputs, n_steps: int) -> int:
    """Rows of ``out`` holding the march of ``n_steps`` steps: those the kernel kept, and the
    pending row when it holds the last step (a march always ends with its last step)."""
    rows = int(out.plan[K.S_ROWS])
    if rows < out.step.shape[0] and out.step[rows] == n_steps and (rows == 0 or out.step[rows - 1] != n_steps):
        rows += 1
    return max(rows, 1)


def run(system: System, method: str = "newmark", *, raise_on_failure: bool = False, **options):
    """Simulate ``system`` with ``method`` (see slipstep.methods.registry) and return the
    result Dataset (schema in slipstep.results). Options: see :class:`RunOptions`."""
    return Simulation(system, method, **options).run(raise_on_failure=raise_on_failure)
