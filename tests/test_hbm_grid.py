"""Harmonic balance at industrial size (issue 24): the asked grid, the edges, the gathered form.

- the asked grid: every requested frequency is returned exactly, in the requested order
  (a comma list, a 3-point range, an unsorted list), the continuation's own points between
  them marked "continuation" / "turning", ``asked_only`` returning the asked points alone;
- edges with the continuation on: no contacts (an internal error before), every contact
  stuck (a very high normal load), contacts that never close: the answer is the linear
  limit of slipstep.frequency.linear_limits to round-off, and no NaN in the finite numbers;
- the balance on the gathered DOFs (the fast path) against the balance on the contact
  coordinates (the path of issue 13) to round-off, and its Jacobian L^T (dF/dZ) L against
  the full dF/dZ and against finite differences.
"""

import warnings

import numpy as np
import pytest
from hbm_cases import gap_oscillator, jenkins_1dof, jenkins_2dof, wedge

import slipstep as ss
from slipstep.frequency import linear_limits
from slipstep.hbm import HarmonicBalance, frf

FINITE = (
    "amplitude",
    "harmonic_amplitude",
    "harmonic_phase",
    "energy_per_cycle",
    "excitation_work",
    "viscous_dissipation",
    "point_time",
    "linear_free_amplitude",
    "linear_stuck_amplitude",
)


def _quiet_frf(*args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return frf(*args, **kwargs)


# ---- the asked grid ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "asked",
    [
        [340.0, 350.0, 360.0],  # 340:360:3
        [250.0, 280.0, 300.0, 320.0, 335.0, 350.0, 380.0, 420.0, 500.0],  # a comma list of nine
        [340.0, 500.0, 250.0, 360.0],  # unsorted: up, down, up
    ],
)
def test_every_asked_frequency_is_returned_in_the_asked_order(asked):
    ds = _quiet_frf(jenkins_1dof(), asked, harmonics=5, check="none")
    kind = ds.point_kind.values
    assert set(kind) <= {"asked", "continuation", "turning"}
    assert ds.frequency.values[kind == "asked"].tolist() == asked  # exactly, in order
    assert np.all(ds.status.values == "OK")
    # the asked points are solutions at their frequencies: the same by Newton at each
    seq = _quiet_frf(jenkins_1dof(), asked, harmonics=5, check="none", continuation=False)
    assert np.allclose(ds.amplitude.values[kind == "asked"], seq.amplitude.values, rtol=1e-8)
    only = _quiet_frf(jenkins_1dof(), asked, harmonics=5, check="none", asked_only=True)
    assert only.frequency.values.tolist() == asked and np.all(only.point_kind.values == "asked")
    assert np.allclose(only.amplitude.values, seq.amplitude.values, rtol=1e-8)


def test_continuation_points_between_asked_ones_are_marked():
    """Around the gap oscillator's fold the continuation takes points of its own (going back
    over the unstable branch, turning twice); the asked grid is still returned, in order."""
    asked = np.linspace(10.0, 30.0, 11)
    ds = _quiet_frf(gap_oscillator(), asked, harmonics=9, check="none")
    kind, f = ds.point_kind.values, ds.frequency.values
    assert np.array_equal(f[kind == "asked"], asked)
    assert np.sum(kind == "turning") == ds.attrs["turning_points"] == 2
    assert np.sum(kind == "continuation") > 0
    assert np.any(np.diff(f) < 0)  # went back between asked points
    assert ds.point_kind.attrs["units"] == "1" and "asked" in ds.point_kind.attrs["long_name"]


# ---- edges ---------------------------------------------------------------------------------


def _finite(ds):
    for name in FINITE:
        assert np.all(np.isfinite(ds[name].values)), name
    asked = ds.point_kind.values == "asked"
    assert np.all(np.isfinite(ds.harmonic_truncation_estimate.values[asked]))
    assert np.isfinite(ds.attrs["max_harmonic_truncation_estimate"])


def _no_contacts():
    M, K = np.diag([1.0, 0.5]), np.array([[1.5e4, -5e3], [-5e3, 5e3]])
    st = ss.Structure(M, 4 * M, K, dof_names=("a", "b"))
    exc = ss.Excitation(force=ss.Signal(("a", "b"), (ss.Harmonic(10.0, [3.0, 20.0], [0.4, 0.0]),)))
    return ss.System(st, (), exc, name="no-contacts")


@pytest.mark.parametrize("condense", ["auto", "contacts", "dofs"])
def test_a_system_without_contacts_is_the_linear_solution(condense):
    system = _no_contacts()
    f = np.linspace(5.0, 30.0, 6)
    ds = _quiet_frf(system, f, harmonics=3, check="none", condense=condense)  # continuation on
    assert ds.frequency.values.tolist() == f.tolist() and np.all(ds.point_kind.values == "asked")
    lim = linear_limits(system, f)
    assert np.allclose(ds.amplitude.values, lim.linear_free_amplitude.values, rtol=1e-12, atol=0)
    assert np.all(ds.status.values == "OK")
    _finite(ds)
    assert np.all(ds.harmonic_truncation_estimate.values == 0.0)


@pytest.mark.parametrize("make", [jenkins_1dof, jenkins_2dof])
def test_all_contacts_stuck_under_a_high_normal_load_is_the_stuck_limit(make):
    system = make(mu=1.0e6)  # slip force mu N: a million times the force
    f = np.linspace(250.0, 550.0, 7)
    ds = _quiet_frf(system, f, harmonics=5, check="none")
    lim = linear_limits(system, f)
    asked = ds.point_kind.values == "asked"
    assert np.allclose(ds.amplitude.values[asked], lim.linear_stuck_amplitude.values, rtol=1e-10, atol=0)
    assert np.all(ds.energy_per_cycle.values <= 1e-12 * ds.excitation_work.values[:, None])
    _finite(ds)


def test_contacts_that_never_close_are_the_free_limit():
    system = gap_oscillator(force=0.2)  # 0.2 N: even the resonance (5e-4 m) stays below the 1 mm gap
    f = np.linspace(8.0, 25.0, 9)
    ds = _quiet_frf(system, f, harmonics=5, check="none")
    lim = linear_limits(system, f)
    asked = ds.point_kind.values == "asked"
    assert np.allclose(ds.amplitude.values[asked], lim.linear_free_amplitude.values, rtol=1e-10, atol=0)
    assert np.all(ds.amplitude.values < 1e-3)
    assert np.all(ds.energy_per_cycle.values == 0.0)
    _finite(ds)


# ---- the gathered balance -----------------------------------------------------------------


@pytest.mark.parametrize("make, f", [(jenkins_2dof, [200.0, 300.0, 420.0]), (wedge, [150.0, 200.0, 260.0])])
def test_the_gathered_balance_equals_the_contact_balance(make, f):
    """The fast path (unknowns: the DOFs the contacts act on) and the path of issue 13
    (unknowns: the contact coordinates) give the same FRF, continuation and estimate included."""
    system = make()
    assert HarmonicBalance(system, 3).gather.mode == "dofs"  # fewer DOFs than contact coordinates
    a = _quiet_frf(system, f, harmonics=5, check="none", condense="dofs")
    b = _quiet_frf(system, f, harmonics=5, check="none", condense="contacts")
    ka, kb = a.point_kind.values == "asked", b.point_kind.values == "asked"
    for name in ("amplitude", "harmonic_amplitude", "energy_per_cycle", "excitation_work"):
        x, y = a[name].values[ka], b[name].values[kb]
        assert np.allclose(x, y, rtol=1e-9, atol=1e-12 * np.abs(y).max()), name
    e_a, e_b = a.harmonic_truncation_estimate.values[ka], b.harmonic_truncation_estimate.values[kb]
    assert np.allclose(e_a, e_b, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("make, f", [(jenkins_2dof, 300.0), (wedge, 200.0)])
def test_gathered_aft_jacobian_is_the_full_one_seen_through_the_gather(make, f):
    hb = HarmonicBalance(make(), 5, 64, condense="dofs")
    pt = hb.solve(2 * np.pi * f)
    assert pt.converged and {1, 2, 3} <= set(np.unique(hb.aft.st))
    L, nc, r = hb.L, hb.basis.n_coef, hb.r
    _, Jfull = hb.aft.evaluate(pt.Z)
    Jq = Jfull.reshape(nc, hb.nq, nc, hb.nq)
    expected = np.einsum("rm,irjs,sn->imjn", L, Jq, L).reshape(nc * r, nc * r)
    Jg = hb.aft.gathered_jacobian(L)
    assert np.abs(Jg - expected).max() <= 1e-12 * np.abs(expected).max()
    # and against finite differences of y -> L^T F(L y + const)
    Y, const = pt.Y, pt.Z - pt.Y @ L.T

    def gathered(y):
        F, _ = hb.aft.evaluate(y.reshape(Y.shape) @ L.T + const, False)
        return (F @ L).ravel()

    eps = 1e-9 * np.abs(Y).max()
    cols = []
    for i in range(Y.size):
        yp, ym = Y.ravel().copy(), Y.ravel().copy()
        yp[i] += eps
        ym[i] -= eps
        cols.append((gathered(yp) - gathered(ym)) / (2 * eps))
    assert np.abs(Jg - np.array(cols).T).max() <= 1e-6 * np.abs(Jg).max()


def test_gathered_tangent_reports_a_full_workspace_and_leaves_it_clean():
    from slipstep.kernels.aft import gathered_tangent

    hb = HarmonicBalance(jenkins_2dof(), 5, 64, condense="dofs")
    pt = hb.solve(2 * np.pi * 300.0)
    Ac, Mc, src = hb.aft._sample_tangents()
    _, contact_of_row, row_start = hb.aft.rows
    n, r = Ac.shape[0], hb.r
    pair_of = np.full((n, n), -1, np.int64)
    small = (np.zeros(3, np.int64), np.zeros(3, np.int64), np.zeros((3, r, r)))
    assert gathered_tangent(Ac, Mc, src, contact_of_row, row_start, hb.L, pair_of, *small) == -1
    assert np.all(pair_of == -1)
    room = (np.zeros(n * n, np.int64), np.zeros(n * n, np.int64), np.zeros((n * n, r, r)))
    count = gathered_tangent(Ac, Mc, src, contact_of_row, row_start, hb.L, pair_of, *room)
    assert count > n and np.all(pair_of == -1)  # the diagonal and the slider-memory pairs
    assert pt.converged
