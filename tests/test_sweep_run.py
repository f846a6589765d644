"""Sweeps run serially: the per-case summary against closed forms and the paper, the zarr
store (grid view, histories, failures recorded), resuming, and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import slipstep
from slipstep.cli.main import app
from slipstep.errors import InputError, Status
from slipstep.post.summary import FIELDS, field_of, summarise
from slipstep.sweep import Parameter, SerialExecutor, SweepSpec, open_sweep, run_sweep
from slipstep.sweep.store import TIMING_FIELDS, VARYING

# A Jenkins element: the contact's tangential coordinate is the prescribed motion itself,
# u = -p = -XA sin(2 pi f t), and a constant force F on the normal DOF gives N = F.
XA, KT, F_HZ = 10e-6, 1e6, 100.0
JENKINS = f"""
name = "jenkins"
motion_names = ["slide"]

[structure]
dof_names = ["y"]
mass_kg = [[1e-3]]
constant_force_N = [4.0]

[[contacts]]
name = "J"
dof_gather = [[0.0], [1.0]]
motion_gather = [[-1.0], [0.0]]
normal_stiffness_N_per_m = 1e8
tangential_stiffness_N_per_m = {KT}
friction_coefficient = 0.5

[[motion]]
component = "slide"
amplitude = {XA}
frequency_Hz = {F_HZ}

[run]
method = "quasi-static"
periods = 2
steps_per_period = 400
"""

MU = (0.1, 0.3, 0.5)
N = (2.0, 8.0, 30.0)  # mu N / k_t up to 15 um > XA: the last ones stick


@pytest.fixture(scope="module")
def jenkins_store(tmp_path_factory):
    root = tmp_path_factory.mktemp("jenkins")
    (root / "jenkins.toml").write_text(JENKINS)
    spec = SweepSpec(
        base=str(root / "jenkins.toml"),
        parameters=(
            Parameter("contacts.J.friction_coefficient", values=MU, name="mu"),
            Parameter("structure.constant_force_N.1", values=N, name="N"),
        ),
        outputs=slipstep.sweep.Outputs(histories=("tangential_force", "contact_state"), history_points=33),
    )
    report = run_sweep(spec, root / "j.zarr", executor=SerialExecutor())
    return spec, report, root / "j.zarr"


def test_jenkins_sweep_matches_the_closed_form(jenkins_store):
    spec, report, path = jenkins_store
    assert report["computed"] == 9 and report["status_counts"] == {"OK": 9}
    g = open_sweep(path, grid=True)
    assert dict(g.sizes) == {"mu": 3, "N": 3, "interface": 1, "direction": 1, "contact": 1, "phase": 33}
    assert g["mu"].attrs["units"] == "1" and g["N"].attrs["units"] == "N"
    for mu in MU:
        for n in N:
            c = g.sel(mu=mu, N=n).isel(interface=0, direction=0, contact=0)
            slip = mu * n
            stuck = slip / KT >= XA
            energy = 0.0 if stuck else 4 * slip * (XA - slip / KT)  # Jenkins loop area
            k_eq = KT if stuck else slip / XA
            assert float(c.interface_energy_per_cycle_J) == pytest.approx(energy, rel=2e-3, abs=1e-12)
            assert float(c.interface_k_eq_N_per_m) == pytest.approx(k_eq, rel=2e-3)
            assert float(c.direction_peak_T_over_muN) <= 1 + 1e-9
            assert float(c.contact_N_min_N) == pytest.approx(n, rel=1e-9)
            shares = float(c.direction_stick_share + c.direction_slip_share + c.direction_lift_off_share)
            assert shares == pytest.approx(1.0, abs=1e-12)
            if stuck:
                assert float(c.direction_stick_share) == 1.0
            else:
                assert float(c.direction_peak_T_over_muN) == pytest.approx(1.0, abs=1e-12)
            assert str(c.status.values) == "OK" and int(c.status_code) == 0


def test_histories_are_the_resampled_last_period(jenkins_store):
    spec, report, path = jenkins_store
    ds = open_sweep(path)
    assert ds["history_tangential_force"].dims == ("case", "phase", "direction")
    assert ds["history_tangential_force"].attrs["units"] == "N"
    i = 4  # mu = 0.3, N = 8 N: slips at |T| = 2.4 N
    T = ds["history_tangential_force"].values[i, :, 0]
    assert np.abs(T).max() == pytest.approx(0.3 * 8.0, rel=1e-9)
    states = ds["history_contact_state"].values[i, :, 0]
    assert set(np.unique(states)) <= {1, 2, 3} and {2, 3} <= set(np.unique(states))


def test_store_keeps_the_spec_version_and_timings_apart(jenkins_store):
    spec, report, path = jenkins_store
    ds = open_sweep(path)
    assert ds.attrs["slipstep_version"] == slipstep.__version__
    assert json.loads(ds.attrs["sweep_spec"]) == json.loads(json.dumps(spec.to_dict()))
    assert ds.attrs["grid_shape"] == [3, 3] and ds.attrs["parameters"] == ["mu", "N"]
    for name in TIMING_FIELDS:
        assert ds[name].attrs["units"] == "s" and np.all(ds[name].values > 0)
    assert np.all(ds["run_index"].values == 0)
    for name in ds.data_vars:
        base = field_of(name)[0]
        if base in FIELDS:
            assert ds[name].attrs["units"] == FIELDS[base][0]
    assert len(set(ds["case_hash"].values)) == 9


# ---------------------------------------------------------------- summaries


@pytest.fixture(scope="module")
def paper():
    system = slipstep.load_system("paper")
    return system, slipstep.run(system, "quasi-static", periods=3)


def test_summary_of_the_paper_case_reproduces_the_paper(paper):
    system, ds = paper
    s = summarise(ds, system)
    assert s["interface_energy_per_cycle_J[left]"] == pytest.approx(2.52e-3, rel=0.01)
    assert s["interface_energy_per_cycle_J[right]"] == pytest.approx(2.70e-3, rel=0.01)
    assert s["energy_per_cycle_J"] == pytest.approx(
        s["interface_energy_per_cycle_J[left]"] + s["interface_energy_per_cycle_J[right]"], rel=1e-12
    )
    assert s["full_slip_share"] == pytest.approx(0.547, abs=0.002)
    assert s["status_code"] == 0 and s["steps"] == 900 and s["solves"] == ds.attrs["solves"]
    assert s["steady_error"] < 1e-9  # quasi-static: periodic from the second period on
    for d in ("P1", "P2", "P3"):
        assert s[f"direction_peak_T_over_muN[{d}]"] == pytest.approx(1.0, abs=1e-9)  # gross slip reaches mu N
    assert not {"kernel_time_s", "wall_time_s"} & set(s)  # run-to-run varying values are not in the summary
    assert all(isinstance(v, (int, float)) for v in s.values())
    assert all(field_of(k)[0] in FIELDS for k in s)


def test_summary_of_a_run_that_stopped_early_has_the_same_keys(paper):
    system, ok = paper
    ds = slipstep.run(system, "newmark", periods=1, max_iterations=3)
    assert ds.attrs["status"] == "NOT_CONVERGED"
    s = summarise(ds, system)
    assert s["status_code"] == Status.NOT_CONVERGED
    assert set(s) == set(summarise(ok, system))
    assert math.isnan(s["energy_per_cycle_J"]) and math.isnan(s["interface_zeta_eq[right]"])


# ---------------------------------------------------------------- failures, resume, other sweeps


@pytest.mark.parametrize(
    "run, field",
    [
        ({"method": "newmark-fast"}, "method"),
        ({"step_ratio": -1.0}, "step_ratio"),
        ({"linear_solver": "cholesky"}, "linear_solver"),
    ],
)
def test_bad_run_options_are_spec_errors(tmp_path, run, field):
    spec = SweepSpec(base="paper", run=run, parameters=(Parameter("damper.centrifugal_force_N", values=(100.0,)),))
    with pytest.raises(InputError) as exc:
        run_sweep(spec, tmp_path / "x.zarr", executor=SerialExecutor())
    assert exc.value.field == f"[run] {field}"  # the sweep's [run] table
    assert not (tmp_path / "x.zarr").exists()


def test_failed_cases_are_recorded_and_do_not_stop_the_sweep(tmp_path):
    spec = SweepSpec(
        base="paper",
        run={"method": "quasi-static", "periods": 2, "steps_per_period": 100},
        parameters=(
            Parameter("damper.centrifugal_angle_deg", values=(90.0, -90.0)),
            Parameter("damper.contacts.P3.friction_coefficient", values=(0.25, -0.1)),
        ),
    )
    report = run_sweep(spec, tmp_path / "f.zarr", executor=SerialExecutor())
    assert report["status_counts"] == {"OK": 1, "INPUT_ERROR": 2, "PRELOAD_FAILED": 1} and report["failed"] == 3
    ds = open_sweep(tmp_path / "f.zarr")
    status = list(ds.status.values)
    assert status == ["OK", "INPUT_ERROR", "PRELOAD_FAILED", "INPUT_ERROR"]
    assert "P3" in ds.status_message.values[1] and "friction_coefficient" in ds.status_message.values[1]
    assert "singular" in ds.status_message.values[2]
    assert np.isfinite(ds.energy_per_cycle_J.values[0]) and np.isnan(ds.energy_per_cycle_J.values[1:]).all()


def _small_spec(run=None, **kw):
    return SweepSpec(
        base="paper",
        run=run or {"method": "quasi-static", "periods": 2, "steps_per_period": 60},
        parameters=(
            Parameter("damper.centrifugal_force_N", values=(100.0, 200.0, 300.0)),
            Parameter("motion.1.amplitude", values=(5.0, 10.0, 20.0, 40.0)),
        ),
        **kw,
    )


def _same_values(a, b):
    """Every value that must be identical between runs (everything but the timings)."""
    varying = VARYING
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        if name in varying:
            continue
        x, y = a[name].values, b[name].values
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert np.array_equal(x, y), name


def test_an_interrupted_sweep_resumes_with_only_the_missing_cases(tmp_path):
    spec = _small_spec(batch_size=2)
    full = run_sweep(spec, tmp_path / "full.zarr", executor=SerialExecutor())
    assert full["computed"] == 12

    def stop(state):
        if state["computed"] >= 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, tmp_path / "part.zarr", executor=SerialExecutor(), progress=stop)
    part = open_sweep(tmp_path / "part.zarr")
    done = part.status.values != ""
    assert done.sum() == 6  # three batches of two, flushed on the interrupt
    again = run_sweep(spec, tmp_path / "part.zarr", executor=SerialExecutor())
    assert again["skipped"] == 6 and again["computed"] == 6
    resumed = open_sweep(tmp_path / "part.zarr")
    assert np.array_equal(resumed.run_index.values, np.where(done, 0, 1))
    _same_values(resumed, open_sweep(tmp_path / "full.zarr"))
    assert run_sweep(spec, tmp_path / "part.zarr", executor=SerialExecutor())["computed"] == 0


def test_a_write_killed_before_its_status_marks_nothing_done(tmp_path, monkeypatch):
    """A client killed inside a write (here: at its metadata step, before the status) leaves no
    case marked done whose data the store's metadata does not list; the rerun computes them."""
    import inspect

    from slipstep.sweep.store import SweepStore

    spec = _small_spec(batch_size=2)
    original = SweepStore.consolidate

    def killed_in_write(self):
        if inspect.stack()[1].function == "write":
            raise KeyboardInterrupt
        original(self)

    monkeypatch.setattr(SweepStore, "consolidate", killed_in_write)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, tmp_path / "part.zarr", executor=SerialExecutor())
    monkeypatch.undo()
    assert not (open_sweep(tmp_path / "part.zarr").status.values != "").any()
    again = run_sweep(spec, tmp_path / "part.zarr", executor=SerialExecutor())
    assert again["computed"] == 12
    full = run_sweep(spec, tmp_path / "full.zarr", executor=SerialExecutor())["store"]
    _same_values(open_sweep(tmp_path / "part.zarr"), open_sweep(full))


def test_a_store_of_another_sweep_is_refused(tmp_path):
    run_sweep(_small_spec(), tmp_path / "s.zarr", executor=SerialExecutor())
    other = SweepSpec(
        base="paper",
        run={"method": "quasi-static", "periods": 2, "steps_per_period": 60},
        parameters=(Parameter("damper.centrifugal_force_N", values=(100.0, 250.0)),),
    )
    with pytest.raises(InputError, match="holds another sweep") as exc:
        run_sweep(other, tmp_path / "s.zarr", executor=SerialExecutor())
    assert exc.value.field == "output"
    report = run_sweep(other, tmp_path / "s.zarr", executor=SerialExecutor(), overwrite=True)
    assert report["computed"] == 2 and open_sweep(tmp_path / "s.zarr").sizes["case"] == 2
    import zarr

    zarr.open_group(str(tmp_path / "s.zarr"), mode="r+").attrs["slipstep_version"] = "0.0.1"
    with pytest.raises(InputError, match="written by slipstep 0.0.1"):
        run_sweep(other, tmp_path / "s.zarr", executor=SerialExecutor())
    (tmp_path / "plain").mkdir()
    with pytest.raises(InputError, match="not a slipstep sweep store"):
        run_sweep(other, tmp_path / "plain", executor=SerialExecutor(), overwrite=True)


# ---------------------------------------------------------------- CLI


def test_cli_sweep_and_sweep_plot(tmp_path):
    spec = tmp_path / "s.toml"
    spec.write_text(
        '[sweep]\nname = "cli"\nbase = "paper"\n[run]\nmethod = "quasi-static"\nperiods = 2\n'
        'steps_per_period = 60\n[[parameter]]\nkey = "damper.centrifugal_force_N"\n'
        'values = [100.0, 200.0, 300.0]\n[[parameter]]\nkey = "motion.1.amplitude"\n'
        "values = [5.0, 20.0, 40.0]\n"
    )
    runner = CliRunner()
    result = runner.invoke(app, ["sweep", str(spec), "-o", str(tmp_path / "s.zarr"), "--serial", "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["computed"] == 9 and report["executor"] == "serial"
    result = runner.invoke(app, ["sweep", str(spec), "-o", str(tmp_path / "s.zarr"), "--serial"])
    assert result.exit_code == 0 and "all 9 cases are already in" in result.output
    result = runner.invoke(app, ["sweep", str(spec), "-o", str(tmp_path / "t.zarr"), "--serial"])
    assert result.exit_code == 0, result.output
    best = int(np.nanargmax(open_sweep(tmp_path / "t.zarr").energy_per_cycle_J.values))
    assert "computed now" in result.output and f"(case {best})" in result.output
    result = runner.invoke(
        app, ["sweep-plot", str(tmp_path / "s.zarr"), "-q", "interface_zeta_eq[right]", "-o", str(tmp_path / "fig")]
    )
    assert result.exit_code == 0, result.output
    for name in ("design_map.png", "design_curves.png"):
        assert (tmp_path / "fig" / name).stat().st_size > 10_000
    fig = ["-o", str(tmp_path / "fig")]
    bad = [
        (["sweep-plot", str(tmp_path / "s.zarr"), "-q", "interface_zeta_eq", *fig], "pick one"),
        (["sweep-plot", str(tmp_path / "s.zarr"), "-q", "energy", *fig], "is not in the store"),
        (["sweep-plot", str(tmp_path / "s.zarr"), "--at", "mass=3", *fig], "not a parameter"),
        (["sweep-plot", str(tmp_path / "s.zarr"), "--at", "mass", *fig], "not NAME=VALUE"),
        (["sweep-plot", str(tmp_path / "s.zarr"), "--at", "centrifugal_force_N=150", *fig], "not a value of the sweep"),
        (["sweep-plot", str(tmp_path), *fig], "not a slipstep sweep store"),
        (["sweep", str(tmp_path / "none.toml"), "-o", str(tmp_path / "x.zarr"), "--serial"], "not found"),
        (["sweep", str(spec), "-o", str(tmp_path / "x.zarr"), "--serial", "--workers", "2"], "choose one executor"),
    ]
    for args, message in bad:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert message in result.output and "Traceback" not in result.output, (args, result.output)


def test_design_maps_of_a_three_parameter_grid_and_a_sampled_sweep(tmp_path):
    from slipstep.sweep.plots import design_curves, design_map, optimum, quantity

    run = {"method": "quasi-static", "periods": 2, "steps_per_period": 60}
    grid = SweepSpec(
        base="paper",
        run=run,
        parameters=(
            Parameter("damper.centrifugal_force_N", values=(100.0, 300.0)),
            Parameter("motion.1.amplitude", values=(5.0, 20.0, 40.0)),
            Parameter("damper.contacts.*.friction_coefficient", values=(0.2, 0.4), name="mu"),
        ),
    )
    run_sweep(grid, tmp_path / "g.zarr", executor=SerialExecutor())
    ds = open_sweep(tmp_path / "g.zarr")
    values, unit, label = quantity(ds, "interface_energy_per_cycle_J[right]")
    assert unit == "mJ" and "right" in label
    np.testing.assert_allclose(values, ds.interface_energy_per_cycle_J.sel(interface="right").values * 1e3)
    best = optimum(ds, "interface_energy_per_cycle_J[right]")
    assert values[best] == np.nanmax(values)
    fig = design_map(ds, "interface_energy_per_cycle_J[right]", x="amplitude", y="centrifugal_force_N")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "motion.1.amplitude [um]" and ax.get_ylabel() == "damper.centrifugal_force_N [N]"
    assert "mu = " in ax.get_title()  # the third parameter is held (at the optimum's value)
    assert fig.axes[1].get_ylabel().endswith("[mJ]")  # the colour bar
    star = [line for line in ax.lines if line.get_marker() == "*"]
    assert len(star) == 1 and star[0].get_xdata()[0] == ds.amplitude.values[best]
    fig = design_curves(
        ds, "interface_energy_per_cycle_J[right]", x="amplitude", group="mu", at={"centrifugal_force_N": 100.0}
    )
    assert "centrifugal_force_N = 100 N" in fig.axes[0].get_title()
    assert len([line for line in fig.axes[0].lines if line.get_marker() == "o"]) == 2  # one curve per mu

    sampled = SweepSpec(
        base="paper",
        run=run,
        sampling="latin-hypercube",
        samples=12,
        parameters=(
            Parameter("damper.centrifugal_force_N", low=100.0, high=300.0),
            Parameter("motion.1.amplitude", low=2.0, high=60.0, scale="log"),
        ),
    )
    run_sweep(sampled, tmp_path / "s.zarr", executor=SerialExecutor())
    ds = open_sweep(tmp_path / "s.zarr")
    fig = design_map(ds, "energy_per_cycle_J")
    assert fig.axes[0].get_xscale() == "log"
    with pytest.raises(InputError, match="not a grid"):
        open_sweep(tmp_path / "s.zarr", grid=True)


def test_an_assembly_case_sweeps_too(tmp_path):
    """The third kind of case file (substructures + dampers): the built-in blades case over the
    engine-order force frequency and the damper's centrifugal load."""
    spec = SweepSpec(
        base="blades",
        run={"method": "piecewise-linear", "periods": 2},
        parameters=(
            Parameter("dampers.damper.centrifugal_force_N", values=(100.0, 300.0)),
            Parameter("engine_order_force.1.frequency_Hz", values=(280.0, 320.0)),
        ),
    )
    report = run_sweep(spec, tmp_path / "b.zarr", executor=SerialExecutor())
    assert report["status_counts"] == {"OK": 4}
    ds = open_sweep(tmp_path / "b.zarr", grid=True)
    assert ds.attrs["case_kind"] == "assembly" and ds.frequency_Hz.attrs["units"] == "Hz"
    assert (ds.energy_per_cycle_J.values > 0).all()
    assert (ds.direction_peak_T_over_muN.values <= 1 + 1e-9).all()
    # a lighter damper load slips for more of the period at the same forcing (300 N sticks longer)
    assert (
        ds.direction_slip_share.sel(centrifugal_force_N=100.0).values
        >= ds.direction_slip_share.sel(centrifugal_force_N=300.0).values
    ).all()


def test_a_frequency_response_per_case(tmp_path):
    """[outputs.frf]: slipstep.frequency.frf of every case in the store, equal to a direct call;
    where the contact sticks the response is linear in the force and equals the
    frequency-domain linear limit with the contact stuck."""
    from pathlib import Path

    from slipstep.frequency import frf
    from slipstep.sweep import make_plan
    from slipstep.sweep.cases import build_case

    examples = Path(__file__).resolve().parents[1] / "examples"
    spec = slipstep.sweep.spec_from_dict(
        {
            "sweep": {"base": str(examples / "shroud_pair.toml")},
            "run": {"method": "piecewise-linear"},
            "parameter": [{"key": "force.1.amplitude", "values": [0.5, 1.0]}],
            "outputs": {"frf": {"frequencies_Hz": [55.0, 45.0, 50.0], "harmonics": 2, "responses": ["y1", "y2"]}},
        }
    )
    assert run_sweep(spec, tmp_path / "f.zarr", executor=SerialExecutor())["status_counts"] == {"OK": 2}
    ds = open_sweep(tmp_path / "f.zarr")
    assert ds.frf_amplitude.dims == ("case", "frequency", "response") and ds.frf_amplitude.attrs["units"]
    assert list(ds.frequency.values) == [45.0, 50.0, 55.0] and ds.frequency.attrs["units"] == "Hz"
    assert list(ds.response.values) == ["y1", "y2"] and (ds.frf_status.values == "OK").all()
    plan = make_plan(spec)
    system, _ = build_case(plan.case_dict(1), plan.base_dir)
    direct = frf(
        system, [45.0, 50.0, 55.0], solver="march", harmonics=2, responses=["y1", "y2"], method="piecewise-linear"
    )
    for name in ("amplitude", "harmonic_amplitude", "energy_per_cycle", "linear_stuck_amplitude"):
        assert np.array_equal(ds[f"frf_{name}"].values[1], direct[name].values), name
    # the small forces keep the shroud stuck: no friction work, twice the force gives twice the response,
    # and the response is the linear one with the contact stuck
    assert np.abs(ds.frf_energy_per_cycle.values).max() < 1e-12
    np.testing.assert_allclose(ds.frf_amplitude.values[1], 2 * ds.frf_amplitude.values[0], rtol=1e-6)
    np.testing.assert_allclose(ds.frf_amplitude.values, ds.frf_linear_stuck_amplitude.values, rtol=1e-3)
    from slipstep.sweep.plots import frf_curves, write_figures

    fig = frf_curves(ds, response="y2")
    lines = [line for line in fig.axes[0].lines if line.get_marker() == "o"]
    assert len(lines) == 2 and np.allclose(lines[1].get_ydata(), ds.frf_amplitude.sel(response="y2").values[1] * 1e6)
    assert fig.axes[0].get_xlabel() == "excitation frequency [Hz]" and fig.axes[0].get_ylabel().endswith("[um]")
    assert [p.name for p in write_figures(ds, tmp_path)] == ["design_curves.png", "frf_curves.png"]


def test_a_finished_store_opens_without_a_warning_and_run_save_is_honoured(tmp_path):
    import warnings

    import xarray as xr

    spec = _small_spec(batch_size=5)
    run_sweep(spec, tmp_path / "s.zarr", executor=SerialExecutor())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "consolidated metadata" warning, after several batches
        with xr.open_zarr(tmp_path / "s.zarr") as ds:
            assert (ds.status.values == "OK").all()
            steady = ds.steady_error.values
    assert np.isfinite(steady).all()
    # [run.save] keeps only the last period: the two-period steady_error has no data any more
    saved = _small_spec(
        run={"method": "quasi-static", "periods": 2, "steps_per_period": 60, "save": {"last_periods": 1}}
    )
    run_sweep(saved, tmp_path / "saved.zarr", executor=SerialExecutor())
    ds = open_sweep(tmp_path / "saved.zarr")
    assert (ds.status.values == "OK").all()
    assert np.isnan(ds.steady_error.values).all()
