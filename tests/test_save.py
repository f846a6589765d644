"""The save option (slipstep.methods.save): saved subsets equal the slices of a full save bit for
bit, the interpolation at given times has the march's order, the memory estimate is what is
allocated, the limit is checked on the saved sizes, and downstream works from the subset or
refuses it by name."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import slipstep as ss
from slipstep.cli.main import app
from slipstep.casefile.case import CASES_DIR
from slipstep.methods import memory
from slipstep.methods import save as SV
from slipstep.methods.simulation import Simulation
from slipstep.post.summary import summarise
from slipstep.steady import march_to_steady

VARIABLES = (
    "displacement",
    "velocity",
    "acceleration",
    "tangential_displacement",
    "normal_displacement",
    "tangential_force",
    "normal_force",
    "slider",
    "contact_state",
    "solves",
    "step_size",
    "prescribed_motion",
)


def chain(n: int, mu: float = 0.3, force: float = 1.0, contacts: int = 1) -> ss.System:
    """Fixed-free chain of n masses (10 g, 1e6 N/m springs, light damping), a harmonic force
    of ``force`` N at 100 Hz on the tip, and ``contacts`` Jenkins contacts on the last DOFs
    (normal load from a 1 um interference: N = 1 N)."""
    k = 2e6 * np.eye(n) - 1e6 * (np.eye(n, k=1) + np.eye(n, k=-1))
    k[-1, -1] = 1e6
    names = tuple(f"x{i}" for i in range(n))
    elements = []
    for c in range(contacts):
        gather = np.zeros((2, n))
        gather[0, n - 1 - c] = 1.0
        elements.append(ss.ContactElement(f"C{c}", gather, 1e6, 1e5, mu, normal_offset=1e-6))
    amplitude = np.zeros(n)
    amplitude[-1] = force
    exc = ss.Excitation(force=ss.Signal(names, (ss.Harmonic(100.0, amplitude),)))
    return ss.System(ss.Structure(0.01 * np.eye(n), 1e-5 * k, k, names), tuple(elements), exc, name=f"chain{n}")


def same(sub: xr.Dataset, full: xr.Dataset) -> None:
    """``sub`` is exactly the slice of ``full`` at its steps, DOFs, contacts and directions."""
    ref = full.isel(time=sub["step"].values).sel(dof=sub["dof"], contact=sub["contact"], direction=sub["direction"])
    for name in VARIABLES:
        if name in full:
            np.testing.assert_array_equal(sub[name].values, ref[name].values, err_msg=name)
    np.testing.assert_array_equal(sub["time"].values, ref["time"].values)


@pytest.fixture(scope="module")
def paper():
    return ss.load_system("paper")


@pytest.fixture(scope="module")
def paper_full(paper):
    return ss.run(paper, "newmark", periods=2, error_estimate=False)


def test_every_k_and_patterns_are_slices_of_the_full_save(paper, paper_full):
    sub = ss.run(paper, "newmark", periods=2, error_estimate=False, save={"every": 7, "dofs": ["x*", "phi"]})
    steps = sub["step"].values
    n = paper_full.sizes["time"] - 1
    assert steps.tolist() == list(range(0, n + 1, 7)) + ([n] if n % 7 else [])  # every 7th and the last
    assert list(sub["dof"].values) == ["x_G", "phi"]
    same(sub, paper_full)
    one = ss.run(paper, "newmark", periods=2, error_estimate=False, save=ss.Save(contacts=["P3"], dofs="none"))
    assert list(one["contact"].values) == ["P3"] and one.sizes["dof"] == 0
    assert set(one["direction_contact"].values) == {"P3"}
    same(one, paper_full)
    assert one.attrs["save"] == "dofs: none; contacts: P3; every step" and one.attrs["save_all_dofs"] == 0


def test_last_periods_cover_the_window_and_equal_the_full_save(paper, paper_full):
    sub = ss.run(paper, "newmark", periods=2, error_estimate=False, save={"last_periods": 1})
    T, t = paper_full.attrs["period_s"], sub["time"].values
    assert t[0] <= t[-1] - T * (1 - 1e-12) and t[1] > t[-1] - T  # from the step at or before t_end - T
    assert t[-1] == paper_full["time"].values[-1]
    same(sub, paper_full)
    # combined with every: the window start and every 5th step in it
    both = ss.run(paper, "newmark", periods=2, error_estimate=False, save={"last_periods": 1, "every": 5})
    same(both, paper_full)
    assert both.sizes["time"] < sub.sizes["time"] / 4


@pytest.mark.parametrize("method", ["piecewise-linear-adaptive", "quasi-static", "quasi-static-events"])
def test_other_methods_save_the_same_slices(paper, method):
    full = ss.run(paper, method, periods=1.5, error_estimate=False)
    sub = ss.run(paper, method, periods=1.5, error_estimate=False, save={"every": 3, "contacts": ["P1"]})
    assert sub.attrs["steps"] == full.attrs["steps"] and sub.attrs["solves"] == full.attrs["solves"]
    same(sub, full)


def test_given_times_are_exact_at_step_ends_and_second_order_between():
    system = chain(3, mu=50.0)  # stays stuck: a linear march, no state changes
    T = 0.01
    grid = np.linspace(0.0, 2 * T, 97)[1:]  # not on the steps
    runs = {}
    for steps in (400, 800, 12800):  # omega_max dt = 0.5 and 0.25: the march in its asymptotic range
        runs[steps] = ss.run(system, "newmark", periods=2, dt=T / steps, error_estimate=False, save={"times": grid})
    ref = runs[12800]
    errors = {s: np.abs(runs[s]["displacement"].values - ref["displacement"].values).max() for s in (400, 800)}
    verrors = {s: np.abs(runs[s]["velocity"].values - ref["velocity"].values).max() for s in (400, 800)}
    assert 3.0 < errors[400] / errors[800] < 5.5  # O(dt^2): the march's own order, interpolation below it
    assert 2.5 < verrors[400] / verrors[800] < 6.0
    # at the step ends the values are the march's own (theta = 0 or 1)
    full = ss.run(system, "newmark", periods=2, dt=T / 40, error_estimate=False)
    at = full["time"].values[5::9]
    on = ss.run(system, "newmark", periods=2, dt=T / 40, error_estimate=False, save={"times": at})
    for name in ("displacement", "velocity", "acceleration", "tangential_force", "slider"):
        np.testing.assert_allclose(on[name].values, full[name].values[5::9], rtol=1e-12, atol=1e-18, err_msg=name)
    assert "step" not in on.coords and on.attrs["save_every_step"] == 0


def test_memory_estimate_is_the_saved_allocation():
    system = chain(260)
    for save in ("auto", "all", {"every": 4}, {"last_periods": 1, "dofs": ["x1*"]}, {"times": [0.001, 0.002]}):
        sim = Simulation(system, "piecewise-linear", periods=2, error_estimate=False, save=save)
        out, plan = sim.out, sim.save_plan
        rows = out.t.shape[0]
        per_row = sum(a.nbytes for a in out if a.ndim and a.shape[0] == rows) / rows
        assert per_row == memory.point_bytes(plan.dofs.size, plan.rows.size, plan.directions.size)
        expected = memory.run_bytes(rows, plan.dofs.size, plan.rows.size, plan.directions.size, 0, 0)
        assert sim.memory_estimate - expected == pytest.approx(
            sim.memory_estimate - memory.PEAK_FACTOR * rows * per_row
        )
        ds = sim.run()
        assert ds.attrs["status"] == "OK" and ds.sizes["dof"] == plan.dofs.size
    auto = Simulation(system, "piecewise-linear", periods=2, error_estimate=False)
    assert auto.save_plan.dofs.tolist() == [259]  # above FULL_SAVE_MAX_DOFS: the response DOFs (contact, force)
    small = Simulation(chain(SV.FULL_SAVE_MAX_DOFS), "piecewise-linear", periods=1, error_estimate=False)
    assert small.save_plan.all_dofs and small.save_plan.every_step


def test_max_memory_uses_the_saved_sizes():
    system = chain(400)
    full = Simulation(system, "piecewise-linear", periods=3, error_estimate=False, save="all")
    small = Simulation(system, "piecewise-linear", periods=3, error_estimate=False)
    workspace = small.memory_estimate - memory.PEAK_FACTOR * small.out.t.shape[0] * memory.point_bytes(1, 2, 1)
    limit = (full.memory_estimate + small.memory_estimate) / 2  # the full outputs exceed it, the saved ones fit
    assert small.memory_estimate < limit < full.memory_estimate and workspace > 0
    ds = ss.run(system, "piecewise-linear", periods=3, error_estimate=False, max_memory=limit)
    assert ds.attrs["status"] == "OK" and ds.sizes["dof"] == 1
    with pytest.raises(ss.InputError) as info:
        ss.run(system, "piecewise-linear", periods=3, error_estimate=False, max_memory=limit, save="all")
    text = str(info.value)
    assert "max_memory" in text and "save less" in text and "--save-dofs" in text


def test_output_rows_running_out_is_told_apart_from_steps(paper):
    sim = Simulation(paper, "newmark", periods=1, error_estimate=False, save={"every": 2})
    out = sim.out
    sim.out = out._replace(
        **{k: getattr(out, k)[:12].copy() for k in ("t", "dt", "x", "v", "a", "q", "f")},
        **{k: getattr(out, k)[:12].copy() for k in ("w", "state", "solves", "step")},
    )
    sim.march()
    ds = sim.dataset()
    assert ds.attrs["status"] == "CAPACITY" and "out of output rows" in ds.attrs["status_message"]
    # 12 rows: the march stops when fewer than 2 are left (a pending row and a bracket pair)
    assert ds.attrs["steps"] == 20 and ds["step"].values.tolist() == list(range(0, 21, 2))
    same(ds, ss.run(paper, "newmark", periods=1, error_estimate=False))


def test_downstream_works_from_the_subset_or_refuses_it(paper, paper_full, tmp_path):
    big = chain(240, contacts=3)
    ds = ss.run(big, "piecewise-linear", periods=3)  # default save: contacts + response DOFs
    assert ds.sizes["dof"] == 3 and ds.sizes["contact"] == 3
    assert np.isfinite(ds.attrs["energy_error_estimate"])  # the twins save the contacts at every step
    summary = summarise(ds)
    assert np.isfinite(summary["energy_per_cycle_J"]) and summary["energy_per_cycle_J"] > 0
    full = ss.run(big, "piecewise-linear", periods=3, save="all")
    reference = summarise(full)  # the same march: the contact quantities are identical
    for key, value in summary.items():
        if key not in ("steady_error", "kernel_time_s", "wall_time_s"):
            assert value == pytest.approx(reference[key], nan_ok=True), key
    balance = ss.post.energy_balance(full, big)
    assert balance.attrs["relative_residual"] < 1e-6
    with pytest.raises(ss.InputError) as info:
        ss.post.energy_balance(ds, big)
    assert info.value.field == "save" and "every DOF" in str(info.value)
    # save / load round trip keeps the subset, its names, steps and the save attrs
    path = tmp_path / "r.nc"
    ss.save_result(ds, path)
    back = ss.load_result(path)
    assert list(back["dof"].values) == list(ds["dof"].values) and back.attrs["save"] == ds.attrs["save"]
    np.testing.assert_array_equal(back["step"].values, ds["step"].values)
    xr.testing.assert_identical(back.reset_coords(drop=True), ds.reset_coords(drop=True))
    # the steady state keeps its own full save; a user save that drops steps is refused
    steady = march_to_steady(big, "piecewise-linear", tolerance=1e-3, max_periods=3)
    assert steady.status in ("OK", "NOT_STEADY") and steady.period.sizes["dof"] == 240
    assert np.isfinite(steady.change) and steady.period.attrs["save_every_step"] == 1
    with pytest.raises(ss.InputError) as info:
        march_to_steady(big, "piecewise-linear", save={"every": 2})
    assert info.value.field == "save"
    # continuation from the workspace's full last state, whatever was saved
    sim = Simulation(big, "piecewise-linear", periods=1, save={"dofs": "none", "contacts": "none", "every": 50})
    sim.march()
    assert sim.ws.x.shape == (240,) and np.all(np.isfinite(sim.ws.x)) and sim.out.x.shape[1] == 0


def test_cli_and_case_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    res = runner.invoke(app, ["run", "paper", "--save-dofs", "x_G,phi", "--save-every", "10", "--json"])
    assert res.exit_code == 0, res.output
    ds = ss.load_result(tmp_path / "slipstep-out" / "paper_newmark.nc")
    assert list(ds["dof"].values) == ["x_G", "phi"] and np.all(np.diff(ds["step"].values)[:-1] == 10)
    text = (
        (CASES_DIR / "paper.toml")
        .read_text()
        .replace("[run]\n", '[run.save]\ncontacts = ["P1"]\nlast_periods = 1\n\n[run]\n')
    )
    (tmp_path / "case.toml").write_text(text)
    res = runner.invoke(app, ["run", "case.toml", "--save-dofs", "none", "--json"])
    assert res.exit_code == 0, res.output
    ds = ss.load_result(tmp_path / "slipstep-out" / "case_newmark.nc")
    assert list(ds["contact"].values) == ["P1"] and ds.sizes["dof"] == 0
    assert ds.attrs["save"].endswith("every step of the last 1 periods")
    res = runner.invoke(app, ["run", "case.toml", "--save-contacts", "P7"])
    assert res.exit_code == 2 and "--save-contacts" in res.output and "P1" in res.output


@pytest.mark.parametrize(
    "save, field, words",
    [
        ({"dofs": ["x_g"]}, "save.dofs", "x_G"),  # close names listed
        ({"dofs": "blade*"}, "save.dofs", "matches no DOF"),
        ({"contacts": ["P4"]}, "save.contacts", "P1"),
        ({"every": 0}, "save.every", ">= 1"),
        ({"every": 2.5}, "save.every", "whole number"),
        ({"last_periods": 0.5}, "save.last_periods", ">= 1"),
        ({"last_periods": 9}, "save.last_periods", "longer than the run"),
        ({"times": [0.002, 0.001]}, "save.times", "increasing"),
        ({"times": [0.0, 0.5]}, "save.times", "outside the run"),
        ({"times": [0.001], "every": 2}, "save.times", "either"),
        ({"stride": 2}, "save.stride", "dofs, contacts"),
        (42, "save", "slipstep.Save"),
    ],
)
def test_bad_save(paper, save, field, words):
    with pytest.raises(ss.InputError) as info:
        Simulation(paper, "newmark", periods=2, save=save)
    assert info.value.field == field and words in str(info.value)


def test_given_times_finer_than_the_steps_are_the_interpolation_of_the_full_save(paper, paper_full):
    t = paper_full["time"].values
    grid = np.linspace(t[0], t[-1], 7 * t.size)  # about 7 given times per step
    ds = ss.run(paper, "newmark", periods=2, error_estimate=False, save={"times": grid})
    assert ds.sizes["time"] == grid.size and ds.attrs["steps"] == paper_full.attrs["steps"]
    rows = {"t": t, "x": paper_full["displacement"].values, "v": paper_full["velocity"].values}
    rows["a"] = paper_full["acceleration"].values
    for key, name in (("q", "tangential_displacement"), ("f", "tangential_force"), ("w", "slider")):
        rows[key] = paper_full[name].values
    rows.update(state=paper_full["contact_state"].values, solves=paper_full["solves"].values, dt=t * 0)
    expected = SV.interpolate(rows, grid, True, 0.5)
    np.testing.assert_array_equal(ds["displacement"].values, expected["x"])
    np.testing.assert_array_equal(ds["velocity"].values, expected["v"])
    np.testing.assert_array_equal(ds["tangential_force"].values, expected["f"])
    np.testing.assert_array_equal(ds["contact_state"].values, expected["state"])
