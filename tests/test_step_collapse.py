"""A run whose step collapsed warns (issue 29): more than COLLAPSE_FACTOR times the steps its
planned step gives over its duration; the ratio is in the result's attrs."""

import warnings

import pytest
import xarray as xr

import slipstep as ss
from slipstep.methods.simulation import COLLAPSE_FACTOR, collapsed_step_warning


def test_a_fixed_step_run_takes_its_planned_steps_and_does_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        ds = ss.run(ss.load_system("paper"), "piecewise-linear", periods=1, error_estimate=False)
    assert ds.attrs["steps_over_planned"] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("ratio, warns", [(COLLAPSE_FACTOR * 2, True), (COLLAPSE_FACTOR * 0.5, False)])
def test_the_rule(ratio, warns):
    ds = xr.Dataset(attrs={"dt_s": 1e-5, "t_end_s": 1e-2, "steps": int(1000 * ratio)})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        collapsed_step_warning(ds)
    assert ds.attrs["steps_over_planned"] == pytest.approx(ratio)
    assert any("the step collapsed" in str(w.message) for w in caught) == warns
