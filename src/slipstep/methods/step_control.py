"""The time step of every method and scheme, in one place (issue 9 item 2): the implicit
runner (methods/simulation.py), the explicit one (integrators/explicit_simulation.py), the
accuracy rule (methods/accuracy.py) and the advisor (study/advise.py) take their steps from here; the
march computes T_min of the states it visits with the same formula (kernels/march.py
``_state_step_limit``, kernels/eigen.py).

    T_min(S)       = 2 pi / omega_max(S),  omega_max^2 = max |eig(M^-1 (K + K_D(S)))|   (paper Eq. 8)
                     from the largest eigenvalue alone (methods/eigen.py); DOFs without mass
                     condensed out (methods/massless.py)
    convergence    dt <= r T_min / (2 pi sqrt(beta))      modified Newton (paper 4.2), r = step_ratio
    stability      dt <= Omega_crit / omega_max           omega_max over every visitable state
                                                          (:func:`highest_frequency`); Omega_crit of
                                                          the scheme (:func:`newmark_omega_crit`;
                                                          explicit schemes: their class attribute)
    accuracy cap   dt <= max_step, default period / 50    (:func:`default_max_step`)
    fixed step     min(limits) rounded down to whole steps per period (:func:`fixed_step`)
    adaptive step  min(step_factor T_min(S_n), dt_max) in the kernel, step_factor =
                   min(r / (2 pi sqrt(beta)), Omega_crit / (2 pi)) (:func:`kernel_step_factor`)
    capacity       the output rows a march may need (:func:`capacity`)
"""

from __future__ import annotations

import itertools
import math
import warnings
from typing import TYPE_CHECKING


from slipstep.errors import InputError
from slipstep.kernels.codes import LIFT, SLIP_NEG, SLIP_POS, STICK

if TYPE_CHECKING:
    import numpy as np

# light at import (the CLI's listings read the factors below): numpy and the numerical
# modules (kernels.contact, methods.eigen) are imported by the functions that need them

#: all state combinations are searched for the highest frequency up to this many directions
MAX_ENUMERATED_DIRECTIONS = 5
#: default accuracy cap: at least this many steps per excitation period
STEPS_PER_PERIOD_CAP = 50
#: without a period: the cap is this many full-stick steps
STICK_STEPS_CAP = 10


# -- T_min ---------------------------------------------------------------------------------
def effective_stiffness(cs, state) -> "np.ndarray":
    """K_eff = K + K_D(S) of one contact state (the law's stiffness, kernels/contact.py)."""
    import numpy as np

    from slipstep.kernels.contact import add_contact_stiffness

    K = cs.K.copy()
    add_contact_stiffness(cs, np.asarray(state, np.int8), 1.0, K)
    return K


def contact_state_vector(cs, state, field: str = "state") -> "np.ndarray":
    """``state`` as the int8 contact-state vector of ``cs``: one code of kernels/codes.py
    (0 lift-off .. 4 slip-circle) per tangential direction, or an InputError naming ``field``."""
    import numpy as np

    from slipstep.errors import InputError
    from slipstep.kernels.codes import STATE_NAMES

    nd = cs.kt.shape[0]
    codes = ", ".join(f"{i} {name}" for i, name in enumerate(STATE_NAMES))
    raw = np.asarray(state)
    if raw.ndim != 1 or raw.shape[0] != nd:
        raise InputError(
            field,
            f"has shape {raw.shape}, the system has {nd} tangential directions",
            f"give one contact-state code per direction ({nd} values; codes {codes})",
        )
    if raw.dtype.kind not in "iu" or (raw.size and (raw.min() < 0 or raw.max() >= len(STATE_NAMES))):
        raise InputError(field, f"holds {raw.tolist()}, not contact-state codes", f"give integer codes: {codes}")
    return raw.astype(np.int8)


def t_min_of_omega(omega_max: float) -> float:
    """T_min = 2 pi / omega_max [s] (paper Eq. 8; inf when omega_max = 0): the one T_min formula."""
    return 2 * math.pi / omega_max if omega_max > 0 else math.inf


def t_min_of(omega2: float) -> float:
    """T_min of omega_max^2 [rad^2/s^2]: :func:`t_min_of_omega` of its square root."""
    return t_min_of_omega(math.sqrt(omega2)) if omega2 > 0 else math.inf


def state_omega2(cs, state) -> float:
    """omega_max^2 = max |eig(M^-1 (K + K_D(S)))| [rad^2/s^2] from the largest eigenvalue alone
    (methods/eigen.py); with massless DOFs (zero rows of M) those are condensed out, and a state
    in which they have no quasi-static equilibrium is refused (methods/massless.py)."""
    import numpy as np

    from slipstep.methods import eigen
    from slipstep.methods import massless as ML

    state = contact_state_vector(cs, state)
    if cs.banded:  # banded backend (issue 10): Arnoldi on the band, as the march per state
        return eigen.banded_lambda_max(cs, state)
    if cs.M.shape[1] != cs.M.shape[0]:  # the sparse backend (issue 26): the structure's own matrices
        from slipstep.methods import sparse

        return sparse.omega2(cs, state)
    K = effective_stiffness(cs, state)
    zero = ML.massless_mask(cs.M)
    if zero.any():
        ML.check_held(K, np.flatnonzero(zero))
    return float(abs(eigen.largest_eigenvalue(cs.M, K)))


def state_t_min(cs, state) -> float:
    """T_min = 2 pi / omega_max of a contact state [s] (paper Eq. 8), omega_max^2 =
    max |eig(M^-1 (K + K_D(S)))| from the largest eigenvalue alone, massless DOFs condensed."""
    return t_min_of(state_omega2(cs, state))


def state_omega_max(cs, state) -> float:
    """omega_max = sqrt(max |eig(M^-1 (K + K_D(S)))|) of one contact state [rad/s]."""
    return math.sqrt(state_omega2(cs, state))


def state_eigenvalues(cs, state) -> "np.ndarray":
    """Every eigenvalue lambda of M^-1 (K + K_D(S)) (massless DOFs condensed): a full dense
    decomposition, for the analyses that need the whole spectrum (the advisor's frequencies and
    flutter test, the filter's ringing frequencies); the step needs only :func:`state_t_min`."""
    import numpy as np

    from slipstep.methods import massless as ML

    zero = ML.massless_mask(cs.M)
    if zero.any():
        return ML.condensed_eigenvalues(cs, state, np.flatnonzero(zero))
    return np.linalg.eigvals(np.linalg.solve(cs.M, effective_stiffness(cs, state)))


def highest_frequency(cs) -> float:
    """The highest omega_max over the contact states a march can visit [rad/s]: every
    combination of stick, slip+, slip- and lift-off (lift-off shared by a contact's
    directions) for up to MAX_ENUMERATED_DIRECTIONS directions, else full stick and the
    uniform slip states (slip couples mu k_n into the tangential rows and can raise it)."""
    import numpy as np

    nd = cs.kt.shape[0]
    owner = np.asarray(cs.direction_contact)
    if nd <= MAX_ENUMERATED_DIRECTIONS:
        states = itertools.product((STICK, SLIP_POS, SLIP_NEG, LIFT), repeat=nd)
    else:
        states = [(s,) * nd for s in (STICK, SLIP_POS, SLIP_NEG)]
    best = 0.0
    for st in states:
        st = np.array(st, np.int8)
        lifted = {owner[d] for d in range(nd) if st[d] == LIFT}
        if any((st[d] == LIFT) != (owner[d] in lifted) for d in range(nd)):
            continue  # lift-off is a contact's state, not a direction's
        best = max(best, state_omega_max(cs, st))
    return best


# -- factors of the schemes ---------------------------------------------------------------
def convergence_factor(beta: float) -> float:
    """dt <= factor * T_min: the convergence limit of the fixed-point (modified Newton)
    iteration of a Newmark step, dt < T_min / (2 pi sqrt(beta)) (paper 4.2)."""
    return 1.0 / (2.0 * math.pi * math.sqrt(beta))


def newmark_omega_crit(beta: float, gamma: float, alpha_m: float = 0.0, alpha_f: float = 0.0) -> float:
    """Stability limit Omega_crit = omega_max dt of the linear step (inf: unconditionally stable).

    Newmark (Hughes 1987, 9.1): unconditionally stable for 2 beta >= gamma >= 1/2; otherwise
    stable for omega dt <= Omega_crit = 1 / sqrt(gamma/2 - beta) (undamped, the binding case):
    beta = 1/6: 2 sqrt(3) = 3.46; beta = 1/12: sqrt(6) = 2.45. HHT (alpha in [0, 1/3]) and
    generalised alpha (rho_inf in [0, 1]) satisfy alpha_m <= alpha_f <= 1/2,
    beta >= 1/4 + (alpha_f - alpha_m)/2 and are unconditionally stable (Chung & Hulbert 1993)."""
    if alpha_m != 0.0 or alpha_f != 0.0 or 2.0 * beta >= gamma - 1e-14:
        return math.inf
    return 1.0 / math.sqrt(gamma / 2.0 - beta)


def stability_factor(omega_crit: float) -> float:
    """dt <= factor * T_min for stability, factor = Omega_crit / (2 pi) (inf if unconditional)."""
    return omega_crit / (2.0 * math.pi)


def stability_limit(omega_crit: float, omega_max: float) -> float:
    """dt <= Omega_crit / omega_max [s] (inf for an unconditionally stable scheme or omega_max = 0)."""
    return omega_crit / omega_max if omega_max > 0 and math.isfinite(omega_crit) else math.inf


def kernel_step_factor(scheme, step_ratio: float) -> float:
    """The adaptive step's factor dt = factor * T_min(S) of the march: the convergence factor
    times the step ratio, never beyond the stability factor."""
    return min(step_ratio * scheme.step_limit_factor, scheme.stability_limit_factor)


# -- the steps of a run ------------------------------------------------------------------
def default_max_step(period: float | None, dt_stick: float) -> float:
    """The accuracy cap of dynamic steps, fixed and adaptive: at least 50 steps per excitation
    period (the T_min rule of paper 4.2 is a convergence limit and says nothing about accuracy
    when the structure's highest frequency is close to the excitation); without a period, 10
    full-stick steps (the cap then only bounds adaptive steps in lift-off, where T_min = inf)."""
    return period / STEPS_PER_PERIOD_CAP if period else STICK_STEPS_CAP * dt_stick


def step_limits(
    cs, scheme, t_min_stick: float, step_ratio: float, quasi_static: bool, iterates: bool, dt_given: bool
) -> tuple[float, float]:
    """(dt_limit, dt_stability) of an implicit run: the convergence limit r * factor *
    T_min(stick) (paper 4.2), capped at the scheme's stability limit Omega_crit / omega_max
    (omega_max over every visitable contact state) with a warning unless dt is given. A solve
    that does not iterate within a linear phase (``iterates`` False: the piecewise-linear solve
    with rtol) keeps the stability limit only; quasi-static runs have no inertia limit."""
    dt_stability = math.inf
    if math.isfinite(scheme.omega_crit) and not quasi_static:
        dt_stability = stability_limit(scheme.omega_crit, highest_frequency(cs))
    conv = step_ratio * scheme.step_limit_factor * t_min_stick
    if not iterates and not quasi_static:
        conv = dt_stability  # nothing iterates within a linear phase: only stability limits the step
    if conv > dt_stability * (1 + 1e-12) and not dt_given:
        warnings.warn(
            f"step_ratio {step_ratio:g} gives dt = {conv:.4g} s, beyond the stability limit "
            f"{dt_stability:.4g} s of {scheme.name} (omega_max dt <= {scheme.omega_crit:.4g}): the step "
            f"is capped at the stability limit",
            stacklevel=5,
        )
        conv = dt_stability
    return conv, dt_stability


def whole_step_count(period: float, limit: float) -> int:
    """The fewest whole steps per period with steps <= limit: ceil(period / limit)."""
    return math.ceil(period / limit * (1 - 1e-12))


def whole_steps(period: float, limit: float) -> float:
    """The longest step <= limit with a whole number of steps per period: period / ceil(period / limit)."""
    return period / whole_step_count(period, limit)


def fixed_step(
    limit: float,
    max_step: float,
    period: float | None,
    t_end: float,
    dt: float | None = None,
    steps_per_period: int | None = None,
) -> float:
    """The fixed step: ``dt`` when given; quasi-static (``steps_per_period`` given): period /
    steps_per_period; else min(limit, max_step) rounded down to whole steps per period."""
    if dt is not None:
        return dt
    if steps_per_period is not None:
        return (period if period is not None else t_end) / steps_per_period
    if not math.isfinite(limit) and not math.isfinite(max_step):
        raise InputError(
            "structure", "has no stiffness at all in full stick (T_min is infinite)", "add contacts or stiffness"
        )
    if period is not None:
        return whole_steps(period, min(limit, max_step))
    return min(limit, max_step)


def steps_for(t_end: float, dt: float) -> int:
    """Steps of a fixed-step march: ceil(t_end / dt) (a last step shorter than dt ends it)."""
    return math.ceil(t_end / dt * (1 + 1e-12))


def capacity(
    t_end: float,
    dt: float,
    dt_limit: float,
    dt_max: float,
    adaptive: bool,
    rtol: float | None = None,
    t_min_stick: float = math.inf,
) -> int:
    """Output rows a march may need (beyond the initial point): with rtol (dynamic) the local
    error O(dt^3) sets the step: 4 t_end / min(T_min/pi, dt_max) (1e-2 / rtol)^(1/3) + 100;
    adaptive: 3 t_end / min(dt_limit, dt_max) + 100 (redos and short steps); fixed: the steps + 1."""
    if rtol is not None:
        base = min(t_min_stick / math.pi, dt_max)
        return math.ceil(4 * t_end / base * max(1.0, (1e-2 / rtol) ** (1 / 3))) + 100
    if adaptive:
        return 3 * math.ceil(t_end / min(dt_limit, dt_max)) + 100
    return steps_for(t_end, dt) + 1
