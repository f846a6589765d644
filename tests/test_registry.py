"""One registry of methods x schemes x variants (issue 9 item 2): the tables of the methods page,
the CLI help and `slipstep methods` come from slipstep.methods.registry, with one set of defaults."""

import inspect
from pathlib import Path

import pytest
from typer.testing import CliRunner

import slipstep as ss
from docs_pages import gen_pages
from slipstep.cli.main import app
from slipstep.integrators import INTEGRATORS, get_integrator
from slipstep.integrators.base import ImplicitIntegrator
from slipstep.integrators import tables as T
from slipstep.methods import registry as R
from slipstep.methods import schemes

runner = CliRunner()


def _methods_page() -> str:
    """The site's methods page (reference/methods.md), as docs/gen_pages.py renders it."""
    return gen_pages().methods_page()


def test_methods_page_tables_are_the_generated_ones():
    """The page's method and scheme tables are the registry's (`slipstep methods --markdown`)."""
    text = _methods_page()
    assert T.update_tables(text) == text, "the methods page's tables are not the registry's"
    for start, end, key in T.TABLE_BLOCKS:
        assert T.table_blocks()[key] in text
    out = runner.invoke(app, ["methods", "--markdown"]).stdout
    for start, end, key in T.TABLE_BLOCKS:
        assert f"{start}\n{T.table_blocks()[key]}\n{end}" in out


def test_every_method_and_scheme_is_in_the_run_help_and_the_listing():
    help_text = " ".join(runner.invoke(app, ["run", "--help"], terminal_width=400).stdout.split())
    listing = runner.invoke(app, ["methods"], terminal_width=400).stdout
    for m in R.METHODS.values():
        assert m.name + (f"|{m.number}" if m.number else "") in help_text
        assert m.name in listing
    for e in R.SCHEMES.values():
        assert R.scheme_spec(e) in help_text
        assert R.scheme_spec(e) in listing


def test_the_scheme_defaults_are_one_set():
    """hht() and HHT() (and every other pair) take the registry's default; the docs' values."""
    assert R.scheme_default("hht", "alpha") == 0.1
    assert R.scheme_default("generalized-alpha", "rho_inf") == 0.8
    factories = {"newmark": schemes.newmark, "hht": schemes.hht, "generalized-alpha": schemes.generalized_alpha}
    for name, factory in factories.items():
        entry = R.SCHEMES[name]
        defaults = {p: v.default for p, v in inspect.signature(factory).parameters.items()}
        assert defaults == dict(entry.parameters)
        cls_defaults = {p: v.default for p, v in inspect.signature(INTEGRATORS[name].__init__).parameters.items()}
        assert {p: cls_defaults[p] for p, _ in entry.parameters} == dict(entry.parameters)
        assert INTEGRATORS[name]().scheme() == factory()
        assert get_integrator(R.scheme_spec(entry)).scheme() == factory()
    assert ss.hht().name == "hht(alpha=0.1)" and ss.generalized_alpha().name == "generalized-alpha(rho_inf=0.8)"
    assert ss.RunOptions().scheme == schemes.newmark()


def test_registry_integrators_and_variants_agree():
    assert list(INTEGRATORS) == list(R.SCHEMES)
    for name, entry in R.SCHEMES.items():
        integ = INTEGRATORS[name]()
        assert integ.kind == entry.kind and tuple(integ.variants) == entry.variants
    for variant, method in R.VARIANT_METHODS.items():
        assert R.METHODS[method].variant == variant
    assert ImplicitIntegrator._METHOD is R.VARIANT_METHODS
    numbers = {m.number for m in R.METHODS.values() if m.number}
    assert numbers == {"1", "2", "3", "2+3", "4", "3+4"}
    assert all(R.get_method(n).number == n for n in numbers)


def test_cli_run_with_a_scheme(tmp_path):
    result = runner.invoke(
        app, ["run", "paper", "--scheme", "hht", "--periods", "0.5", "--json", "--output-dir", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    ds = ss.load_result(tmp_path / "paper_newmark_hht.nc")
    assert ds.attrs["scheme"] == "hht(alpha=0.1)"
    result = runner.invoke(
        app, ["run", "paper", "-m", "2", "--scheme", "rk4", "--periods", "0.5", "--output-dir", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    ds = ss.load_result(tmp_path / "paper_newmark-adaptive_rk4.nc")
    assert ds.attrs["method"] == "rk4-adaptive" and ds.attrs["adaptive_step"]


@pytest.mark.parametrize(
    "args, key",
    [
        (["-m", "3", "--scheme", "rk4"], "--scheme"),
        (["--scheme", "rk4", "--rtol", "1e-3"], "--rtol"),
        (["--scheme", "hht(0.5)"], "--scheme"),
        (["--scheme", "leapfrog"], "--scheme"),
    ],
)
def test_cli_run_refuses_a_scheme_that_does_not_apply(args, key, tmp_path):
    result = runner.invoke(app, ["run", "paper", "--periods", "0.5", "--output-dir", str(tmp_path), *args])
    assert result.exit_code == 2, result.output
    assert key in result.output and "Traceback" not in result.output


def test_paper_time_ratios_are_the_papers():
    """The ratios Figure 8 marks beside ours are those physics.md 7 states (the paper's Section
    6), read from the text, one per paper method."""
    import re

    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "physics.md").read_text().split())
    sentence = text[text.index("CPU time relative to Method 1:") :].split(". ")[0]
    stated = {
        label.replace("Methods", "Method"): (wording, float(value))
        for label, wording, value in re.findall(r"(Methods? [\d+]+) (about|below) ([\d.]+)", sentence)
    }
    assert len(stated) == 4
    for name in R.PAPER_METHODS:
        method = R.get_method(name)
        expected = ("about", 1.0) if name == "newmark" else stated[method.paper_label]
        assert method.paper_time_ratio == expected
    assert all(m.paper_time_ratio is None for m in R.METHODS.values() if m.name not in R.PAPER_METHODS)


def test_comparison_figure_marks_the_papers_ratios(tmp_path, monkeypatch):
    """fig8_time_ratios.png draws one paper marker per paper method other than Method 1, at its
    stated ratio, and names it under the bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slipstep.study import compare

    rows = [
        {"method": m, "paper_method": R.get_method(m).paper_label, "time_ratio": 0.3, "kernel_time_s": 1e-3}
        for m in ("newmark", "piecewise-linear", "quasi-static", "quasi-static-events")
    ]
    seen = {}
    original = plt.subplots

    def subplots(*args, **kwargs):
        fig, ax = original(*args, **kwargs)
        seen["ax"] = ax
        return fig, ax

    monkeypatch.setattr(plt, "subplots", subplots)
    compare.plot_time_ratios(rows, tmp_path / "fig8.png")
    ax = seen["ax"]
    heights = sorted(round(seg[0][1], 9) for c in ax.collections for seg in c.get_segments())
    assert heights == [0.1, 0.5]
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    assert "paper: about 0.5" in ticks[1] and "paper: < 0.1" in ticks[2]
    assert "paper:" not in ticks[0] and "paper:" not in ticks[3]
    assert (tmp_path / "fig8.png").stat().st_size > 0
