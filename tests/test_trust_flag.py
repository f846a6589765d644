"""Issue 29 item 3: the trust flag of Methods 1 and 2 (slipstep.methods.invariants.tolerance_check).

    tolerance_over_range = tol L / R,   R = max_j (max_t x_j - min_t x_j)

L the length scale (model/system.py: the larger of the motion amplitude and the static deflection
|f| / k of the loads, k the largest contact normal or structural diagonal stiffness). Above
TOLERANCE_RANGE_FLAG (1e-8) the run warns and ``invariants.flagged`` names the reason.

The clamped oscillator below: one DOF (m = 1 kg, k = 1e4 N/m) pressed by f0 = 100 N onto one
contact (k_n = k_t = 1e6 N/m, mu = 0.5) and shaken by 1e-3 N at 10 Hz: it sticks, so its range is
about 2e-3 N / (k + k_n + k_t) = 1e-9 m, while L = 100 N / 1e6 N/m = 1e-4 m: at the default tolerance
1e-11, tol L / R is about 1e-6 and the Newton stop leaves steps up to 1e-15 m = 1e-6 of the range off
their equation. On main before the flag, Method 1 returned it OK and unflagged (no step above the
step audit's 1e4 x tolerance), 2.2e-6 of the range off full Newton at 1e-13 (tol L / R = 9.7e-7);
at the tolerance the warning suggests (1e-13) it is 2.6e-8 off.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from typer.testing import CliRunner

import slipstep as ss
from slipstep.cli.main import app
from slipstep.methods.invariants import TOLERANCE_RANGE_FLAG, flagged
from slipstep.study.verification import agreement_error

F0, AMPLITUDE, KN, K = 100.0, 1e-3, 1e6, 1e4

CLAMPED = f"""\
name = "clamped"

[structure]
dof_names = ["x"]
mass_kg = [[1.0]]
stiffness_N_per_m = [[{K}]]
constant_force_N = [{F0}]

[[contacts]]
name = "C"
dof_gather = [[1.0], [1.0]]
normal_stiffness_N_per_m = {KN}
tangential_stiffness_N_per_m = {KN}
friction_coefficient = 0.5

[[force]]
component = "x"
amplitude = {AMPLITUDE}
frequency_Hz = 10.0
"""


def clamped() -> ss.System:
    contact = ss.ContactElement("C", np.array([[1.0], [1.0]]), KN, KN, 0.5)
    force = ss.Signal(("x",), (ss.Harmonic(10.0, np.array([AMPLITUDE])),))
    excitation = ss.Excitation(constant_force=np.array([F0]), force=force)
    return ss.System(ss.Structure(np.eye(1), None, np.array([[K]])), (contact,), excitation, name="clamped")


def _run(system, method, **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = ss.run(system, method, periods=2, error_estimate=False, **options)
    return ds, [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]


@pytest.mark.parametrize("method", ["newmark", "newmark-adaptive"])
def test_flag_fires_on_a_response_far_below_the_length_scale(method):
    ds, messages = _run(clamped(), method)
    assert ds.attrs["status"] == "OK"
    x = ds["displacement"].values
    length = F0 / KN  # L by hand: the static deflection of the loads on the stiffest spring
    assert ds.attrs["length_scale_m"] == pytest.approx(length, rel=1e-12)
    expected = ds.attrs["tolerance"] * length / np.ptp(x, axis=0).max()
    assert ds.attrs["tolerance_over_range"] == pytest.approx(expected, rel=1e-9)
    assert 1e-7 < ds.attrs["tolerance_over_range"] < 1e-5  # 1e-11 x 1e-4 m / about 1e-9 m
    reasons = flagged(ds.attrs)
    assert len(reasons) == 1 and "tolerance option" in reasons[0]
    assert any("may differ from the discrete solution" in m and "tolerance=" in m for m in messages)


def test_the_suggested_tolerance_clears_the_flag_and_the_result_is_closer():
    """The flag is no false alarm here: at the default tolerance Method 1 is more than 1e-6 of the
    range off full Newton at 1e-13 (a silent wrong result before the flag); at the tolerance the
    warning suggests it is not flagged and within 1e-7."""
    system = clamped()
    ref, _ = _run(system, "full-newton", tolerance=1e-13)
    loose, messages = _run(system, "newmark")
    text = next(m for m in messages if "tolerance=" in m)
    suggested = float(text.split("tolerance=")[1].split(",")[0])
    assert f"slipstep run --tolerance {suggested:.0e}" in text  # and the command-line option
    assert suggested == 1e-13  # the power of ten below 1e-11 x 1e-8 / (tol L / R = 9.7e-7)
    tight, messages = _run(system, "newmark", tolerance=suggested)
    assert tight.attrs["tolerance_over_range"] <= TOLERANCE_RANGE_FLAG
    assert not [m for m in messages if "may differ from the discrete solution" in m]
    assert agreement_error(loose, ref) > 1e-6
    assert agreement_error(tight, ref) < 1e-7


def test_flag_silent_on_the_paper_case():
    ds, messages = _run(ss.load_system("paper"), "newmark")
    assert ds.attrs["status"] == "OK"
    assert 0.0 < ds.attrs["tolerance_over_range"] < TOLERANCE_RANGE_FLAG
    assert flagged(ds.attrs) == []
    assert not [m for m in messages if "may differ from the discrete solution" in m]


def test_only_the_modified_newton_methods_carry_it():
    ds, _ = _run(clamped(), "piecewise-linear")
    assert "tolerance_over_range" not in ds.attrs and flagged(ds.attrs) == []


def test_flagged_reads_both_reasons():
    attrs = {"steps_above_tolerance": 3, "max_step_residual": 2e-6, "tolerance": 1e-11}
    assert len(flagged(attrs)) == 1 and "3 steps" in flagged(attrs)[0]
    attrs["tolerance_over_range"] = 2 * TOLERANCE_RANGE_FLAG
    assert len(flagged(attrs)) == 2
    attrs.update(steps_above_tolerance=0, tolerance_over_range=0.5 * TOLERANCE_RANGE_FLAG)
    assert flagged(attrs) == []


def test_cli_json_and_table_show_the_flag(tmp_path):
    case = tmp_path / "clamped.toml"
    case.write_text(CLAMPED)
    cli = CliRunner()
    result = cli.invoke(app, ["run", str(case), "-m", "1", "--periods", "2", "--output-dir", str(tmp_path), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["tolerance_over_range"] > TOLERANCE_RANGE_FLAG
    assert len(summary["trust_flags"]) == 1 and "tolerance option" in summary["trust_flags"][0]
    paper = cli.invoke(app, ["run", "paper", "-m", "1", "--periods", "1", "--output-dir", str(tmp_path), "--json"])
    assert json.loads(paper.stdout)["trust_flags"] == []
    table = cli.invoke(app, ["run", str(case), "-m", "1", "--periods", "2", "--output-dir", str(tmp_path)])
    assert "tolerance / response range" in table.stdout and "trust flag" in table.stdout
