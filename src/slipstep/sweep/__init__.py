"""Design sweeps: many variants of a case, run serially or on dask.distributed, stored in zarr.

    from slipstep import sweep
    spec = sweep.load_spec("examples/amplitude_sweep.toml")     # or sweep.SweepSpec(...)
    report = sweep.run_sweep(spec, "amp.zarr")                  # local loopback dask cluster
    ds = sweep.open_sweep("amp.zarr", grid=True)                # one dimension per parameter

A leaf of the package (like the CLI): the core never imports it. Modules: ``spec`` (the
TOML/Python specification), ``cases`` (key paths, sample points, hashes), ``execute`` (one
case, batches, the serial and dask executors), ``store`` (the zarr store), ``run`` (the
driver), ``plots`` (design maps and curves).
"""

from slipstep.sweep.cases import Plan, make_plan, resolve
from slipstep.sweep.execute import DaskExecutor, SerialExecutor, run_case
from slipstep.sweep.run import run_sweep
from slipstep.sweep.spec import Outputs, Parameter, SweepSpec, load_spec, spec_from_dict
from slipstep.sweep.store import grid_view, open_sweep

__all__ = [
    "DaskExecutor",
    "Outputs",
    "Parameter",
    "Plan",
    "SerialExecutor",
    "SweepSpec",
    "grid_view",
    "load_spec",
    "make_plan",
    "open_sweep",
    "resolve",
    "run_case",
    "run_sweep",
    "spec_from_dict",
]
