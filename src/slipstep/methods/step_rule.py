"""The step rule of a dynamic march (issue 26 item 3): what sets the step, 't-min' (the
paper's convergence limit of the fixed-point iteration, paper 4.2) or 'accuracy' (the cap
T / 50 or max_step, refined by the step-doubling estimate, and the stability limit). One place
of the rule, used by the plan (methods/plan.py) and by the sparse backend's choice
(methods/sparse.py)."""

from __future__ import annotations

from slipstep.errors import InputError
from slipstep.kernels import march as K


def step_rule_of(method, opt, period: float | None) -> str:
    """The step rule of ``method`` (a registry Method) under ``opt`` (RunOptions) for an excitation of period ``period`` [s]
    (None: tables only); the one place of the rule.

    Given (opt.step_rule), it wins; 'accuracy' for a method that iterates within a step
    (Methods 1, 2, full Newton, the event-driven ones) is refused: its fixed-point iteration
    converges only below the T_min limit. Not given:

        'accuracy'  the dynamic piecewise-linear methods (Methods 3, 2+3, 3+4: nothing iterates
                    within a linear phase, so T_min sets nothing) when something caps the step
                    (the period's T / 50 or max_step) and something controls the error (the
                    step-doubling estimate, rtol, or the user's max_step): dt = min(cap,
                    stability limit), refined by the estimate;
        't-min'     every other case (paper 4.2): the methods that iterate, Method 4 (its step
                    is T / steps_per_period), runs driven by tables without a period or
                    max_step, and runs with error_estimate off and neither rtol nor max_step,
                    where T / 50 unchecked by any estimate is not safe (a random system marched
                    by Method 3 at T / 50 without the estimate diverged).
    """
    iterates = method.solver != K.PIECEWISE_LINEAR and not method.quasi_static
    if opt.step_rule is not None:
        if opt.step_rule == "accuracy" and iterates:
            raise InputError(
                "step_rule",
                f"is 'accuracy', but {method.name} iterates within a step and converges only below the T_min limit",
                "use step_rule 't-min' (the default of this method) or a piecewise-linear method",
            )
        return opt.step_rule
    if method.solver != K.PIECEWISE_LINEAR or method.quasi_static:
        return "t-min"
    capped = period is not None or opt.max_step is not None
    controlled = opt.error_estimate or opt.rtol is not None or opt.max_step is not None
    return "accuracy" if capped and controlled else "t-min"
