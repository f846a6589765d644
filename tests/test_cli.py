"""The `slipstep` command line (typer): run, compare, cases; short runs (1-2 periods).

Bounds used below come from physics.md sections 6-7 (paper case): Method 2 takes fewer steps
than Method 1 (161 against 187 per period), the quasi-static method needs about one solve per
step against about 12 for Method 1, Method 3 solves the same discrete equations as Method 1,
and every method stays within 0.45 um and 5 % of CF of Method 1 (here checked after the
low-pass filter of the damper's ringing, which the short runs leave in the raw signals).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from slipstep.cli.main import app
from slipstep.methods.registry import COMPARE_METHODS
from slipstep.output.results import SCHEMA, load

from test_bad_input import STRUCTURE

REQUIRED_RUN = (
    "method",
    "status",
    "steps",
    "iterations",
    "state_changes",
    "kernel_time_s",
    "t_min_s",
    "dt_s",
    "output",
    "solves",
    "mean_solves_per_step",
)
REQUIRED_COMPARE = (
    "method",
    "steps",
    "solves",
    "mean_solves_per_step",
    "single_solve_share",
    "state_changes",
    "kernel_time_s",
    "time_ratio",
    "max_disp_diff_um",
    "max_force_diff_pct_cf",
)

runner = CliRunner()


def invoke(*args):
    result = runner.invoke(app, list(args))
    assert "Traceback" not in result.output, result.output
    return result


@pytest.fixture(scope="module")
def run_json(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    result = invoke("run", "paper", "--method", "3", "--periods", "1", "--output-dir", str(out), "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout), out


def test_run_json_is_one_object_with_required_keys(run_json):
    summary, out = run_json
    assert set(REQUIRED_RUN) <= set(summary)
    assert summary["method"] == "piecewise-linear" and summary["status"] == "OK"
    assert summary["output"] == str(out / "paper_piecewise-linear.nc")


def test_run_writes_loadable_dataset_matching_json(run_json):
    summary, _ = run_json
    ds = load(summary["output"])
    for key in REQUIRED_RUN:
        if key == "output":
            continue
        if isinstance(summary[key], str):
            assert ds.attrs[key] == summary[key], key
        else:
            assert ds.attrs[key] == pytest.approx(summary[key], rel=1e-12), key
    # the file is the run: steps + 1 points (time 0 = preload), per-step solves add up to the total
    assert ds.sizes["time"] == summary["steps"] + 1
    assert int(ds.solves[1:].sum()) == summary["solves"]
    assert set(ds.data_vars) <= set(SCHEMA)
    # one 200 Hz period at the fixed step dt = T_min/pi rounded to whole steps per period (physics.md 6: 187)
    assert summary["steps"] * summary["dt_s"] == pytest.approx(5e-3, rel=1e-9)
    assert summary["dt_s"] <= summary["t_min_s"] / math.pi * (1 + 1e-12)


def test_run_table_and_method_aliases(tmp_path):
    result = invoke("run", "paper", "-m", "2+3", "--periods", "1", "--output-dir", str(tmp_path))
    assert result.exit_code == 0, result.output
    for text in ("piecewise-linear-adaptive", "Method 2+3", "steps", "state changes", "T_min", "kernel time"):
        assert text in result.stdout
    assert (tmp_path / "paper_piecewise-linear-adaptive.nc").exists()


def test_run_toml_structure_case_uses_its_run_table(tmp_path):
    """A [structure] case file whose [run] table picks the method (quasi-static) and 2 periods."""
    case = tmp_path / "two_dof.toml"
    case.write_text(STRUCTURE + '\n[run]\nmethod = "4"\nperiods = 2\nsteps_per_period = 100\n')
    result = invoke("run", str(case), "--output-dir", str(tmp_path), "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["method"] == "quasi-static" and summary["steps"] == 200
    assert summary["output"].endswith("two_dof_quasi-static.nc")
    # the command line wins over the [run] table
    result = invoke("run", str(case), "--output-dir", str(tmp_path), "--json", "--method", "newmark", "--periods", "1")
    summary = json.loads(result.stdout)
    assert summary["method"] == "newmark" and summary["t_end_s"] == pytest.approx(0.02)


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare")
    result = invoke("compare", "paper", "--periods", "1", "--repeats", "2", "--output-dir", str(out), "--json")
    assert result.exit_code == 0, result.output
    return {row["method"]: row for row in json.loads(result.stdout)}, out / "paper"  # <output-dir>/<case>/


def test_compare_json_rows_and_keys(compared):
    rows, _ = compared
    assert list(rows) == list(COMPARE_METHODS)  # the paper's methods and the event-driven one
    for row in rows.values():
        assert set(REQUIRED_COMPARE) <= set(row)
        assert row["status"] == "OK" and row["kernel_time_s"] > 0
        assert row["mean_solves_per_step"] == pytest.approx(row["solves"] / row["steps"])
        assert 0.0 <= row["single_solve_share"] <= 1.0
        assert row["timed_in"] == "a fresh process"  # compare.fresh_process_times
    assert rows["newmark"]["time_ratio"] == 1.0
    assert rows["newmark"]["max_disp_diff_um"] == 0.0


def test_compare_counts_follow_the_paper(compared):
    rows, _ = compared
    m1, m2, m3, m4 = (rows[k] for k in ("newmark", "newmark-adaptive", "piecewise-linear", "quasi-static"))
    assert m2["steps"] < m1["steps"] == 187
    assert m4["solves"] < m1["solves"] and m3["solves"] < m1["solves"]
    assert m1["mean_solves_per_step"] > 5  # modified Newton with the full-stick tangent (paper: ~11 at 200 Hz)
    # Method 3: one solve per step plus about one more per state change (physics.md 4)
    assert m3["solves"] - m3["steps"] <= m3["state_changes"] + 5
    assert m3["single_solve_share"] >= 1 - (m3["state_changes"] + 5) / m3["steps"]


@pytest.mark.xfail(
    strict=True,
    reason="paper claim (> 90 % single-solve steps for Method 3) not reached on the "
    "paper case: the damper's ringing causes ~32 raw state changes per period, "
    "each costing one extra solve (share ~0.83); reported to the lead",
)
def test_compare_piecewise_linear_single_solve_share_above_90_percent(compared):
    rows, _ = compared
    assert rows["piecewise-linear"]["single_solve_share"] > 0.9


def test_compare_accuracy_against_method_1(compared):
    rows, _ = compared
    # Method 3 at the same fixed step: the same discrete solution (solver tolerance)
    assert rows["piecewise-linear"]["max_disp_diff_um"] < 1e-3
    assert rows["piecewise-linear"]["max_force_diff_pct_cf"] < 1e-2
    for row in rows.values():  # physics.md 6 bounds, after the low-pass filter
        assert row["max_disp_diff_filtered_um"] < 0.45, row["method"]
        assert row["max_force_diff_filtered_pct_cf"] < 5.0, row["method"]
    # the quasi-static march sees the paper's six transitions, the dynamic ones chatter (30-50 per period)
    assert rows["quasi-static"]["state_changes_last_period"] in (6, 7)
    assert rows["newmark"]["state_changes_last_period"] > 12


def test_compare_writes_table_and_figures(compared):
    rows, out = compared
    saved = json.loads((out / "comparison.json").read_text())
    assert [r["method"] for r in saved] == list(rows)
    lines = (out / "comparison.csv").read_text().strip().splitlines()
    assert len(lines) == 1 + len(rows) and lines[0].startswith("method,")
    for name in ("fig8_time_ratios.png", "fig5_iterations.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name


def test_compare_subset_always_includes_reference(tmp_path):
    result = invoke(
        "compare",
        "paper",
        "--periods",
        "1",
        "--repeats",
        "1",
        "--methods",
        "4",
        "--output-dir",
        str(tmp_path),
        "--json",
    )
    assert result.exit_code == 0, result.output
    assert [r["method"] for r in json.loads(result.stdout)] == ["newmark", "quasi-static"]


def test_compare_table_output(tmp_path):
    result = invoke(
        "compare", "paper", "--periods", "1", "--repeats", "1", "--methods", "3", "--output-dir", str(tmp_path)
    )
    assert result.exit_code == 0, result.output
    for text in ("Method 1", "Method 3", "time ratio", "% CF", "comparison.csv", "fig8_time_ratios.png"):
        assert text in result.stdout


def test_bad_input_exit_code_2_and_message(tmp_path):
    result = invoke("run", "paper", "--method", "runge-kutta", "--output-dir", str(tmp_path))
    assert result.exit_code == 2
    assert "method" in result.output and "unknown method 'runge-kutta'" in result.output
    assert not list(tmp_path.glob("*.nc"))


def test_help_documents_commands():
    result = invoke("--help")
    assert result.exit_code == 0
    for command in ("run", "compare", "cases", "methods"):
        assert command in result.output
    for command in ("run", "compare"):
        text = invoke(command, "--help").output
        for option in ("--periods", "--output-dir", "--json"):
            assert option in text
    assert "paper" in invoke("cases").stdout
    assert "quasi-static" in invoke("methods").stdout


def test_compare_rows_are_json_numbers(compared):
    rows, _ = compared
    for row in rows.values():
        for key in REQUIRED_COMPARE[1:]:
            assert isinstance(row[key], (int, float)) and np.isfinite(row[key]), (row["method"], key)


def test_compare_schemes_lists_every_variant(tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "compare",
            "paper",
            "--schemes",
            "newmark,central-difference",
            "--periods",
            "1",
            "--repeats",
            "1",
            "--json",
            "--output-dir",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    by = {(r["scheme"], r["variant"]): r for r in rows}
    assert len(rows) == 8
    assert by[("newmark", "piecewise-linear")]["solves"] < by[("newmark", "fixed")]["solves"] / 5
    assert by[("newmark", "both")]["steps"] < by[("newmark", "fixed")]["steps"]
    assert by[("central-difference", "piecewise-linear")]["status"] == "n/a"
    assert by[("newmark", "fixed")]["time_ratio"] == 1.0
    assert (tmp_path / "paper" / "schemes.md").read_text().startswith("| scheme |")
