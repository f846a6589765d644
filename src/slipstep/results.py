"""The output schema, in one place, and the builder of result Datasets.

Every variable carries ``units`` and ``long_name``. Dimensions: ``time`` (non-uniform for
adaptive methods), ``dof`` (structure DOFs), ``motion`` (prescribed motion components),
``contact`` (contact elements) and ``direction`` (tangential directions: one per 2D
contact, two per quasi-3D contact; each owns a slider and a state).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from slipstep.kernels.codes import STATE_NAMES  # contact_state values (defined once, in the kernels' codes)

STATE_TEXT = ", ".join(f"{code} {name}" for code, name in enumerate(STATE_NAMES))

SCHEMA: dict[str, tuple[tuple[str, ...], str, str]] = {
    # name: (dims, units, long_name)
    "displacement": (("time", "dof"), "m or rad (see dof_unit)", "DOF displacement x"),
    "velocity": (("time", "dof"), "m/s or rad/s", "DOF velocity v"),
    "acceleration": (("time", "dof"), "m/s^2 or rad/s^2", "DOF acceleration a"),
    "prescribed_motion": (("time", "motion"), "m", "prescribed motion p"),
    "tangential_displacement": (("time", "direction"), "m", "contact tangential relative displacement u"),
    "normal_displacement": (("time", "contact"), "m", "contact normal approach v (> 0: interference)"),
    "tangential_force": (("time", "direction"), "N", "contact tangential force T"),
    "normal_force": (("time", "contact"), "N", "contact normal force N (>= 0: compression)"),
    "slider": (("time", "direction"), "m", "slider position w"),
    "contact_state": (("time", "direction"), "1", f"contact state ({STATE_TEXT})"),
    "solves": (("time",), "1", "linear solves (iterations) in the step ending at this time"),
    "step_size": (("time",), "s", "time step ending at this time (0 at the initial point)"),
}

DYNAMIC_ONLY = ("velocity", "acceleration")


def build_dataset(system, out, n_stored: int, motion: np.ndarray, attrs: dict, dynamic: bool, compiled) -> xr.Dataset:
    """Assemble the Dataset of the first ``n_stored`` + 1 points from kernel outputs."""
    k = n_stored + 1
    cs = compiled
    tan_rows = np.asarray(cs.tangential_row)
    nrm_rows = np.asarray(cs.normal_row)
    data = {
        "displacement": out.x[:k],
        "velocity": out.v[:k],
        "acceleration": out.a[:k],
        "prescribed_motion": motion[:k],
        "tangential_displacement": out.q[:k][:, tan_rows],
        "normal_displacement": out.q[:k][:, nrm_rows],
        "tangential_force": out.f[:k][:, tan_rows],
        "normal_force": out.f[:k][:, nrm_rows],
        "slider": out.w[:k],
        "contact_state": out.state[:k],
        "solves": out.solves[:k],
        "step_size": out.dt[:k],
    }
    variables = {}
    for name, values in data.items():
        if not dynamic and name in DYNAMIC_ONLY:
            continue
        dims, units, long_name = SCHEMA[name]
        variables[name] = xr.Variable(dims, np.array(values), {"units": units, "long_name": long_name})
    variables["contact_state"].attrs.update(flag_values=np.arange(len(STATE_NAMES), dtype=np.int8), flag_meanings=" ".join(
        s.replace("-", "_").replace("+", "_pos") for s in STATE_NAMES))
    coords = {
        "time": ("time", np.array(out.t[:k]), {"units": "s", "long_name": "time after the static preload"}),
        "dof": ("dof", list(system.structure.dof_names)),
        "dof_unit": ("dof", list(system.structure.dof_units)),
        "motion": ("motion", list(system.motion_names)),
        "contact": ("contact", list(system.contact_names)),
        "direction": ("direction", system.direction_names()),
        "direction_contact": ("direction", [system.contact_names[i] for i in np.asarray(cs.direction_contact)]),
        "friction_coefficient": ("contact", np.asarray(cs.mu), {"units": "1"}),
        "contact_law": ("contact", [c.law for c in system.contacts]),
        "normal_stiffness": ("contact", np.asarray(cs.kn), {"units": "N/m"}),
        "tangential_stiffness": ("direction", np.asarray(cs.kt), {"units": "N/m"}),
    }
    clean = {key: (int(v) if isinstance(v, (bool, np.bool_)) else v) for key, v in attrs.items() if v is not None}
    return xr.Dataset(variables, coords=coords, attrs=clean)


def save(ds: xr.Dataset, path) -> None:
    """Write a result to netCDF (h5netcdf engine)."""
    ds.to_netcdf(path, engine="h5netcdf")


def load(path) -> xr.Dataset:
    """Read a result written by :func:`save`."""
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()
