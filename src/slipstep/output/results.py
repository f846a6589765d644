"""The output schema, in one place, and the builder of result Datasets.

Every variable carries ``units`` and ``long_name``. Dimensions: ``time`` (non-uniform for
adaptive methods), ``dof`` (structure DOFs), ``motion`` (prescribed motion components),
``contact`` (contact elements) and ``direction`` (tangential directions: one per 2D
contact, two per quasi-3D contact; each owns a slider and a state).
"""

from __future__ import annotations

import os

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

#: the coordinates of a result: name -> (unit when the coordinate has no ``units`` attribute, meaning)
COORDS: dict[str, tuple[str, str]] = {
    "time": ("s", "time after the static preload (non-uniform for the adaptive methods)"),
    "dof": ("-", "structure DOF names"),
    "dof_unit": ("-", "unit of each DOF (m or rad)"),
    "motion": ("-", "prescribed motion components"),
    "contact": ("-", "contact element names"),
    "direction": (
        "-",
        "tangential directions (one per 2D contact, two per quasi-3D contact); each owns a slider and a state",
    ),
    "direction_contact": ("-", "the contact each direction belongs to"),
    "contact_law": ("-", "the friction law each contact uses (see the case-file reference, Contact laws)"),
    "friction_coefficient": ("1", "mu of each contact"),
    "normal_stiffness": ("N/m", "k_n of each contact"),
    "tangential_stiffness": ("N/m", "k_t of each direction"),
    "step": ("1", "the march's step number of each saved time (absent for outputs at given times)"),
}

#: the attributes of a result (``ds.attrs``): name -> (unit, meaning)
ATTRS: dict[str, tuple[str, str]] = {
    "title": ("-", "one-line title of the result"),
    "case": ("-", "case name"),
    "method": ("-", "method name (see Methods)"),
    "paper_method": ("-", "the paper's label of the method (Method 1 ... Method 4)"),
    "solver": ("-", "step solver: modified-newton, full-newton or piecewise-linear"),
    "adaptive_step": ("1", "1 when the step follows the contact state (Methods 2, 2+3), else 0"),
    "quasi_static": ("1", "1 for the quasi-static method (no velocity, acceleration), else 0"),
    "scheme": ("-", "time-integration scheme and its parameters, e.g. newmark(beta=1/4, gamma=1/2)"),
    "linear_solver": (
        "-",
        "state solves: direct (LU per state), low-rank (Woodbury update), banded (RCM-ordered banded LU per "
        "state: sparse structures) or sparse (one sparse LU, the contact problem condensed: docs/sparse.md)",
    ),
    "linear_solver_reason": (
        "-",
        "why that backend ran: the linear_solver given, or 'auto' with the estimated cost per step of each backend "
        "[us] (methods.sparse.step_costs)",
    ),
    "bandwidth": ("1", "half-bandwidth kl = ku of the banded backend after the RCM order; -1 for dense backends"),
    "status": (
        "-",
        "OK, or why the march stopped early (NOT_CONVERGED, STATE_CYCLING, SINGULAR, CAPACITY, "
        "NON_FINITE, INTERRUPTED, DIVERGED; INVARIANT: completed but a contact invariant broken, see "
        "broken_invariant); the result then holds the steps before it",
    ),
    "status_message": ("-", "the status in words, with the fix"),
    "steps": ("1", "accepted time steps"),
    "solves": ("1", "linear solves (iterations) over the run"),
    "iterations": ("1", "the same count as solves (the paper's word)"),
    "mean_solves_per_step": ("1", "solves / steps"),
    "factorisations": ("1", "matrix factorisations (one per new contact state for the piecewise-linear solver)"),
    "law_calls": ("1", "contact-law evaluations"),
    "redone_steps": ("1", "steps redone with a smaller step (adaptive methods: the new state needed one)"),
    "fallback_steps": (
        "1",
        "steps the piecewise-linear state loop did not settle (state cycling) and handed to modified Newton",
    ),
    "state_changes": ("1", "steps whose contact-state tuple differs from the previous step's"),
    "dt_s": ("s", "the fixed step (adaptive methods: the full-stick step)"),
    "t_min_s": ("s", "T_min of the full-stick state, 2 pi / omega_max (paper Eq. 8)"),
    "t_end_s": ("s", "simulated time"),
    "period_s": ("s", "excitation period"),
    "step_ratio": ("1", "r in dt = r T_min / pi"),
    "steps_per_period": ("1", "steps per period (quasi-static method)"),
    "max_step_s": ("s", "accuracy cap of dynamic steps (default period / 50)"),
    "tolerance": ("1", "Newton tolerance, relative to length_scale_m"),
    "state_tolerance": ("1", "relative tolerance of the contact-state compatibility check"),
    "kernel_time_s": ("s", "time spent in the compiled march (excludes set-up and the Dataset)"),
    "save": ("-", "what the run saved (the save option): DOFs, contacts and time grid, in words"),
    "save_all_dofs": ("1", "1 when every DOF was saved (dof coordinate: the saved ones)"),
    "save_all_contacts": ("1", "1 when every contact was saved"),
    "save_every_step": (
        "1",
        "1 when every step was saved (from the first saved time), 0 for every k-th or given times",
    ),
    "save_whole_run": ("1", "1 when the saved times start at the start of the march (not the last periods only)"),
    "wall_time_s": ("s", "time of the whole run() call"),
    "length_scale_m": (
        "m",
        "displacement scale of the tolerances: the larger of the motion amplitude and the static "
        "deflection abs(f) / k of the loads, at least 1 nm",
    ),
    "energy_error_estimate": (
        "1",
        "relative error estimate of the loop energy per cycle, by step doubling (NaN when not available)",
    ),
    "peak_force_error_estimate": (
        "1",
        "relative error estimate of the peak contact force, by step doubling (NaN when not available)",
    ),
    "error_estimate_method": ("-", "how the error estimates were obtained"),
    "step_rule": (
        "-",
        "what set the step: `t-min` (the paper's T_min rule) or `accuracy` (cap, error estimate and stability "
        "only; `step_rule` option, `--step-rule`)",
    ),
    "rtol": ("1", "the accuracy the user set (`rtol` option, `--rtol`); NaN: off, the default step rule applies"),
    "failed_at_step": ("1", "on failure: the step that failed"),
    "failed_at_time_s": ("s", "on failure: the time it failed at"),
    "states_visited": ("-", "on failure: the contact states tried in the failing step"),
    "broken_invariant": (
        "-",
        "status INVARIANT: the contact invariant the march broke (finite, rows written, N >= 0, |T| <= mu N, "
        "slip along T), its step, time and contact",
    ),
    "steps_above_tolerance": (
        "1",
        "Methods 1 and 2 (Newmark, full save): steps accepted with a balance residual above 1e4 x tolerance of "
        "their forces (a warning names them; the result may be off the discrete solution)",
    ),
    "max_step_residual": ("1", "Methods 1 and 2: the largest balance residual of a step, relative to its forces"),
    "first_step_above_tolerance": ("1", "the first step counted in steps_above_tolerance"),
    "tolerance_over_range": (
        "1",
        "Methods 1 and 2 (OK runs): tolerance x length_scale_m / the largest DOF range of the run, about how far "
        "off the discrete solution the Newton stop may leave the result, as a fraction of the range; above 1e-8 "
        "the run warns (slipstep.methods.invariants.TOLERANCE_RANGE_FLAG, flagged)",
    ),
    "twin_difference": (
        "1",
        "the sensitivity twin (sensitivity_check option): max |x - x_twin| / the largest DOF range, x_twin the run "
        "with every load and motion scaled by 1 + 1e-10 and the Newton tolerance 100 times tighter; the result is "
        "not reproducible to better than this fraction of its range (NaN: the twin failed); above 1e-6 the run warns "
        "(SensitivityWarning; slipstep.methods.sensitivity_twin.TWIN_FLAG, flagged)",
    ),
    "twin_time_s": ("s", "CPU time of the sensitivity twin (present when it ran)"),
    "steps_over_planned": (
        "1",
        "steps taken over the steps of the planned step dt_s for the duration (slipstep.run; above 50 the step "
        "collapsed and the run warns)",
    ),
}
#: the attributes only a failed (or suspect) march has
FAILURE_ATTRS = (
    "failed_at_step",
    "failed_at_time_s",
    "states_visited",
    "broken_invariant",
    "first_step_above_tolerance",
)


def interpolate(rows: dict, grid: np.ndarray, dynamic: bool, gamma: float | None) -> dict:
    """The saved rows (t, x, v, a, q, f, w, state, solves, dt, step: the step ends around each
    given time) at the given times ``grid`` (the ``times`` choice of slipstep.methods.save). theta = (t - t_0) / h in the
    step [t_0, t_1] of length h:

        x = h00 x_0 + h10 h v_0 + h01 x_1 + h11 h v_1   (cubic Hermite; linear without v)
        a = (1 - theta) a_0 + theta a_1
        v = v_0 + theta h ((1 - gamma) a_0 + gamma a)    (Newmark; v_1 at theta = 1)

    with h00 = 2 th^3 - 3 th^2 + 1, h10 = th^3 - 2 th^2 + th, h01 = 3 th^2 - 2 th^3,
    h11 = th^3 - th^2; q, f, w linear; the state of the nearest step end; solves and
    step_size those of the step holding the time."""
    t = rows["t"]
    right = np.clip(np.searchsorted(t, grid, side="left"), 0, t.size - 1)
    left = np.maximum(right - 1, 0)
    h = t[right] - t[left]
    safe = np.where(h > 0, h, 1.0)
    th = np.where(h > 0, (grid - t[left]) / safe, 1.0)[:, None]
    hh = h[:, None]
    x0, x1 = rows["x"][left], rows["x"][right]
    out = {"t": np.asarray(grid, float)}
    if dynamic:
        v0, v1, a0, a1 = rows["v"][left], rows["v"][right], rows["a"][left], rows["a"][right]
        th2, th3 = th * th, th * th * th
        out["x"] = (2 * th3 - 3 * th2 + 1) * x0 + (th3 - 2 * th2 + th) * hh * v0 + (3 * th2 - 2 * th3) * x1
        out["x"] = out["x"] + (th3 - th2) * hh * v1
        a = (1 - th) * a0 + th * a1
        out["a"] = a
        out["v"] = v0 + th * hh * ((1 - gamma) * a0 + gamma * a)
    else:
        out["x"] = (1 - th) * x0 + th * x1
        out["v"] = np.zeros_like(out["x"])
        out["a"] = np.zeros_like(out["x"])
    for key in ("q", "f", "w"):
        out[key] = (1 - th) * rows[key][left] + th * rows[key][right]
    nearest = np.where(th[:, 0] < 0.5, left, right)
    out["state"] = rows["state"][nearest]
    out["solves"] = rows["solves"][right]
    out["dt"] = h
    return out


def kernel_rows(system, out, n_stored: int, compiled, plan=None, grid=None, dynamic=True, gamma=None):
    """The first ``n_stored`` + 1 rows of the kernel outputs (dict of t, x, v, a, q, f, w,
    state, solves, dt, step; interpolated at the times ``grid`` if given), the saved contacts
    and directions, and the columns of q and f that hold the directions' tangential and the
    contacts' normal components: (rows, contacts, dirs, tan_cols, nrm_cols)."""
    k = n_stored + 1
    cs = compiled
    nc = len(system.contact_names)
    contacts = np.arange(nc) if plan is None else plan.contacts
    dirs = np.asarray(out.dirs)
    column = {int(r): i for i, r in enumerate(np.asarray(out.rows))}
    tan_cols = np.array([column[int(r)] for r in np.asarray(cs.tangential_row)[dirs]], np.int64)
    nrm_cols = np.array([column[int(r)] for r in np.asarray(cs.normal_row)[contacts]], np.int64)
    rows = {key: getattr(out, key)[:k] for key in ("t", "x", "v", "a", "q", "f", "w", "state", "solves", "dt", "step")}
    if grid is not None:
        rows = interpolate(rows, grid, dynamic, gamma)
    return rows, contacts, dirs, tan_cols, nrm_cols


def build_dataset(
    system,
    out,
    n_stored: int,
    motion: np.ndarray,
    attrs: dict,
    dynamic: bool,
    compiled,
    plan=None,
    grid=None,
    gamma=None,
) -> xr.Dataset:
    """Assemble the Dataset of the first ``n_stored`` + 1 rows of kernel outputs: the saved DOFs
    (coordinate ``dof``), contacts and directions of ``plan`` (slipstep.methods.save.Plan;
    None: all), at the saved steps (coordinate ``step``), or interpolated at the given times
    ``grid`` (:func:`interpolate`; ``gamma``: the Newmark gamma of the march)."""
    cs = compiled
    n = len(system.structure.dof_names)
    dofs = np.arange(n) if plan is None else plan.dofs
    rows, contacts, dirs, tan_cols, nrm_cols = kernel_rows(system, out, n_stored, compiled, plan, grid, dynamic, gamma)
    data = {
        "displacement": rows["x"],
        "velocity": rows["v"],
        "acceleration": rows["a"],
        "prescribed_motion": motion[: rows["t"].shape[0]],
        "tangential_displacement": rows["q"][:, tan_cols],
        "normal_displacement": rows["q"][:, nrm_cols],
        "tangential_force": rows["f"][:, tan_cols],
        "normal_force": rows["f"][:, nrm_cols],
        "slider": rows["w"],
        "contact_state": rows["state"],
        "solves": rows["solves"],
        "step_size": rows["dt"],
    }
    variables = {}
    for name, values in data.items():
        if not dynamic and name in DYNAMIC_ONLY:
            continue
        dims, units, long_name = SCHEMA[name]
        variables[name] = xr.Variable(dims, np.array(values), {"units": units, "long_name": long_name})
    variables["contact_state"].attrs.update(
        flag_values=np.arange(len(STATE_NAMES), dtype=np.int8),
        flag_meanings=" ".join(s.replace("-", "_").replace("+", "_pos") for s in STATE_NAMES),
    )
    names, units = system.structure.dof_names, system.structure.dof_units
    cnames, dnames = system.contact_names, system.direction_names()
    owner = np.asarray(cs.direction_contact)
    coords = {
        "time": ("time", np.array(rows["t"]), {"units": "s", "long_name": "time after the static preload"}),
        "dof": ("dof", [names[i] for i in dofs]),
        "dof_unit": ("dof", [units[i] for i in dofs]),
        "motion": ("motion", list(system.motion_names)),
        "contact": ("contact", [cnames[i] for i in contacts]),
        "direction": ("direction", [dnames[d] for d in dirs]),
        "direction_contact": ("direction", [cnames[owner[d]] for d in dirs]),
        "friction_coefficient": ("contact", np.asarray(cs.mu)[contacts], {"units": "1"}),
        "contact_law": ("contact", [system.contacts[i].law for i in contacts]),
        "normal_stiffness": ("contact", np.asarray(cs.kn)[contacts], {"units": "N/m"}),
        "tangential_stiffness": ("direction", np.asarray(cs.kt)[dirs], {"units": "N/m"}),
    }
    if "step" in rows:
        coords["step"] = ("time", np.array(rows["step"]), {"units": "1", "long_name": "step number of the march"})
    clean = {key: (int(v) if isinstance(v, (bool, np.bool_)) else v) for key, v in attrs.items() if v is not None}
    return xr.Dataset(variables, coords=coords, attrs=clean)


def saved(ds: xr.Dataset, what: str) -> bool:
    """Whether ``ds`` saved ``what`` (attrs of slipstep.methods.save.Plan.attrs; a result
    without them saved everything): 'all_dofs', 'all_contacts', 'every_step' (every step from
    its first time: not every k-th, not interpolated at given times), 'whole_run' (from t = 0)."""
    return bool(ds.attrs.get(f"save_{what}", 1))


def save(ds: xr.Dataset, path) -> None:
    """Write a result to netCDF-4 (h5netcdf engine), atomically (slipstep.output.io.atomic_path):
    a failure (disk full, interrupt) leaves any previous file at ``path`` intact and raises
    :class:`~slipstep.errors.OutputError` for a failure of the disk.

    A file that cannot fit is refused before any byte is written. When the disk (or the file
    size limit) leaves less than twice the file, the file is built in memory and written with
    plain writes: HDF5 itself may crash (segmentation fault) when the disk fills under it."""
    import io

    from slipstep.errors import InputError
    from slipstep.output.io import atomic_path, ensure_space

    if not isinstance(ds, xr.Dataset):
        raise InputError("ds", f"is a {type(ds).__name__}", "give the Dataset returned by slipstep.run")
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise InputError("path", f"is {path!r}", "give a file path")
    size = ds.nbytes * 1.02 + 262144  # the file: the data plus about 30 KB of HDF5 metadata (measured)
    free = ensure_space(path, size)
    with atomic_path(path) as tmp:
        if free < 2 * size + 32 * 2**20:
            image = io.BytesIO()
            ds.to_netcdf(image, engine="h5netcdf")
            with open(tmp, "wb") as fh:
                fh.write(image.getbuffer())
        else:
            ds.to_netcdf(tmp, engine="h5netcdf")


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def load(path, field: str = "result") -> xr.Dataset:
    """Read a result written by :func:`save`. Refuses (InputError naming ``field``) a file that
    is not a slipstep result (schema check: the variables, dims and units of :data:`SCHEMA`),
    and any HDF5 feature that reads outside the file: external storage, external or soft
    links, virtual datasets. The checks and the read use the same open file."""
    from slipstep.errors import InputError

    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise InputError(field, f"is {path!r}", "give the path of a .nc result file")

    def refuse(problem: str) -> InputError:
        return InputError(
            field, f"{str(path)!r} {problem}", "give a .nc file written by `slipstep run` or slipstep.save_result"
        )

    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise InputError(field, f"file {str(path)!r} does not exist", "give the path of a .nc result file") from None
    except OSError as exc:
        raise InputError(
            field, f"{str(path)!r} cannot be read ({exc.strerror})", "give a readable .nc result file"
        ) from None
    with fh:
        head = fh.read(8)
        if head != HDF5_SIGNATURE:
            kind = "a netCDF-3 file" if head[:3] == b"CDF" else "empty" if not head else "not a netCDF-4/HDF5 file"
            raise refuse(f"is not a slipstep result ({kind})")
        fh.seek(0)
        nbytes = _check_hdf5(fh, refuse)
        from slipstep.output.io import memory_limit

        limit = memory_limit()
        if nbytes > limit:
            from slipstep.output.io import format_bytes

            raise refuse(
                f"would need {format_bytes(nbytes)} of memory to load, more than the limit {format_bytes(limit)}"
            )
        fh.seek(0)
        try:
            with xr.open_dataset(fh, engine="h5netcdf") as opened:
                ds = opened.load()
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise refuse(f"is not a readable netCDF-4 file ({' '.join(str(exc).split())[:200]})") from None
    problem = schema_problem(ds)
    if problem:
        raise refuse(f"is not a slipstep result ({problem})")
    return ds


def _check_hdf5(fh, refuse) -> int:
    """Walk every object of the HDF5 file: refuse non-hard links, external storage and
    virtual datasets; return the bytes its datasets hold once loaded."""
    import h5py

    try:
        f = h5py.File(fh, "r")
    except OSError as exc:
        raise refuse(f"is not a readable HDF5 file ({' '.join(str(exc).split())[:200]})") from None
    total = 0
    with f:
        stack = [f]
        while stack:
            group = stack.pop()
            for name in group:
                link = group.get(name, getlink=True)
                if not isinstance(link, h5py.HardLink):
                    kind = "an external link" if isinstance(link, h5py.ExternalLink) else "a soft or user-defined link"
                    raise refuse(
                        f"contains {kind} ({group.name.rstrip('/')}/{name}): refused, it reads outside the file"
                    )
                obj = group[name]
                if isinstance(obj, h5py.Group):
                    stack.append(obj)
                elif isinstance(obj, h5py.Dataset):
                    if obj.external:
                        raise refuse(f"stores dataset {obj.name} in external files: refused, it reads outside the file")
                    if obj.is_virtual:
                        raise refuse(f"holds a virtual dataset ({obj.name}): refused, it reads outside the file")
                    total += int(obj.size) * max(int(obj.dtype.itemsize), 1)
    return total


REQUIRED_ATTRS = ("case", "method", "status", "quasi_static")


def schema_problem(ds: xr.Dataset) -> str:
    """'' if ``ds`` has the layout of :data:`SCHEMA` (variables, dims, units, attributes),
    else what is wrong."""
    missing = [a for a in REQUIRED_ATTRS if a not in ds.attrs]
    if missing:
        return f"attribute(s) {missing} missing"
    if "time" not in ds.coords or ds["time"].ndim != 1:
        return "no time coordinate"
    quasi_static = bool(ds.attrs["quasi_static"])
    for name, (dims, units, _) in SCHEMA.items():
        if name not in ds.variables:
            if quasi_static and name in DYNAMIC_ONLY:
                continue
            return f"variable {name!r} missing"
        var = ds[name]
        if var.dims != dims:
            return f"variable {name!r} has dims {var.dims}, expected {dims}"
        if var.attrs.get("units") != units:
            return f"variable {name!r} has units {var.attrs.get('units')!r}, expected {units!r}"
    return ""
