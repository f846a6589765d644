"""Periodic steady states by marching and by shooting (slipstep.steady), checked against an
independent continuous-time reference (scipy), the frequency-domain linear solution, the
energy balance over a period and finite differences of the one-period map."""

from pathlib import Path

import numpy as np
import pytest
from jenkins_reference import periodic_orbit

import slipstep as ss
from slipstep.errors import InputError
from slipstep.frequency import harmonics, linear_response, retune
from slipstep.post.energy import energy_balance, friction_energy_per_period
from slipstep.steady import march_to_steady, shoot
from slipstep.steady.marching import march_one_period, period_simulation, start
from slipstep.steady.shooting import (
    _from_unknowns,
    _unknowns,
    finite_difference_jacobian,
    moving_sliders,
    period_jacobian,
)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FINE = 2000  # steps per period for comparisons with continuous-time solutions (phase error ~ 1e-6)


def jenkins(mu=1.0, contacts=True):
    system = ss.load_system(EXAMPLES / "jenkins.toml")
    if not contacts:
        return ss.System(system.structure, (), system.excitation, name="free")
    c = system.contacts[0]
    contact = ss.ContactElement(
        c.name, c.dof_gather, c.tangential_stiffness, c.normal_stiffness, mu, normal_offset=c.normal_offset
    )
    return ss.System(system.structure, (contact,), system.excitation, name="jenkins")


def chain(y_force=10.0):
    """The contact chain with a smaller normal force amplitude: no lift-off, N varies."""
    system = ss.load_system(EXAMPLES / "contact_chain.toml")
    h = system.excitation.force.harmonics[0]
    amp = h.amplitude.copy()
    amp[3] = y_force
    force = ss.Signal(system.excitation.force.components, (ss.Harmonic(h.frequency, amp, h.phase),))
    return ss.System(system.structure, system.contacts, ss.Excitation(force=force), name="chain")


def amplitude_energy(steady):
    amp = float(harmonics(steady.period, n_harmonics=1)["amplitude"][0])
    return amp, float(friction_energy_per_period(steady.period).sum())


def test_jenkins_march_shoot_and_independent_reference():
    system = jenkins()
    marched = march_to_steady(system, tolerance=1e-10, max_periods=2000, min_steps_per_period=FINE)
    shot = shoot(system, tolerance=1e-10, min_steps_per_period=FINE)
    assert marched.ok and shot.ok, (marched.message, shot.message)
    a_m, e_m = amplitude_energy(marched)
    a_s, e_s = amplitude_energy(shot)
    assert a_s == pytest.approx(a_m, rel=1e-6) and e_s == pytest.approx(e_m, rel=1e-6)
    s = shot.final_state
    a_ref, e_ref = periodic_orbit(2.5, 100.0, 1e7, 1e7, 50.0, 100.0, 350.0, s.x[0], s.v[0], s.w[0], int(s.states[0]))
    assert a_s == pytest.approx(a_ref, rel=1e-4)
    assert e_s == pytest.approx(e_ref, rel=1e-4)
    assert 40e-6 < a_ref < 60e-6 and e_ref > 0  # macroslip: spring force k_t a >> slip force
    # shooting needs far fewer periods than marching to the same tolerance; the orbit is stable
    assert shot.periods * 5 < marched.periods
    assert marched.floquet_multipliers is None
    assert np.abs(shot.floquet_multipliers).max() < 1.0


@pytest.mark.parametrize("case", ["stuck", "free", "chain-stuck"])
def test_linear_limits_equal_frequency_domain_solution(case):
    system = {
        "stuck": lambda: jenkins(mu=1e6),
        "free": lambda: jenkins(contacts=False),
        "chain-stuck": lambda: _stuck_chain(),
    }[case]()
    previous = None
    for f in (200.0, 275.0, 350.0, 425.0, 500.0):
        s = retune(system, f)
        X, _ = linear_response(s, stuck=bool(s.contacts))
        X = X[f]
        marched = march_to_steady(s, tolerance=1e-7, max_periods=3000, min_steps_per_period=1000, initial=previous)
        shot = shoot(s, tolerance=1e-9, min_steps_per_period=1000, initial=previous)
        previous = marched
        for steady in (marched, shot):
            assert steady.ok, steady.message
            h = harmonics(steady.period, n_harmonics=2)
            c = h["harmonic_amplitude"].values[1] * np.exp(1j * h["harmonic_phase"].values[1])
            # sine convention of the excitation: Im(X e^{iwt}) = |X| cos(wt + arg X - pi/2)
            expected = X * np.exp(-0.5j * np.pi)
            assert np.abs(c - expected).max() <= 1e-4 * np.abs(expected).max(), (case, f, steady.solver)
            assert np.abs(h["harmonic_amplitude"].values[2]).max() <= 1e-6 * np.abs(expected).max()
    assert shot.periods <= 3  # a linear orbit: one Newton step from any start


def _stuck_chain():
    s = chain()
    contacts = tuple(
        ss.ContactElement(
            c.name, c.dof_gather, c.tangential_stiffness, c.normal_stiffness, 1e6, normal_offset=c.normal_offset
        )
        for c in s.contacts
    )
    return ss.System(s.structure, contacts, s.excitation, name="chain-stuck")


@pytest.mark.parametrize("make", [jenkins, chain], ids=["jenkins", "chain"])
def test_energy_balance_over_steady_period(make):
    for f in (300.0, 390.0):
        system = retune(make(), f)
        for steady in (shoot(system, tolerance=1e-11), march_to_steady(system, tolerance=1e-11, max_periods=5000)):
            assert steady.ok, steady.message
            eb = energy_balance(steady.period, system)
            work = float(eb["external_work"][-1])
            dissipated = float(eb["damping_dissipation"][-1] + eb["friction_dissipation"][-1])
            assert float(eb["friction_dissipation"][-1]) > 0.05 * work > 0  # the contacts slip
            assert abs(work - dissipated) <= 1e-6 * work, (f, steady.solver)
            n = steady.period["normal_force"]
            assert float(n.min()) > 0  # no lift-off (a step ending in lift-off breaks the exact balance)
            if make is chain:
                assert float(np.ptp(n.sel(contact="foot").values)) > 1.0  # the normal load varies


@pytest.mark.parametrize(
    "case,method,f",
    [
        ("chain", "piecewise-linear", 280.0),
        ("paper", "quasi-static", 200.0),
        ("paper", "piecewise-linear-adaptive", 200.0),
    ],
)
def test_period_jacobian_matches_finite_differences(case, method, f):
    system = retune(ss.load_system(EXAMPLES / "contact_chain.toml") if case == "chain" else ss.load_system("paper"), f)
    sim = period_simulation(system, method, None, {})
    quasi = sim.method.quasi_static
    n = system.n_dofs
    start(sim, None, 0.0)
    for _ in range(3):  # a few periods from the preload: a state with stick, slip (and lift-off)
        _, _, end, _ = march_one_period(sim)
        start(sim, end, 0.0)
    z = _unknowns(end, quasi)
    start(sim, _from_unknowns(z, n, quasi, end.states), 0.0)
    march_one_period(sim)
    phi = period_jacobian(sim)  # through the recorded steps (kernels/sensitivity.py)
    fd = finite_difference_jacobian(sim)  # central differences of the marched period map
    col = np.abs(fd).max(axis=0) + np.abs(phi).max(axis=0) + 1e-300
    assert np.abs(phi - fd).max(axis=0).max() / 1 <= 1e-5 * col.max()
    assert (np.abs(phi - fd).max(axis=0) <= 1e-5 * col).all()


def test_period_jacobian_over_the_moving_sliders_is_the_full_one_restricted():
    """Shooting's Jacobian over (x, v, the sliders that leave stick) equals the one over every
    slider restricted to those rows and columns: a slider stuck over the period keeps its w."""
    system = retune(ss.load_system(EXAMPLES / "contact_chain.toml"), 280.0)
    sim = period_simulation(system, "piecewise-linear", None, {})
    start(sim, None, 0.0)
    for _ in range(3):
        _, _, end, _ = march_one_period(sim)
        start(sim, end, 0.0)
    march_one_period(sim)
    n2 = 2 * system.n_dofs
    moving = moving_sliders(sim)
    nd = len(system.direction_names())
    assert 0 < moving.size <= nd
    full = period_jacobian(sim)
    part = period_jacobian(sim, moving)
    keep = np.r_[0:n2, n2 + moving]
    np.testing.assert_allclose(part, full[np.ix_(keep, keep)], rtol=0, atol=1e-12 * np.abs(full).max())


def test_floquet_multipliers_of_a_linear_orbit():
    """A stuck Jenkins oscillator is linear: multipliers exp(lambda T) of m s^2 + c s + k_tot,
    |mu| = exp(-c T / 2m); its slider never moves (one neutral direction)."""
    system = retune(jenkins(mu=1e6), 300.0)
    shot = shoot(system, tolerance=1e-10, min_steps_per_period=FINE)
    assert shot.neutral_directions == 1
    mu = shot.floquet_multipliers
    assert mu.size == 2
    T = 1 / 300.0
    assert np.abs(mu) == pytest.approx([np.exp(-100.0 * T / 5.0)] * 2, rel=1e-5)
    wd = np.sqrt(2e7 / 2.5 - (100 / 5.0) ** 2)
    assert abs(np.angle(mu[0])) == pytest.approx(abs(np.angle(np.exp(1j * wd * T))), rel=1e-4)


def test_marching_reports_its_cap_and_continues():
    system = jenkins()
    capped = march_to_steady(system, tolerance=1e-9, max_periods=3)
    assert capped.status == "NOT_STEADY" and capped.periods == 3 and capped.change > 1e-9
    steady = march_to_steady(system, tolerance=1e-9, max_periods=2000)
    again = march_to_steady(system, tolerance=1e-9, initial=steady)
    assert again.ok and again.periods == 1  # continued from a steady state: steady at once
    assert float(again.period.time[0]) == 0.0


def test_start_from_continues_a_march_exactly():
    system = chain()
    whole = ss.Simulation(system, "piecewise-linear", periods=2.0).run()
    sim = ss.Simulation(system, "piecewise-linear", periods=1.0)
    sim.march()
    ws = sim.ws
    sim.start_from(ws.x.copy(), ws.v.copy(), ws.a.copy(), ws.w.copy(), ws.state.copy(), t_start=system.period)
    second = sim.run()
    assert float(second.time[0]) == pytest.approx(system.period)
    assert np.allclose(second.displacement[-1], whole.displacement[-1], rtol=0, atol=1e-12 * 1e-3)
    assert np.allclose(second.slider[-1], whole.slider[-1], rtol=0, atol=1e-15)


def test_bad_input_names_the_field():
    system = jenkins()
    with pytest.raises(InputError, match="scheme"):
        shoot(system, scheme=ss.hht(0.1))
    with pytest.raises(InputError, match="periods"):
        march_to_steady(system, periods=3)
    with pytest.raises(InputError, match="tolerance"):
        march_to_steady(system, tolerance=2.0)
    with pytest.raises(InputError, match="min_steps_per_period"):
        march_to_steady(system, min_steps_per_period=1)
    with pytest.raises(InputError, match="initial"):
        march_to_steady(system, initial=[1.0])


def test_shooting_a_friction_circle_orbit_has_the_multiplier_marching_sees():
    """A friction-circle contact slipping in coupled slip most of the period: its Phi depends on
    the slip directions, so it is built by central differences of the period map. Shooting then
    converges in a few Newton iterations to the marched orbit, and its largest multiplier is
    the rate at which the marched periods approach that orbit."""
    n = 7
    K = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    A = np.zeros((3, n))
    A[0, 2] = A[1, 3] = A[2, 4] = 1.0
    contact = ss.ContactElement("C", A, 1e6, 1e6, 0.3, normal_offset=1e-5, law="3d-circle")
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(30.0, [0, 20.0, 0, -15.0, 0, 8.0, 0]),))
    structure = ss.Structure(np.eye(n) * 0.2, damping=3e-5 * K, stiffness=K)
    system = ss.System(structure, (contact,), ss.Excitation(force=force), name="ring")
    marched = march_to_steady(system, method="piecewise-linear", tolerance=1e-12, max_periods=3000)
    shot = shoot(system, method="piecewise-linear", tolerance=1e-10)
    assert marched.ok and shot.ok
    assert (shot.period.contact_state.values == 4).mean() > 0.5  # mostly coupled slip
    assert shot.newton_iterations <= 4  # (with the state-only Phi: 10 iterations, 16 periods)
    x_s, x_m = shot.period.displacement.values, marched.period.displacement.values
    assert np.abs(x_s - x_m).max() <= 1e-9 * np.abs(x_m).max()
    e = np.array(marched.changes)
    window = np.flatnonzero((e < 1e-3) & (e > 1e-10))
    rate = (e[window[-1]] / e[window[0]]) ** (1.0 / (window[-1] - window[0]))
    rho = np.abs(shot.floquet_multipliers).max()
    assert rho == pytest.approx(rate, rel=0.1), (rho, rate)  # (state-only Phi: 0.36 against 0.48)
