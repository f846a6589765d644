"""Slow sine sweep: one transient march with the excitation frequency swept linearly,
the response envelope read against the instantaneous frequency.

    f(t) = f_0 + (f_1 - f_0) t / D,     theta(t) = 2 pi (f_0 t + (f_1 - f_0) t^2 / (2 D))

Every harmonic a sin(2 pi r f_fund t + phi) of the excitation (r its ratio to the fundamental:
engine orders and higher harmonics keep their ratio) becomes a sin(r theta(t) + phi), sampled
in a table (``samples_per_cycle`` points per cycle of the highest harmonic, linear
interpolation: relative error about (2 pi / samples)^2 / 8). The response is cut into the
cycles of theta (theta(t_k) = 2 pi k); the envelope of a cycle is half the peak-to-peak range
of each response DOF within it, at the instantaneous frequency of the cycle's middle, and is
interpolated onto the frequency grid. A sweep that is slow against the decay time of the
resonances tends to the stepped steady-state FRF, and shows the jumps of a nonlinear one.
The cycles of the first ``LEAD_IN`` (2 %) of the sweep hold the start transient and are left
out, and so are the grid points inside it (NaN).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import xarray as xr

from slipstep.errors import InputError, Status
from slipstep.output.frf_dataset import empty_frf, finalise
from slipstep.methods.save import Save
from slipstep.model.excitation import Signal, Tabulated
from slipstep.model.validate import positive
from slipstep.model.system import System

LEAD_IN = 0.02


def _swept(signal: Signal | None, f_fund: float, f0: float, f1: float, duration: float, samples: int, what: str):
    if signal is None:
        return None
    if signal.tables:
        raise InputError(f"excitation.{what}", "has tabulated components", "sweep a harmonic excitation")
    r_max = max(h.frequency for h in signal.harmonics) / f_fund
    n = int(math.ceil(duration * max(f0, f1) * r_max * samples)) + 1
    t = np.linspace(0.0, duration, n)
    theta = 2 * np.pi * (f0 * t + (f1 - f0) * t * t / (2 * duration))
    values = np.zeros((n, len(signal.components)))
    for h in signal.harmonics:
        r = h.frequency / f_fund
        values += h.amplitude[None, :] * np.sin(r * theta[:, None] + h.phase[None, :])
    return Signal(signal.components, (), (Tabulated(t, values),), signal.ramp_time)


def swept_system(system: System, f0: float, f1: float, duration: float, samples_per_cycle: int = 128) -> System:
    """The system with its harmonic excitation replaced by the linear sweep f0 -> f1 over
    ``duration`` seconds (tabulated)."""
    f_fund = system.excitation.fundamental_frequency
    if f_fund is None:
        raise InputError("excitation", "has no harmonic to sweep", "give a harmonic force or motion")
    exc = system.excitation
    new = dataclasses.replace(
        exc,
        force=_swept(exc.force, f_fund, f0, f1, duration, samples_per_cycle, "force"),
        motion=_swept(exc.motion, f_fund, f0, f1, duration, samples_per_cycle, "motion"),
        period=None,
    )
    return dataclasses.replace(system, excitation=new)


def cycle_envelope(t: np.ndarray, y: np.ndarray, f0: float, f1: float, duration: float):
    """(instantaneous frequency at each cycle's middle, half peak-to-peak of y per cycle)."""
    cycles = f0 * t + (f1 - f0) * t * t / (2 * duration)  # theta / 2 pi
    k = np.floor(cycles).astype(np.int64)
    n_cycles = int(k[-1])
    freq, env = [], []
    bounds = np.searchsorted(k, np.arange(n_cycles + 1))
    for c in range(n_cycles):
        a, b = bounds[c], bounds[c + 1]
        if b - a < 2:
            continue
        seg = y[a : b + 1]
        env.append(0.5 * (seg.max(axis=0) - seg.min(axis=0)))
        tm = 0.5 * (t[a] + t[min(b, t.size - 1)])
        freq.append(f0 + (f1 - f0) * tm / duration)
    return np.array(freq), np.array(env).reshape(len(env), -1)


def sine_sweep(
    system: System,
    frequencies,
    *,
    direction: str = "up",
    duration: float | None = None,
    cycles_per_point: float = 30.0,
    method="piecewise-linear",
    responses=None,
    min_steps_per_period: int = 50,
    samples_per_cycle: int = 128,
    linear: bool = True,
    **run_options,
) -> xr.Dataset:
    """Sweep through the range of ``frequencies`` [Hz] (upward or downward) in one march and
    return the envelope on that grid in the FRF layout (``amplitude``; the harmonic and energy
    variables are NaN; the linear limits are computed unless linear=False). ``duration`` [s] defaults to ``cycles_per_point`` cycles of the mean
    frequency per grid point."""
    from slipstep import __version__
    from slipstep.model.frequency_grid import check_frequencies
    from slipstep.methods.simulation import Simulation

    f = np.sort(check_frequencies(frequencies))
    if f.size < 2:
        raise InputError("frequencies", "needs at least two values for a sweep", "give a range, e.g. 150:450:61")
    if direction not in ("up", "down"):
        raise InputError("direction", f"is {direction!r} for a sine sweep", "use 'up' or 'down'")
    f0, f1 = (f[0], f[-1]) if direction == "up" else (f[-1], f[0])
    D = (
        positive("duration", duration)
        if duration is not None
        else positive("cycles_per_point", cycles_per_point) * f.size / f.mean()
    )
    swept = swept_system(system, f0, f1, D, samples_per_cycle)
    f_fund = system.excitation.fundamental_frequency
    r_max = (
        max(
            (
                h.frequency
                for s in (system.excitation.force, system.excitation.motion)
                if s is not None
                for h in s.harmonics
            ),
            default=f_fund,
        )
        / f_fund
    )
    opts = dict(run_options)
    opts.setdefault("sensitivity_check", False)  # the FRF has its own checks: no perturbed twin
    opts.setdefault("max_step", 1.0 / (f[-1] * r_max * min_steps_per_period))
    names = list(system.structure.dof_names)
    responses = names if responses is None else list(responses)
    opts.setdefault("save", Save(dofs=[r for r in responses if r in names] or "all"))  # the responses, every step
    sim = Simulation(swept, method, duration=D, **opts)
    saved = set(sim.save_plan.dofs.tolist())
    if not sim.save_plan.every_step or any(names.index(r) not in saved for r in responses if r in names):
        raise InputError(
            "save",
            f"is {sim.save_plan.text!r}: the sine sweep needs its responses at every step",
            "drop the save option",
        )
    ds_t = sim.run()
    units = [system.structure.dof_units[names.index(r)] for r in responses]
    grid = f if direction == "up" else f[::-1]
    out = empty_frf(grid, responses, units, system.contact_names, 0)
    t = ds_t["time"].values
    y = ds_t["displacement"].sel(dof=responses).values
    fc, env = cycle_envelope(t, y, f0, f1, D)
    settled = np.abs(fc - f0) >= LEAD_IN * abs(f1 - f0)  # the start transient is left out
    fc, env = fc[settled], env[settled]
    order = np.argsort(fc)
    inside = np.abs(grid - f0) >= LEAD_IN * abs(f1 - f0)
    for j in range(len(responses)):
        out["amplitude"][:, j] = np.where(inside, np.interp(grid, fc[order], env[order, j]), np.nan)
    status = ds_t.attrs["status"]
    out["status"][:] = status
    if status != Status.OK.name:  # points beyond the failure are not reached
        reached = f0 + (f1 - f0) * t[-1] / D
        beyond = grid > reached if direction == "up" else grid < reached
        out["amplitude"][beyond] = np.nan
    if linear:
        from slipstep.steady.linear import linear_limits

        lim = linear_limits(system, grid, responses)
        for name in ("linear_free_amplitude", "linear_stuck_amplitude"):
            out[name].values[:] = lim[name].values
    out.attrs.update(
        case=system.name,
        solver="sine-sweep",
        sweep=direction,
        method=sim.method.name,
        sweep_duration_s=D,
        sweep_rate_Hz_per_s=(f1 - f0) / D,
        slipstep_version=__version__,
    )
    return finalise(out)
