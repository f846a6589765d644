"""The reference FRF: ``frf(system, frequencies, solver="shoot", method="events")``, each
point the exact periodic orbit of the event-driven march (steady/exact_orbit.py: Newton on
the exact period map), in the layout of slipstep.output.frf_schema.

Per point: the amplitudes (half the peak-to-peak over ``SAMPLES`` uniform samples of the
orbit), the harmonics (the FFT of those samples), the friction energy per contact, the
excitation work and the viscous dissipation per cycle (Gauss-Legendre on the exact solution:
methods/exact_events.energy_balance), the energy-balance residual, the largest multiplier
of the period map's Jacobian, ``steady_change`` the orbit's residual |P(z) - z| (scaled),
``periods_to_steady`` the exact periods marched for the point. ``error_estimate`` is 0 (no
time discretisation: the error is the orbit's residual and round-off) and steps_per_period,
time_step NaN (there is no step).
"""

from __future__ import annotations

import time

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.output.frf_dataset import concat_sweeps, empty_frf, finalise
from slipstep.frequency.harmonics import amplitudes_phases, fourier_coefficients
from slipstep.steady.linear import linear_limits
from slipstep.model.system import System

#: uniform samples per period for the amplitudes and harmonics
SAMPLES = 4096
#: the orbit's residual asked by default (the steady tolerance of frf is at most this)
TOLERANCE = 1e-12
#: options of steady/exact_orbit.periodic_orbit that frf passes on
ORBIT_OPTIONS = ("settle_periods", "max_iterations")
#: options of the time-stepping steady solvers that have no meaning without a step (the CLI sets them)
STEP_ONLY_OPTIONS = ("max_periods", "min_steps_per_period", "steps_per_period", "max_step", "dt", "step_ratio")


def exact_frf_dataset(
    system: System,
    frequencies: np.ndarray,
    direction: str = "up",
    responses=None,
    n_harmonics: int = 5,
    tolerance: float = TOLERANCE,
    linear: bool = True,
    progress=None,
    **options,
) -> xr.Dataset:
    """The FRF Dataset of the exact periodic orbits at ``frequencies`` [Hz] (module docstring);
    ``direction`` 'up', 'down' or 'both' (the down sweep from the up sweep's last orbit);
    ``options``: those of steady/exact_orbit.periodic_orbit (ORBIT_OPTIONS); the step options of
    the time-stepping solvers (STEP_ONLY_OPTIONS) have no meaning here and are dropped."""
    unknown = sorted(set(options) - set(ORBIT_OPTIONS) - set(STEP_ONLY_OPTIONS))
    if unknown:
        raise InputError(
            unknown[0], "is not an option of the exact steady state (method 'events')", f"use only {ORBIT_OPTIONS}"
        )
    options = {k: v for k, v in options.items() if k in ORBIT_OPTIONS}
    names = list(system.structure.dof_names)
    responses = names if responses is None else list(responses)
    unknown = [r for r in responses if r not in names]
    if unknown:
        raise InputError("responses", f"{unknown} are not DOFs of the system", f"use names from {names}")
    sweeps, guess = [], None
    for name in ("up", "down") if direction == "both" else (direction,):
        grid = np.sort(frequencies) if name == "up" else np.sort(frequencies)[::-1]
        ds, guess = _sweep(system, grid, responses, n_harmonics, tolerance, guess, progress, options)
        ds.attrs["sweep"] = name
        sweeps.append(ds)
    out = sweeps[0] if len(sweeps) == 1 else concat_sweeps(*sweeps)
    if linear:
        lim = linear_limits(system, out["frequency"].values, responses)
        for var in ("linear_free_amplitude", "linear_stuck_amplitude"):
            out[var] = (("frequency", "response"), lim[var].values, out[var].attrs)
    from slipstep import __version__

    out.attrs.update(
        case=system.name,
        solver="shoot",
        method="events",
        steady_tolerance=tolerance,
        slipstep_version=__version__,
        error_estimate_method="none: exact between events (the orbit's residual and round-off)",
    )
    return out


def _sweep(system, grid, responses, n_harmonics, tolerance, guess, progress, options):
    from slipstep.steady.exact_orbit import periodic_orbit

    names = list(system.structure.dof_names)
    cols = [names.index(r) for r in responses]
    units = [system.structure.dof_units[i] for i in cols]
    ds = empty_frf(grid, responses, units, system.contact_names, n_harmonics)
    columns = {name: ds[name].values.copy() for name in ds.data_vars}
    cs = system.compile("dense")
    owner = np.asarray(cs.direction_contact)
    for i, f in enumerate(grid):
        start = time.perf_counter()
        orbit = periodic_orbit(system, float(f), guess=guess, tolerance=tolerance, **options)
        period = 1.0 / float(f)
        t = np.linspace(0.0, period, SAMPLES + 1)
        y = orbit.trajectory.evaluate(t)["x"][:, cols]
        A, phase = amplitudes_phases(fourier_coefficients(t, y, period, n_harmonics))
        per_contact = np.array([orbit.friction_per_direction[owner == c].sum() for c in range(len(system.contacts))])
        work = orbit.excitation_work
        values = {
            "amplitude": 0.5 * np.ptp(y, axis=0),
            "harmonic_amplitude": A,
            "harmonic_phase": phase,
            "energy_per_cycle": per_contact,
            "excitation_work": work,
            "viscous_dissipation": orbit.viscous_energy,
            "energy_balance_residual": (work - orbit.viscous_energy - per_contact.sum()) / max(abs(work), 1e-300),
            "periods_to_steady": orbit.periods,
            "steady_change": orbit.residual,
            "floquet_multiplier_max": float(np.abs(orbit.multipliers).max(initial=0.0)),
            "status": "OK" if orbit.converged else "NOT_CONVERGED",
            "status_message": ""
            if orbit.converged
            else f"Newton on the exact period map: residual {orbit.residual:.3g}",
            "error_estimate": 0.0 if orbit.converged else np.nan,
            "point_time": time.perf_counter() - start,
        }
        for name, value in values.items():
            columns[name][i] = value
        guess = (orbit.x0, orbit.v0, orbit.w0) if orbit.converged else None
        if progress is not None:
            progress(i + 1, len(grid), float(f), None)
    for name, value in columns.items():
        ds[name].values = value
    return finalise(ds), guess
