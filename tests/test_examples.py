"""The examples run and say something true: the amplitude sweep of the paper's damper (a sweep
spec) and the quasi-3D shroud-pair case (a general structure with damping and external forces)."""

from pathlib import Path

import numpy as np
import pytest

import slipstep
from slipstep.post.energy import energy_balance

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_amplitude_sweep_design_curve(tmp_path):
    """examples/amplitude_sweep.toml: the designer's curve of the paper's damper, energy per
    cycle of each interface against the platform amplitude for several centrifugal loads."""
    import warnings

    from slipstep.sweep import SerialExecutor, load_spec, open_sweep, run_sweep
    from slipstep.sweep.plots import write_figures

    spec = load_spec(EXAMPLES / "amplitude_sweep.toml")
    report = run_sweep(spec, tmp_path / "amp.zarr", executor=SerialExecutor())
    assert report["status_counts"] == {"OK": 96}
    g = open_sweep(tmp_path / "amp.zarr", grid=True).sel(centrifugal_force_N=200.0)
    energy = g.interface_energy_per_cycle_J * 1e3  # mJ
    k_eq = g.interface_k_eq_N_per_m * 1e-6  # N/um
    # 2 um: both interfaces stick (a closed loop without area), secant stiffness = k_t of the face
    assert abs(energy.sel(amplitude=2.0)).max() < 1e-9
    assert float(k_eq.sel(amplitude=2.0, interface="right")) == pytest.approx(26.0, rel=1e-6)
    # 10 um: the right face slips, the left still sticks
    assert (
        abs(float(energy.sel(amplitude=10.0, interface="left")))
        < 1e-9
        < float(energy.sel(amplitude=10.0, interface="right"))
    )
    # 25 um is the paper's case: 2.52 and 2.70 mJ
    assert float(energy.sel(amplitude=25.0, interface="left")) == pytest.approx(2.52, rel=0.01)
    assert float(energy.sel(amplitude=25.0, interface="right")) == pytest.approx(2.70, rel=0.01)
    # more centrifugal load: more energy at large amplitude, but it sticks longer at small ones
    right = open_sweep(tmp_path / "amp.zarr", grid=True).interface_energy_per_cycle_J.sel(interface="right")
    assert np.all(np.diff(right.sel(amplitude=70.0).values) > 0)
    assert right.sel(amplitude=4.0, centrifugal_force_N=50.0) > right.sel(amplitude=4.0, centrifugal_force_N=400.0)
    # the dynamic solution, filtered, dissipates the same energy (paper: superposed results)
    system = slipstep.load_system("paper")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the filter warns only when it cannot separate the ringing
        dyn = slipstep.post.filter_dataset(slipstep.run(system, "piecewise-linear", periods=3), system)
    s = slipstep.post.loop_summary(dyn, system)
    for name in ("left", "right"):
        assert float(s.interface_energy_J.sel(interface=name)) * 1e3 == pytest.approx(
            float(energy.sel(amplitude=25.0, interface=name)), rel=0.05
        ), name
    paths = write_figures(open_sweep(tmp_path / "amp.zarr"), tmp_path, "interface_energy_per_cycle_J[right]")
    assert [p.name for p in paths] == ["design_map.png", "design_curves.png"]


@pytest.fixture(scope="module")
def shroud():
    system, _ = slipstep.load_case(EXAMPLES / "shroud_pair.toml")
    runs = {
        m: slipstep.run(system, m, periods=10) for m in ("newmark", "piecewise-linear", "piecewise-linear-adaptive")
    }
    return system, runs


def test_shroud_pair_runs_and_slips_in_both_directions(shroud):
    system, runs = shroud
    ds = runs["piecewise-linear"]
    assert {m: r.attrs["status"] for m, r in runs.items()} == dict.fromkeys(runs, "OK")
    assert ds.sizes["direction"] == 2
    # the default step rule (issue 8): period/50 (the cap), refined to 55 steps per period by the
    # step-doubling estimate of the loop energy (0.5 % target); the result's own estimate < 1 %
    assert ds.attrs["dt_s"] == pytest.approx(1 / 900 / 55)
    assert ds.attrs["energy_error_estimate"] < 0.01
    states = ds.contact_state.values
    assert np.any(states[:, 0] >= 2) and np.any(states[:, 1] >= 2)  # each direction slips
    # each tangential direction obeys its own friction limit against the shared N
    N = ds.normal_force.values[:, 0]
    assert np.all(np.abs(ds.tangential_force.values) <= 0.3 * N[:, None] * (1 + 1e-7) + 1e-9)


def test_shroud_pair_method3_is_method1_and_energy_balances(shroud):
    system, runs = shroud
    a, b = runs["newmark"], runs["piecewise-linear"]
    amplitude = np.abs(a.displacement.values).max()
    assert np.abs(a.displacement.values - b.displacement.values).max() < 1e-6 * amplitude
    for m in ("newmark", "piecewise-linear"):
        eb = energy_balance(runs[m], system)
        assert eb.attrs["relative_residual"] < 1e-6, m
        assert eb.friction_dissipation.values[-1] > 0 and eb.damping_dissipation.values[-1] > 0


def test_compare_without_constant_load(tmp_path):
    """compare on a case with no constant load: forces are then scaled by the largest contact force."""
    import json

    from typer.testing import CliRunner

    from slipstep.cli.main import app

    result = CliRunner().invoke(
        app,
        [
            "compare",
            str(EXAMPLES / "shroud_pair.toml"),
            "--methods",
            "1,3",
            "--periods",
            "4",
            "--repeats",
            "1",
            "--json",
            "--output-dir",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = {r["method"]: r for r in json.loads(result.stdout)}
    assert rows["piecewise-linear"]["force_scale_N"] > 0
    assert rows["piecewise-linear"]["max_force_diff_pct_cf"] < 1e-3
    assert rows["piecewise-linear"]["solves"] < rows["newmark"]["solves"] / 3
