"""The zarr store of a sweep: one row per case, written incrementally, resumable.

Layout (read it with :func:`open_sweep`; every variable has ``units`` and ``long_name``):

* dimension ``case`` (one entry per case of the plan, fixed when the store is created) with the
  coordinates ``case_hash`` (SHA-256 of the resolved case, slipstep.sweep.cases) and one
  coordinate per parameter (its name, e.g. ``centrifugal_force_N``; attrs ``units``, ``key``);
* ``status`` ("" until the case is computed, then OK, NOT_CONVERGED, ..., INPUT_ERROR,
  PRELOAD_FAILED, ERROR), ``status_message``, ``warning``;
* the summary fields (slipstep.post.summary.FIELDS), over ``case`` or (case, interface),
  (case, contact), (case, direction);
* optional histories ``history_<variable>`` over (case, phase, <its dimension>);
* optional frequency responses ``frf_<name>`` (slipstep.frequency.FRF_SCHEMA) over (case,
  frequency, ...) with the coordinates frequency [Hz], harmonic, response;
* run-to-run varying values, apart: ``kernel_time_s``, ``wall_time_s``, ``case_time_s``, ``case_cpu_s``,
  ``worker``, ``run_index`` (the invocation of the sweep that computed the case) and
  ``frf_point_time`` (all in VARYING).

Attributes: ``slipstep_sweep`` (layout version), ``slipstep_version``, ``sweep_spec`` (the
spec as JSON), ``sweep_name``, ``sampling``, ``parameters``, ``grid_shape`` (a grid sweep),
``case_kind``, ``runs``.

Crash safety. The store is created in a temporary directory and renamed into place. Each
flush writes the data of the finished cases first and their ``status`` last; zarr writes
each chunk to a temporary file and renames it. A killed client therefore leaves every
flushed case complete and every other case with an empty status: a rerun computes exactly
those, into the same rows (a case has one row, so nothing can be duplicated).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from slipstep.errors import InputError

LAYOUT = 1
RETRY_STATUS = "TASK_FAILED"  # slipstep.sweep.execute.STATUS_TASK
CASE_CHUNK = 1024
TIMING_FIELDS = {
    "kernel_time_s": ("s", "kernel time of the march (varies between runs)"),
    "wall_time_s": ("s", "time of Simulation.run: march and Dataset (varies between runs)"),
    "case_time_s": ("s", "time of the whole case: build, run, summary (varies between runs)"),
    "case_cpu_s": ("s", "CPU time of the whole case in its worker thread (varies between runs)"),
}
RESERVED = {
    "frequency",
    "harmonic",
    "response",
    "case",
    "case_hash",
    "status",
    "status_message",
    "warning",
    "worker",
    "run_index",
    "phase",
    "interface",
    "contact",
    "direction",
    "dof",
    "motion",
    "kernel_time_s",
    "wall_time_s",
    "case_time_s",
    "case_cpu_s",
}
# what differs between identical runs: the timings, the worker, the invocation
VARYING = set(TIMING_FIELDS) | {"worker", "run_index", "frf_point_time"}
TEXT_FIELDS = {
    "status": "status of the case (empty: not computed yet)",
    "status_message": "status message",
    "warning": "warnings raised by the case",
}


def _zarr():
    import zarr

    return zarr


class SweepStore:
    """The client-side writer of a sweep store (the only writer)."""

    def __init__(self, path: Path, group):
        self.path = Path(path)
        self.group = group
        self.n_cases = int(group.attrs["n_cases"])
        self.run_index = int(group.attrs.get("runs", 0))
        self._arrays = {name: group[name] for name in group.array_keys()}

    # -- opening -------------------------------------------------------------------------------
    @classmethod
    def open_or_create(cls, path: str | Path, plan, labels: dict, overwrite: bool = False) -> SweepStore:
        """Open the store of ``plan`` at ``path`` to resume it, or create it. An existing store of
        another sweep (different cases) is an error unless ``overwrite``."""
        from slipstep import __version__

        path = Path(path)
        if path.exists():
            if not _is_sweep_store(path):
                raise InputError(
                    "output",
                    f"{str(path)!r} exists and is not a slipstep sweep store",
                    "give a new path (e.g. results.zarr) or remove it",
                )
            if overwrite:
                shutil.rmtree(path)
            else:
                # the arrays on disk, not the consolidated list: a process killed inside a write may
                # have created arrays after the last consolidation
                store = cls(path, _zarr().open_group(str(path), mode="r+", use_consolidated=False))
                store._check_same(plan)
                written = store.group.attrs.get("slipstep_version")
                if written != __version__:
                    raise InputError(
                        "output",
                        f"{str(path)!r} was written by slipstep {written}, this is "
                        f"{__version__}: its numbers would mix two versions",
                        "give a new store path, or --overwrite to start again",
                    )
                store.group.attrs["runs"] = store.run_index + 1
                store.consolidate()
                return store
        if not path.parent.exists():
            raise InputError("output", f"the folder of {str(path)!r} does not exist", "create it or give another path")
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
        try:
            _create(tmp, plan, labels)
            os.replace(tmp, path)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        store = cls(path, _zarr().open_group(str(path), mode="r+"))
        store.group.attrs["runs"] = 1
        store.consolidate()
        return store

    def consolidate(self) -> None:
        """Write the consolidated metadata (every array's metadata in the group's zarr.json), so
        that ``xr.open_zarr(store)`` opens the store in one read and without a warning. Called
        on opening and in every write before the status (an array created by a write is then listed too)."""
        import warnings

        with warnings.catch_warnings():  # zarr notes that format 3 has no consolidated metadata yet
            warnings.simplefilter("ignore", UserWarning)
            _zarr().consolidate_metadata(str(self.path))

    def _check_same(self, plan) -> None:
        stored = _text(self._arrays["case_hash"][:])
        new = np.asarray(plan.hashes, dtype=str)
        if stored.shape != new.shape or np.any(stored != new):
            differ = int(np.sum(stored != new)) if stored.shape == new.shape else None
            what = (
                f"{differ} of its {new.size} cases differ"
                if differ is not None
                else f"it has {stored.size} cases, this sweep {new.size}"
            )
            raise InputError(
                "output",
                f"{str(self.path)!r} holds another sweep ({what}: the spec, its base case "
                "or the slipstep defaults changed)",
                "give a new store path, or --overwrite to start again",
            )

    # -- state -----------------------------------------------------------------------------------
    def done(self) -> np.ndarray:
        """True for every case already in the store (its status written), except the cases
        whose task was lost (TASK_FAILED): a rerun computes those again."""
        status = _text(self._arrays["status"][:])
        return (status != "") & (status != RETRY_STATUS)

    # -- writing ---------------------------------------------------------------------------------
    def write(self, results: list[dict]) -> None:
        """Write finished cases: their data first, then the consolidated metadata (which lists the
        arrays the data created), their status last: a process killed at any point leaves no case
        marked done whose data a reader cannot open."""
        if not results:
            return
        results = sorted(results, key=lambda r: r["index"])
        idx = np.array([r["index"] for r in results], dtype=np.int64)
        columns: dict[str, list] = {}
        for r in results:
            for key in r["summary"]:
                columns.setdefault(key, [None] * len(results))
        for i, r in enumerate(results):
            for key, value in r["summary"].items():
                columns[key][i] = value
        grouped = _group_fields(columns)
        for base, (dim, labels, values) in grouped.items():
            arr = self._summary_array(base, dim, labels, values)
            if dim is None:
                arr.oindex[idx] = _column(values, arr.dtype)
            else:
                positions = self._label_positions(dim, labels)
                block = np.full((len(results), len(labels)), np.nan)
                for j, col in enumerate(values):
                    block[:, j] = [np.nan if v is None else v for v in col]
                arr.oindex[idx, positions] = block
        self._write_histories(idx, results)
        self._write_frf(idx, results)
        for key in TIMING_FIELDS:
            self._arrays[key].oindex[idx] = np.array([r["timing"].get(key, np.nan) for r in results], float)
        self._arrays["worker"].oindex[idx] = np.array([r.get("worker", "") for r in results], dtype=str)
        self._arrays["run_index"].oindex[idx] = np.full(idx.size, self.run_index, np.int64)
        self._arrays["status_message"].oindex[idx] = np.array([r["message"] for r in results], dtype=str)
        self._arrays["warning"].oindex[idx] = np.array([r["warning"] for r in results], dtype=str)
        self.consolidate()  # before the status: a reader opens through the consolidated metadata
        self._arrays["status"].oindex[idx] = np.array([r["status"] for r in results], dtype=str)  # last: done

    def _summary_array(self, base: str, dim, labels, values):
        from slipstep.post.summary import FIELDS
        from slipstep.sweep.mistuning import MISTUNING_FIELDS

        if base in self._arrays:
            return self._arrays[base]
        units, long_name = {**FIELDS, **MISTUNING_FIELDS}.get(base, ("1", base))
        if dim is None:
            sample = next((v for v in values if v is not None), 0.0)
            integer = isinstance(sample, (int, np.integer)) and not isinstance(sample, bool)
            dtype, fill = ("i8", -1) if integer else ("f8", np.nan)
            shape, chunks, dims = (self.n_cases,), (min(self.n_cases, CASE_CHUNK),), ["case"]
        else:
            self._label_positions(dim, labels)
            n = self._arrays[dim].shape[0]
            dtype, fill = "f8", np.nan
            shape, chunks, dims = (self.n_cases, n), (min(self.n_cases, CASE_CHUNK), n), ["case", dim]
        attrs = {"units": units, "long_name": long_name}
        if dtype == "i8":
            attrs["missing_value"] = -1
        arr = self.group.create_array(
            base, shape=shape, chunks=chunks, dtype=dtype, fill_value=fill, dimension_names=dims, attributes=attrs
        )
        self._arrays[base] = arr
        return arr

    def _label_positions(self, dim: str, labels: list[str]) -> np.ndarray:
        if dim not in self._arrays:
            arr = self.group.create_array(
                dim,
                shape=(len(labels),),
                dtype=str,
                fill_value="",
                dimension_names=[dim],
                attributes={"long_name": f"{dim} names"},
            )
            arr[:] = np.array(labels, dtype=str)
            self._arrays[dim] = arr
        known = list(_text(self._arrays[dim][:]))
        missing = [lab for lab in labels if lab not in known]
        if missing:
            raise InputError(
                dim,
                f"{missing} appear in a case but not in the store's {dim}s {known}",
                "sweep values only: the parameters must not change the model's topology",
            )
        return np.array([known.index(lab) for lab in labels], dtype=np.int64)

    def _write_frf(self, idx: np.ndarray, results: list[dict]) -> None:
        from slipstep.frequency import FRF_SCHEMA

        if not any(r.get("frf") for r in results):
            return
        for name in FRF_SCHEMA:
            arr = self._arrays.get(f"frf_{name}")
            if arr is not None:
                arr.oindex[idx] = _frf_block(arr, idx, results, name)

    def _write_histories(self, idx: np.ndarray, results: list[dict]) -> None:
        names = {n for r in results for n in r["histories"]}
        for name in sorted(names):
            arr = self._arrays.get(f"history_{name}")
            if arr is None:
                continue
            block = np.full(
                (idx.size,) + arr.shape[1:], arr.fill_value if arr.dtype.kind != "f" else np.nan, dtype=arr.dtype
            )
            for i, r in enumerate(results):
                if name in r["histories"]:
                    block[i] = r["histories"][name]
            arr.oindex[idx] = block


def _frf_block(arr, idx: np.ndarray, results: list[dict], name: str) -> np.ndarray:
    """The rows of one FRF variable for the cases ``idx`` (missing: NaN or "")."""
    text = arr.dtype.kind not in "fiu"
    block = np.full((idx.size,) + arr.shape[1:], "" if text else np.nan, dtype=object if text else arr.dtype)
    for i, r in enumerate(results):
        if name in r.get("frf", {}):
            block[i] = r["frf"][name]
    return block.astype(str) if text else block


def _column(values: list, dtype) -> np.ndarray:
    """A column of one summary field: missing values (None, and NaN in an integer field) as the
    field's fill value (NaN, or -1 for integers)."""
    if np.dtype(dtype).kind == "f":
        return np.array([np.nan if v is None else v for v in values], dtype=dtype)
    return np.array([-1 if v is None or (isinstance(v, float) and v != v) else v for v in values], dtype=dtype)


def _text(values) -> np.ndarray:
    """Text arrays as numpy str (zarr returns numpy's variable-width StringDType)."""
    return np.asarray(values).astype(object).astype(str)


def _group_fields(columns: dict[str, list]) -> dict:
    """Summary keys -> {base: (dim or None, labels, values per label (or values))}."""
    from slipstep.post.summary import dimension_of, field_of

    grouped: dict = {}
    for key, values in columns.items():
        base, label = field_of(key)
        dim = dimension_of(base) if label is not None else None
        if dim is None:
            grouped[key] = (None, None, values)
        else:
            entry = grouped.setdefault(base, (dim, [], []))
            entry[1].append(label)
            entry[2].append(values)
    return grouped


def _is_sweep_store(path: Path) -> bool:
    meta = path / "zarr.json"
    if not meta.is_file():
        return False
    try:
        return "slipstep_sweep" in json.loads(meta.read_text()).get("attributes", {})
    except (OSError, ValueError):
        return False


def _create(path: Path, plan, labels: dict) -> None:
    """A new store for ``plan``: the case dimension, parameters, status, timings, histories."""
    from slipstep import __version__
    from slipstep.output.results import SCHEMA

    zarr = _zarr()
    g = zarr.open_group(str(path), mode="w")
    n = plan.n_cases
    chunk = (min(n, CASE_CHUNK),)

    def array(name, dtype, fill, attrs, dims=("case",), shape=None, chunks=None):
        return g.create_array(
            name,
            shape=shape or (n,),
            chunks=chunks or chunk,
            dtype=dtype,
            fill_value=fill,
            dimension_names=list(dims),
            attributes=attrs,
        )

    array("case", "i8", -1, {"long_name": "case number (0-based, in the order of the plan)"})[:] = np.arange(n)
    array("case_hash", str, "", {"long_name": "SHA-256 (24 hex digits) of the resolved case"})[:] = np.array(
        plan.hashes, dtype=str
    )
    for j, p in enumerate(plan.parameters):
        array(p.name, "f8", np.nan, {"units": p.unit, "long_name": ", ".join(p.keys), "key": list(p.keys)})[:] = (
            plan.values[:, j]
        )
    for name, long_name in TEXT_FIELDS.items():
        array(name, str, "", {"long_name": long_name})
    for name, (units, long_name) in TIMING_FIELDS.items():
        array(name, "f8", np.nan, {"units": units, "long_name": long_name})
    array("worker", str, "", {"long_name": "host:pid of the worker that computed the case (varies between runs)"})
    array("run_index", "i8", -1, {"long_name": "invocation of the sweep that computed the case (0: the first)"})

    def label_coordinate(dim):
        g.create_array(
            dim,
            shape=(len(labels[dim]),),
            dtype=str,
            fill_value="",
            dimension_names=[dim],
            attributes={"long_name": f"{dim} names"},
        )[:] = np.array(labels[dim], dtype=str)

    for dim in ("interface", "contact", "direction"):
        if dim in labels:
            label_coordinate(dim)
    points = plan.outputs["history_points"]
    if plan.outputs["histories"]:
        phase = g.create_array(
            "phase",
            shape=(points,),
            dtype="f8",
            fill_value=np.nan,
            dimension_names=["phase"],
            attributes={"units": "1", "long_name": "phase in the last period (t - t_end + T) / T"},
        )
        phase[:] = np.linspace(0.0, 1.0, points)
    for name in plan.outputs["histories"]:
        dims, units, long_name = SCHEMA[name]
        dim = dims[1] if len(dims) > 1 else None
        if dim is not None and dim not in labels:
            continue
        if dim is not None and dim not in g:
            label_coordinate(dim)
        width = (len(labels[dim]),) if dim is not None else ()
        integer = name == "contact_state"
        g.create_array(
            f"history_{name}",
            shape=(n, points) + width,
            chunks=(min(n, 256), points) + width,
            dtype="i1" if integer else "f8",
            fill_value=-1 if integer else np.nan,
            dimension_names=["case", "phase"] + ([dim] if dim else []),
            attributes={"units": units, "long_name": f"{long_name}, last period"},
        )
    if plan.outputs.get("frf"):
        _create_frf(g, plan, labels)
    spec = plan.spec
    g.attrs.update(
        {
            "slipstep_sweep": LAYOUT,
            "slipstep_version": __version__,
            "title": f"slipstep sweep: {spec.name}",
            "sweep_name": spec.name,
            "description": spec.description,
            "sweep_spec": json.dumps(spec.to_dict()),
            "spec_source": spec.source,
            "sampling": spec.sampling,
            "parameters": [p.name for p in plan.parameters],
            "grid_shape": list(plan.grid_shape) if plan.grid_shape else None,
            "case_kind": plan.kind,
            "n_cases": n,
            "runs": 0,
        }
    )


def _create_frf(g, plan, labels: dict) -> None:
    """The FRF variables of every case: ``frf_<name>`` over (case, <its FRF_SCHEMA dims>), with
    the frequency [Hz], harmonic and response coordinates (slipstep.output.frf_schema)."""
    from slipstep.frequency import FRF_SCHEMA
    from slipstep.output.frf_schema import TEXT_VARIABLES

    cfg = plan.outputs["frf"]
    coords = {
        "frequency": np.array(cfg["frequencies_Hz"], float),
        "harmonic": np.arange(max(np.atleast_1d(cfg["harmonics"])) + 1),  # 0..H (hbm: H = the highest kept)
        "response": np.array(cfg["responses"] or labels["dof"], dtype=str),
    }
    attrs = {
        "frequency": {"units": "Hz", "long_name": "excitation frequency of the FRF points"},
        "harmonic": {"long_name": "harmonic number of the response (0: mean)"},
        "response": {"long_name": "response DOFs of the FRF"},
    }
    for dim, values in coords.items():
        if values.dtype.kind == "U":
            dtype, fill = str, ""
        else:
            dtype, fill = values.dtype, (-1 if values.dtype.kind == "i" else np.nan)
        g.create_array(
            dim, shape=values.shape, dtype=dtype, fill_value=fill, dimension_names=[dim], attributes=attrs[dim]
        )[:] = values
    sizes = {**{d: v.size for d, v in coords.items()}, "contact": len(labels["contact"])}
    n = plan.n_cases
    for name, (dims, units, long_name) in FRF_SCHEMA.items():
        if any(d not in sizes for d in dims):
            continue
        shape = (n,) + tuple(sizes[d] for d in dims)
        text = name in TEXT_VARIABLES
        g.create_array(
            f"frf_{name}",
            shape=shape,
            chunks=(min(n, 64),) + shape[1:],
            dtype=str if text else "f8",
            fill_value="" if text else np.nan,
            dimension_names=["case", *dims],
            attributes={"units": units, "long_name": f"FRF: {long_name}"},
        )


# -- reading -------------------------------------------------------------------------------------


def open_sweep(path: str | Path, grid: bool = False):
    """The store as an in-memory xarray Dataset over ``case`` (text as str); ``grid=True``
    gives the dense grid view of a grid sweep: one dimension per parameter (first slowest)."""
    import xarray as xr

    path = Path(path)
    if not _is_sweep_store(path):
        raise InputError(
            "store", f"{str(path)!r} is not a slipstep sweep store", "give the .zarr folder written by `slipstep sweep`"
        )
    with xr.open_zarr(str(path), chunks=None) as ds:
        ds = ds.load()
    for name, var in list(ds.variables.items()):
        if var.dtype.kind == "T" or var.dtype == object:
            ds[name] = var.copy(data=_text(var.values))
    params = list(ds.attrs["parameters"])
    ds = ds.set_coords([c for c in ["case_hash", *params] if c in ds.data_vars])
    return grid_view(ds) if grid else ds


def grid_view(ds):
    """A grid sweep's Dataset with ``case`` unfolded into one dimension per parameter."""
    import xarray as xr

    shape = ds.attrs.get("grid_shape")
    if not shape:
        raise InputError(
            "grid",
            f"the sweep is {ds.attrs.get('sampling')!r} sampled, not a grid",
            "use the case dimension (or plot a scatter)",
        )
    params = list(ds.attrs["parameters"])
    axes = {}
    for j, name in enumerate(params):
        v = ds[name].values.reshape(shape)
        axes[name] = np.moveaxis(v, j, 0)[(slice(None),) + (0,) * (len(shape) - 1)]
    out = {}
    for name, var in ds.variables.items():
        if "case" not in var.dims or name in params or name == "case":
            continue
        rest = tuple(d for d in var.dims if d != "case")
        values = var.transpose("case", *rest).values.reshape(tuple(shape) + tuple(var.sizes[d] for d in rest))
        out[name] = xr.Variable(tuple(params) + rest, values, var.attrs)
    coords = {name: (name, axes[name], ds[name].attrs) for name in params}
    for name, c in ds.coords.items():
        if "case" not in c.dims:
            coords[name] = c
    data_names = [n for n in out if n not in ("case_hash",)]
    return xr.Dataset({n: out[n] for n in data_names}, coords={**coords, "case_hash": out["case_hash"]}, attrs=ds.attrs)
