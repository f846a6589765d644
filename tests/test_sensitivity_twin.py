"""Issue 29 item 3: the sensitivity twin (slipstep.methods.sensitivity_twin) and `tolerance` from the
command line and case files.

    twin_difference = max_t,j |x_j - x~_j| / R,   R = the largest DOF range of the run

x~ the run with every load and motion scaled by 1 + 1e-10 and the Newton tolerance 100 times tighter.
Above TWIN_FLAG (1e-6) the run warns (SensitivityWarning) and ``invariants.flagged`` gives the reason.

The flagged systems are seeded stick-1dof oscillators of slipstep.study.trust_systems (one DOF held
by one 2D contact, 7-35 % of the steps change contact state) that Method 1 returned OK, unflagged and
1.3e-5 and 4.2e-5 of their range off full Newton and the piecewise-linear solve at 1e-13 (which
agree to 1e-8) before the twin: the first (system 125) is not sensitive to its loads (a 1e-10 change
moves it 4e-10) but its Newton-tolerance steps land on other stick/slip decisions; the second (system
1388) is chaotic (a 1e-10 change of the loads moves Method 1's result by 6.7e-5 of its range).
"""

from __future__ import annotations

import json
from pathlib import Path
import warnings

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import slipstep as ss
from slipstep.casefile.case import CASES_DIR
from slipstep.cli.main import app
from slipstep.methods import sensitivity_twin as ST
from slipstep.methods.invariants import flagged
from slipstep.study.trust_systems import trust_system
from slipstep.study.verification import agreement_error, perturbed, tight_references

GRID = {"periods": 2, "error_estimate": False, "step_rule": "t-min"}  # the paper's grid, as the benchmark


def stick_1dof(i: int) -> ss.System:
    return trust_system(np.random.default_rng([29, 0, i]), "stick-1dof")


def _run(system, method="newmark", **options):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = ss.run(system, method, **{**GRID, **options})
    return ds, [w for w in caught if issubclass(w.category, ST.SensitivityWarning)]


@pytest.mark.parametrize("i", [125, 1388])
def test_a_stick_slip_oscillator_off_its_references_is_flagged(i):
    system = stick_1dof(i)
    ds, caught = _run(system)  # sensitivity_check='auto' (the default): the twin runs (state changes >= 5 %)
    ref, pl = tight_references(system, 2)
    assert agreement_error(pl, ref) <= 1e-8  # decidable: the references agree
    error = agreement_error(ds, ref)
    assert ds.attrs["status"] == "OK" and error > 1e-6  # off, under OK
    assert ds.attrs["state_changes"] >= ST.AUTO_STATE_CHANGE_SHARE * ds.attrs["steps"]
    assert ds.attrs["twin_difference"] > ST.TWIN_FLAG
    assert ds.attrs["twin_difference"] == pytest.approx(error, rel=2.0)  # about the result's own error
    assert len(caught) == 1 and "not reproducible" in str(caught[0].message)
    assert "--tolerance" in str(caught[0].message) and "statistics over periods" in str(caught[0].message)
    reasons = flagged(ds.attrs)
    assert any("twin_difference" in r for r in reasons)
    # without the twin the other flags do not see it (the class this flag is for)
    assert flagged({k: v for k, v in ds.attrs.items() if k != "twin_difference"}) == []


def test_the_chaotic_one_is_sensitive_to_its_loads():
    """System 1388: a 1e-10 change of the loads alone moves Method 1's result by far more than 1e-10."""
    system = stick_1dof(1388)
    base, _ = _run(system, sensitivity_check=False)
    moved, _ = _run(perturbed(system, ST.PERTURBATION), sensitivity_check=False)
    assert agreement_error(moved, base) / ST.PERTURBATION > 1e4


def test_twin_difference_is_the_difference_of_the_two_marches():
    """The attr against the twin run by hand: the perturbed system at the tighter tolerance."""
    system = stick_1dof(125)
    ds, _ = _run(system, sensitivity_check=True)
    twin, _ = _run(perturbed(system, ST.PERTURBATION), tolerance=ST.twin_tolerance(1e-11), sensitivity_check=False)
    assert ds.attrs["twin_difference"] == pytest.approx(agreement_error(twin, ds), rel=1e-3)
    assert ds.attrs["twin_time_s"] > 0


def test_the_paper_case_is_not_flagged():
    ds, caught = _run(ss.load_system("paper"), periods=3)
    assert ds.attrs["twin_difference"] < ST.TWIN_FLAG  # the twin ran ('auto': 19 % of the steps change state)
    assert not caught and flagged(ds.attrs) == []


def test_off_and_not_wanted():
    system = stick_1dof(125)
    ds, caught = _run(system, sensitivity_check=False)
    assert "twin_difference" not in ds.attrs and not caught
    ds, _ = _run(stick_1dof(3))  # 'auto': no step changes state, no twin
    assert ds.attrs["state_changes"] < ST.AUTO_STATE_CHANGE_SHARE * ds.attrs["steps"]
    assert "twin_difference" not in ds.attrs
    ds, _ = _run(stick_1dof(3), sensitivity_check=True)  # asked: it runs
    assert ds.attrs["twin_difference"] < ST.TWIN_FLAG


@pytest.fixture
def no_twin(monkeypatch):
    def refuse(sim):
        raise AssertionError("the sensitivity twin ran")

    monkeypatch.setattr(ST, "twin_difference", refuse)


def test_auto_is_off_in_the_steady_state_and_frf_paths(no_twin):
    from slipstep.frequency import sine_sweep
    from slipstep.steady import march_to_steady

    paper = ss.load_system("paper")
    st = march_to_steady(paper, method="newmark", max_periods=3, tolerance=1e-3)
    assert st is not None
    jenkins = ss.load_system(Path(__file__).resolve().parents[1] / "examples" / "jenkins.toml")
    sweep = sine_sweep(jenkins, [260.0, 280.0], cycles_per_point=3, method="newmark")
    assert sweep.sizes["frequency"] > 0
    with pytest.raises(AssertionError, match="twin ran"):  # the guard works: a plain run calls it
        ss.run(paper, "newmark", periods=1, error_estimate=False)


def test_a_sweep_case_runs_without_the_twin():
    from slipstep.casefile.specs import RunSpec
    from slipstep.sweep.case_run import _run_options

    assert _run_options(RunSpec(tolerance=1e-12), {})["sensitivity_check"] is False
    assert _run_options(RunSpec(tolerance=1e-12), {})["tolerance"] == 1e-12


def test_tolerance_from_the_case_file_and_the_command_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = (CASES_DIR / "paper.toml").read_text()
    assert 'step_rule = "t-min"' in text
    (tmp_path / "tight.toml").write_text(text.replace('step_rule = "t-min"', 'step_rule = "t-min"\ntolerance = 1e-13'))
    runner = CliRunner()
    for args, expected in ((["tight.toml"], 1e-13), (["tight.toml", "--tolerance", "1e-12"], 1e-12)):
        result = runner.invoke(app, ["run", *args, "--periods", "1", "--json", "-o", "out"])
        assert result.exit_code == 0, result.output
        summary = json.loads(result.stdout)
        with xr.open_dataset(summary["output"]) as ds:
            assert ds.attrs["tolerance"] == expected
        assert "twin_difference" in summary and "trust_flags" in summary


def test_the_trust_flag_names_the_command_line_option():
    from slipstep.methods.invariants import tolerance_text

    text = tolerance_text(1e-6, 1e-11)
    assert "--tolerance 1e-13" in text and "[run] tolerance" in text


def test_auto_skips_long_runs(monkeypatch):
    """'auto' runs the twin only while steps x DOFs is at most AUTO_MAX_WORK (the paper case: 561 x 3)."""
    paper = ss.load_system("paper")
    monkeypatch.setattr(ST, "AUTO_MAX_WORK", 561 * 3 - 1)
    ds, _ = _run(paper, periods=3)
    assert ds.attrs["steps"] * 3 > ST.AUTO_MAX_WORK and "twin_difference" not in ds.attrs
    monkeypatch.setattr(ST, "AUTO_MAX_WORK", 561 * 3)
    ds, _ = _run(paper, periods=3)
    assert "twin_difference" in ds.attrs
