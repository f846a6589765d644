"""The step rule of solves that do not iterate (issue 26, item 3): step_rule 'accuracy' for the
piecewise-linear methods (the cap T / 50, the step-doubling refinement and the stability limit;
T_min sets nothing), the methods that iterate keep the paper's 't-min' rule (refusing
'accuracy'), and ``compare`` marches every method on the paper's rule so Methods 1 and 3 take
the same steps."""

import pytest

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
