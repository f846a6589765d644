"""The options of a run (:class:`RunOptions`): every field, its default and its validation.

One place for the defaults of a march; :func:`slipstep.methods.plan.plan_run` validates them
(:meth:`RunOptions.validated`) before anything is computed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError
from slipstep.kernels import settings as KS
from slipstep.methods import memory
from slipstep.methods import save as SV
from slipstep.methods.schemes import Scheme, newmark
from slipstep.model.validate import positive

#: the values of RunOptions.linear_solver
LINEAR_SOLVERS = ("auto", "direct", "low-rank", "banded", "sparse")
#: the values of RunOptions.step_rule (None: the method's default, methods/step_rule.py ``step_rule_of``)
STEP_RULES = ("accuracy", "t-min")


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
        reordered by reverse Cuthill-McKee, a banded LU per contact state: slipstep.model.system,
        kernels/banded.py), 'sparse' (one sparse LU per step size, the contact problem condensed
        on the contact coordinates: kernels/sparse.py; the dynamic piecewise-linear methods) or
        'auto' (sparse where methods.sparse.auto_choice estimates it cheapest per step, for a
        method it serves and at least methods.sparse.SPARSE_MIN_N DOFs, banded for a sparse structure of at least
        slipstep.model.system.BANDED_MIN_N DOFs with a narrow band, else low-rank when the contact
        coordinates are at most half the DOFs, else direct).
    rtol: accuracy the user sets (dynamic methods): the step follows the local error estimate
        of each step (kernels/march.py, "accuracy control") so that the loop energy per cycle is
        within about rtol; it never exceeds the contact-state / convergence rule of Newton
        methods, nor the stability limit; the piecewise-linear solve obeys only the latter.
    step_rule: what sets the step of a dynamic run: 't-min' (the paper's rule: the convergence
        limit r T_min(stick) / (2 pi sqrt(beta)), the cap max_step and the stability limit) or
        'accuracy' (the solves that do not iterate, the piecewise-linear methods only: the cap
        max_step refined by the step-doubling error estimate, and the stability limit; T_min
        plays no part; with a period or max_step only). None: the method's default
        (methods/step_rule.py ``step_rule_of``): 'accuracy' for the dynamic piecewise-linear
        methods with a period or max_step and an error control (error_estimate, rtol or
        max_step), else 't-min'; ``slipstep compare`` and the built-in paper case pass 't-min'
        so that Methods 1 and 3 march the paper's steps.
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
    sensitivity_check: march a twin with every load and motion scaled by 1 + 1e-10 and the Newton
        tolerance 100 times tighter, and record how far the response moved (attr twin_difference,
        a fraction of its range; a SensitivityWarning above methods.sensitivity_twin.TWIN_FLAG =
        1e-6): True on every OK run (``run()``), False never, 'auto' on the dynamic fixed-step
        runs where at least 5 % of the steps changed a contact state and steps x DOFs is at most
        2e6 (methods/sensitivity_twin.py). The steady-state, FRF, sweep and HBM cross-check paths
        never run it.
    """

    periods: float = 3.0
    duration: float | None = None
    step_ratio: float = 1.0
    steps_per_period: int = 300
    scheme: Scheme = field(default_factory=newmark)
    tolerance: float = KS.NEWTON_TOL
    state_tolerance: float = KS.STATE_RTOL
    singular_tolerance: float = KS.SINGULAR_RTOL
    max_iterations: int = KS.MAX_ITER
    max_state_iterations: int = KS.MAX_STATE_ITER
    max_redo: int = KS.MAX_REDO
    max_step: float | None = None
    preload_increments: int = 45
    fallback: bool = True
    dt: float | None = None
    linear_solver: str = "auto"
    rtol: float | None = None
    step_rule: str | None = None
    error_estimate: bool = True
    max_memory: float | None = None
    massless_dofs: object = "auto"
    save: object = "auto"
    sensitivity_check: object = "auto"

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
        if self.step_rule is not None and self.step_rule not in STEP_RULES:
            raise InputError("step_rule", f"is {self.step_rule!r}", "use 'accuracy' or 't-min' (or leave it out)")
        SV.as_save(self.save)
        check = self.sensitivity_check
        if not (check == "auto" if isinstance(check, str) else isinstance(check, (bool, np.bool_))):
            raise InputError("sensitivity_check", f"is {self.sensitivity_check!r}", "use 'auto', True or False")
        if not isinstance(self.scheme, Scheme):
            raise InputError("scheme", f"is {self.scheme!r}", "use slipstep.newmark(), hht() or generalized_alpha()")
        return self
