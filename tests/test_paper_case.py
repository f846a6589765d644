"""The built-in `paper` case against the numbers of physics.md sections 6 and 7.

Every expensive run is done once per module (fixtures with scope="module"); 3 periods each.
"""

import math

import numpy as np
import pytest

import slipstep as ss
from slipstep.kernels.contact import LIFT, STICK
from slipstep.post.energy import friction_energy_per_period

CF = 200.0  # N, the centrifugal load of the case
UM = 1e-6


def sig3(value):
    """Round to 3 significant digits."""
    return float(f"{value:.3g}")


@pytest.fixture(scope="module")
def system():
    return ss.load_system("paper")


@pytest.fixture(scope="module")
def quasi_static(system):
    ds = ss.run(system, "quasi-static", periods=3, raise_on_failure=True)
    return ds


@pytest.fixture(scope="module")
def newmark(system):
    return ss.run(system, "newmark", periods=3, raise_on_failure=True)


def last_period(ds):
    period = ds.attrs["period_s"]
    t_end = float(ds.time[-1])
    return ds.sel(time=slice(t_end - period * (1 + 1e-9), None))


def state_change_indices(states):
    """Indices k (into the array) where the state row differs from row k - 1."""
    return np.nonzero(np.any(states[1:] != states[:-1], axis=1))[0] + 1


# --- linear numbers: stick frequencies, T_min, step count ---------------------------------


def test_stick_frequencies_and_t_min(system):
    cs = system.compile()
    t_min = ss.state_t_min(cs, np.full(3, STICK, np.int8))
    ev = ss.state_eigenvalues(cs, np.full(3, STICK, np.int8))
    assert np.allclose(np.imag(ev), 0.0)
    f_khz = np.sort(np.sqrt(np.real(ev))) / (2 * math.pi) / 1e3
    assert [sig3(f) for f in f_khz] == [8.41, 10.5, 11.9]
    # 4 significant digits where physics.md gives them
    assert [round(f, 2) for f in f_khz] == [8.41, 10.48, 11.86]
    assert sig3(t_min * 1e6) == 84.3


def test_newmark_step_is_t_min_over_pi_with_187_steps_per_period(system):
    sim = ss.Simulation(system, "newmark", periods=1)
    assert sig3(sim.t_min_stick / math.pi * 1e6) == 26.8
    assert round(sim.period / sim.dt) == 187
    assert sim.period / sim.dt == pytest.approx(187, abs=1e-9)
    assert sim.dt <= sim.t_min_stick / math.pi


# --- static preload ---------------------------------------------------------------------


def test_preload(quasi_static):
    x0 = quasi_static.displacement.isel(time=0).values
    assert [sig3(x0[0] / UM), sig3(x0[1] / UM), sig3(x0[2] * 1e3)] == [-1.29, 5.88, 0.563]
    N0 = quasi_static.normal_force.isel(time=0).values
    T0 = quasi_static.tangential_force.isel(time=0).values
    assert [sig3(v) for v in N0] == [43.6, 72.9, 99.9]
    assert [sig3(v) for v in T0] == [17.4, 24.1, -25.0]
    mu = quasi_static.friction_coefficient.values
    # P3 slipping, P1 on the slip boundary (|T| = mu N to 3 digits)
    assert abs(T0[2]) == pytest.approx(mu[2] * N0[2], rel=1e-9)
    assert abs(T0[0]) == pytest.approx(mu[0] * N0[0], rel=1e-3)
    # static equilibrium: K x + A^T f = f_e with K = 0
    cs = ss.load_system("paper").compile()
    f = np.zeros(cs.A.shape[0])
    f[cs.tangential_row] = T0
    f[cs.normal_row] = N0
    assert np.allclose(cs.A.T @ f, cs.constant_force, atol=1e-9 * CF)


# --- quasi-static march (Method 4) -------------------------------------------------------


def test_quasi_static_six_state_changes_at_the_paper_phases(quasi_static):
    last = last_period(quasi_static)
    states = last.contact_state.values
    t = last.time.values
    assert len(t) == 301
    idx = state_change_indices(states)
    assert len(idx) == 6
    phases = (t[idx] / quasi_static.attrs["period_s"]) % 1.0 * 360.0
    step_deg = 360.0 / 300
    expected = np.array([91.2, 134.4, 172.8, 271.2, 322.8, 352.8])
    assert np.all(np.abs(phases - expected) <= step_deg + 1e-9), phases
    assert not np.any(states == LIFT)
    assert np.all(last.normal_force.values > 0)


def test_quasi_static_full_slip_share(quasi_static):
    states = last_period(quasi_static).contact_state.values[1:]  # 300 steps of the last period
    share = np.all(states >= 2, axis=1).mean()
    assert round(100 * share, 1) == 54.7


def test_quasi_static_dissipated_energy_per_face(quasi_static):
    per_contact = friction_energy_per_period(quasi_static)
    left = float(per_contact.sel(contact=["P1", "P2"]).sum())
    right = float(per_contact.sel(contact="P3"))
    assert left == pytest.approx(2.52e-3, rel=0.01)
    assert right == pytest.approx(2.70e-3, rel=0.01)


def test_quasi_static_tangential_force_ranges(quasi_static):
    T = last_period(quasi_static).tangential_force
    left = T.sel(direction=["P1", "P2"]).sum("direction").values
    right = T.sel(direction="P3").values
    assert [sig3(left.min()), sig3(left.max())] == [-78.6, 47.1]
    assert [sig3(right.min()), sig3(right.max())] == [-32.8, 55.0]


# --- Newmark (Method 1) against quasi-static ---------------------------------------------


def test_newmark_vs_quasi_static_last_period(quasi_static, newmark):
    """physics.md 6: damper displacement within 0.45 um, contact forces within 5 % of CF.
    The quasi-static result (300 steps/period) is interpolated linearly onto Newmark's
    times; the displacement bound is on the centre-of-mass translations x_G, y_G."""
    qs, nm = last_period(quasi_static), last_period(newmark)
    t_nm, t_qs = nm.time.values, qs.time.values
    for j in range(2):
        ref = np.interp(t_nm, t_qs, qs.displacement.values[:, j])
        assert np.abs(nm.displacement.values[:, j] - ref).max() < 0.45 * UM
    for name in ("tangential_force", "normal_force"):
        for j in range(3):
            ref = np.interp(t_nm, t_qs, qs[name].values[:, j])
            assert np.abs(nm[name].values[:, j] - ref).max() < 0.05 * CF, (name, j)


def test_newmark_raw_state_changes_are_chatter(newmark):
    """physics.md 6: 30-50 raw dynamic state changes per period (ringing)."""
    n = len(state_change_indices(last_period(newmark).contact_state.values))
    assert 30 <= n <= 50


# --- iteration and step statistics (physics.md 7) -----------------------------------------


def test_method1_iterations_per_step_at_200_hz(newmark):
    """physics.md 7: about 11 iterations per step. Issue 8 made the stop stricter (increment
    AND force residual, contact coordinates AND DOFs, default tolerance 1e-11): 17.2 now; the
    paper's count corresponds to a looser stop (11.6 with the old increment-only test at 1e-8)."""
    assert newmark.attrs["steps"] == 3 * 187
    assert 15.5 <= newmark.attrs["mean_solves_per_step"] <= 18.5
    solves = newmark.solves.values[1:]
    assert solves.sum() == newmark.attrs["solves"]


@pytest.fixture(scope="module")
def piecewise_linear(system):
    # the paper's steps (187 per period): Method 3 on the T_min rule, as the built-in case's [run] sets it
    return ss.run(system, "piecewise-linear", periods=3, step_rule="t-min", raise_on_failure=True)


def test_method3_extra_solves_only_at_state_changes(piecewise_linear):
    """Method 3 postulates S_{n+1} = S_n: a step needs more than one solve exactly when the
    state changes, and a transition costs one extra solve (rarely two)."""
    ds = piecewise_linear
    solves = ds.solves.values[1:]
    states = ds.contact_state.values
    changed = np.any(states[1:] != states[:-1], axis=1)
    assert ds.attrs["steps"] == 3 * 187
    assert ds.attrs["fallback_steps"] == 0
    assert np.all(solves[~changed] == 1)
    assert np.all(solves[changed] >= 2)
    assert (solves[changed] == 2).mean() > 0.9
    assert changed.sum() == ds.attrs["state_changes"]


@pytest.mark.xfail(
    strict=True,
    reason=(
        "physics.md 7 claims one solve in > 90 % of Method-3 steps, but physics.md 6 also states 30-50 raw "
        "(chatter) state changes per 187-step period; each costs one extra solve, so the share is "
        "1 - changes/steps = 0.81 here (109 changes in 561 steps). Reported to the lead; not loosened."
    ),
)
def test_method3_single_solve_share_paper_claim(piecewise_linear):
    solves = piecewise_linear.solves.values[1:]
    assert (solves == 1).mean() > 0.9


@pytest.mark.parametrize("method", ["newmark-adaptive", "piecewise-linear-adaptive"])
def test_method2_steps_per_period(system, method):
    ds = ss.run(system, method, periods=3, step_rule="t-min", raise_on_failure=True)  # the paper's rule
    per_period = ds.attrs["steps"] / 3
    assert per_period == pytest.approx(161, rel=0.03)
    assert per_period < 187
    dt = ds.step_size.values[1:]
    assert dt.max() <= ds.attrs["period_s"] / 50 * (1 + 1e-12)
