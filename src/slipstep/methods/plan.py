"""The plan of a march: everything a march needs, computed without running a kernel
(docs/architecture.md, "RunPlan and plan_run").

    plan = plan_run(system, "piecewise-linear", periods=3)
    plan.dt, plan.capacity, plan.settings, plan.save_plan, plan.backend

:func:`plan_run` validates the options (:class:`slipstep.methods.options.RunOptions`),
compiles the system for its backend, and applies the step rule (methods/step_control.py):

    dt0 = min(r T_min(stick) / pi, T / 50, stability limit),   whole steps per period
          (step_rule 't-min', the paper's; the default of the methods that iterate)
    dt0 = min(T / 50, stability limit),                        whole steps per period
          (step_rule 'accuracy', piecewise-linear methods only, their default where a period
          or max_step caps the step and an error estimate checks it: nothing iterates within
          a linear phase, so T_min sets nothing; :func:`step_rule_of`)

(quasi-static: T / steps_per_period; ``dt`` given: that step), the step capacity of the run
and its memory estimate, checked before any allocation. The default rule's step-doubling
refinement runs twin marches, so it is not part of the plan: ``accuracy.pilot_plan(plan)``
returns the refined plan (``plan.pilot_allowed`` says when the default rule asks for it).
A plan is frozen; a variant is a new plan (:meth:`RunPlan.replace`, :meth:`RunPlan.with_step`,
:meth:`RunPlan.retuned`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from slipstep.errors import InputError
from slipstep.kernels import march as K
from slipstep.kernels.codes import EXACT_EVENTS
from slipstep.kernels.contact import STICK
from slipstep.methods import massless as ML
from slipstep.methods import memory
from slipstep.methods import save as SV
from slipstep.methods import sparse as SB
from slipstep.methods import step_control as SC
from slipstep.methods.buffers import workspace_bytes
from slipstep.methods.options import RunOptions
from slipstep.methods.registry import Method, get_method
from slipstep.methods.step_control import default_max_step, state_t_min
from slipstep.methods.step_rule import step_rule_of
from slipstep.model.contact import without_piecewise_linear_form
from slipstep.model.system import CompiledSystem, System, is_sparse

#: rtol -> local error bound rtol * RTOL_LOCAL_FACTOR * L (calibrated: loop energy within rtol on the paper case)
RTOL_LOCAL_FACTOR = 0.1


@dataclass(frozen=True, eq=False)
class RunPlan:
    """What a march of ``method`` on ``system`` with ``options`` needs (module docstring).

    compiled: the compiled system (massless DOFs condensed: methods/massless.py); massless:
    their indices (None unless the method treats DOFs without inertia); t_min_stick [s]: T_min
    of full stick; period [s] (None for tables only) and t_end [s]: the run's length after the
    start; dt [s]: the (first) step; dt_limit, dt_stability [s]: the step rule's limit and the
    scheme's stability limit; max_step [s]: the cap of dynamic steps; capacity: the steps the
    outputs hold at most; low_rank: the state solve by the capacitance matrix; memory_estimate
    [bytes]; settings: the kernel's MarchSettings (t_start = 0, t_end); save_plan: what the march
    stores (methods/save.py); coarse: the pilot's twin at 2 dt over the whole run when the
    refinement made it (accuracy.estimate reuses it), else None."""

    system: System
    method: Method
    options: RunOptions
    compiled: CompiledSystem
    massless: np.ndarray | None
    t_min_stick: float
    period: float | None
    t_end: float
    save_plan: SV.Plan
    dt_limit: float
    dt_stability: float
    max_step: float
    dt: float = math.nan
    capacity: int = 0
    low_rank: bool = False
    memory_estimate: float = 0.0
    settings: K.MarchSettings | None = None
    coarse: tuple | None = None

    @property
    def quasi_static(self) -> bool:
        return self.method.quasi_static

    @property
    def backend(self) -> str:
        """The structure backend of the march: 'sparse', 'banded', 'low-rank' or 'dense'."""
        if is_sparse(self.compiled):
            return "sparse"
        return "banded" if self.compiled.banded else ("low-rank" if self.low_rank else "dense")

    @property
    def backend_reason(self) -> str:
        """Why the march runs on :attr:`backend`: the linear_solver the user gave, or the reason
        of 'auto' (methods.sparse.backend_reason: the estimated cost per step of each backend)."""
        return SB.backend_reason(self.system, self.method, self.options, self.backend)

    @property
    def step_rule(self) -> str:
        """The step rule of the run, 'accuracy' or 't-min' (:func:`step_rule_of`)."""
        return step_rule_of(self.method, self.options, self.period)

    @property
    def stick(self) -> np.ndarray:
        """Full stick, the contact state of the preload and of T_min's step rule."""
        return np.full(self.compiled.kt.shape[0], STICK, np.int8)

    @property
    def pilot_allowed(self) -> bool:
        """Does the default step rule refine this plan's step (accuracy.pilot_plan)?"""
        opt = self.options
        return (
            opt.error_estimate
            and not self.method.quasi_static
            and self.period is not None
            and opt.dt is None
            and opt.max_step is None
            and opt.rtol is None
        )

    def retuned(self, frequency_hz: float, system: System | None = None, **option_changes) -> "RunPlan":
        """The plan of the same run at the excitation frequency ``frequency_hz`` [Hz] (the next
        FRF point): ``system`` is the retuned system when the caller has one (else
        model.retune.retune(self.system, frequency_hz)), ``option_changes`` the options that change
        with the point (the steady solvers' step T / N). The compiled matrices, T_min and the
        step limits are kept (no compile, no eigenvalue problem) when only the frequencies
        change; the same array layout, so a marcher takes it (Marcher.retarget). Another system
        or a change of a layout option is planned again from the start (plan_run)."""
        return retuned_plan(self, frequency_hz, system, **option_changes)

    def replace(self, **changes) -> "RunPlan":
        """This plan with some fields changed (no field is recomputed: see :meth:`with_step`)."""
        return replace(self, **changes)

    def fixed_step(self, max_step: float) -> float:
        """The fixed step under the cap ``max_step``: :func:`slipstep.methods.step_control.fixed_step`."""
        opt = self.options
        spp = opt.steps_per_period if self.method.quasi_static else None
        return SC.fixed_step(self.dt_limit, max_step, self.period, self.t_end, opt.dt, spp)

    def with_step(self, dt: float, max_step: float | None = None, coarse: tuple | None = None) -> "RunPlan":
        """This plan with the step ``dt`` (and the cap ``max_step``): its capacity, memory
        estimate and settings recomputed; refused when one step is longer than the run."""
        max_step = self.max_step if max_step is None else max_step
        opt, cs, t_end = self.options, self.compiled, self.t_end
        if dt > t_end * (1 + 1e-12):
            field_name = "duration" if opt.duration is not None else "periods"
            raise InputError(
                field_name,
                f"gives {t_end:.3g} s, shorter than one time step ({dt:.3g} s)",
                "simulate longer or use a smaller step",
            )
        quasi = self.method.quasi_static
        capacity = SC.capacity(
            t_end, dt, self.dt_limit, max_step, self.method.adaptive, None if quasi else opt.rtol, self.t_min_stick
        )
        # the event-driven kernel factorises J(S) (n x n) itself: its cache must be n x n (issue 29: a
        # low-rank cache of nq x nq was written out of bounds)
        low_rank = use_low_rank(cs, opt.linear_solver) and self.method.solver != K.EVENTS
        estimate = check_memory(cs, capacity, opt, quasi, low_rank, self.save_plan, t_end)
        return replace(
            self,
            dt=dt,
            max_step=max_step,
            capacity=capacity,
            low_rank=low_rank,
            memory_estimate=estimate,
            settings=kernel_settings(self, dt, max_step, low_rank),
            coarse=coarse,
        )


def plan_run(system: System, method: str | Method = "newmark", **options) -> RunPlan:
    """The plan of a march (module docstring); runs no kernel. Raises InputError naming the
    option at fault."""
    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    unknown = set(options) - set(RunOptions.__dataclass_fields__)
    if unknown:
        raise InputError(
            "options", f"unknown option(s) {sorted(unknown)}", f"use only {sorted(RunOptions.__dataclass_fields__)}"
        )
    method = method if isinstance(method, Method) else get_method(method)
    opt = RunOptions(**options).validated()
    cs = system.compile(_backend_of(system, method, opt))
    if cs.banded:
        check_banded_method(method)
    if is_sparse(cs):
        SB.check_method(method, opt)
        SB.check_contacts(system)
    if method.solver in (K.EVENTS, EXACT_EVENTS):
        check_event_case(system, cs, method.name)
    stick = np.full(cs.kt.shape[0], STICK, np.int8)
    massless = ML.select_massless(system, opt.massless_dofs) if method.massless else None
    if massless is not None:  # those DOFs without inertia; T_min of the dynamic part
        cs = ML.inertia_free(cs, massless)
    elif opt.massless_dofs != "auto":
        raise InputError(
            "massless_dofs",
            f"is only used by the quasi-static-dofs method, not {method.name}",
            "use method quasi-static-dofs or drop the option",
        )
    if is_sparse(cs) and not sparse_t_min_needed(cs, method, opt, system.period):
        t_min_stick = math.nan  # not computed: neither the step rule nor the given dt uses it (methods/sparse.py)
        dt_limit, dt_stability = _step_limits(cs, method, opt, math.inf, system.period)
    else:
        t_min_stick = state_t_min(cs, stick)  # massless DOFs (zero rows of M) condensed
        dt_limit, dt_stability = _step_limits(cs, method, opt, t_min_stick, system.period)
    plan = _timed_plan(system, method, opt, cs, massless, t_min_stick, dt_limit, dt_stability)
    if is_sparse(cs):
        SB.check_adaptive(plan)
    return plan


def _backend_of(system: System, method: Method, opt: RunOptions) -> str:
    """The System.compile backend of the linear_solver option: 'auto' takes the sparse backend
    where methods.sparse.auto_chooses says so (a sparse structure on which its estimated cost
    per step is the lowest, marched by a method it serves), else the rule of System.compile."""
    if opt.linear_solver == "auto" and SB.auto_chooses(system, method, opt):
        return "sparse"
    return compile_backend(opt.linear_solver)


def sparse_t_min_needed(cs, method, opt, period: float | None) -> bool:
    """Does a plan on the sparse backend need T_min of full stick? Always up to DENSE_EIGEN_MAX_N DOFs (cheap, and
    the dense backend's value); beyond, only under the 't-min' step rule without a given dt
    (the 'accuracy' rule's step and a given dt do not use it, and the eigen-solve of a large
    mesh costs more than its march)."""
    if cs.M.shape[0] <= SB.DENSE_EIGEN_MAX_N:
        return True
    return step_rule_of(method, opt, period) != "accuracy" and opt.dt is None


def _step_limits(
    cs: CompiledSystem, method: Method, opt: RunOptions, t_min_stick: float, period: float | None
) -> tuple[float, float]:
    """(dt_limit, dt_stability) of the step rule: :func:`slipstep.methods.step_control.step_limits`."""
    no_t_min = opt.rtol is not None or step_rule_of(method, opt, period) == "accuracy"
    iterates = not (no_t_min and method.solver == K.PIECEWISE_LINEAR)
    return SC.step_limits(
        cs, opt.scheme, t_min_stick, opt.step_ratio, method.quasi_static, iterates, opt.dt is not None
    )


#: the options the step limits, the compiled system and the workspace depend on: a plan
#: retuned with other values of these is planned again from the start (plan_run)
_LAYOUT_OPTIONS = (
    "scheme",
    "step_ratio",
    "rtol",
    "step_rule",
    "linear_solver",
    "massless_dofs",
    "max_state_iterations",
)


def _timed_plan(
    system: System,
    method: Method,
    opt: RunOptions,
    cs: CompiledSystem,
    massless,
    t_min_stick: float,
    dt_limit: float,
    dt_stability: float,
) -> RunPlan:
    """The part of :func:`plan_run` that depends on the excitation's period: the run's length,
    the save plan, the step and the capacity."""
    period = system.period
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
    save_plan = SV.resolve(opt.save, system, cs, 0.0, t_end, period)
    scheme = opt.scheme
    if period is None and opt.max_step is None and step_rule_of(method, opt, period) == "accuracy" and opt.dt is None:
        raise InputError(
            "step_rule",
            "is 'accuracy', but the excitation has no period, so there is no accuracy cap T / 50",
            "give max_step (or dt), or use step_rule 't-min'",
        )
    max_step = opt.max_step if opt.max_step is not None else default_max_step(period, dt_limit)
    _check_time_scales(t_end, dt_limit, max_step, opt)
    plan = RunPlan(
        system, method, opt, cs, massless, t_min_stick, period, t_end, save_plan, dt_limit, dt_stability, max_step
    )
    dt = plan.fixed_step(max_step)
    if opt.dt is not None and opt.dt > dt_stability * (1 + 1e-12):
        raise InputError(
            "dt",
            f"is {opt.dt:.4g} s, beyond the stability limit {dt_stability:.4g} s of the "
            f"scheme {scheme.name} (Omega_crit = {scheme.omega_crit:.4g})",
            "give a smaller dt or use an unconditionally stable scheme (2 beta >= gamma)",
        )
    if plan.pilot_allowed:  # the refinement may shorten the step: the length check waits for it
        return plan.replace(dt=dt)
    return plan.with_step(dt)


def replanned(plan: RunPlan, compiled: CompiledSystem) -> RunPlan:
    """``plan``'s run on ``compiled``, a compiled system of the same layout whose numbers differ
    (contact stiffnesses or friction patched by a sweep, slipstep.sweep.runner): T_min of full
    stick, the step limits and the timed part planned again, as :func:`plan_run` plans them.
    For plans without massless DOFs and without the pilot refinement (the runner's own)."""
    if plan.massless is not None or plan.pilot_allowed:
        raise ValueError("replanned: a plan with massless DOFs or a pilot refinement is planned by plan_run")
    t_min_stick = state_t_min(compiled, plan.stick)
    dt_limit, dt_stability = _step_limits(compiled, plan.method, plan.options, t_min_stick, plan.period)
    return _timed_plan(plan.system, plan.method, plan.options, compiled, None, t_min_stick, dt_limit, dt_stability)


def retuned_plan(plan: RunPlan, frequency_hz: float, system: System | None = None, **option_changes) -> RunPlan:
    """:meth:`RunPlan.retuned` (see there)."""
    from slipstep.model.retune import retune

    system = retune(plan.system, frequency_hz) if system is None else system
    opt = replace(plan.options, **option_changes).validated()
    cs = _retuned_compiled(plan, system)
    layout_same = all(_same(getattr(opt, k), getattr(plan.options, k)) for k in _LAYOUT_OPTIONS)
    # the default rule follows error_estimate, max_step and the period: the step limits go with it
    layout_same = layout_same and step_rule_of(plan.method, opt, system.period) == plan.step_rule
    if cs is None or not layout_same or (opt.dt is None) != (plan.options.dt is None):
        fields = {name: getattr(opt, name) for name in RunOptions.__dataclass_fields__}
        return plan_run(system, plan.method, **fields)
    return _timed_plan(system, plan.method, opt, cs, plan.massless, plan.t_min_stick, plan.dt_limit, plan.dt_stability)


def _same(a, b) -> bool:
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # arrays inside
        return a is b


def _retuned_compiled(plan: RunPlan, system: System) -> CompiledSystem | None:
    """plan's compiled system with the excitation frequencies of ``system``, when ``system``
    differs from plan's only by them (a retune: the same structure, contacts, constant loads,
    amplitudes and phases); None otherwise. Equal to ``system.compile(...)`` array for array."""
    from slipstep.model.excitation import compile_signal

    old = plan.system
    same = (
        system.structure is old.structure
        and len(system.contacts) == len(old.contacts)
        and all(a is b for a, b in zip(system.contacts, old.contacts))
        and system.motion_names == old.motion_names
        and _same_array(system.excitation.constant_force, old.excitation.constant_force)
    )
    if not same:
        return None
    cs, n, m = plan.compiled, old.structure.n_dofs, len(old.motion_names)
    frequencies = []
    for what, count in (("force", n), ("motion", m)):
        new_sig, old_sig = getattr(system.excitation, what), getattr(old.excitation, what)
        if (new_sig is None) != (old_sig is None):
            return None
        a, b = compile_signal(new_sig, count), compile_signal(old_sig, count)
        if a.table_time.size or b.table_time.size or a.ramp_time != b.ramp_time:
            return None
        if not np.array_equal(a.sin_coefficient, b.sin_coefficient):
            return None
        if not np.array_equal(a.cos_coefficient, b.cos_coefficient):
            return None
        frequencies.append(np.ascontiguousarray(a.frequency, dtype=np.float64))
    return cs._replace(force_frequency=frequencies[0], motion_frequency=frequencies[1])


def _same_array(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return np.array_equal(np.asarray(a), np.asarray(b))


def kernel_settings(plan: RunPlan, dt: float, max_step: float, low_rank: bool) -> K.MarchSettings:
    """The kernel's MarchSettings of a march from t = 0 to plan.t_end with the step dt."""
    opt, cs, method, scheme = plan.options, plan.compiled, plan.method, plan.options.scheme
    accuracy_on = opt.rtol is not None and not method.quasi_static
    return K.march_settings(
        beta=scheme.beta,
        gamma=scheme.gamma,
        alpha_m=scheme.alpha_m,
        alpha_f=scheme.alpha_f,
        dt=dt,
        step_factor=_kernel_step_factor(plan),
        dt_max=min(max_step, plan.dt_stability),
        tol=opt.tolerance,
        state_rtol=opt.state_tolerance,
        singular_rtol=opt.singular_tolerance,
        t_start=0.0,
        t_end=plan.t_end,
        rtol=opt.rtol if accuracy_on else 0.0,
        err_scale=RTOL_LOCAL_FACTOR * cs.length_scale if accuracy_on else 0.0,
        solver=method.solver,
        adaptive=method.adaptive,
        inertia=not method.quasi_static,
        max_iter=opt.max_iterations,
        max_state_iter=opt.max_state_iterations,
        max_redo=opt.max_redo,
        fallback=opt.fallback,
        signals=True,
        preload=0,
        structure=K.BANDED if cs.banded else (K.LOW_RANK if low_rank else K.DENSE),  # (sparse: its own kernel)
    )


def _kernel_step_factor(plan: RunPlan) -> float:
    """The adaptive step's factor dt = factor T_min(S_n) (capped at dt_max): the paper's
    (:func:`slipstep.methods.step_control.kernel_step_factor`) under the 't-min' rule; under
    'accuracy' the stability factor alone (inf for an unconditionally stable scheme: the step is
    the cap dt_max = min(max_step, stability limit))."""
    scheme = plan.options.scheme
    if plan.step_rule == "accuracy" and not plan.method.quasi_static:
        return scheme.stability_limit_factor
    return SC.kernel_step_factor(scheme, plan.options.step_ratio)


def check_banded_method(method: Method) -> None:
    """The banded backend (sparse structures) runs the implicit march's methods; the
    event-driven march and the partly quasi-static method need the dense matrices."""
    if method.solver in (K.EVENTS, EXACT_EVENTS) or method.massless:
        raise InputError(
            "method",
            f"{method.name} needs the dense backend; this sparse structure compiles to the banded one",
            "use newmark, piecewise-linear, their adaptive variants or quasi-static, or give dense matrices "
            "(linear_solver='direct' for a small model)",
        )


def check_event_case(system: System, cs: CompiledSystem, name: str = "quasi-static-events") -> None:
    """The event-driven methods (``name``: quasi-static-events, events) need phases that are
    linear in known harmonic functions of time; the dynamic one a mass on every DOF."""
    other = "quasi-static" if name == "quasi-static-events" else "piecewise-linear"
    if cs.force_table_time.size or cs.motion_table_time.size:
        raise InputError(
            "method",
            f"{name} needs harmonic loads and motions, the case has tables",
            f"use method '{other}' for tabulated signals",
        )
    if cs.force_ramp > 0 or cs.motion_ramp > 0:
        raise InputError(
            "ramp_time",
            f"is set: {name} needs unramped harmonic signals",
            f"remove ramp_time or use method '{other}'",
        )
    circles = without_piecewise_linear_form(system.contacts)
    if circles:
        laws = sorted({c.law for c in system.contacts if c.name in circles})
        raise InputError(
            "method",
            f"{name} needs piecewise-linear contact laws; {circles} use {', '.join(map(repr, laws))}",
            f"use method '{other}' for friction-circle contacts",
        )
    if name != "quasi-static-events" and not cs.banded and np.linalg.matrix_rank(cs.M) < cs.M.shape[0]:
        raise InputError(
            "method",
            f"{name} needs a mass on every DOF (the mass matrix is singular)",
            "use method 'quasi-static-dofs' or 'piecewise-linear' for DOFs without inertia",
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


def compile_backend(linear_solver: str) -> str:
    """The System.compile backend a linear_solver option asks for."""
    return {"banded": "banded", "direct": "dense", "low-rank": "dense", "sparse": "sparse"}.get(linear_solver, "auto")


def use_low_rank(cs: CompiledSystem, linear_solver: str) -> bool:
    """The low-rank (Woodbury) state solve pays when the contact coordinates are few against
    the DOFs (kernels/state_solve.py): 'auto' takes it when 2 nq <= n (never with the banded
    backend, whose banded LU per state is already O(n b^2), nor the sparse one)."""
    if cs.banded or is_sparse(cs):
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
    work = SB.workspace_bytes(cs, opt.max_state_iterations) if is_sparse(cs) else None
    fixes = "simulate fewer periods (or a shorter duration)" + (
        ", use fewer steps_per_period" if quasi_static else ", raise the step ratio"
    )
    points = capacity + 1
    if plan is not None:
        n, nq, nd = plan.dofs.size, plan.rows.size, plan.directions.size
        points = SV.rows_needed(plan, capacity, 0.0, t_end)
        fixes = "save less (save: fewer dofs, every k-th step or the last periods; --save-dofs, --save-every), " + fixes
    limit = None if opt.max_memory is None else memory.parse_size("max_memory", opt.max_memory)
    if work is None:
        work = workspace_bytes(cs, opt.max_state_iterations, low_rank)
    return memory.check(points, n, nq, nd, m, work, limit, field_name, fixes)
