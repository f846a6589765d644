"""Every figure renders to a non-empty PNG from a short run; the plot CLI writes them."""

import numpy as np
import pytest
from PIL import Image

import slipstep
from slipstep.post import plots
from slipstep.post import filter_dataset


@pytest.fixture(scope="module")
def runs():
    system = slipstep.load_system("paper")
    return (
        system,
        slipstep.run(system, "quasi-static", periods=2),
        slipstep.run(system, "piecewise-linear", periods=2),
        slipstep.run(system, "piecewise-linear-adaptive", periods=2),
    )


def _check_png(path, min_px=(400, 250)):
    assert path.exists() and path.stat().st_size > 5_000
    with Image.open(path) as im:
        assert im.format == "PNG"
        assert im.size[0] >= min_px[0] and im.size[1] >= min_px[1]
        arr = np.asarray(im.convert("L"))
        assert arr.std() > 5  # not a blank image


def test_every_figure_renders(runs, tmp_path):
    system, qs, dyn, ad = runs
    figs = {
        "time_histories": plots.plot_time_histories([qs, dyn]),
        "loops": plots.plot_loops(dyn, filter_dataset(dyn, system)),
        "step_size": plots.plot_step_size(ad),
        "iterations": plots.plot_iterations([qs, dyn, ad]),
        "methods": plots.plot_method_comparison(
            [
                {"method": "newmark", "paper_method": "Method 1", "time_ratio": 1.0},
                {"method": "piecewise-linear", "paper_method": "Method 3", "time_ratio": 0.5},
                {"method": "quasi-static", "time_ratio": 0.07},
            ]
        ),
        "states": plots.plot_state_timeline(ad),
    }
    for name, fig in figs.items():
        _check_png(plots.save_figure(fig, tmp_path / f"{name}.png"))


def test_axis_labels_carry_units(runs):
    _, qs, dyn, _ = runs
    fig = plots.plot_time_histories([qs, dyn])
    labels = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
    assert "T P1 [N]" in labels and "x_G [um]" in labels and "phi [mrad]" in labels
    assert fig.axes[-1].get_xlabel() == "time [ms]"
    loops = plots.plot_loops(qs)
    assert loops.axes[0].get_xlabel() == "tangential displacement u [um]"


def test_write_figures_and_plot_cli(runs, tmp_path):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    system, qs, dyn, _ = runs
    paths = plots.write_figures(
        dyn, tmp_path / "api", reference=qs, system=system, comparison=[{"method": "newmark", "time_ratio": 1.0}]
    )
    assert len(paths) == 7  # incl. interface loops and the method bars
    for p in paths:
        _check_png(p)
    result_file = tmp_path / "m3.nc"
    slipstep.save_result(dyn, result_file)
    res = CliRunner().invoke(app, ["plot", str(result_file), "--output-dir", str(tmp_path / "cli")])
    assert res.exit_code == 0, res.output
    written = sorted((tmp_path / "cli").glob("*.png"))
    assert len(written) == 6  # the result names the built-in case: loops filtered, interfaces too
    for p in written:
        _check_png(p)
    bad = CliRunner().invoke(app, ["plot", str(tmp_path / "missing.nc")])
    assert bad.exit_code == 2
