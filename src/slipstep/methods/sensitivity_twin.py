"""The sensitivity twin of a run (issue 29 item 3): a perturbed, tighter twin of the march.

A status-OK result can be off its discrete solution by far more than the step solver's error:
where the system amplifies per-step errors (chaotic impact oscillators: a 1e-10 change of the
loads moves the response by 1e4..1e10 times as much), and where a step solved to the Newton
tolerance lands on a contact state or a stick/slip decision its tighter solution does not take
(single-DOF stick-slip oscillators: the result moves by 1e-6..2e-4 of its range between tolerance
1e-11 and 1e-13). No tolerance-based flag sees either: both are properties of the trajectory. The
twin measures them. With the run's plan (the same time grid, save plan, scheme and start rule) it
marches the system whose every load and motion (constant, harmonic, tabulated) is scaled by
1 + PERTURBATION (:func:`perturbed`, :func:`perturbed_compiled`) with the Newton tolerance times
TWIN_TOLERANCE_FACTOR (not below TWIN_MIN_TOLERANCE; the piecewise-linear solves have none), from
its own static preload, and records

    twin_difference = max_t,j |x_j - x~_j| / R,   R = max_j (max_t x_j - min_t x_j)

(x the run's saved DOF histories, x~ the twin's on the same rows, interpolated in time where an
adaptive grid moved; R the largest DOF range, the denominator of
study.verification.agreement_error). It is the change of the result under a change of its inputs
and of its solver far below what any user controls: the result is neither reproducible nor
accurate to better than that fraction of its range (on a system that is not sensitive the tighter
twin is close to the discrete solution, so twin_difference is close to the result's own error).
Above TWIN_FLAG the run warns (:class:`SensitivityWarning`, :func:`sensitivity_text`) and
``invariants.flagged`` gives the reason.

The option ``sensitivity_check`` (RunOptions): True runs the twin on every OK march of
``slipstep.run`` / ``Simulation.run`` (dynamic and quasi-static, fixed or adaptive step; not the
explicit schemes nor 'events', which have no Simulation); False never; 'auto' (the default) only
where it is likely needed and cheap (:func:`auto_wanted`): a dynamic fixed-step march in which at
least AUTO_STATE_CHANGE_SHARE of the steps changed a contact state (the counters) and whose
steps x DOFs is at most AUTO_MAX_WORK. The steady-state paths march with ``march()`` (no twin),
the FRF, sweep and HBM cross-check paths pass False (they have their own checks).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace

import numpy as np

#: the relative change of every load and motion of the twin (study.verification's sensitivity twin too)
PERTURBATION = 1e-10
#: the twin's Newton tolerance: the run's times this ...
TWIN_TOLERANCE_FACTOR = 1e-2
#: ... and not below this (modified Newton stalls at round-off below it)
TWIN_MIN_TOLERANCE = 1e-14
#: above this twin_difference the run warns (the agreement bar of benchmarks/random_systems.py --trust)
TWIN_FLAG = 1e-6
#: 'auto' runs the twin when at least this share of the steps changed a contact state ...
AUTO_STATE_CHANGE_SHARE = 0.05
#: ... and the march's steps x DOFs is at most this (the twin costs about one more march)
AUTO_MAX_WORK = 2e6


class SensitivityWarning(RuntimeWarning):
    """A run that moved by more than TWIN_FLAG of its range under the sensitivity twin (module
    docstring): not reproducible to better than twin_difference of its range."""


def perturbed(system, eps: float):
    """The System with every load and motion (constant, harmonic, tabulated) scaled by 1 + eps."""

    def scale(sig):
        if sig is None:
            return None
        return replace(
            sig,
            harmonics=tuple(replace(h, amplitude=h.amplitude * (1 + eps)) for h in sig.harmonics),
            tables=tuple(replace(tab, values=tab.values * (1 + eps)) for tab in sig.tables),
        )

    exc = system.excitation
    f0 = None if exc.constant_force is None else np.asarray(exc.constant_force) * (1 + eps)
    return replace(system, excitation=replace(exc, constant_force=f0, force=scale(exc.force), motion=scale(exc.motion)))


def perturbed_compiled(cs, eps: float):
    """The compiled system (model.system.CompiledSystem) of :func:`perturbed`: the constant force,
    the force and motion coefficients and tables scaled by 1 + eps (every load enters the march
    linearly, condensed or not), the length scale of the tolerances kept."""
    s = 1.0 + eps
    return cs._replace(
        constant_force=cs.constant_force * s,
        force_sin=cs.force_sin * s,
        force_cos=cs.force_cos * s,
        force_table_value=cs.force_table_value * s,
        motion_sin=cs.motion_sin * s,
        motion_cos=cs.motion_cos * s,
        motion_table_value=cs.motion_table_value * s,
    )


def auto_wanted(sim) -> bool:
    """Does 'auto' run the twin on this OK march (module docstring)?"""
    from slipstep.kernels.codes import C_STATE_CHANGES, C_STEPS

    plan = sim.plan
    if plan.method.quasi_static or plan.method.adaptive or plan.massless is not None:
        return False
    steps = int(sim.out.counters[C_STEPS])
    if steps < 1 or steps * plan.system.n_dofs > AUTO_MAX_WORK:
        return False
    return int(sim.out.counters[C_STATE_CHANGES]) >= AUTO_STATE_CHANGE_SHARE * steps


def check(sim, given_start: bool = False) -> dict:
    """The sensitivity-twin attrs of the OK march of ``sim`` (a Simulation after ``march()``), by
    its option ``sensitivity_check``: {} when the twin does not run; else ``twin_difference``
    (module docstring; NaN when the twin failed or nothing moved) and ``twin_time_s`` (the twin's
    CPU time), with a SensitivityWarning above TWIN_FLAG. ``given_start``: the march started from
    a given state (start_from), which the twin cannot reproduce: no twin."""
    from slipstep.errors import Status

    option = sim.options.sensitivity_check
    auto = isinstance(option, str)  # 'auto' (RunOptions.validated: else a bool)
    if (not auto and not option) or sim.status != Status.OK or given_start:
        return {}
    if auto and not auto_wanted(sim):
        return {}
    cpu = time.process_time()
    value = twin_difference(sim)
    attrs = {"twin_difference": value, "twin_time_s": time.process_time() - cpu}
    if value > TWIN_FLAG:
        warnings.warn(sensitivity_text(value, float(sim.options.tolerance)), SensitivityWarning, stacklevel=4)
    return attrs


def twin_tolerance(tolerance: float) -> float:
    """The twin's Newton tolerance (module docstring)."""
    return max(tolerance * TWIN_TOLERANCE_FACTOR, min(tolerance, TWIN_MIN_TOLERANCE))


def twin_difference(sim) -> float:
    """twin_difference (module docstring) of the march of ``sim``: the twin on the perturbed
    compiled system with the same plan (grid, save plan) at the twin's tolerance, from its own
    static preload; NaN when the twin does not end OK, nothing moved or no DOF was saved."""
    from slipstep.errors import InputError, SolverError, Status
    from slipstep.kernels.codes import C_STEPS
    from slipstep.methods.buffers import saved_rows
    from slipstep.methods.marcher import Marcher
    from slipstep.methods.plan import kernel_settings
    from slipstep.methods.start import static_equilibrium

    plan = sim.plan
    out = sim.out
    rows = saved_rows(out, int(out.counters[C_STEPS]))
    x, t = np.asarray(out.x[:rows]), np.asarray(out.t[:rows])
    if rows < 2 or x.ndim != 2 or x.shape[1] == 0:
        return math.nan
    span = float(np.ptp(x, axis=0).max())
    if not span > 0.0:
        return math.nan
    other = plan.replace(
        system=perturbed(plan.system, PERTURBATION),
        compiled=perturbed_compiled(plan.compiled, PERTURBATION),
        options=replace(plan.options, tolerance=twin_tolerance(plan.options.tolerance)),
        coarse=None,
    )
    other = other.replace(settings=kernel_settings(other, plan.dt, plan.max_step, plan.low_rank))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            marcher = Marcher(other)
            segment = marcher.advance(static_equilibrium(other, marcher.ws))
        except (InputError, SolverError):
            return math.nan
    if segment.status != Status.OK:
        return math.nan
    tw = marcher.out
    rows2 = saved_rows(tw, int(tw.counters[C_STEPS]))
    x2, t2 = np.asarray(tw.x[:rows2]), np.asarray(tw.t[:rows2])
    if rows2 != rows or not np.array_equal(t2, t):  # an adaptive grid moved: the twin at the run's times
        x2 = np.column_stack([np.interp(t, t2, x2[:, j]) for j in range(x.shape[1])])
    return float(np.abs(x - x2).max() / span)


def sensitivity_text(value: float, tolerance: float) -> str:
    """The words of the sensitivity flag (the warning, and the reason ``invariants.flagged`` gives)."""
    return (
        f"the response moved by {value:.2g} of its range (twin_difference, above {TWIN_FLAG:g}) in a twin run "
        f"with every load scaled by 1 + {PERTURBATION:g} and the Newton tolerance {1 / TWIN_TOLERANCE_FACTOR:g} "
        f"times tighter (now {tolerance:g}): the result is not reproducible to better than that, since the "
        "trajectory amplifies the step solver's error (chaotic impacts, or stick/slip decisions at the tolerance). "
        "Tighten the tolerance (tolerance option, `slipstep run --tolerance`, [run] tolerance) or use "
        "method='piecewise-linear' (`-m 3`, no Newton tolerance), and trust statistics over periods (loop energy, "
        "peak forces), not the trajectory"
    )
