"""The sweep's fast path (summary from the kernel's arrays, no Dataset) against the plain
path (slipstep.run and post.summary.summarise of its Dataset): equal to 1e-12 on cases
that stick, slip, lift off, stop before a period, and march adaptively."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slipstep.post.summary import summarise
from slipstep.sweep import Parameter, SerialExecutor, SweepSpec, open_sweep, run_sweep
from slipstep.sweep.cases import build_case, make_plan
from slipstep.sweep.execute import payload_of, run_case


def _plain(plan, i):
    """The case run the plain way: its System, Simulation.run (the Dataset), summarise."""
    from slipstep.methods.simulation import Simulation
    from slipstep.sweep.execute import _run_options

    system, run = build_case(plan.case_dict(i), plan.base_dir)
    ds = Simulation(system, run.method or "newmark", **_run_options(run, plan.extra_run)).run()
    return ds.attrs["status"], summarise(ds, system)


def _assert_equal(fast: dict, plain: dict):
    assert fast.keys() == plain.keys()
    for key, value in plain.items():
        got = fast[key]
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(got), key
        else:
            assert got == pytest.approx(value, rel=1e-12, abs=1e-300), key


@pytest.mark.parametrize(
    "run",
    [
        {"method": "quasi-static", "periods": 2, "steps_per_period": 80},
        {"method": "quasi-static", "periods": 0.6, "steps_per_period": 80},  # no full period: NaN loops
        {"method": "newmark", "periods": 2.3, "steps_per_period": 64},  # t_end - T between steps: interpolated
    ],
)
def test_fast_summary_equals_the_plain_run(run):
    spec = SweepSpec(
        base="paper",
        run=run,
        parameters=(
            Parameter("damper.centrifugal_force_N", values=(50.0, 400.0)),
            Parameter("motion.1.amplitude", values=(2.0, 60.0)),
        ),
    )
    plan = make_plan(spec)
    payload = payload_of(plan)
    for i in range(plan.n_cases):
        fast = run_case(payload, plan.values[i])
        status, plain = _plain(plan, i)
        assert fast["status"] == status
        _assert_equal(fast["summary"], plain)


def test_fast_path_store_equals_the_plain_path_store(tmp_path, monkeypatch):
    """A whole sweep through the fast path and through the plain one (fast path switched
    off) give the same store values."""
    import slipstep.sweep.case_run as ex  # where the runner and run_case look it up

    spec = SweepSpec(
        base="paper",
        run={"method": "quasi-static", "periods": 2, "steps_per_period": 60},
        parameters=(Parameter("damper.contacts.*.friction_coefficient", values=(0.1, 0.3, 0.6)),),
    )
    run_sweep(spec, tmp_path / "fast.zarr", executor=SerialExecutor())
    monkeypatch.setattr(ex, "_fast", lambda payload, options: False)
    run_sweep(spec, tmp_path / "plain.zarr", executor=SerialExecutor())
    a, b = open_sweep(tmp_path / "fast.zarr"), open_sweep(tmp_path / "plain.zarr")
    for name in a.data_vars:
        if a[name].dtype.kind == "f" and name not in ("kernel_time_s", "wall_time_s", "case_time_s", "case_cpu_s"):
            np.testing.assert_allclose(a[name].values, b[name].values, rtol=1e-12, atol=0, equal_nan=True)
