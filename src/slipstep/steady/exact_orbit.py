"""Exact periodic orbits (steady states) by shooting on the exact period map of the method
``events`` (methods/exact_events.py): a reference steady state and FRF with no
time-discretisation error.

    orbit = periodic_orbit(system, 350.0)
    orbit.friction_energy, orbit.excitation_work, orbit.amplitude, orbit.multipliers

The unknowns are the state at t = 0, z = (x, v, w) (the sliders of every direction; a
slipping or lifted direction's slider is the one its law gives), and the period map
P(z) = z(T) is one exact march over T = 1 / frequency. Newton on r(z) = P(z) - z with the
Jacobian by forward differences of the exact map (one march per unknown; each column
accurate to about the square root of round-off, which slows Newton's last iterations but
not the fixed point it converges to): acceptable for the small systems (a few DOFs and
contacts) this reference is for; the Jacobian from the propagators and the event-time
sensitivities (issue 28, item 3) is not built. The Newton step is a least-squares solve, so
a slider stuck over the whole period (a neutral direction of the map: its multiplier is 1)
does not stop it. The multipliers reported are the eigenvalues of that Jacobian of P.

``frf(system, frequencies, solver="shoot", method="events")`` is the reference FRF built on
these orbits (slipstep.frequency.exact); :func:`exact_frf` returns the orbits themselves.
``slipstep.steady.shoot(system, method="events")`` returns it as a SteadyState
(:func:`steady_state`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError, Status
from slipstep.methods.exact_events import ExactEventRun, Trajectory, energy_balance, march
from slipstep.kernels.codes import STICK
from slipstep.model.system import System

#: forward-difference step of the Jacobian, relative to each unknown's scale
FD_STEP = 1e-7


@dataclass
class ExactOrbit:
    """A periodic orbit of the exact march (module docstring). frequency_hz; x0, v0, w0 (the
    state at t = 0); trajectory (one period from it); residual (the scaled |P(z) - z|, max
    norm); iterations (Newton); converged; amplitude (n,) half the peak-to-peak of each DOF
    [DOF units]; friction_per_direction (nd,) [J per cycle]; friction_energy, excitation_work, viscous_energy [J per cycle] (the energy
    balance over the period: methods/exact_events.energy_balance); multipliers (the eigenvalues
    of the period map's Jacobian at the orbit); periods (the exact periods marched in all)."""

    frequency_hz: float
    x0: np.ndarray
    v0: np.ndarray
    w0: np.ndarray
    trajectory: Trajectory
    residual: float
    iterations: int
    converged: bool
    amplitude: np.ndarray
    friction_per_direction: np.ndarray
    friction_energy: float
    excitation_work: float
    viscous_energy: float
    multipliers: np.ndarray
    periods: int = 0  # exact periods marched in all (settling, Newton, the Jacobians)
    run: ExactEventRun | None = field(default=None, repr=False)  # the run of the retuned system

    def dataset(self):
        """The orbit's period [0, T] as a result Dataset (the time-domain schema, every plan.dt)."""
        self.run.trajectory = self.trajectory
        return self.run.dataset()


def period_map(run: ExactEventRun, z: np.ndarray, period: float) -> tuple[np.ndarray, Trajectory]:
    """P(z) and the trajectory of one period from z = (x, v, w) at t = 0 (counted in
    ``run.periods_marched``)."""
    model = run.model
    run.periods_marched = getattr(run, "periods_marched", 0) + 1
    n = model.n
    x, v, w = z[:n], z[n : 2 * n], z[2 * n :]
    traj = march(model, 0.0, x, v, w, np.full(model.nd, STICK, np.int8), period, run.max_events)
    if traj.status != Status.OK:
        return np.full_like(z, np.nan), traj
    end = traj.evaluate([period])
    return np.concatenate([end["x"][0], end["v"][0], end["w"][0]]), traj


def periodic_orbit(
    system: System,
    frequency_hz: float,
    guess: tuple | None = None,
    settle_periods: int = 20,
    tolerance: float = 1e-12,
    max_iterations: int = 30,
    samples: int = 20000,
) -> ExactOrbit:
    """The periodic orbit of ``system`` under its harmonic excitation moved to ``frequency_hz``
    [Hz] (module docstring). ``guess``: (x, v, w) at t = 0, default the state after
    ``settle_periods`` exact periods from the static preload. ``tolerance``: on the residual
    |P(z) - z|, each unknown relative to its scale (the orbit's largest |x| and |v|).
    ``samples``: points per period for the amplitudes."""
    from slipstep.model.retune import retune

    if settle_periods < 0 or max_iterations < 1:
        raise InputError(
            "settle_periods", "or max_iterations is out of range", "give settle_periods >= 0, max_iterations >= 1"
        )
    system = retune(system, frequency_hz)
    run = ExactEventRun(system, periods=1)
    model, period = run.model, 1.0 / frequency_hz
    if guess is None:
        s = run.start
        z = np.concatenate([s.x, s.v, s.w])
        for _ in range(settle_periods):
            z, _ = period_map(run, z, period)
    else:
        z = np.concatenate([np.asarray(g, float).ravel() for g in guess])
    n = model.n
    Pz, traj = period_map(run, z, period)
    residual, iterations, J = math.inf, 0, None
    for iterations in range(1, max_iterations + 1):
        scale = _scales(z, Pz, n, model.length, frequency_hz)
        r = (Pz - z) / scale
        residual = float(np.abs(r).max())
        if not np.isfinite(residual) or residual <= tolerance:
            break
        J = _jacobian(run, z, Pz, period, scale)
        step = np.linalg.lstsq(J - np.eye(z.size), -r, rcond=1e-12)[0] * scale
        z = z + step
        Pz, traj = period_map(run, z, period)
    if J is None or residual > tolerance:
        J = _jacobian(run, z, Pz, period, _scales(z, Pz, n, model.length, frequency_hz))
    balance = energy_balance(traj)
    t = np.linspace(0.0, period, samples + 1)
    x = traj.evaluate(t)["x"]
    return ExactOrbit(
        float(frequency_hz),
        z[:n].copy(),
        z[n : 2 * n].copy(),
        z[2 * n :].copy(),
        traj,
        residual,
        iterations,
        bool(residual <= tolerance),
        0.5 * (x.max(axis=0) - x.min(axis=0)),
        np.asarray(balance["friction_per_direction"]),
        float(balance["friction_dissipation"]),
        float(balance["input_work"]),
        float(balance["viscous_dissipation"]),
        np.linalg.eigvals(J) if J is not None else np.array([]),
        run.periods_marched,
        run,
    )


def exact_frf(system: System, frequencies, **options) -> list[ExactOrbit]:
    """The exact steady state at each frequency [Hz] (:func:`periodic_orbit`), each Newton
    started from the previous point's orbit (the first from the settled preload)."""
    orbits, guess = [], None
    for f in frequencies:
        orbit = periodic_orbit(system, float(f), guess=guess, **options)
        orbits.append(orbit)
        guess = (orbit.x0, orbit.v0, orbit.w0) if orbit.converged else None
    return orbits


def _scales(z, Pz, n: int, length: float, frequency_hz: float) -> np.ndarray:
    """Each unknown's scale: the largest |x| (and |w|), the largest |v|, floored by the
    system's length scale (times the angular frequency for v)."""
    both = np.concatenate([np.abs(z), np.abs(np.nan_to_num(Pz))])
    sx = max(both[:n].max(initial=0.0), both[2 * n :].max(initial=0.0), 1e-3 * length)
    sv = max(both[n : 2 * n].max(initial=0.0), 2 * np.pi * frequency_hz * 1e-3 * length)
    return np.concatenate([np.full(n, sx), np.full(n, sv), np.full(z.size - 2 * n, sx)])


def _jacobian(run: ExactEventRun, z, Pz, period: float, scale) -> np.ndarray:
    """dP/dz in the scaled unknowns by forward differences of the exact map."""
    J = np.empty((z.size, z.size))
    for i in range(z.size):
        dz = np.zeros_like(z)
        dz[i] = FD_STEP * scale[i]
        J[:, i] = (period_map(run, z + dz, period)[0] - Pz) / scale / FD_STEP
    return J


def steady_state(system: System, tolerance: float = 1e-12, initial=None, max_iterations: int = 30):
    """The exact periodic orbit of ``system`` at its own excitation frequency as a
    slipstep.steady.SteadyState (what ``shoot(system, method="events")`` returns): ``period``
    the Dataset of the orbit's period, ``final_state`` the state at T, ``change`` the orbit's
    residual, ``floquet_multipliers`` those of the finite-difference Jacobian. ``initial``: a
    State, a SteadyState or a mapping of x, v, w (slipstep.steady.state.as_state)."""
    import time

    from slipstep.methods.state import State
    from slipstep.steady.state import SteadyState, as_state

    start = time.perf_counter()
    if system.period is None:
        raise InputError("excitation", "has no period", "give a harmonic excitation")
    guess = None
    if initial is not None:
        cs = system.compile("dense")
        s = as_state(initial, cs.M.shape[0], cs.kt.shape[0])
        guess = (s.x, s.v if s.v is not None else np.zeros_like(s.x), s.w if s.w is not None else np.zeros(cs.kt.size))
    orbit = periodic_orbit(system, 1.0 / system.period, guess=guess, tolerance=tolerance, max_iterations=max_iterations)
    ds = orbit.dataset()
    T = 1.0 / orbit.frequency_hz
    end = orbit.trajectory.evaluate([T])
    final = State(T, end["x"][0], end["v"][0], end["a"][0], end["w"][0], end["state"][0])
    status = "OK" if orbit.converged else "NOT_CONVERGED"
    message = (
        f"exact periodic orbit after {orbit.iterations} Newton iteration(s): residual {orbit.residual:.2e}"
        if orbit.converged
        else f"Newton on the exact period map did not converge: residual {orbit.residual:.2e}"
    )
    ds.attrs.update(steady_status=status, steady_change=orbit.residual, periods_to_steady=orbit.periods)
    return SteadyState(
        period=ds,
        periods=orbit.periods,
        status=status,
        message=message,
        final_state=final,
        change=orbit.residual,
        solver="shoot",
        method="events",
        floquet_multipliers=orbit.multipliers,
        newton_iterations=orbit.iterations,
        wall_time_s=time.perf_counter() - start,
    )
