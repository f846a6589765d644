"""Building FRF Datasets in the one layout of :mod:`slipstep.output.frf_schema`."""

from __future__ import annotations

import numpy as np
import xarray as xr

from slipstep.output.frf_schema import FRF_SCHEMA, TEXT_VARIABLES


def empty_frf(
    frequencies, responses, response_units, contacts, n_harmonics: int, attrs: dict | None = None
) -> xr.Dataset:
    """An FRF Dataset of the schema with every value NaN (floats) or "" (status), to be
    filled point by point. Dims: frequency (as given, in computing order), harmonic 0..H,
    response (DOF names, coordinate response_unit), contact."""
    freqs = np.asarray(frequencies, float)
    sizes = {
        "frequency": freqs.size,
        "harmonic": int(n_harmonics) + 1,
        "response": len(responses),
        "contact": len(contacts),
    }
    variables = {}
    for name, (dims, units, long_name) in FRF_SCHEMA.items():
        shape = tuple(sizes[d] for d in dims)
        values = np.full(shape, "", dtype=object) if name in TEXT_VARIABLES else np.full(shape, np.nan)
        if name == "point_kind":  # the grid of a stepped FRF is the asked one (HBM sets its own kinds)
            values[:] = "asked"
        variables[name] = xr.Variable(dims, values, {"units": units, "long_name": long_name})
    coords = {
        "frequency": ("frequency", freqs, {"units": "Hz", "long_name": "excitation (fundamental) frequency"}),
        "harmonic": ("harmonic", np.arange(sizes["harmonic"]), {"long_name": "harmonic number"}),
        "response": ("response", list(responses)),
        "response_unit": ("response", list(response_units)),
        "contact": ("contact", list(contacts)),
    }
    return xr.Dataset(variables, coords=coords, attrs=dict(attrs or {}))


def finalise(ds: xr.Dataset) -> xr.Dataset:
    """Make the text variables (schema.TEXT_VARIABLES) fixed-width string variables (netCDF-friendly)."""
    for name in TEXT_VARIABLES & set(ds.data_vars):
        ds[name] = ds[name].astype(str)
        ds[name].attrs.update(units=FRF_SCHEMA[name][1], long_name=FRF_SCHEMA[name][2])
    return ds


def concat_sweeps(up: xr.Dataset, down: xr.Dataset) -> xr.Dataset:
    """Both directions in one Dataset along ``sweep`` ("up", "down"), frequencies ascending."""
    up = up.sortby("frequency")
    down = down.sortby("frequency")
    out = xr.concat(
        [up, down],
        dim=xr.DataArray(["up", "down"], dims="sweep", name="sweep"),
        data_vars="all",
        coords="minimal",
        compat="override",
        join="override",
    )
    for name in ("linear_free_amplitude", "linear_stuck_amplitude"):  # the same in both
        if name in out and "sweep" in out[name].dims:
            out[name] = out[name].isel(sweep=0, drop=True)
    out.attrs = dict(up.attrs)
    out.attrs["sweep"] = "both"
    return out
