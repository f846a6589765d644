"""A march that cannot go on stops with a status naming where, and keeps what it computed."""

import numpy as np
import pytest

import slipstep


def _sliding_block(force_ratio):
    """A free block (x tangential, y normal) pressed by F_y onto a friction contact and pushed
    along by F_x(t) = force_ratio * mu * F_y * sin(2 pi 10 t). Quasi-statically there is no
    equilibrium once |F_x| > mu N: the slipping block is a mechanism (K + K_D singular)."""
    mu, F = 0.3, 100.0
    contact = slipstep.ContactElement("C", np.eye(2), 1e7, 1e7, mu)
    force = slipstep.Signal(("x", "y"), (slipstep.Harmonic(10.0, [force_ratio * mu * F, 0.0]),))
    exc = slipstep.Excitation(constant_force=[0.0, F], force=force)
    return slipstep.System(slipstep.Structure(np.eye(2), dof_names=("x", "y")), (contact,), exc, name="block")


def test_quasi_static_mechanism_has_no_equilibrium_and_says_where():
    ds = slipstep.run(_sliding_block(2.0), "quasi-static", periods=1)
    assert ds.attrs["status"] == "SINGULAR"
    msg = ds.attrs["status_message"]
    assert "t = " in msg and "step" in msg and "slip" in msg
    # F_x reaches mu N at phase 30 deg: the failure is there, to one step
    assert ds.attrs["failed_at_time_s"] == pytest.approx(0.1 / 12, abs=0.1 / 300)
    # the steps before the failure are kept and are finite
    assert 0 < ds.attrs["steps"] < 300
    assert ds.sizes["time"] == ds.attrs["steps"] + 1
    assert np.all(np.isfinite(ds.displacement.values))
    assert ds.attrs["failed_at_time_s"] > ds.time.values[-1]
    # below the friction limit the same block is in equilibrium all along
    assert slipstep.run(_sliding_block(0.5), "quasi-static", periods=1).attrs["status"] == "OK"


def test_raise_on_failure_carries_the_partial_result():
    with pytest.raises(slipstep.SolverError) as info:
        slipstep.run(_sliding_block(2.0), "quasi-static", periods=1, raise_on_failure=True)
    assert info.value.result is not None
    assert info.value.result.attrs["status"] == "SINGULAR"


def test_newton_iteration_cap_reports_not_converged_with_partial_result():
    system = slipstep.load_system("paper")
    ds = slipstep.run(system, "newmark", periods=1, max_iterations=3)
    assert ds.attrs["status"] == "NOT_CONVERGED"
    assert "failed_at_step" in ds.attrs and ds.attrs["failed_at_step"] >= 1
    assert np.all(np.isfinite(ds.tangential_force.values))


def test_cycling_without_fallback_names_the_states_visited():
    system = slipstep.load_system("paper")
    ds = slipstep.run(system, "piecewise-linear", periods=1, max_state_iterations=1, fallback=False)
    assert ds.attrs["status"] == "STATE_CYCLING"
    assert "P1=" in ds.attrs["states_visited"]
    # with the fallback (default) the same run completes and counts the fallback steps
    ok = slipstep.run(system, "piecewise-linear", periods=1, max_state_iterations=1)
    assert ok.attrs["status"] == "OK" and ok.attrs["fallback_steps"] > 0
