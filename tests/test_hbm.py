"""Harmonic balance on the same System as the time marching (issue 13).

- linear limits: no contacts, and every contact stuck (mu very large), equal the
  frequency-domain linear solution computed here independently;
- single-DOF and 2-DOF Jenkins oscillators: with enough harmonics the HBM amplitude and
  friction energy per cycle agree with the marched periodic steady state to 1e-4 (the
  automatic cross-check of slipstep.hbm.frf); energy balance W = D_v + sum E_c per point;
- harmonic adequacy: the warning fires at H = 1 wherever the error exceeds 1 %, and the
  estimate is small where the harmonics suffice;
- continuation: through the Jenkins resonance peak, around the two turning points of a
  stiffening (gap) oscillator, and over the excitation level (stuck at low levels);
- the Dataset layout (slipstep.output.frf_schema.FRF_SCHEMA) and bad input.
"""

import json
import warnings

import numpy as np
import pytest
from hbm_cases import gap_oscillator, jenkins_1dof, jenkins_2dof

import slipstep as ss
from slipstep.output.frf_schema import FRF_SCHEMA
from slipstep.hbm import frf, level_response
from slipstep.hbm.adequacy import HarmonicAdequacyWarning


def _linear(M, C, K, F, f):
    w = 2 * np.pi * f
    return np.abs(np.linalg.solve(K - w**2 * M + 1j * w * C, F))


def test_no_contact_equals_the_frequency_domain_solution():
    M, K = np.diag([1.0, 0.5]), np.array([[1.5e4, -5e3], [-5e3, 5e3]])
    C = 4 * M
    st = ss.Structure(M, C, K, dof_names=("a", "b"))
    system = ss.System(
        st, (), ss.Excitation(force=ss.Signal(("a", "b"), (ss.Harmonic(10.0, [3.0, 20.0], [0.4, 0.0]),)))
    )
    f = np.array([5.0, 10.0, 17.0, 30.0])
    ds = frf(system, f, harmonics=3, continuation=False, check="none")
    F = np.array([3.0, 20.0]) * np.exp(1j * np.array([0.4, 0.0]))
    exact = np.array([_linear(M, C, K, F, fi) for fi in f])
    assert np.allclose(ds.amplitude.values, exact, rtol=1e-9, atol=0)
    assert np.allclose(ds.linear_free_amplitude.values, exact, rtol=1e-9, atol=0)
    assert np.all(ds.status.values == "OK")


def test_open_gap_and_multi_harmonic_forcing_equal_the_linear_solution():
    """A contact that never closes (the gap oscillator at a small force) is the free linear
    structure; a force with harmonics 1 and 3 gives each harmonic its own linear response."""
    system = gap_oscillator(force=0.5)
    sig = ss.Signal(("x",), (ss.Harmonic(10.0, [0.5]), ss.Harmonic(30.0, [0.2], [0.3])))
    system = ss.System(system.structure, system.contacts, ss.Excitation(force=sig))
    f = np.array([8.0, 12.0, 25.0])
    ds = frf(system, f, harmonics=3, continuation=False, check="none")
    st = system.structure
    for j, (m, a, ph) in enumerate(((1, 0.5, 0.0), (3, 0.2, 0.3))):
        exact = np.array(
            [_linear(st.mass, st.damping, st.stiffness, np.array([a * np.exp(1j * ph)]), m * fi)[0] for fi in f]
        )
        assert np.allclose(ds.harmonic_amplitude.values[:, m, 0], exact, rtol=1e-10)
    assert np.all(ds.harmonic_amplitude.values[:, 2, 0] < 1e-12 * ds.amplitude.values[:, 0])
    assert np.allclose(ds.amplitude.values, ds.linear_free_amplitude.values, rtol=1e-9)
    assert np.all(ds.amplitude.values[:, 0] < 1e-3)  # below the gap: the contact never closed


@pytest.mark.parametrize(
    "make, f", [(jenkins_1dof, [300.0, 350.0, 450.0, 600.0]), (jenkins_2dof, [200.0, 300.0, 500.0])]
)
def test_stuck_contacts_equal_the_frequency_domain_solution(make, f):
    system = make(mu=1.0e6)
    ds = frf(system, f, harmonics=5, continuation=False, check="none")
    st = system.structure
    Kst = st.stiffness + sum(
        np.outer(c.dof_gather[0], c.dof_gather[0]) * c.tangential_stiffness[0] for c in system.contacts
    )
    F = system.excitation.force.harmonics[0].amplitude
    exact = np.array([_linear(st.mass, st.damping, Kst, F, fi) for fi in f])
    assert np.allclose(ds.amplitude.values, exact, rtol=1e-9, atol=0)
    assert np.allclose(ds.linear_stuck_amplitude.values, exact, rtol=1e-9, atol=0)
    assert np.all(ds.energy_per_cycle.values <= 1e-12 * ds.excitation_work.values[:, None])


@pytest.mark.parametrize("make, f, H, samples", [(jenkins_1dof, 350.0, 45, 1024), (jenkins_2dof, 300.0, 31, 512)])
def test_hbm_agrees_with_the_marched_steady_state(make, f, H, samples):
    """The issue's check: with H large enough, amplitude and loop energy agree with marching to
    1e-4 (the marched reference: Method 3 with 2000 steps per period, itself converged to about 1e-5)."""
    system = make()
    ds = frf(
        system,
        [f],
        harmonics=H,
        samples=samples,
        check="peak",
        check_options={"tolerance": 1e-5, "max_periods": 400, "steps_per_period": 2000},
    )
    assert ds.status.values[0] == "OK"
    assert ds.check_amplitude_rel_diff.values[0] <= 1e-4
    assert ds.check_energy_rel_diff.values[0] <= 1e-4
    summary = json.loads(ds.attrs["check_summary"])
    assert summary[0]["march_status"] == "OK" and summary[0]["march_energy_J"] > 0
    # energy balance of the harmonic balance itself
    W, Dv, E = ds.excitation_work.values, ds.viscous_dissipation.values, ds.energy_per_cycle.values.sum(axis=1)
    assert np.allclose(W, Dv + E, rtol=1e-8)


def test_adequacy_warning_fires_at_h1_where_the_error_exceeds_one_percent():
    system = jenkins_1dof()
    f = np.array([150.0, 200.0, 250.0, 300.0, 350.0, 500.0])
    with pytest.warns(HarmonicAdequacyWarning, match="more harmonics"):
        h1 = frf(system, f, harmonics=1, continuation=False, check="none")
    ref = frf(system, f, harmonics=31, samples=512, continuation=False, check="none", adequacy=False)
    a_err = np.abs(h1.amplitude.values[:, 0] / ref.amplitude.values[:, 0] - 1)
    e_err = np.abs(h1.energy_per_cycle.values[:, 0] / ref.energy_per_cycle.values[:, 0] - 1)
    err = np.maximum(a_err, e_err)
    est = h1.harmonic_truncation_estimate.values
    assert np.any(err > 0.01)
    assert np.all(est[err > 0.01] > 0.01)  # fires wherever the error exceeds 1 %
    assert np.all(est > 0.3 * np.minimum(err, 1.0))  # never far below the error
    with warnings.catch_warnings():
        warnings.simplefilter("error", HarmonicAdequacyWarning)
        h15 = frf(system, f, harmonics=15, samples=256, continuation=False, check="none")
    assert np.all(h15.harmonic_truncation_estimate.values < 1e-3)
    assert np.all(np.abs(h15.amplitude.values[:, 0] / ref.amplitude.values[:, 0] - 1) < 1e-3)


def test_auto_harmonics_raises_h_until_adequate():
    with warnings.catch_warnings():
        warnings.simplefilter("error", HarmonicAdequacyWarning)
        ds = frf(jenkins_1dof(), [200.0, 300.0], harmonics=1, continuation=False, check="none", auto_harmonics=True)
    assert max(ds.attrs["harmonics"]) > 1
    assert np.all(ds.harmonic_truncation_estimate.values <= 0.01)


def test_continuation_passes_the_resonance_peak():
    system = jenkins_1dof()
    grid = np.linspace(150.0, 600.0, 31)
    ds = frf(system, grid, harmonics=7, check="none", adequacy=False)
    f, amp = ds.frequency.values, ds.amplitude.values[:, 0]
    assert ds.attrs["continuation_status"] == "OK"
    assert (
        f[0] == pytest.approx(150.0, rel=1e-14)
        and f[-1] == pytest.approx(600.0, rel=1e-14)
        and np.all(ds.status.values == "OK")
    )
    assert np.all(np.diff(f) > 0)  # a single-valued curve here
    assert np.max(np.diff(f)) <= 1.5 * (grid[1] - grid[0])  # steps of about the grid spacing at most
    i = int(np.argmax(amp))
    assert 0 < i < f.size - 1 and 300 < f[i] < 340  # peak between the free (318 Hz) and stuck (450 Hz) modes
    # the points are solutions: the same amplitudes by Newton at fixed frequency
    seq = frf(system, f[[0, i, -1]], harmonics=7, continuation=False, check="none", adequacy=False)
    assert np.allclose(seq.amplitude.values[:, 0], amp[[0, i, -1]], rtol=1e-8)
    W, Dv, E = ds.excitation_work.values, ds.viscous_dissipation.values, ds.energy_per_cycle.values.sum(axis=1)
    assert np.allclose(W, Dv + E, rtol=1e-8)


def test_continuation_follows_turning_points():
    ds = frf(gap_oscillator(), np.linspace(10.0, 30.0, 21), harmonics=9, check="none")
    f = ds.frequency.values
    assert ds.attrs["continuation_status"] == "OK" and f[-1] == pytest.approx(30.0, rel=1e-14)
    assert ds.attrs["turning_points"] == 2
    assert np.any(np.diff(f) < 0)  # it went back over the unstable branch
    # three coexisting solutions at one frequency in the fold
    f_mid = 0.5 * (f[np.argmax(ds.amplitude.values[:, 0])] + f[np.diff(f, prepend=f[0]) < 0].min())
    crossings = np.sum(np.diff(np.sign(f - f_mid)) != 0)
    assert crossings == 3
    # H = 9 is adequate at the asked points (the continuation's own points include one just past
    # the fold, where the estimate measures the distance between the branches: about 1 %)
    asked = ds.point_kind.values == "asked"
    assert np.all(ds.harmonic_truncation_estimate.values[asked] < 0.01)


def test_level_continuation_is_stuck_then_slips():
    system = jenkins_1dof()
    ds = level_response(system, 350.0, [0.05, 2.0], harmonics=7, check="none", adequacy=False)
    lv, amp = ds.excitation_level.values, ds.amplitude.values[:, 0]
    assert ds.attrs["continuation_status"] == "OK" and lv[0] == 0.05 and lv[-1] == pytest.approx(2.0, rel=1e-14)
    assert np.all(np.diff(lv) > 0) and np.all(np.diff(amp) > 0)
    # stuck at low levels: proportional to the level, equal to the stuck linear limit
    stuck = ds.energy_per_cycle.values[:, 0] <= 1e-12 * ds.excitation_work.values
    assert stuck[0] and not stuck[-1]
    assert np.allclose(amp[stuck], ds.linear_stuck_amplitude.values[stuck, 0], rtol=1e-9)
    assert np.allclose(ds.frequency.values, 350.0, rtol=1e-14)


def test_dataset_layout_is_the_frf_schema():
    ds = frf(jenkins_2dof(), [250.0, 300.0], harmonics=(1, 3, 5), continuation=False, check="none")
    assert set(ds.data_vars) == set(FRF_SCHEMA)
    for name, (dims, units, _) in FRF_SCHEMA.items():
        assert ds[name].dims == dims and ds[name].attrs["units"] == units
    assert ds.attrs["solver"] == "hbm" and ds.attrs["harmonics"] == [0, 1, 3, 5]
    assert list(ds.response.values) == ["x1", "x2"] and list(ds.contact.values) == ["J1", "J2"]
    h = ds.harmonic_amplitude.values
    assert np.all(np.isnan(h[:, [2, 4]])) and np.all(np.isfinite(h[:, [0, 1, 3, 5]]))
    # x = sum_h A_h cos(h Omega t + phi_h): the amplitude is bounded by the sum of the harmonics
    assert np.all(ds.amplitude.values <= np.nansum(h[:, 1:], axis=1) * (1 + 1e-12))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"frequencies": [-1.0]}, "frequencies"),
        ({"frequencies": [300.0], "responses": ["nope"]}, "responses"),
        ({"frequencies": [300.0], "harmonics": 0}, "harmonics"),
        ({"frequencies": [300.0], "harmonics": 15, "samples": 16}, "samples"),
        ({"frequencies": [300.0], "check": "sometimes"}, "check"),
    ],
)
def test_bad_input_names_the_field(kwargs, field):
    with pytest.raises(ss.InputError) as err:
        frf(jenkins_1dof(), **kwargs)
    assert err.value.field == field


def test_tabulated_excitation_is_rejected():
    system = jenkins_1dof()
    table = ss.Signal(("x",), (), (ss.Tabulated(np.array([0.0, 1.0]), np.array([0.0, 1.0])),))
    bad = ss.System(system.structure, system.contacts, ss.Excitation(force=table, period=0.01))
    with pytest.raises(ss.InputError) as err:
        frf(bad, [100.0], check="none")
    assert err.value.field == "force_table"


def test_paper_case_dissipated_energy():
    """The rigid damper held only by its contacts (K = 0: the h = 0 balance needs the contact
    stiffness on both sides) under the paper's platform motion: the energy per period of
    physics.md section 6 (left 2.52 mJ = contacts 1 + 2, right 2.70 mJ), to 1 %."""
    ds = frf(ss.load_system("paper"), [200.0], harmonics=7, continuation=False, check="none", adequacy=False)
    e = ds.energy_per_cycle.values[0]
    assert ds.status.values[0] == "OK"
    assert e[0] + e[1] == pytest.approx(2.52e-3, rel=0.01)
    assert e[2] == pytest.approx(2.70e-3, rel=0.01)
    W, Dv = ds.excitation_work.values[0], ds.viscous_dissipation.values[0]
    assert W == pytest.approx(Dv + e.sum(), rel=1e-6)  # the motions' work goes into friction


def test_blades_continuation_passes_the_peak():
    system = ss.load_system("blades")
    ds = frf(system, np.linspace(300.0, 420.0, 13), harmonics=3, check="none", adequacy=False, responses=["blade1.8.x"])
    f, amp = ds.frequency.values, ds.amplitude.values[:, 0]
    assert ds.attrs["continuation_status"] == "OK" and np.all(ds.status.values == "OK")
    assert f[-1] == pytest.approx(420.0, rel=1e-14)
    i = int(np.argmax(amp))
    assert 0 < i < f.size - 1  # an interior peak, between the free (253 Hz) and stuck (366 Hz) modes
    assert amp[i] < ds.linear_stuck_amplitude.values[:, 0].max()
    assert np.all(ds.energy_per_cycle.values[i] > 0)


def test_a_friction_circle_contact_is_refused_with_the_time_domain_fix():
    """The AFT Jacobian is built from the law's piecewise-linear form, which the friction
    circle's coupled slip does not have: an InputError naming the contacts and the fix."""
    n = 3
    A = np.zeros((3, n))
    A[0, 0] = A[1, 1] = A[2, 2] = 1.0
    circle = ss.ContactElement("C", A, 1e6, 1e6, 0.3, normal_offset=1e-5, law="3d-circle")
    force = ss.Signal(("x0", "x1", "x2"), (ss.Harmonic(30.0, [10.0, 5.0, 0.0]),))
    system = ss.System(ss.Structure(np.eye(n), stiffness=1e5 * np.eye(n)), (circle,), ss.Excitation(force=force))
    with pytest.raises(ss.InputError) as err:
        frf(system, [30.0], harmonics=3)
    assert err.value.field == "contacts"
    assert "['C']" in str(err.value) and "solver 'shoot'" in str(err.value)
