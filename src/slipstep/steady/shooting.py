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
from slipstep.kernels.codes import C_STEPS, SLIP_COUPLED
from slipstep.kernels.sensitivity import period_sensitivity
from slipstep.kernels.settings import contact_table
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
from slipstep.steady.state import State, as_state, period_scales
from slipstep.system import System


def _unknowns(s: State, quasi: bool) -> np.ndarray:
    return s.unknowns(quasi)


def _from_unknowns(z: np.ndarray, n: int, quasi: bool, states) -> State:
    return State.from_unknowns(z, n, quasi, states)


def period_jacobian(sim: Simulation) -> np.ndarray:
    """Phi = dP/dz of the period just marched by ``sim`` (from the start set by start_from):
    exact through the recorded steps (kernels/sensitivity.py) when every step's state has a
    piecewise-linear form, by central differences of the period map when a friction-circle
    contact slipped (:func:`finite_difference_jacobian`: there the step depends on the slip
    direction, not on the state alone)."""
    if coupled_period(sim):
        return finite_difference_jacobian(sim)
    cs = sim.compiled
    n, nd, nq = cs.M.shape[0], cs.kt.shape[0], cs.A.shape[0]
    quasi = sim.method.quasi_static
    m = (n if quasi else 2 * n) + nd
    Z = np.zeros((3 * n + nd, m))
    iw = n if quasi else 2 * n
    Z[:n, :n] = np.eye(n)
    Z[3 * n :, iw:] = np.eye(nd)
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
        Z[2 * n : 3 * n, iw:] = -Minv @ (cs.A.T @ H)
    scheme = sim.options.scheme
    period_sensitivity(
        cs.M,
        cs.C,
        cs.K,
        cs.A,
        cs.AT,
        *contact_table(cs),
        scheme.beta,
        scheme.gamma,
        not quasi,
        sim.out.dt,
        sim.out.state,
        int(sim.out.counters[C_STEPS]),
        Z,
    )
    rows = np.r_[0:n, 3 * n : 3 * n + nd] if quasi else np.r_[0 : 2 * n, 3 * n : 3 * n + nd]
    return Z[rows]


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
    """Phi depends only on the recorded (dt, contact state) sequence of the period and on which
    contacts are closed at its start: a period that repeats the last sequence reuses its Phi
    (not a period with a coupled slip, whose Phi also depends on the slip directions)."""

    def __init__(self):
        self.key, self.phi, self.built = None, None, 0

    def __call__(self, sim: Simulation) -> np.ndarray:
        k = int(sim.out.counters[C_STEPS]) + 1
        key = (sim.out.state[:k].tobytes(), sim.out.dt[:k].tobytes(), (sim.q0[sim.compiled.normal_row] > 0.0).tobytes())
        if key != self.key or coupled_period(sim):
            self.key, self.phi = key, period_jacobian(sim)
            self.built += 1
        return self.phi


def neutral_sliders(phi: np.ndarray, n_state: int, nd: int) -> np.ndarray:
    """Unknown indices of sliders stuck over the whole period (row of Phi = unit vector)."""
    out = []
    for d in range(nd):
        i = n_state + d
        row = phi[i].copy()
        row[i] -= 1.0
        if np.abs(row).max(initial=0.0) == 0.0:
            out.append(i)
    return np.array(out, dtype=np.int64)


def floquet(phi: np.ndarray, neutral: np.ndarray) -> np.ndarray:
    """Eigenvalues of Phi without the neutral slider directions, by decreasing modulus."""
    keep = np.setdiff1d(np.arange(phi.shape[0]), neutral)
    ev = np.linalg.eigvals(phi[np.ix_(keep, keep)]) if keep.size else np.zeros(0, complex)
    return ev[np.argsort(-np.abs(ev))]


def newton_step(phi: np.ndarray, residual: np.ndarray, scale: np.ndarray, neutral: np.ndarray) -> np.ndarray:
    """dz solving (Phi - I) dz = -R in scaled unknowns (least squares), neutral sliders fixed."""
    free = np.setdiff1d(np.arange(phi.shape[0]), neutral)
    s = scale[free]
    Ahat = (phi[np.ix_(free, free)] - np.eye(free.size)) * s[None, :] / s[:, None]
    dhat = np.linalg.lstsq(Ahat, -residual[free] / s, rcond=1e-13)[0]
    dz = np.zeros(phi.shape[0])
    dz[free] = dhat * s
    return dz


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
    **run_options,
):
    """Periodic steady state by shooting (see the module docstring); returns a SteadyState
    whose ``periods`` counts every period marched (Newton residuals, settling, fallback) and
    ``jacobians`` the one-period Jacobians built. Options as :func:`march_to_steady`."""
    wall = time.perf_counter()
    check_tolerance(tolerance, max_periods)
    for name, value, low in (
        ("max_iterations", max_iterations, 1),
        ("settle_periods", settle_periods, 0),
        ("max_backtracks", max_backtracks, 0),
        ("warmup_periods", warmup_periods, 0),
    ):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InputError(name, f"is {value!r}", f"give a whole number >= {low}")
    sim = period_simulation(system, method, min_steps_per_period, run_options)
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
    periods, kernel, changes = 0, 0.0, []
    jacobian = JacobianCache()
    warmup = int(round(t0 / T)) + (warmup_periods if initial is None else 0)
    if warmup > 0:  # march through the ramp, and from the preload past the start transient
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
    for it in range(max_iterations):
        start(sim, state, t0)
        status, s0, end, e = march_one_period(sim)
        periods += 1
        kernel += sim.kernel_time
        changes.append(e)
        if status != Status.OK:
            return stop(status.name, end)
        if e <= tolerance:
            phi = jacobian(sim)
            neutral = neutral_sliders(phi, n_state, nd)
            return stop("OK", end, floquet_multipliers=floquet(phi, neutral), neutral_directions=int(neutral.size))
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
        phi = jacobian(sim)
        newton += 1
        neutral = neutral_sliders(phi, n_state, nd)
        scales = period_scales(sim.out, int(sim.out.counters[C_STEPS]), cs, system.structure.dof_units, quasi)
        z0 = _unknowns(s0, quasi)
        dz = newton_step(phi, _unknowns(end, quasi) - z0, scales.vector(quasi, nd), neutral)
        best, backtracks = (e, z0, dz, end), 0
        state = _from_unknowns(z0 + dz, n, quasi, end.states)
    # fallback: plain marching from the last iterate
    start(sim, state, t0)
    status, k, ch, end, kt_ = march_periods(sim, 0, tolerance, max(max_periods - periods, 1))
    periods, kernel = periods + k, kernel + kt_
    changes += ch
    result = stop(status, end)
    result.message = f"Newton did not converge in {max_iterations} iterations; fell back to marching: {result.message}"
    return result
