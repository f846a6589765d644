"""The Python face of an explicit march (central difference, RK4): options, preload,
step size, kernel call, Dataset. Mirrors :class:`slipstep.methods.simulation.Simulation`:
the options are validated by methods/plan.py, the start is methods/start.py's static
equilibrium, the kernel is called by methods/marcher.py's KernelEntry, and the result has the
standard schema (Runner.dataset).

    sim = ExplicitSimulation(system, get_integrator("rk4"), adaptive=True, periods=2)
    ds = sim.run()
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from slipstep.errors import InputError, Status
from slipstep.kernels import explicit as E
from slipstep.kernels.settings import march_settings
from slipstep.methods import accuracy
from slipstep.methods.buffers import allocate_outputs
from slipstep.methods.invariants import check_march
from slipstep.methods.divergence import check_divergence
from slipstep.methods.marcher import KernelEntry
from slipstep.methods.options import RunOptions
from slipstep.methods.plan import plan_run
from slipstep.methods.simulation import Runner
from slipstep.methods.start import static_equilibrium
from slipstep.methods import step_control as SC
from slipstep.methods.eigen import mass_factor
from slipstep.model.validate import positive
from slipstep.model.system import System

DEFAULT_STEP_RATIO = RunOptions.step_ratio  # the one default (RunOptions)

#: options an explicit run understands (the rest of RunOptions is for implicit solvers)
EXPLICIT_OPTIONS = (
    "periods",
    "duration",
    "step_ratio",
    "max_step",
    "max_redo",
    "preload_increments",
    "singular_tolerance",
    "state_tolerance",
    "tolerance",
)


class ExplicitSimulation(Runner):
    """One system marched by an explicit integrator, fixed or contact-state adaptive step.

    dt (fixed) = period / ceil(period / min(step_ratio * Omega_crit / omega_max, max_step)), with
    Omega_crit the integrator's stability limit and omega_max the highest frequency over every
    visitable contact state (full stick for most systems; slip can couple higher).
    Adaptive: dt = step_ratio * factor * T_min(S_n), capped at max_step (default period / 50).
    """

    failure_hint = (
        " (an explicit scheme diverges above its stability limit: lower step_ratio; "
        "or a fluttering slip state: `slipstep advise` lists states with complex eigenvalues)"
    )

    def __init__(self, system: System, integrator, adaptive: bool = False, **options):
        if not isinstance(system, System):
            raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
        unknown = set(options) - set(EXPLICIT_OPTIONS)
        if unknown:
            raise InputError(
                "options",
                f"unknown option(s) {sorted(unknown)} for the explicit scheme {integrator.name}",
                f"use only {sorted(EXPLICIT_OPTIONS)}",
            )
        if integrator.kind != "explicit" or integrator.kernel_kind is None:
            raise InputError("scheme", f"{integrator.name} is not an explicit scheme", "use central-difference or rk4")
        self.system, self.integrator, self.adaptive = system, integrator, bool(adaptive)
        ratio = positive("step_ratio", options.get("step_ratio", DEFAULT_STEP_RATIO))
        self._options_given, self._accuracy = dict(options), None
        if ratio > 1.0:
            raise InputError(
                "step_ratio",
                f"is {ratio}: an explicit scheme is unstable above its stability limit",
                "use step_ratio <= 1 (the limit itself is marginal; 0.9 leaves a margin)",
            )
        # validation of the common options by the implicit plan; the preload: its static equilibrium
        pre = plan_run(
            system,
            "newmark",
            error_estimate=False,
            **{k: v for k, v in options.items() if k in RunOptions.__dataclass_fields__},
        )
        self.options = pre.options
        self.compiled = cs = pre.compiled
        if cs.banded:  # issue 10: the explicit kernels use the dense matrices
            raise InputError(
                "scheme",
                f"{integrator.name} needs the dense backend; this sparse structure compiles to the banded one",
                "use an implicit method (newmark, piecewise-linear, ...), or linear_solver='direct' for a small model",
            )
        self.start = static_equilibrium(pre)
        self.q0, self.f0 = self.start.terms.q.copy(), self.start.terms.f.copy()
        self.t_min_stick, self.period, self.t_end = pre.t_min_stick, pre.period, pre.t_end
        factor = ratio * integrator.step_limit_factor
        # the stability limit over every visitable contact state (methods/step_control.py)
        self.dt_limit = SC.stability_limit(ratio * integrator.omega_crit, SC.highest_frequency(cs))
        period, t_end = self.period, self.t_end
        opt = self.options
        self.max_step = dt_max = (
            opt.max_step if opt.max_step is not None else SC.default_max_step(period, self.dt_limit)
        )
        dt = SC.fixed_step(self.dt_limit, dt_max, period, t_end)
        if dt > t_end:
            raise InputError(
                "duration",
                f"({t_end:.3g} s) is shorter than one time step ({dt:.3g} s)",
                "simulate longer or use a smaller step",
            )
        self.dt = dt
        capacity = SC.capacity(t_end, dt, self.dt_limit, dt_max, self.adaptive)
        if capacity > 50_000_000:
            raise InputError("duration", f"needs {capacity} steps", "shorten the run")
        self.settings = march_settings(
            dt=dt,
            step_factor=factor,
            dt_max=dt_max,
            t_start=0.0,
            t_end=t_end,
            singular_rtol=opt.singular_tolerance,
            divergence=1e6 * cs.length_scale,
            solver=integrator.kernel_kind,
            adaptive=self.adaptive,
            max_redo=opt.max_redo,
        )
        self.ws = _allocate_explicit_workspace(cs)
        self.out = allocate_outputs(cs, capacity)
        self.entry = KernelEntry()
        self.status = None
        self.kernel_time = math.nan

    @property
    def preload_state(self) -> tuple:
        """The start as (x, v, a, fe, gf, w, state) (the former form; ``start`` is the State)."""
        s = self.start
        return (s.x, s.v, s.a, s.terms.fe, s.terms.gf, s.w, s.contact_state)

    @property
    def _packed(self):
        return self.entry.packed

    def kernel_arguments(self) -> tuple:
        """The explicit kernel's arguments (sys, settings, ws, out, q0, f0)."""
        return (self.compiled, self.settings, self.ws, self.out, self.q0, self.f0)

    def march(self) -> Status:
        """Run the kernel from the preload state; returns the status (also in self.status)."""
        ws, s = self.ws, self.start
        for dst, src in zip((ws.x, ws.v, ws.a, ws.w, ws.state), (s.x, s.v, s.a, s.w, s.contact_state)):
            dst[:] = src
        self.status, self.kernel_time = self.entry.call(
            E.explicit_kernel(self.settings.structure),
            self.kernel_arguments(),
            self.out,
            self.out.t,
            self.t_end,
            self.progress,
        )
        self._check_interrupted()
        self.status = check_divergence(self.status, self.compiled, self.out)
        return check_march(self)  # the contact invariants of an OK march (slipstep.methods.invariants)

    def _visited_states(self) -> str:
        return ""

    def accuracy_attrs(self) -> dict:
        """The step-doubling estimate with a finer twin (an explicit scheme cannot double its
        step): the same scheme at half the step ratio and cap, err ~ |Q_dt - Q_dt/2| 4/3
        (methods/accuracy.py); computed once; warns above 1 %."""
        if self._accuracy is not None:
            return self._accuracy
        nan = {
            "energy_error_estimate": math.nan,
            "peak_force_error_estimate": math.nan,
            "error_estimate_method": "none",
        }
        if self.status != Status.OK or self.period is None:
            return nan
        opts = dict(
            self._options_given,
            step_ratio=self._options_given.get("step_ratio", DEFAULT_STEP_RATIO) / 2,
            max_step=self.max_step / 2,
            duration=self.t_end,
        )
        opts.pop("periods", None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            twin = ExplicitSimulation(self.system, self.integrator, adaptive=self.adaptive, **opts)
            if twin.march() != Status.OK:
                return nan
        n, m = int(self.out.counters[E.C_STEPS]), int(twin.out.counters[E.C_STEPS])
        e1, p1 = accuracy.loop_energy(self.out, n, self.compiled, self.period)
        e2, p2 = accuracy.loop_energy(twin.out, m, twin.compiled, self.period)
        self._accuracy = {
            "energy_error_estimate": accuracy.richardson(e1, e2, 0.5),
            "peak_force_error_estimate": accuracy.richardson(p1, p2, 0.5),
            "error_estimate_method": "step halving: the same scheme at half the step",
        }
        if self._accuracy["energy_error_estimate"] > accuracy.WARN_LIMIT:
            warnings.warn(
                f"the estimated time-discretisation error of the dissipated energy per cycle is "
                f"{100 * self._accuracy['energy_error_estimate']:.2g} % (step halving): lower step_ratio "
                f"or max_step",
                stacklevel=3,
            )
        return self._accuracy

    def method_attrs(self) -> dict:
        name = self.integrator.name
        return {
            "method": f"{name}-adaptive" if self.adaptive else name,
            "paper_method": "App. A (explicit)",
            "solver": "explicit",
            "adaptive_step": self.adaptive,
            "quasi_static": False,
            "scheme": name,
            "fallback_steps": 0,
        }


def _allocate_explicit_workspace(cs) -> E.ExplicitWorkspace:
    n, nq, nd, m = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.B.shape[1]
    cap = 512
    z = lambda *shape: np.zeros(shape)
    i8 = lambda *shape: np.zeros(shape, np.int8)
    return E.ExplicitWorkspace(
        x=z(n),
        v=z(n),
        a=z(n),
        w=z(nd),
        state=i8(nd),
        x1=z(n),
        v1=z(n),
        a1=z(n),
        q1=z(nq),
        f1=z(nq),
        w1=z(nd),
        state1=i8(nd),
        gf=z(n),
        fe=z(n),
        p=z(m),
        rhs=z(n),
        xs=z(n),
        vs=z(n),
        kx=z(4, n),
        kv=z(4, n),
        fs=z(nq),
        ws_=z(nd),
        ss=i8(nd),
        lu=z(n, n),
        piv=np.zeros(n, np.int64),
        mass_factor=mass_factor(cs.M),
        tmin_keys=i8(cap, nd),
        tmin_used=np.zeros(cap, np.bool_),
        tmin_value=z(cap),
    )
