"""Periodic steady state by shooting: Newton on the one-period map of the march.

Unknowns z = (x, v, w) at the start of a period (quasi-static: (x, w)); the acceleration is
the consistent one, a = M^-1 (f_e - C v - K x - A^T f(x, w)). With P the discrete
one-period map of the march (the piecewise-linear Newmark steps), the periodic orbit solves

    R(z) = P(z) - z = 0,     Newton:  (Phi - I) dz = -R(z),   Phi = dP/dz

Phi is the exact derivative of the discrete map, propagated through the recorded steps of
the period (kernels/sensitivity.py): each step is linear in the previous state once its
contact state is known, so when the state sequence of the orbit is found Newton converges
in one more iteration. The Newton system is solved in scaled unknowns (the block scales of
slipstep.steady.state) by least squares; a slider that sticks over the whole period has a
row e_d of Phi (its position is a free parameter of the orbit, multiplier exactly 1): it is
kept fixed and its multiplier reported as neutral. When Newton stalls (the change decreases
less than the best period so far), the step is halved along the last Newton direction up to
``max_backtracks`` times, then the march continues ``settle_periods`` periods from the best
period before Newton resumes; after ``max_iterations`` periods in Newton the solver falls back
to plain marching.

From the static preload (no ``initial``) the march first runs ``warmup_periods`` periods: the
start transient visits contact-state sequences far from the orbit's, where Newton wanders.

The Floquet multipliers are the eigenvalues of Phi at the converged orbit (neutral ones
removed): all inside the unit circle for a stable orbit.
"""

from __future__ import annotations

import math
import time

import numpy as np

from slipstep.errors import InputError, SolverError, Status
from slipstep.kernels.codes import C_STEPS, SLIP_COUPLED, STICK
from slipstep.kernels.sensitivity import period_sensitivity
from slipstep.kernels.settings import contact_table
from slipstep.methods.blas import on_one_blas_thread
from slipstep.methods.invariants import check_march
from slipstep.methods.massless import inverse_mass
from slipstep.methods.simulation import Simulation
from slipstep.steady.marching import (
    check_tolerance,
    finish,
    march_one_period,
    march_periods,
    period_simulation,
    start,
)
from slipstep.steady.state import State, SteadyState, as_state, period_scales
from slipstep.model.structure import DENSE_MAX_N
from slipstep.model.system import System


def _unknowns(s: State, quasi: bool) -> np.ndarray:
    return s.unknowns(quasi)


def _from_unknowns(z: np.ndarray, n: int, quasi: bool, states) -> State:
    return State.from_unknowns(z, n, quasi, states)


def _auto_takes_sparse(system: System, method, run_options: dict) -> bool:
    """Would linear_solver 'auto' march ``method`` on the sparse backend (False where the
    options are bad: the plan names them)?"""
    from slipstep.methods import sparse as SB
    from slipstep.methods.options import RunOptions
    from slipstep.methods.registry import get_method

    if method is None or system.n_dofs < SB.SPARSE_MIN_N:
        return False
    try:
        m = method if not isinstance(method, str) else get_method(method)
        return SB.auto_chooses(system, m, RunOptions(**run_options).validated())
    except (InputError, TypeError, ValueError):
        return False


def dense_backend_options(system: System, run_options: dict, method=None) -> dict:
    """The run options with ``linear_solver='direct'`` added for a sparse structure (which
    ``System.compile`` would put on the banded backend): the period Jacobian Phi is dense over
    2 n + n_d unknowns whatever the backend, so shooting marches densely (a sparse structure
    above DENSE_MAX_N DOFs is refused there, naming harmonic balance). A given linear_solver is
    kept. Dense input matrices keep 'auto' (the dense backend) unless 'auto' would take the
    condensed sparse backend by its cost estimate (methods.sparse.auto_chooses): then 'direct'."""
    if "linear_solver" in run_options:
        return run_options
    if not system.structure.sparse:
        return (
            {**run_options, "linear_solver": "direct"}
            if _auto_takes_sparse(system, method, run_options)
            else run_options
        )
    if system.n_dofs > DENSE_MAX_N:
        raise InputError(
            "structure",
            f"is a sparse structure of {system.n_dofs} DOFs: shooting's period Jacobian is dense over 2n unknowns "
            f"(at most {DENSE_MAX_N} DOFs)",
            "use solver='hbm' (slipstep.frf's auto rule takes it), or march_to_steady",
        )
    return {**run_options, "linear_solver": "direct"}


def period_jacobian(sim: Simulation, sliders: np.ndarray | None = None) -> np.ndarray:
    """Phi = dP/dz of the period just marched by ``sim`` (from the start set by start_from), over
    the unknowns z = (x, v, w[sliders]) (quasi-static: (x, w[sliders])); ``sliders`` default:
    all. Exact through the recorded steps (kernels/sensitivity.py) when every step's state has a
    piecewise-linear form, by central differences of the period map when a friction-circle
    contact slipped (:func:`finite_difference_jacobian`, all sliders: there the step depends on
    the slip direction, not on the state alone). A slider left out must stay stuck over the
    period (:func:`moving_sliders`): its w is then constant."""
    if coupled_period(sim):
        return _finite_difference_columns(sim, sliders)
    cs = sim.compiled
    n, nd, nq = cs.M.shape[0], cs.kt.shape[0], cs.A.shape[0]
    sliders = np.arange(nd) if sliders is None else np.asarray(sliders, np.int64)
    na = sliders.size
    quasi = sim.method.quasi_static
    m = (n if quasi else 2 * n) + na
    Z = np.zeros((3 * n + na, m))
    iw = n if quasi else 2 * n
    Z[:n, :n] = np.eye(n)
    Z[3 * n :, iw:] = np.eye(na)
    if not quasi:
        Z[n : 2 * n, n : 2 * n] = np.eye(n)
        # consistent a0: da = -M^-1 (K dx + C dv + A^T (G dx + H dw)), f elastic at the start
        G = np.zeros((nq, n))
        H = np.zeros((nq, nd))
        closed = sim.q0[cs.normal_row] > 0.0
        for c in np.flatnonzero(closed):
            G[cs.normal_row[c]] = cs.kn[c] * cs.A[cs.normal_row[c]]
        for d in range(nd):
            if closed[cs.direction_contact[d]]:
                tr = cs.tangential_row[d]
                G[tr] = cs.kt[d] * cs.A[tr]
                H[tr, d] = -cs.kt[d]
        Minv = inverse_mass(cs.M)  # 0 on DOFs without mass (a = 0 there)
        Z[2 * n : 3 * n, :n] = -Minv @ (cs.K + cs.A.T @ G)
        Z[2 * n : 3 * n, n : 2 * n] = -Minv @ cs.C
        Z[2 * n : 3 * n, iw:] = -Minv @ (cs.A.T @ H[:, sliders])
    wrow = np.full(nd, -1, np.int64)
    wrow[sliders] = np.arange(na)
    scheme = sim.options.scheme
    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(cs)
    exact = period_sensitivity(
        cs.M,
        cs.C,
        cs.K,
        cs.A,
        nrow,
        lcode,
        lpar,
        fdir,
        ndir,
        trow,
        kt,
        scheme.beta,
        scheme.gamma,
        not quasi,
        sim.out.dt,
        sim.out.state,
        int(sim.out.counters[C_STEPS]),
        wrow,
        sim.settings.singular_rtol,
        Z,
    )
    if not exact:  # a J(S) of the period is singular to the march's own test: the period map's differences
        return _finite_difference_columns(sim, sliders)
    rows = np.r_[0:n, 3 * n : 3 * n + na] if quasi else np.r_[0 : 2 * n, 3 * n : 3 * n + na]
    return Z[rows]


def _finite_difference_columns(sim: Simulation, sliders: np.ndarray | None) -> np.ndarray:
    """:func:`finite_difference_jacobian` over the unknowns (x, v, w[sliders]) of :func:`period_jacobian`."""
    phi = finite_difference_jacobian(sim)
    if sliders is None:
        return phi
    n_state = sim.compiled.M.shape[0] * (1 if sim.method.quasi_static else 2)
    keep = np.r_[0:n_state, n_state + np.asarray(sliders, np.int64)]
    return phi[np.ix_(keep, keep)]


def moving_sliders(sim: Simulation) -> np.ndarray:
    """The sliders that leave stick (slip or lift off) in some step of the period just marched;
    the others keep their position over the period: neutral directions of the period map."""
    k = int(sim.out.counters[C_STEPS]) + 1
    return np.flatnonzero((sim.out.state[1:k] != STICK).any(axis=0)).astype(np.int64)


def coupled_period(sim: Simulation) -> bool:
    """Did a contact slip in a state without a piecewise-linear form (the friction circle's
    coupled slip) in the period just marched?"""
    return bool(np.any(sim.out.state[: int(sim.out.counters[C_STEPS]) + 1] == SLIP_COUPLED))


FD_RELATIVE_STEP = 1e-6  # central differences: step / block scale (x and w; v)


def finite_difference_jacobian(sim: Simulation) -> np.ndarray:
    """Phi = dP/dz by central differences: for each unknown j, the period marched from
    z +- h_j e_j, Phi[:, j] = (P(z + h_j e_j) - P(z - h_j e_j)) / (2 h_j), h_j =
    FD_RELATIVE_STEP times the largest |x| and |w| (or |v|) at the start (the system's length
    scale, over the period for v, when they are zero); 2 m marches of one period. A side whose
    period stops gives way to the one-sided difference with P(z). The period from z itself is
    marched again last, so ``sim`` holds it as before."""
    quasi = sim.method.quasi_static
    s0 = sim.start
    t0 = float(sim.settings.t_start)
    n = sim.compiled.M.shape[0]
    z = _unknowns(s0, quasi)
    length = float(np.abs(np.r_[s0.x, s0.w]).max(initial=0.0)) or float(sim.compiled.length_scale)
    speed = float(np.abs(s0.v).max(initial=0.0)) or float(sim.compiled.length_scale) / float(sim.period)

    def period_end(zp):
        start(sim, _from_unknowns(zp, n, quasi, s0.states), t0)
        status, _, end, _ = march_one_period(sim)
        return _unknowns(end, quasi) if status == Status.OK else None

    base = period_end(z)
    columns = []
    for j in range(z.size):
        h = FD_RELATIVE_STEP * (speed if (not quasi and n <= j < 2 * n) else length)
        step = np.zeros_like(z)
        step[j] = h
        plus, minus = period_end(z + step), period_end(z - step)
        if plus is not None and minus is not None:
            columns.append((plus - minus) / (2.0 * h))
        elif plus is not None or minus is not None:
            columns.append((plus - base) / h if plus is not None else (base - minus) / h)
        else:
            start(sim, s0, t0)
            march_one_period(sim)
            raise SolverError(f"the finite-difference period Jacobian: both periods perturbed in unknown {j} stopped")
    start(sim, s0, t0)
    march_one_period(sim)
    return np.column_stack(columns)


class JacobianCache:
    """Phi over the free unknowns of the period just marched: (x, v) and the sliders that leave
    stick in it (:func:`moving_sliders`; the others are neutral directions, kept fixed). Phi
    depends only on the recorded (dt, contact state) sequence of the period and on which
    contacts are closed at its start: a period that repeats the last sequence reuses its Phi
    (not a period with a coupled slip, whose Phi also depends on the slip directions).
    Returns (Phi, free), free the indices of Phi's unknowns in z = (x, v, w)."""

    def __init__(self):
        self.key, self.value, self.built = None, None, 0

    def __call__(self, sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
        k = int(sim.out.counters[C_STEPS]) + 1
        key = (sim.out.state[:k].tobytes(), sim.out.dt[:k].tobytes(), (sim.q0[sim.compiled.normal_row] > 0.0).tobytes())
        if key != self.key or coupled_period(sim):
            n_state = sim.compiled.M.shape[0] * (1 if sim.method.quasi_static else 2)
            sliders = moving_sliders(sim)
            self.key = key
            self.value = (period_jacobian(sim, sliders), np.r_[0:n_state, n_state + sliders].astype(np.int64))
            self.built += 1
        return self.value


def floquet(phi: np.ndarray) -> np.ndarray:
    """Eigenvalues of Phi over the free unknowns (neutral slider directions left out), by
    decreasing modulus."""
    ev = np.linalg.eigvals(phi) if phi.size else np.zeros(0, complex)
    return ev[np.argsort(-np.abs(ev))]


LU_PIVOT_FLOOR = 1e-12  # below this pivot ratio of its LU the Newton matrix is solved by least squares


def newton_step(phi: np.ndarray, residual: np.ndarray, scale: np.ndarray, free: np.ndarray) -> np.ndarray:
    """dz solving (Phi - I) dz = -R over the free unknowns in scaled unknowns,

        (Phi_hat - I) dz_hat = -R_hat,   Phi_hat = S^-1 Phi S,  R_hat = S^-1 R[free],  dz = S dz_hat,

    S = diag(scale[free]) the block scales, by LU (least squares where the matrix is singular to
    round-off); the neutral sliders are kept fixed (dz = 0 there). phi is over z[free], residual
    and scale over z."""
    import scipy.linalg

    s = scale[free]
    matrix = (phi - np.eye(free.size)) * s[None, :] / s[:, None]
    rhs = -residual[free] / s
    dhat = None
    if free.size:
        lu, piv = scipy.linalg.lu_factor(matrix, check_finite=False)
        pivots = np.abs(np.diag(lu))
        if pivots.min() > LU_PIVOT_FLOOR * pivots.max():
            dhat = scipy.linalg.lu_solve((lu, piv), rhs, check_finite=False)
    if dhat is None:
        dhat = np.linalg.lstsq(matrix, rhs, rcond=1e-13)[0]
    dz = np.zeros(residual.size)
    dz[free] = dhat * s
    return dz


PREDICTOR_MAX_RATIO = 2.0  # extrapolate at most twice the last frequency step


def predicted_start(history, frequency_hz: float, n: int, quasi: bool) -> State | None:
    """The secant predictor between FRF points: from the orbits z_a, z_b of the last two points
    (at f_a, f_b: ``history``, the SteadyState's ``orbit_history``), the start z_b + r (z_b - z_a),
    r = (f - f_b) / (f_b - f_a), for the point at f = ``frequency_hz`` (None without two points,
    or for a step more than PREDICTOR_MAX_RATIO times the last one)."""
    if len(history) < 2:
        return None
    (f_a, s_a), (f_b, s_b) = history[-2], history[-1]
    if f_a == f_b or abs(frequency_hz - f_b) > PREDICTOR_MAX_RATIO * abs(f_b - f_a):
        return None
    r = (frequency_hz - f_b) / (f_b - f_a)
    z_a, z_b = _unknowns(s_a, quasi), _unknowns(s_b, quasi)
    return _from_unknowns(z_b + r * (z_b - z_a), n, quasi, s_b.states)


def _shooting_size(system, *args, **kwargs) -> int:
    """Unknowns of a shooting problem for the BLAS-thread rule (methods/blas.py): about 2n."""
    return 2 * system.n_dofs if isinstance(system, System) else 0


@on_one_blas_thread(_shooting_size)  # small dense Jacobians: one BLAS thread
def shoot(
    system: System,
    *,
    tolerance: float = 1e-6,
    initial=None,
    max_iterations: int = 60,
    max_periods: int = 200,
    method="piecewise-linear",
    min_steps_per_period: int | None = None,
    settle_periods: int = 3,
    max_backtracks: int = 3,
    warmup_periods: int = 5,
    predictor: bool = True,
    march_fallback: bool = True,
    **run_options,
):
    """Periodic steady state by shooting (see the module docstring); returns a SteadyState
    whose ``periods`` counts every period marched (Newton residuals, settling, fallback) and
    ``jacobians`` the one-period Jacobians built. Options as :func:`march_to_steady`;
    predictor: with ``initial`` a SteadyState of an FRF point that carries the orbits of the two
    points before (``orbit_history``), start from their secant extrapolation
    (:func:`predicted_start`; the previous orbit if the predicted period fails). When Newton
    from a given start has not converged after half of ``max_iterations``, the search starts
    afresh from the static preload (``warmup_periods`` marched first): the orbit of a distant
    frequency can be a worse start than the preload. After max_iterations, the last iterate is
    marched up to max_periods (march_fallback; False: the solve ends NOT_STEADY there, for a
    caller with a better start to try). method "events": the exact periodic orbit
    (steady/exact_orbit.steady_state; the step and march options do not apply)."""
    wall = time.perf_counter()
    check_tolerance(tolerance, max_periods)
    if method == "events":  # Newton on the exact period map (steady/exact_orbit.py)
        from slipstep.steady.exact_orbit import steady_state

        return steady_state(system, min(tolerance, 1e-12), initial, max_iterations)
    for name, value, low in (
        ("max_iterations", max_iterations, 1),
        ("settle_periods", settle_periods, 0),
        ("max_backtracks", max_backtracks, 0),
        ("warmup_periods", warmup_periods, 0),
    ):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InputError(name, f"is {value!r}", f"give a whole number >= {low}")
    run_options = dense_backend_options(system, run_options, method)
    sim = period_simulation(system, method, min_steps_per_period, run_options, initial)
    if sim.compiled.banded or sim.plan.backend == "sparse":  # the period Jacobian is dense in 2 n + nd unknowns
        raise InputError(
            "linear_solver",
            f"is '{sim.plan.backend}': shooting's period Jacobian needs the dense matrices",
            "leave linear_solver unset (shooting then marches a sparse structure of up to "
            f"{DENSE_MAX_N} DOFs densely), use solver='hbm', or march_to_steady",
        )
    scheme = sim.options.scheme
    if not sim.method.quasi_static and (scheme.alpha_m != 0 or scheme.alpha_f != 0):
        raise InputError(
            "scheme",
            f"is {scheme.name}: shooting differentiates the Newmark step",
            "use a Newmark scheme (slipstep.newmark(beta, gamma)) or the quasi-static method",
        )
    cs = sim.compiled
    n, nd = cs.M.shape[0], cs.kt.shape[0]
    quasi = sim.method.quasi_static
    n_state = n if quasi else 2 * n
    T = sim.period
    t0 = math.ceil(max(cs.force_ramp, cs.motion_ramp) / T - 1e-9) * T  # shoot on the periodic map
    state = as_state(initial, n, nd) if initial is not None else None
    history = initial.orbit_history if isinstance(initial, SteadyState) else ()
    guess = predicted_start(history, 1.0 / T, n, quasi) if predictor else None
    periods, kernel, changes = 0, 0.0, []
    jacobian = JacobianCache()
    warmup = int(round(t0 / T)) + (warmup_periods if initial is None else 0)
    if warmup > 0:
        guess = None  # march through the ramp, and from the preload past the start transient
        start(sim, state, 0.0)
        status, k, ch, state, kt_ = march_periods(sim, 0, tolerance, warmup)
        periods, kernel = periods + k, kernel + kt_
        changes += ch
        if status not in ("OK", "NOT_STEADY"):  # a failed march (steady already: Newton checks it in one period)
            return finish(sim, status, periods, changes, state, kernel, wall, "shoot")

    def stop(status, end, **extra):
        """The result from where the search stands now (the counts as they are at the call)."""
        return finish(
            sim,
            status,
            periods,
            changes,
            end,
            kernel,
            wall,
            "shoot",
            newton_iterations=newton,
            jacobians=jacobian.built,
            **extra,
        )

    best = None  # (change, z0, dz, end state) of the best period so far
    backtracks = newton = 0
    restart_at = max_iterations // 2 if initial is not None else -1
    for it in range(max_iterations):
        if it == restart_at:  # Newton from the given start stalls: start afresh from the preload
            start(sim, None, 0.0)
            status, k, ch, state, kt_ = march_periods(sim, 0, tolerance, int(round(t0 / T)) + warmup_periods)
            periods, kernel = periods + k, kernel + kt_
            changes += ch
            guess, best, backtracks = None, None, 0
            if status not in ("OK", "NOT_STEADY"):
                return stop(status, state)
        start(sim, guess if guess is not None else state, t0)
        status, s0, end, e = march_one_period(sim, check=False)  # an iterate: checked when kept
        periods += 1
        kernel += sim.kernel_time
        changes.append(e)
        if guess is not None:  # the predicted start (the previous point's orbit if its period fails)
            guess = None
            if status != Status.OK:
                continue  # from the previous point's orbit instead
        if status != Status.OK:
            return stop(status.name, end)
        if e <= tolerance:
            status = check_march(sim)  # the contact invariants of the period kept
            if status != Status.OK:
                return stop(status.name, end)
            phi, free = jacobian(sim)
            return stop(
                "OK",
                end,
                floquet_multipliers=floquet(phi),
                neutral_directions=int(n_state + nd - free.size),
                orbit_history=(*history[-1:], (1.0 / T, s0)),
            )
        if best is not None and e >= best[0]:  # no progress: a shorter step along the last Newton step
            if backtracks < max_backtracks:
                backtracks += 1
                state = _from_unknowns(best[1] + 0.5**backtracks * best[2], n, quasi, best[3].states)
                continue
            if settle_periods > 0:  # Newton stalls: let the march settle the state sequence
                start(sim, best[3], t0)
                status, k, ch, end, kt_ = march_periods(sim, 0, tolerance, settle_periods)
                periods, kernel = periods + k, kernel + kt_
                changes += ch
                if status not in ("OK", "NOT_STEADY"):  # (steady: the next period confirms it, with Floquet)
                    return stop(status, end)
                state, best, backtracks = end, None, 0
                continue
        phi, free = jacobian(sim)
        newton += 1
        scales = period_scales(sim.out, int(sim.out.counters[C_STEPS]), cs, system.structure.dof_units, quasi)
        z0 = _unknowns(s0, quasi)
        dz = newton_step(phi, _unknowns(end, quasi) - z0, scales.vector(quasi, nd), free)
        best, backtracks = (e, z0, dz, end), 0
        state = _from_unknowns(z0 + dz, n, quasi, end.states)
    if not march_fallback:  # the caller has a better start than marching (an FRF's harmonic balance)
        result = stop("NOT_STEADY", state)
        result.message = f"Newton did not converge in {max_iterations} iterations (no marching fallback asked)"
        return result
    # fallback: plain marching from the last iterate
    start(sim, state, t0)
    status, k, ch, end, kt_ = march_periods(sim, 0, tolerance, max(max_periods - periods, 1))
    periods, kernel = periods + k, kernel + kt_
    changes += ch
    result = stop(status, end)
    result.message = f"Newton did not converge in {max_iterations} iterations; fell back to marching: {result.message}"
    return result
