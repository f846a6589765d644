"""The step rule of solves that do not iterate (issue 26, item 3): step_rule 'accuracy' for the
piecewise-linear methods (the cap T / 50, the step-doubling refinement and the stability limit;
T_min sets nothing), their default where a period or max_step caps the step and an error
control checks it; the methods that iterate keep the paper's 't-min' rule (refusing
'accuracy'), and ``compare`` and the built-in paper case march every method on the paper's rule
so Methods 1 and 3 take the same steps."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import slipstep as ss
from slipstep.study.compare import compare
from slipstep.errors import InputError
from slipstep.methods import step_control as SC
from slipstep.methods.plan import plan_run


@pytest.fixture(scope="module")
def paper():
    return ss.load_system("paper")


def test_the_piecewise_linear_step_is_the_cap_not_t_min(paper):
    T = paper.period
    acc = plan_run(paper, "piecewise-linear", error_estimate=False, step_rule="accuracy")
    tmin = plan_run(paper, "piecewise-linear", error_estimate=False, step_rule="t-min")
    assert (acc.step_rule, tmin.step_rule) == ("accuracy", "t-min")
    # Newmark average acceleration is unconditionally stable: only the cap T / 50 remains
    assert acc.dt == pytest.approx(T / SC.STEPS_PER_PERIOD_CAP, rel=1e-12)
    # the paper's rule: r T_min(stick) / (2 pi sqrt(beta)), whole steps per period (below T / 50 here)
    limit = tmin.options.scheme.step_limit_factor * tmin.t_min_stick
    assert limit < T / SC.STEPS_PER_PERIOD_CAP
    assert tmin.dt == pytest.approx(SC.whole_steps(T, limit), rel=1e-12)


def test_methods_that_iterate_keep_the_paper_rule_and_refuse_accuracy(paper):
    m1 = plan_run(paper, "newmark", error_estimate=False)
    m3 = plan_run(paper, "piecewise-linear", error_estimate=False, step_rule="t-min")
    assert m1.step_rule == "t-min" and m1.dt == m3.dt
    with pytest.raises(InputError) as info:
        plan_run(paper, "newmark", step_rule="accuracy")
    assert info.value.field == "step_rule"
    with pytest.raises(InputError) as info:
        plan_run(paper, "piecewise-linear", step_rule="cfl")
    assert info.value.field == "step_rule"


def test_the_adaptive_piecewise_linear_step_is_capped_only(paper):
    acc = plan_run(paper, "piecewise-linear-adaptive", error_estimate=False, step_rule="accuracy")
    tmin = plan_run(paper, "piecewise-linear-adaptive", error_estimate=False, step_rule="t-min")
    assert acc.settings.step_factor == float("inf")  # dt = min(inf T_min(S), dt_max) = dt_max
    assert tmin.settings.step_factor == pytest.approx(SC.kernel_step_factor(tmin.options.scheme, 1.0))


def test_a_run_records_its_rule_and_marches_the_cap(paper):
    ds = ss.run(paper, "piecewise-linear", periods=1, error_estimate=False, step_rule="accuracy")
    assert ds.attrs["step_rule"] == "accuracy"
    assert ds.attrs["steps"] == SC.STEPS_PER_PERIOD_CAP


def test_compare_marches_methods_1_and_3_on_the_same_steps(paper):
    datasets = {}
    options = {"step_rule": "accuracy"}  # compare overrides it: the paper's rule for every method
    with pytest.raises(InputError):  # Method 1 refuses 'accuracy': compare must not pass it on
        plan_run(paper, "newmark", **options)
    compare(
        paper, methods="piecewise-linear", periods=0.5, repeats=1, fresh_process=False, datasets=datasets, **options
    )
    rules = {name: ds.attrs["step_rule"] for name, ds in datasets.items()}
    assert rules == {"newmark": "t-min", "piecewise-linear": "t-min"}
    assert datasets["newmark"].attrs["dt_s"] == datasets["piecewise-linear"].attrs["dt_s"]


# ---- the default rule (methods/step_rule.py step_rule_of) --------------------------------------


@pytest.mark.parametrize(
    "method, rule",
    [
        ("newmark", "t-min"),  # Method 1: iterates
        ("newmark-adaptive", "t-min"),  # Method 2: iterates
        ("full-newton", "t-min"),
        ("piecewise-linear", "accuracy"),  # Method 3
        ("piecewise-linear-adaptive", "accuracy"),  # Method 2+3
        ("quasi-static", "t-min"),  # Method 4: its step is T / steps_per_period
    ],
)
def test_the_default_rule_of_each_method(paper, method, rule):
    plan = plan_run(paper, method, error_estimate=False, max_step=paper.period / 50)
    assert plan.step_rule == rule


def test_the_default_rule_of_method_3_plus_4():
    blades = ss.load_system("blades")
    assert plan_run(blades, "quasi-static-dofs", periods=1).step_rule == "accuracy"
    assert plan_run(blades, "quasi-static-dofs", periods=1, error_estimate=False).step_rule == "t-min"


def test_the_default_accuracy_step_is_the_cap_refined_not_t_min(paper):
    T = paper.period
    plan = plan_run(paper, "piecewise-linear")
    assert plan.step_rule == "accuracy" and plan.pilot_allowed
    assert plan.dt == pytest.approx(T / SC.STEPS_PER_PERIOD_CAP, rel=1e-12)  # before the refinement
    # the paper's T_min step is shorter: the rule changed the step, not only its name
    assert plan.dt > 1.5 * plan_run(paper, "piecewise-linear", step_rule="t-min").dt


def test_without_error_control_the_default_is_t_min(paper):
    """T / 50 unchecked by any estimate is not safe (a random system diverged there): with
    error_estimate off and neither rtol nor max_step, Method 3 keeps the paper's rule."""
    off = plan_run(paper, "piecewise-linear", error_estimate=False)
    m1 = plan_run(paper, "newmark", error_estimate=False)
    assert off.step_rule == "t-min" and off.dt == m1.dt
    assert plan_run(paper, "piecewise-linear", error_estimate=False, rtol=1e-3).step_rule == "accuracy"
    capped = plan_run(paper, "piecewise-linear", error_estimate=False, max_step=paper.period / 80)
    assert capped.step_rule == "accuracy" and capped.dt == pytest.approx(paper.period / 80, rel=1e-12)


def tables_only_system():
    """The paper case with its harmonic motion replaced by a table of the same motion (no period)."""
    from slipstep.casefile.case import CASES_DIR

    text = (CASES_DIR / "paper.toml").read_text()
    t = np.linspace(0.0, 0.02, 401)
    table = (
        '[[motion_table]]\ncomponent = "right.x"\n'
        f"times_s = {list(map(float, t))}\nvalues = {list(map(float, 25e-6 * np.sin(2 * np.pi * 200 * t)))}\n"
    )
    start = text.index("[[motion]]")
    end = text.index("[run]")
    return text[:start] + table + "\n" + text[end:].replace('step_rule = "t-min"', "")


def test_a_run_driven_by_tables_defaults_to_t_min_and_accuracy_needs_max_step(paper, tmp_path):
    path = tmp_path / "tables.toml"
    path.write_text(tables_only_system())
    system = ss.load_system(path)
    assert system.period is None
    plain = plan_run(system, "piecewise-linear", duration=0.005)
    assert plain.step_rule == "t-min"
    assert plain.dt == pytest.approx(plain.options.scheme.step_limit_factor * plain.t_min_stick, rel=1e-12)
    capped = plan_run(system, "piecewise-linear", duration=0.005, max_step=1e-4)
    assert capped.step_rule == "accuracy" and capped.dt == pytest.approx(1e-4, rel=1e-12)
    with pytest.raises(InputError) as info:
        plan_run(system, "piecewise-linear", duration=0.005, step_rule="accuracy")
    assert info.value.field == "step_rule"


def test_explicit_rule_wins_over_the_default(paper):
    tmin = plan_run(paper, "piecewise-linear", step_rule="t-min")
    assert tmin.step_rule == "t-min"
    assert tmin.dt == plan_run(paper, "newmark").dt
    forced = plan_run(paper, "piecewise-linear", error_estimate=False, step_rule="accuracy")
    assert forced.step_rule == "accuracy" and forced.dt == pytest.approx(paper.period / SC.STEPS_PER_PERIOD_CAP)
    with pytest.raises(InputError) as info:
        plan_run(paper, "newmark-adaptive", max_step=paper.period / 50, step_rule="accuracy")
    assert info.value.field == "step_rule"


def test_default_run_attrs_record_rule_step_and_cap(paper):
    ds = ss.run(paper, "piecewise-linear", periods=1)
    a = ds.attrs
    assert a["step_rule"] == "accuracy"
    assert a["max_step_s"] >= a["dt_s"] > 0
    assert a["steps"] * a["dt_s"] == pytest.approx(a["t_end_s"], rel=1e-9)  # fixed step: whole steps per period
    assert a["steps"] < 187  # the paper's T_min rule marches 187 steps per period here
    from slipstep.output.results import ATTRS

    assert {"step_rule", "dt_s", "max_step_s"} <= set(ATTRS)
    assert ATTRS["dt_s"][0] == ATTRS["max_step_s"][0] == "s"


def test_the_paper_case_marches_the_papers_steps_from_the_command_line(tmp_path):
    from slipstep.cli.main import app

    def steps(*extra):
        args = ["run", "paper", "-m", "3", "--periods", "1", "--json", "-o", str(tmp_path), *extra]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        row = json.loads(result.output.strip().splitlines()[-1])
        return row["steps"], row["step_rule"]

    assert steps() == (187, "t-min")  # [run] step_rule = "t-min" of the built-in case
    n, rule = steps("--step-rule", "accuracy")  # the flag wins over the case key
    assert rule == "accuracy" and n < 187


def test_without_an_estimate_method_3_keeps_t_min_where_the_cap_alone_diverges():
    """A seeded random system (issue 8's generator) on which Method 3 at T / 50 with no error
    estimate diverges: the default rule without error control is the paper's, and agrees with
    a tight full-Newton reference on its grid."""
    from slipstep.study.verification import agreement_error, random_system

    system = random_system(np.random.default_rng([8, 170]))
    unchecked = ss.run(system, "piecewise-linear", periods=1, error_estimate=False, step_rule="accuracy")
    assert unchecked.attrs["status"] == "DIVERGED"
    default = ss.run(system, "piecewise-linear", periods=1, error_estimate=False)
    ref = ss.run(system, "full-newton", periods=1, tolerance=1e-13, error_estimate=False)
    assert default.attrs["step_rule"] == "t-min" and default.attrs["status"] == "OK"
    assert default.attrs["dt_s"] == ref.attrs["dt_s"]
    assert agreement_error(default, ref) <= 1e-6


def test_a_retuned_plan_follows_the_rule_of_its_options(paper):
    """RunPlan.retuned keeps the step limits only when the rule stays: giving max_step to a
    Method 3 plan without an estimate turns the default to 'accuracy' (its step is the cap)."""
    plan = plan_run(paper, "piecewise-linear", error_estimate=False)
    assert plan.step_rule == "t-min"
    cap = 1 / 150 / 60
    capped = plan.retuned(150.0, max_step=cap)
    assert capped.step_rule == "accuracy" and capped.dt == pytest.approx(cap, rel=1e-12)
    same = plan.retuned(150.0)
    assert same.step_rule == "t-min" and same.t_min_stick == plan.t_min_stick
    assert same.dt == pytest.approx(SC.whole_steps(1 / 150, plan.dt_limit), rel=1e-12)
