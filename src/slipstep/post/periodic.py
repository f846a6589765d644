"""Steady state (periodicity) detection and last-period extraction of result Datasets.

A run is periodic (in steady state) from period k on when consecutive periods of the DOF
displacement agree:

    e_k = max_t |x(t) - x(t - T)| / max(range of x over the record, length scale),
    t in period k (t_0 + (k-1) T, t_0 + k T],  k = 2, 3, ...

Both periods are first interpolated linearly onto a common phase grid (the finer of the
two), so the comparison works on uniform and non-uniform (adaptive) time grids alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from slipstep.errors import InputError

_REL = 1e-9  # relative time tolerance when matching period boundaries to grid points


def period_of(ds: xr.Dataset, period: float | None = None) -> float:
    """The excitation period [s]: ``period`` if given, else the Dataset attribute period_s."""
    T = period if period is not None else ds.attrs.get("period_s")
    if T is None or not np.isfinite(T) or T <= 0:
        raise InputError(
            "period", "the result has no excitation period (attribute period_s)", "pass period= in seconds"
        )
    return float(T)


def _interp_row(ds: xr.Dataset, t0: float) -> xr.Dataset:
    """One time point at ``t0``: linear interpolation of float variables, the state held
    from the previous stored point (integer variables), as a 1-point Dataset."""
    t = ds["time"].values
    i = int(np.searchsorted(t, t0, side="right"))  # t[i-1] <= t0 < t[i]
    i = min(max(i, 1), t.size - 1)
    s = (t0 - t[i - 1]) / (t[i] - t[i - 1])
    out = ds.isel(time=[i - 1]).copy(deep=True)
    for name, var in ds.data_vars.items():
        if "time" not in var.dims or not np.issubdtype(var.dtype, np.floating):
            continue
        a = var.isel(time=i - 1).values
        b = var.isel(time=i).values
        out[name].values[0] = a + s * (b - a)
    return out.assign_coords(time=[t0])


def last_period(ds: xr.Dataset, period: float | None = None) -> xr.Dataset:
    """The last full period [t_end - T, t_end] of ``ds`` (closed at both ends).

    On a grid where t_end - T is not a stored time (adaptive steps) a point is inserted
    there by linear interpolation (contact state: the state of the step that contains it),
    so loops closed over the extracted period start and end at the same phase.
    """
    T = period_of(ds, period)
    t = ds["time"].values
    if t[-1] - t[0] < T * (1 - _REL):
        raise InputError(
            "period",
            f"the result lasts {t[-1] - t[0]:.6g} s, shorter than one period {T:.6g} s",
            "simulate at least one full period",
        )
    t0 = t[-1] - T
    tol = _REL * T
    j = int(np.argmin(np.abs(t - t0)))
    if abs(t[j] - t0) <= tol + 1e-12 * abs(t0):
        return ds.isel(time=slice(j, None))
    k = int(np.searchsorted(t, t0, side="right"))
    return xr.concat(
        [_interp_row(ds, t0), ds.isel(time=slice(k, None))],
        dim="time",
        data_vars="minimal",
        coords="minimal",
        compat="override",
    )


def _phase_compare(t: np.ndarray, y: np.ndarray, a: float, T: float) -> float:
    """max |y(t) - y(t - T)| over t in [a + T, a + 2T], both periods on a common phase grid."""
    ma = (t >= a - _REL * T) & (t <= a + T + _REL * T)
    mb = (t >= a + T - _REL * T) & (t <= a + 2 * T + _REL * T)
    n = max(ma.sum(), mb.sum(), 2)
    phase = np.linspace(0.0, T, n)
    diff = 0.0
    for c in range(y.shape[1]):
        ya = np.interp(a + phase, t, y[:, c])
        yb = np.interp(a + T + phase, t, y[:, c])
        diff = max(diff, float(np.abs(yb - ya).max()))
    return diff


@dataclass(frozen=True)
class Periodicity:
    """Result of :func:`periodicity`.

    errors: e_k for k = 2..n (relative, see the module docstring), one per period pair;
    steady_from: first period k (1-based) from which every later e is below ``rtol``
    (None if the last pair is not); periodic: the last pair agrees within ``rtol``.
    """

    errors: tuple[float, ...]
    rtol: float
    steady_from: int | None
    n_periods: int

    @property
    def periodic(self) -> bool:
        return self.steady_from is not None

    def text(self) -> str:
        errs = ", ".join(f"{e:.2e}" for e in self.errors) or "none (fewer than 2 periods)"
        if self.periodic:
            return (
                f"steady state from period {self.steady_from} of {self.n_periods} (period-to-period "
                f"differences {errs}, tolerance {self.rtol:g})"
            )
        return f"not periodic within {self.rtol:g}: period-to-period differences {errs}"


def periodicity(
    ds: xr.Dataset, variable: str = "displacement", rtol: float = 1e-3, period: float | None = None
) -> Periodicity:
    """Compare consecutive periods of ``variable`` (default the DOF displacement); see the
    module docstring for e_k. ``rtol`` is the relative tolerance of steady state."""
    T = period_of(ds, period)
    t = ds["time"].values
    if variable == "displacement" and ds.sizes.get("dof", 0) == 0 and ds.sizes.get("direction", 0) > 0:
        variable = "tangential_force"  # no DOF saved (the save option): the contact forces
    if variable not in ds or ds[variable].size == 0:
        from slipstep.errors import InputError

        raise InputError(
            "save", f"of this result saved no {variable} ({ds.attrs.get('save')})", "save DOFs or contacts"
        )
    y = np.asarray(ds[variable].values, float).reshape(t.size, -1)
    n = int(np.floor((t[-1] - t[0]) / T * (1 + _REL)))
    scale = max(float(np.ptp(y, axis=0).max(initial=0.0)), float(ds.attrs.get("length_scale_m", 0.0)) * 1e-3, 1e-300)
    errors = tuple(_phase_compare(t, y, t[0] + (k - 1) * T, T) / scale for k in range(1, n))
    steady = None
    for k in range(len(errors), 0, -1):
        if errors[k - 1] <= rtol:
            steady = k + 1
        else:
            break
    return Periodicity(errors, rtol, steady, n)
