"""Frequency responses (slipstep.frequency): harmonics, retune, the FRF driver in both
directions and its layout, the sine sweep, the CLI command and its plot."""

import json
from types import SimpleNamespace
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import slipstep as ss
from slipstep.errors import InputError
from slipstep.frequency import (
    FRF_SCHEMA,
    frf,
    harmonics,
    linear_limits,
    retune,
    sine_sweep,
)
from slipstep.frequency.harmonics import fourier_coefficients

ROOT = Path(__file__).resolve().parents[1]
JENKINS = ROOT / "examples" / "jenkins.toml"


def _record(t, x, period):
    return xr.Dataset(
        {"displacement": (("time", "dof"), x)},
        coords={"time": t, "dof": ["a", "b"], "dof_unit": ("dof", ["m", "rad"])},
        attrs={"period_s": period},
    )


@pytest.mark.parametrize("grid", ["uniform", "non-uniform"])
def test_harmonics_of_a_known_signal(grid):
    T = 0.01
    w = 2 * np.pi / T
    if grid == "uniform":
        t = np.linspace(0, T, 401)
    else:  # an adaptive-step-like grid, fine enough for the trapezoid rule
        rng = np.random.default_rng(1)
        t = np.sort(np.concatenate([[0, T], rng.uniform(0, T, 20000)]))
    x = np.c_[0.5 + 2.0 * np.cos(w * t + 0.3) + 0.25 * np.cos(3 * w * t - 1.0), -1e-3 * np.sin(2 * w * t)]
    t_shift = t + 7 * T  # the last period of a longer record: phases from its start
    h = harmonics(_record(t_shift, x, T), n_harmonics=4)
    A = h["harmonic_amplitude"].values
    phi = h["harmonic_phase"].values
    tol = 1e-12 if grid == "uniform" else 1e-6
    assert A[:, 0] == pytest.approx([0.5, 2.0, 0.0, 0.25, 0.0], abs=tol * 10)
    assert phi[1, 0] == pytest.approx(0.3, abs=tol * 10) and phi[3, 0] == pytest.approx(-1.0, abs=tol * 10)
    assert A[2, 1] == pytest.approx(1e-3, rel=tol * 10) and phi[2, 1] == pytest.approx(np.pi / 2, abs=tol * 10)
    assert h["amplitude"].values[1] == pytest.approx(1e-3, rel=1e-3)
    assert list(h["response_unit"].values) == ["m", "rad"]


def test_harmonics_bad_input():
    t = np.linspace(0, 1, 11)
    with pytest.raises(InputError, match="harmonics"):
        fourier_coefficients(t, np.zeros((11, 1)), 1.0, 6)
    with pytest.raises(InputError, match="responses"):
        harmonics(_record(t, np.zeros((11, 2)), 1.0), responses=["nope"])


def test_retune_moves_the_fundamental_and_keeps_multiples():
    base = ss.load_system(JENKINS)
    comps = base.excitation.force.components
    two = ss.Signal(
        comps, (ss.Harmonic(350.0, np.array([100.0])), ss.Harmonic(1050.0, np.array([5.0]), np.array([0.4])))
    )
    system = ss.System(base.structure, base.contacts, ss.Excitation(force=two), name="two")
    moved = retune(system, 200.0)
    freqs = [h.frequency for h in moved.excitation.force.harmonics]
    assert freqs == [200.0, pytest.approx(600.0)]
    assert moved.excitation.force.harmonics[1].phase[0] == 0.4 and moved.period == pytest.approx(1 / 200)
    assert [h.frequency for h in system.excitation.force.harmonics] == [350.0, 1050.0]  # the original is kept
    table = ss.System(
        base.structure,
        base.contacts,
        ss.Excitation(force=ss.Signal(comps, (), (ss.Tabulated([0.0, 1.0], [[0.0], [1.0]]),)), period=0.01),
    )
    with pytest.raises(InputError, match="excitation.force"):
        retune(table, 100.0)
    with pytest.raises(InputError, match="frequency"):
        retune(system, -1.0)


@pytest.fixture(scope="module")
def jenkins_frf():
    system = ss.load_system(JENKINS)
    f = np.linspace(260.0, 440.0, 10)
    return (
        system,
        frf(system, f, solver="shoot", direction="both", tolerance=1e-9, min_steps_per_period=400),
        frf(system, f, solver="march", tolerance=1e-9, max_periods=2000, min_steps_per_period=400),
    )


def test_frf_layout_and_netcdf(jenkins_frf, tmp_path):
    _, both, up = jenkins_frf
    for name, (dims, units, _) in FRF_SCHEMA.items():
        assert name in up and up[name].dims == dims, name
        assert up[name].attrs["units"] == units
    assert both.sizes["sweep"] == 2 and list(both["sweep"].values) == ["up", "down"]
    assert up.attrs["solver"] == "march" and up.attrs["sweep"] == "up" and up.attrs["case"] == "jenkins"
    assert (up["status"].values == "OK").all() and (both["status"].values == "OK").all()
    path = tmp_path / "frf.nc"
    both.to_netcdf(path, engine="h5netcdf")
    back = xr.load_dataset(path, engine="h5netcdf")
    assert np.array_equal(back["amplitude"].values, both["amplitude"].values)
    assert list(back["status"].values.ravel()) == ["OK"] * 20


def test_frf_between_linear_limits_and_solvers_agree(jenkins_frf):
    system, both, up = jenkins_frf
    amp = up["amplitude"].sel(response="x").values
    free = up["linear_free_amplitude"].sel(response="x").values
    stuck = up["linear_stuck_amplitude"].sel(response="x").values
    assert (amp >= np.minimum(free, stuck)).all()  # never below both linear responses
    # the friction peak lies between the two linear resonances in frequency and below both peaks
    fine = linear_limits(system, np.linspace(250, 500, 2501))
    peak_free, peak_stuck = (fine[v].sel(response="x") for v in ("linear_free_amplitude", "linear_stuck_amplitude"))
    assert float(peak_free.idxmax()) == pytest.approx(np.sqrt(1e7 / 2.5) / (2 * np.pi), abs=0.2)
    assert float(peak_stuck.idxmax()) == pytest.approx(np.sqrt(2e7 / 2.5) / (2 * np.pi), abs=0.2)
    i = int(np.argmax(amp))
    assert float(peak_free.idxmax()) < up["frequency"].values[i] < float(peak_stuck.idxmax())
    assert amp[i] < 0.6 * min(float(peak_free.max()), float(peak_stuck.max()))
    shot = both["amplitude"].sel(sweep="up", response="x").values
    assert shot == pytest.approx(amp, rel=1e-4)
    assert both["energy_per_cycle"].sel(sweep="up").values.ravel() == pytest.approx(
        up["energy_per_cycle"].values.ravel(), rel=1e-4
    )
    assert np.abs(up["energy_balance_residual"].values).max() < 1e-6
    assert (both["periods_to_steady"].values < up["periods_to_steady"].values.max()).all()
    assert (both["floquet_multiplier_max"].values < 1).all() and np.isnan(up["floquet_multiplier_max"]).all()


def test_sine_sweep_tends_to_the_stepped_frf(jenkins_frf):
    system, _, up = jenkins_frf
    f = up["frequency"].values
    sweep = sine_sweep(system, f, cycles_per_point=60)
    assert sweep.attrs["solver"] == "sine-sweep" and sweep.attrs["sweep_duration_s"] > 1
    amp = sweep["amplitude"].sel(response="x").values
    assert np.isnan(amp[0]) and np.isfinite(amp[1:]).all()  # the start transient is not reported
    away = ((f < 300) | (f > 360)) & (f > f[0])  # away from the peak the envelope follows the steady state
    assert sweep["amplitude"].sel(response="x").values[away] == pytest.approx(
        up["amplitude"].sel(response="x").values[away], rel=0.03
    )
    assert np.array_equal(sweep["linear_free_amplitude"].values, up["linear_free_amplitude"].values)


def test_frf_bad_input():
    system = ss.load_system(JENKINS)
    with pytest.raises(InputError, match="frequencies"):
        frf(system, [100.0, -5.0])
    with pytest.raises(InputError, match="solver"):
        frf(system, [100.0], solver="nope")
    with pytest.raises(InputError, match="direction"):
        frf(system, [100.0], direction="sideways")
    with pytest.raises(InputError, match="responses"):
        frf(system, [100.0], responses=["y"])
    with pytest.raises(InputError, match="harmonics"):
        frf(system, [100.0], harmonics=-1)
    with pytest.raises(InputError, match="settle_periods"):
        frf(system, [100.0], solver="shoot", settle_periods=-2)


def _cli(*args, cwd):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    return CliRunner().invoke(app, list(args))


def test_cli_frf_writes_netcdf_and_plot(tmp_path):
    r = _cli(
        "frf",
        str(JENKINS),
        "--frequencies",
        "300:340:3",
        "--solver",
        "shoot",
        "--direction",
        "both",
        "-o",
        str(tmp_path),
        "--json",
        cwd=tmp_path,
    )
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["points"] == 6 and summary["points_not_ok"] == 0 and summary["peak_frequency_Hz"] == 320.0
    ds = xr.load_dataset(tmp_path / "jenkins_frf.nc", engine="h5netcdf")
    assert ds.sizes["frequency"] == 3 and ds.attrs["solver"] == "shoot"
    png = (tmp_path / "jenkins_frf.png").read_bytes()
    assert png[:4] == b"\x89PNG" and len(png) > 20_000
    bad = _cli("frf", str(JENKINS), "--frequencies", "300:abc", cwd=tmp_path)
    assert bad.exit_code == 2 and "--frequencies" in bad.output and "Traceback" not in bad.output


def test_docs_frf_table_is_the_declared_schema():
    import re

    text = (ROOT / "docs" / "frequency_response.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| ([a-z, ]+) \| ([^|]+) \|", text, flags=re.MULTILINE)
    table = {name: (tuple(d.strip() for d in dims.split(",")), units.strip()) for name, dims, units in rows}
    declared = {name: (dims, units) for name, (dims, units, _) in FRF_SCHEMA.items()}
    assert all(declared.get(name) == row for name, row in table.items())  # every documented row is right
    # every variable is documented here, except those only harmonic balance writes (docs/hbm.md)
    assert {n for n, (_, _, text) in FRF_SCHEMA.items() if "harmonic balance only:" not in text} <= set(table)


def test_readme_frf_example_runs():

    readme = (ROOT / "README.md").read_text()
    block = readme.split("## Forced response")[1].split("```python\n")[1].split("```")[0]
    block = block.replace('"examples/jenkins.toml"', repr(str(JENKINS))).replace(
        "np.linspace(250, 450, 61)", "np.linspace(300, 340, 5)"
    )
    exec(compile(block, "README", "exec"), {})


def test_frf_interrupted_keeps_the_points_done(monkeypatch):
    from slipstep.frequency import response

    solve = response.STEADY_SOLVERS["shoot"]
    calls = []

    def interrupted_at_third(system, **kw):
        calls.append(kw.get("min_steps_per_period") is None)  # the first solve of a point (then its step doubling)
        if sum(calls) == 3:
            raise KeyboardInterrupt
        return solve(system, **kw)

    monkeypatch.setitem(response.STEADY_SOLVERS, "shoot", interrupted_at_third)
    ds = frf(ss.load_system(JENKINS), np.linspace(300, 340, 5), solver="shoot", direction="both")
    assert ds.attrs["interrupted"] == 1
    assert list(ds["status"].sel(sweep="up").values) == ["OK", "OK"] + ["INTERRUPTED"] * 3
    assert (ds["status"].sel(sweep="down").values == "INTERRUPTED").all()
    assert np.isfinite(ds["amplitude"].sel(sweep="up").values[:2]).all()
    assert np.isnan(ds["amplitude"].sel(sweep="up").values[2:]).all()


def test_plot_many_contacts_and_both_sweeps(tmp_path):
    from slipstep.output.frf_dataset import concat_sweeps, empty_frf
    from slipstep.frequency.plots import default_response, plot_frf

    f = np.linspace(100, 200, 11)
    parts = []
    for k in range(2):
        ds = empty_frf(f, ["x", "phi"], ["m", "rad"], [f"P{i}" for i in range(8)], 1)
        ds["amplitude"].values[:] = np.c_[1e-5 / (1 + ((f - 150) / 10) ** 2), 1e-2 * np.ones_like(f)]
        ds["energy_per_cycle"].values[:] = np.outer(f, np.arange(8)) * 1e-6
        ds["status"].values[:] = "OK"
        ds["floquet_multiplier_max"].values[:] = 0.9 + 0.3 * (f == 150)
        ds["linear_free_amplitude"].values[:] = 2e-5
        parts.append(ds)
    both = concat_sweeps(*parts)
    assert default_response(both) == "x"  # metres before radians
    png = plot_frf(both, tmp_path / "f.png").read_bytes()
    assert png[:4] == b"\x89PNG"


def test_the_plot_draws_the_linear_limits_on_a_fine_grid(tmp_path):
    """The linear limits beside an FRF are drawn on FINE_POINTS frequencies spanning its grid
    (a 5-point grid would draw a linear resonance as a triangle): at the grid's ends they equal
    the FRF's own linear limits; a structure above FINE_MAX_DOFS DOFs keeps the FRF's points."""
    from slipstep.frequency.plots import FINE_POINTS, fine_linear_limits, plot_frf

    system = ss.load_system(JENKINS)
    ds = frf(system, np.linspace(300, 340, 3), solver="shoot", rtol=None)
    fine = fine_linear_limits(system, ds, "x")
    assert fine.sizes["frequency"] == FINE_POINTS
    for name in ("linear_free_amplitude", "linear_stuck_amplitude"):
        ends = fine[name].sel(response="x").values[[0, -1]]
        np.testing.assert_allclose(ends, ds[name].sel(response="x").values[[0, -1]], rtol=1e-12)
    assert plot_frf(ds, tmp_path / "f.png", linear=fine).stat().st_size > 10_000
    big = SimpleNamespace(n_dofs=10_000)
    assert fine_linear_limits(big, ds) is None
