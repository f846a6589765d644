"""Harmonic content of a steady-state period (the FRF schema's cosine convention).

Over one period T (Omega = 2 pi / T, t measured from the start of the period):

    c_h = (1/T) int_0^T x(t) e^{-i h Omega t} dt,     x(t) = sum_h A_h cos(h Omega t + phi_h)
    A_0 = Re c_0,   A_h = 2 |c_h|,   phi_h = arg c_h   (h >= 1)

On a uniform grid (fixed-step methods) the trapezoid rule of this integral over the periodic
samples is the discrete Fourier transform of the N points of the period (numpy.fft.rfft);
on a non-uniform grid (adaptive steps) the trapezoid rule is applied on the stored points.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.post.periodic import last_period, period_of


def fourier_coefficients(t: np.ndarray, y: np.ndarray, period: float, n_harmonics: int) -> np.ndarray:
    """c_h, h = 0..n_harmonics, of samples y (nt, k) at times t covering exactly one period."""
    t = np.asarray(t, float) - t[0]
    y = np.asarray(y, float).reshape(t.size, -1)
    dt = np.diff(t)
    if dt.size and np.allclose(dt, dt.mean(), rtol=1e-9, atol=0.0):
        n = t.size - 1
        if n_harmonics > n // 2:
            raise InputError(
                "harmonics",
                f"is {n_harmonics}, more than the {n // 2} a period of {n} steps resolves",
                "ask for fewer harmonics or use more steps per period",
            )
        return np.fft.rfft(y[:-1], axis=0)[: n_harmonics + 1] / n
    h = np.arange(n_harmonics + 1)
    e = np.exp(-1j * 2 * np.pi / period * np.outer(t, h))  # (nt, H+1)
    f = e[:, :, None] * y[:, None, :]
    return 0.5 * ((f[1:] + f[:-1]) * dt[:, None, None]).sum(axis=0) / period


def amplitudes_phases(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A_h, phi_h) of Fourier coefficients c_h (the module docstring's convention)."""
    A = 2.0 * np.abs(c)
    A[0] = c[0].real
    phase = np.angle(c)
    phase[0] = 0.0
    return A, phase


def harmonics(
    ds: xr.Dataset, responses=None, n_harmonics: int = 5, variable: str = "displacement", period: float | None = None
) -> xr.Dataset:
    """Amplitudes and phases of harmonics 0..n_harmonics of ``variable`` over the last period
    of the result ``ds`` (a steady-state period or a longer record), for the DOFs named in
    ``responses`` (default all). Returns a Dataset with ``harmonic_amplitude`` and
    ``harmonic_phase`` over (harmonic, response) and ``amplitude`` (half the peak-to-peak
    range) over response, units as in slipstep.output.frf_schema."""
    if isinstance(n_harmonics, bool) or not isinstance(n_harmonics, (int, np.integer)) or n_harmonics < 0:
        raise InputError("harmonics", f"is {n_harmonics!r}", "give a whole number >= 0")
    T = period_of(ds, period)
    last = last_period(ds, T)
    names = list(ds["dof"].values)
    responses = names if responses is None else list(responses)
    unknown = [r for r in responses if r not in names]
    if unknown:
        raise InputError("responses", f"{unknown} are not DOFs of the result", f"use names from {names}")
    y = last[variable].sel(dof=responses).values
    c = fourier_coefficients(last["time"].values, y, T, int(n_harmonics))
    A, phase = amplitudes_phases(c)
    units = list(ds["dof_unit"].sel(dof=responses).values)
    coords = {"harmonic": np.arange(n_harmonics + 1), "response": responses, "response_unit": ("response", units)}
    return xr.Dataset(
        {
            "harmonic_amplitude": (("harmonic", "response"), A, {"units": "m or rad (see response_unit)"}),
            "harmonic_phase": (("harmonic", "response"), phase, {"units": "rad"}),
            "amplitude": (("response",), 0.5 * np.ptp(y, axis=0), {"units": "m or rad (see response_unit)"}),
        },
        coords=coords,
    )
