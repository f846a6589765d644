"""The Python face of a time march (a facade, docs/architecture.md): a plan
(methods/plan.py: options validated, system compiled, the step rule), a marcher
(methods/marcher.py: buffers and kernel), the static equilibrium to start from
(methods/start.py) and the result Dataset (slipstep.output.results). No numerics here.

    sim = Simulation(system, "piecewise-linear", periods=3)
    ds = sim.run()            # march from the static preload + Dataset
    sim.march()               # re-march from the same start (for timing)
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from slipstep.errors import InputError, Interrupted, SolverError, Status
from slipstep.kernels import march as K
from slipstep.kernels.codes import EXACT_EVENTS, SOLVER_NAMES
from slipstep.methods import accuracy, sensitivity_twin
from slipstep.methods.invariants import check_march
from slipstep.methods.accuracy import check_divergence  # noqa: F401  (re-exported)
from slipstep.methods.buffers import (  # noqa: F401  (re-exported: the former homes of these names)
    allocate_outputs as _allocate_outputs,
    allocate_workspace as _allocate_workspace,
    cache_capacities as _cache_capacities,
    lu_width as _lu_width,
    reset_cache as _reset_cache,
    reset_outputs,
    saved_rows,
    workspace_bytes as _workspace_bytes,
)
from slipstep.methods.marcher import (  # noqa: F401  (re-exported)
    Marcher,
    Segment,
    _layout_key,
    compiled_entry,
    march_kernel,
)
from slipstep.methods.options import LINEAR_SOLVERS, RunOptions  # noqa: F401  (re-exported)
from slipstep.methods.plan import (  # noqa: F401  (re-exported)
    RTOL_LOCAL_FACTOR,
    RunPlan,
    check_banded_method,
    check_event_case,
    check_memory,
    compile_backend,
    plan_run,
    use_low_rank,
)
from slipstep.methods.registry import Method
from slipstep.methods.start import (  # noqa: F401  (re-exported)
    consistent_start,
    elastic_contact_force,
    mass_solve,
    static_equilibrium,
    structure_product,
)
from slipstep.methods.state import State
from slipstep.methods.step_control import default_max_step, state_t_min  # noqa: F401  (re-exported)
from slipstep.model.excitation import evaluate_compiled, force_signal, motion_signal
from slipstep.output.results import STATE_NAMES, build_dataset
from slipstep.model.system import System

_motion_signal, _force_signal = motion_signal, force_signal  # (their former names)


class Runner:
    """What every march runner shares: run(), the Dataset and the failure report.

    Subclasses set system, compiled, options, out (kernels.march.Outputs), status,
    kernel_time, dt, t_min_stick, t_end, period, and implement march(), method_attrs()
    (method, paper_method, solver, adaptive_step, quasi_static, scheme, ...) and
    _visited_states() (the contact states tried at a failure, as text)."""

    failure_hint = ""
    progress = False  # draw a progress bar on stderr for runs longer than a second (the CLI sets it)
    keep_interrupted = False  # Ctrl-C: return the partial result (True) or raise Interrupted carrying it

    def accuracy_attrs(self) -> dict:
        """The time-discretisation error estimate attrs (see Simulation.accuracy_attrs)."""
        return {}

    def _check_interrupted(self) -> None:
        """Ctrl-C stopped the march: raise Interrupted carrying the partial result, unless
        keep_interrupted."""
        if self.status == Status.INTERRUPTED and not self.keep_interrupted:
            partial = self.dataset()
            raise Interrupted(partial.attrs["status_message"], partial)

    def run(self, raise_on_failure: bool = False):
        """Preloaded march + Dataset. On failure the Dataset holds every step done before it."""
        start = time.perf_counter()
        self.march()
        if hasattr(self, "plan"):  # the sensitivity twin (issue 29 item 3; explicit runners have no plan)
            self.step_audit = {**self.step_audit, **sensitivity_twin.check(self, getattr(self, "given_start", False))}
        ds = self.dataset()
        ds.attrs["wall_time_s"] = time.perf_counter() - start
        collapsed_step_warning(ds)
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
        if getattr(self, "broken_invariant", None) is not None:  # Status.INVARIANT (slipstep.methods.invariants)
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
        motion = evaluate_compiled(motion_signal(self.compiled), t)
        failure = self.failure_report()
        message = self.status_message(failure)
        method = self.method_attrs()
        attrs = {"title": f"slipstep result: {self.system.name}, {method['method']}", "case": self.system.name}
        attrs.update(method)
        attrs.update(
            {
                "status": self.status.name,
                "status_message": message,
                **self.run_counts(),
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
        attrs.update(getattr(self, "step_audit", {}))  # slipstep.methods.invariants.audit_steps (issue 29)
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

    def run_counts(self) -> dict:
        """The march's counts: steps, solves (= iterations), mean_solves_per_step,
        factorisations, law_calls, redone_steps, state_changes."""
        c = self.out.counters
        n_steps = int(c[K.C_STEPS])
        rows = saved_rows(self.out, n_steps)
        solves = int(self.out.solves[1:rows].sum()) if rows == n_steps + 1 else int(c[K.C_SOLVES])
        return {
            "steps": n_steps,
            "solves": solves,
            "iterations": solves,
            "mean_solves_per_step": solves / max(n_steps, 1),
            "factorisations": int(c[K.C_FACTORISATIONS]),
            "law_calls": int(c[K.C_LAW_CALLS]),
            "redone_steps": int(c[K.C_REDOS]),
            "state_changes": int(c[K.C_STATE_CHANGES]),
        }

    def status_message(self, failure: dict | None = None) -> str:
        """The status text of the march (attr status_message): the status, and for a failure
        where and in which states it stopped."""
        failure = self.failure_report() if failure is None else failure
        n_steps = int(self.out.counters[K.C_STEPS])
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
        return message


class Simulation(Runner):
    """One system marched by one method with one set of options: :func:`plan_run` (refined by
    the default rule's pilot, accuracy.pilot_plan), a :class:`Marcher` and the static
    equilibrium; :meth:`start_from` sets another start. The plan's fields (dt, t_end, settings,
    save_plan, ...) and the marcher's buffers (ws, out) read as attributes."""

    def __init__(self, system: System, method: str | Method = "newmark", **options):
        if _exact_events(method):
            raise InputError(
                "method",
                "'events' marches no time steps: it has no Simulation (marcher, workspace, start_from)",
                "use slipstep.run(system, 'events') (runner: slipstep.methods.exact_events.ExactEventRun), "
                "and slipstep.steady.shoot(system, method='events') for the steady state",
            )
        plan = plan_run(system, method, **options)
        if plan.pilot_allowed:
            plan = accuracy.pilot_plan(plan)
        self._set_up(plan, Marcher(plan))
        self.start = static_equilibrium(plan, self.marcher.ws)

    @classmethod
    def from_plan(cls, plan: RunPlan, marcher: Marcher | None = None) -> "Simulation":
        """The facade of a plan (no pilot refinement) on ``marcher`` (one already holding the
        plan: Marcher.retarget; default a new one). The static equilibrium is computed when
        first needed (a march continued from a given state never needs it)."""
        sim = cls.__new__(cls)
        sim._set_up(plan, Marcher(plan) if marcher is None else marcher)
        return sim

    def _set_up(self, plan: RunPlan, marcher: Marcher) -> None:
        self.plan, self.marcher = plan, marcher
        self.status = None
        self.kernel_time = math.nan
        self.segment: Segment | None = None
        self._accuracy = None
        self._start = None

    @property
    def start(self) -> State:
        """The state the next march starts from (the static equilibrium unless start_from set another)."""
        if self._start is None:
            self._start = static_equilibrium(self.plan, self.marcher.ws)
        return self._start

    @start.setter
    def start(self, state: State) -> None:
        self._start = state

    # -- the plan's and the marcher's fields ---------------------------------------------
    system = property(lambda self: self.plan.system)
    method = property(lambda self: self.plan.method)
    options = property(lambda self: self.plan.options)
    compiled = property(lambda self: self.plan.compiled)
    massless = property(lambda self: self.plan.massless)
    stick = property(lambda self: self.plan.stick)
    t_min_stick = property(lambda self: self.plan.t_min_stick)
    period = property(lambda self: self.plan.period)
    t_end = property(lambda self: self.plan.t_end)
    save_plan = property(lambda self: self.plan.save_plan)
    dt = property(lambda self: self.plan.dt)
    dt_limit = property(lambda self: self.plan.dt_limit)
    dt_stability = property(lambda self: self.plan.dt_stability)
    max_step = property(lambda self: self.plan.max_step)
    low_rank = property(lambda self: self.plan.low_rank)
    memory_estimate = property(lambda self: self.plan.memory_estimate)
    ws = property(lambda self: self.marcher.ws)
    _packed = property(lambda self: self.marcher.entry.packed)

    @property
    def out(self) -> K.Outputs:
        return self.marcher.out

    @out.setter
    def out(self, value: K.Outputs) -> None:
        self.marcher.out = value

    @property
    def settings(self) -> K.MarchSettings:
        """The kernel settings of the next march (settable: tests force a step past its limit)."""
        return self.marcher.settings

    @settings.setter
    def settings(self, value: K.MarchSettings) -> None:
        self.marcher.settings = value

    @property
    def progress(self) -> bool:
        return self.marcher.progress

    @progress.setter
    def progress(self, value: bool) -> None:
        self.marcher.progress = bool(value)

    @property
    def q0(self) -> np.ndarray:
        """Local contact displacements at the start."""
        return self.start.terms.q

    @property
    def f0(self) -> np.ndarray:
        """Local contact forces at the start."""
        return self.start.terms.f

    @property
    def preload_state(self) -> tuple:
        """The start as (x, v, a, fe, gf, w, state) in the kernel's DOF order (the former form;
        ``start`` is the State)."""
        s, cs = self.start, self.compiled
        order = np.asarray(cs.dof_order) if cs.banded else slice(None)
        k = lambda values: values[order]  # noqa: E731
        return (k(s.x), k(s.v), k(s.a), k(s.terms.fe), k(s.terms.gf), s.w, s.contact_state)

    def kernel_arguments(self) -> tuple:
        """The march kernel's arguments (sys, settings, ws, out, q0, f0): Marcher.kernel_arguments."""
        return self.marcher.kernel_arguments()

    # -- marching -------------------------------------------------------------------------
    def start_from(self, x, v=None, a=None, w=None, state=None, t_start: float = 0.0) -> None:
        """Start the following marches from a given state at time ``t_start`` [s] instead of the
        preload (continuation of a steady state, shooting): start.consistent_start, ``w``
        defaulting to the current start's sliders. The march then covers [t_start, t_start +
        duration]; it has no step-doubling estimate (its twins march from the preload)."""
        w = self.start.w if w is None else w
        self.start = consistent_start(self.plan, x, v, w, state, t_start, a)
        self.given_start = True  # no sensitivity twin (it marches from the preload)
        self._accuracy = accuracy.no_estimate("none (started from a given state)")

    def march(self, kernel=None, check: bool = True) -> Status:
        """March from the start (the preload, or the state of :meth:`start_from`) over t_end:
        Marcher.advance (``kernel``: another kernel entry of the same arguments, as
        tests/test_quasi_static.py does); returns the status (also in self.status). ``check``
        False leaves out the contact invariants (slipstep.methods.invariants.check_march) for a
        caller that checks the march it keeps (shooting's Newton iterates)."""
        self.segment = self.marcher.advance(self.start, kernel=kernel)
        self.status, self.kernel_time = self.segment.status, self.segment.kernel_time_s
        self._check_interrupted()
        return check_march(self) if check else self.status

    def accuracy_attrs(self) -> dict:
        """energy_error_estimate, peak_force_error_estimate, error_estimate_method: see
        :func:`slipstep.methods.accuracy.estimate` (computed once per Simulation)."""
        if self._accuracy is not None:
            return self._accuracy
        result = accuracy.estimate(self.plan, self.status, self.out)
        if self.status == Status.OK:
            self._accuracy = result
        return result

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
            "step_rule": self.plan.step_rule,
            "linear_solver": {"dense": "direct"}.get(self.plan.backend, self.plan.backend),
            "linear_solver_reason": self.plan.backend_reason,
            "bandwidth": int(self.compiled.kl) if self.compiled.banded else -1,
            **(
                {}
                if self.massless is None
                else {"massless_dofs": ", ".join(self.system.structure.dof_names[i] for i in self.massless)}
            ),
        }


def run(system: System, method: str = "newmark", *, raise_on_failure: bool = False, **options):
    """Simulate ``system`` with ``method`` (see slipstep.methods.registry) and return the
    result Dataset (schema in slipstep.output.results). Options: see :class:`RunOptions`
    (method ``events``: methods/exact_events.py, which also takes ``max_events``)."""
    if _exact_events(method):
        from slipstep.methods.exact_events import ExactEventRun

        return ExactEventRun(system, **options).run(raise_on_failure=raise_on_failure)
    return Simulation(system, method, **options).run(raise_on_failure=raise_on_failure)


def _exact_events(method) -> bool:
    """Is ``method`` (a name, a paper number or a Method) the exact event-driven one?"""
    from slipstep.methods.registry import get_method

    return (method if isinstance(method, Method) else get_method(method)).solver == EXACT_EVENTS


#: a run taking more than this many times the steps of its planned step warns (issue 29)
COLLAPSE_FACTOR = 50


def collapsed_step_warning(ds) -> None:
    """Warn when a run took more than COLLAPSE_FACTOR times the steps its planned step dt_s
    gives over its duration (the step collapsed: a state cycle, an accuracy control chasing a
    non-smooth response); the ratio is recorded as the attr ``steps_over_planned``."""
    dt, duration, steps = ds.attrs.get("dt_s"), ds.attrs.get("t_end_s"), ds.attrs.get("steps")
    if not dt or not duration or not steps or not math.isfinite(dt) or not math.isfinite(duration):
        return
    planned = max(math.ceil(duration / dt - 1e-9), 1)
    ratio = steps / planned
    ds.attrs["steps_over_planned"] = ratio
    if ratio > COLLAPSE_FACTOR:
        warnings.warn(
            f"the run took {steps} steps, {ratio:.0f} times the {planned} of its planned step "
            f"{dt:.3g} s: the step collapsed (see redone_steps, fallback_steps, state_changes); "
            "check the units and the contact stiffnesses, or use the piecewise-linear method",
            RuntimeWarning,
            stacklevel=3,
        )
