"""The exact event-driven dynamic method ``events`` (methods/exact_events.py,
kernels/exact_events.py) against closed forms, an independent event-located integration,
the energy balance and the contact law's bounds; the cases it refuses."""

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.integrate import solve_ivp

import slipstep as ss
from slipstep.errors import InputError
from slipstep.kernels.codes import LIFT, SLIP_NEG, SLIP_POS, STICK
from slipstep.methods.exact_events import ExactEventRun, energy_balance

ROOT = Path(__file__).resolve().parents[1]
JENKINS = ROOT / "examples" / "jenkins.toml"
M, C, K, KT, FS, F = 2.5, 100.0, 1e7, 1e7, 50.0, 100.0  # the Jenkins oscillator of issue 24


def exact_run(system, **options):
    run = ExactEventRun(system, **options)
    run.march()
    return run, run.dataset()


# -- (a) a linear system against the matrix exponential of the augmented first-order form ----
def two_dof(contacts=()):
    structure = ss.Structure(
        np.diag([1.0, 2.0]), [[3.0, -1.0], [-1.0, 2.0]], [[2e4, -1e4], [-1e4, 1e4]], dof_names=("a", "b")
    )
    force = ss.Signal(("a", "b"), (ss.Harmonic(30.0, [0.0, 5.0], [0.0, 0.3]),))
    excitation = ss.Excitation(constant_force=[1.0, -2.0], force=force)
    return ss.System(structure, tuple(contacts), excitation, name="two_dof")


def augmented_reference(system, t, x0):
    """x(t), v(t) of M x'' + C x' + K x = f_c + F sin(W t + phi) from (x0, 0): the exponential of
    the autonomous augmented system (x, v, 1, sin W t, cos W t) (Van Loan), independent of the
    modal form of the method."""
    cs = system.compile()
    n = cs.M.shape[0]
    Mi = np.linalg.inv(cs.M)
    om = 2 * np.pi * cs.force_frequency[0]
    G = np.zeros((2 * n + 3, 2 * n + 3))
    G[:n, n : 2 * n] = np.eye(n)
    G[n : 2 * n, :n], G[n : 2 * n, n : 2 * n] = -Mi @ cs.K, -Mi @ cs.C
    G[n : 2 * n, 2 * n] = Mi @ cs.constant_force
    G[n : 2 * n, 2 * n + 1], G[n : 2 * n, 2 * n + 2] = Mi @ cs.force_sin[:, 0], Mi @ cs.force_cos[:, 0]
    G[2 * n + 1, 2 * n + 2], G[2 * n + 2, 2 * n + 1] = om, -om
    z0 = np.concatenate([x0, np.zeros(n), [1.0, 0.0, 1.0]])
    z = np.array([sla.expm(G * tk) @ z0 for tk in t])
    return z[:, :n], z[:, n : 2 * n]


@pytest.mark.parametrize("contacts", ["none", "open"])
def test_linear_system_against_the_closed_form(contacts):
    """No contact, or a contact whose gap never closes: the linear solution to 1e-10."""
    open_contact = ss.ContactElement("gap", [[1.0, 0.0], [0.0, 1.0]], 1e5, 1e5, 0.3, normal_offset=-1.0)
    system = two_dof(() if contacts == "none" else (open_contact,))
    run, ds = exact_run(system, periods=4)
    assert ds.attrs["status"] == "OK" and ds.attrs["events"] == 0
    x0 = np.linalg.solve(system.compile().K, system.compile().constant_force)
    t = ds.time.values[::7]
    x_ref, v_ref = augmented_reference(system, t, x0)
    x, v = ds.displacement.values[::7], ds.velocity.values[::7]
    assert np.abs(x - x_ref).max() <= 1e-10 * np.abs(x_ref).max()
    assert np.abs(v - v_ref).max() <= 1e-10 * np.abs(v_ref).max()
    if contacts == "open":
        assert np.all(ds.contact_state.values == LIFT) and np.all(ds.normal_force.values == 0.0)


# -- (b) the Jenkins oscillator against an independent event-located integration --------------
def jenkins_ivp(omega, t_out, rtol=1e-12):
    """x, v at t_out and the event times of m x'' + c x' + k x + T = F sin(omega t) from rest,
    stick/slip by solve_ivp (DOP853) with terminal events (stick: |k_t (x - w)| reaches Fs;
    slip: x' changes sign, then stick with the slider where the slip left it)."""
    t, x, v, w, mode = 0.0, 0.0, 0.0, 0.0, 0
    out, events = np.full((t_out.size, 2), np.nan), []
    while t < t_out[-1]:
        if mode == 0:

            def rhs(tt, y, w=w):
                return [y[1], (F * np.sin(omega * tt) - C * y[1] - K * y[0] - KT * (y[0] - w)) / M]

            def up(tt, y, w=w):
                return KT * (y[0] - w) - FS

            def down(tt, y, w=w):
                return KT * (y[0] - w) + FS

            up.terminal = down.terminal = True
            up.direction, down.direction = 1, -1
            found = [up, down]
        else:

            def rhs(tt, y, s=mode):
                return [y[1], (F * np.sin(omega * tt) - C * y[1] - K * y[0] - s * FS) / M]

            def stop(tt, y):
                return y[1]

            stop.terminal, stop.direction = True, -mode
            found = [stop]
        sol = solve_ivp(rhs, (t, t_out[-1]), [x, v], "DOP853", rtol=rtol, atol=1e-22, events=found, dense_output=True)
        inside = (t_out >= t) & (t_out <= sol.t[-1])
        out[inside] = sol.sol(t_out[inside]).T
        t, x, v = sol.t[-1], sol.y[0, -1], sol.y[1, -1]
        hit = [i for i, te in enumerate(sol.t_events) if te.size]
        if not hit:
            break
        events.append(t)
        if mode == 0:
            mode = 1 if hit[0] == 0 else -1
        else:
            w, mode = x - mode * FS / KT, 0
    return out, np.array(events)


@pytest.mark.parametrize("frequency", [300.0, 350.0])
def test_jenkins_against_an_independent_event_located_integration(frequency):
    from slipstep.frequency import retune

    system = retune(ss.load_system(JENKINS), frequency)
    run, ds = exact_run(system, periods=12)
    ref, events = jenkins_ivp(2 * np.pi * frequency, ds.time.values)
    assert ds.attrs["status"] == "OK" and ds.attrs["events"] == events.size >= 20
    x, v = ds.displacement.values[:, 0], ds.velocity.values[:, 0]
    assert np.abs(x - ref[:, 0]).max() <= 1e-9 * np.abs(ref[:, 0]).max()
    assert np.abs(v - ref[:, 1]).max() <= 1e-9 * np.abs(ref[:, 1]).max()
    assert np.abs(np.array(run.trajectory.event_times) - events).max() <= 1e-9 / frequency


# -- (c) energy balance, (d) the law's bounds on every output row ------------------------------
def lifting_pair():
    """A 2-DOF body on a 2D contact whose normal load swings through zero: lift-off, re-contact,
    stick and slip in both directions."""
    structure = ss.Structure(
        np.diag([0.5, 0.5]), 0.002 * np.diag([2e6, 3e6]), np.diag([2e6, 3e6]), dof_names=("u", "v")
    )
    contact = ss.ContactElement("pad", [[1.0, 0.0], [0.0, -1.0]], 3e6, 4e6, 0.5)
    force = ss.Signal(("u", "v"), (ss.Harmonic(120.0, [40.0, 60.0], [0.0, 1.0]),))
    return ss.System(structure, (contact,), ss.Excitation(constant_force=[0.0, -30.0], force=force), name="lifting")


@pytest.mark.parametrize("case", ["jenkins", "paper", "lifting"])
def test_energy_balance_and_the_law_hold(case):
    system = {"jenkins": lambda: ss.load_system(JENKINS), "paper": lambda: ss.load_system("paper")}.get(
        case, lifting_pair
    )()
    run, ds = exact_run(system, periods=3)
    assert ds.attrs["status"] == "OK" and ds.attrs["events"] >= 6
    balance = energy_balance(run.trajectory)
    assert balance["friction_dissipation"] > 0
    assert abs(balance["residual"]) <= 1e-11 * abs(balance["input_work"])
    N, T = ds.normal_force.values, ds.tangential_force.values
    mu_n = (ds.friction_coefficient.values * N)[
        :, [list(ds.contact.values).index(c) for c in ds.direction_contact.values]
    ]
    assert N.min() >= 0.0
    assert np.all(np.abs(T) <= mu_n * (1 + 1e-12) + 1e-12 * np.abs(T).max())
    if case == "lifting":
        states = set(np.unique(ds.contact_state.values))
        assert {LIFT, STICK, SLIP_POS, SLIP_NEG} <= states


# -- the result schema, the cap, the refusals -----------------------------------------------
def test_result_schema_and_the_event_cap():
    from slipstep.output.results import schema_problem

    ds = ss.run(ss.load_system(JENKINS), "events", periods=2, save={"times": np.linspace(0.0, 2 / 350.0, 41)})
    assert schema_problem(ds) == "" and ds.sizes["time"] == 41
    assert ds.attrs["method"] == "events" and ds.attrs["events"] > 0
    with pytest.raises(InputError, match="no Simulation"):  # no marcher: compare, march_to_steady refuse it
        ss.Simulation(ss.load_system(JENKINS), "events", periods=2)
    capped = ss.run(ss.load_system(JENKINS), "events", periods=2, max_events=3)
    assert capped.attrs["status"] == "EVENT_CAP"
    assert "jenkins" in capped.attrs["status_message"] and "t = " in capped.attrs["status_message"]
    assert capped.time.values[-1] < 2 / 350.0


def test_refused_cases_name_the_reason():
    paper = ss.load_system("paper")
    system, _ = ss.load_case(ROOT / "examples" / "shroud_pair.toml")
    contact = dataclasses.replace(system.contacts[0], law="3d-circle", tangential_stiffness=1.5e7)
    with pytest.raises(InputError, match="3d-circle") as err:
        ss.run(dataclasses.replace(system, contacts=(contact,)), "events")
    assert err.value.field == "method"
    motion = paper.excitation.motion
    ramped = dataclasses.replace(paper.excitation, motion=dataclasses.replace(motion, ramp_time=1e-3))
    with pytest.raises(InputError) as err:
        ss.run(dataclasses.replace(paper, excitation=ramped), "events")
    assert err.value.field == "ramp_time"
    table = ss.Tabulated([0.0, 1e-3, 2e-3], [[0.0] * 4, [0.0, 0.0, 1e-6, 0.0], [0.0] * 4])
    tabled = dataclasses.replace(paper.excitation, motion=dataclasses.replace(motion, tables=(table,)))
    with pytest.raises(InputError, match="tables"):
        ss.run(dataclasses.replace(paper, excitation=tabled), "events")


# -- convergence of Methods 1 and 3 towards the exact solution --------------------------------
@pytest.mark.parametrize(
    "case, periods, steps", [("jenkins", 3, (800, 1600)), ("paper", 1, (6400, 12800))], ids=["jenkins", "paper"]
)
def test_methods_1_and_3_converge_at_second_order(case, periods, steps):
    """The largest displacement error over the run, relative to the largest displacement, falls
    by 4 when the fixed step halves (measured: 2.0 on both cases; docs/exact_events.md)."""
    system = ss.load_system(JENKINS if case == "jenkins" else "paper")
    run, _ = exact_run(system, periods=periods)
    period = run.plan.period
    for method in ("newmark", "piecewise-linear"):
        errors = []
        for n in steps:
            with warnings.catch_warnings():  # Method 1's balance-residual notes at these steps (issue 29)
                warnings.simplefilter("ignore", RuntimeWarning)
                ds = ss.run(system, method, periods=periods, dt=period / n, error_estimate=False)
            ref = run.trajectory.evaluate(ds.time.values)["x"]
            errors.append(np.abs(ds.displacement.values - ref).max() / np.abs(ref).max())
        order = np.log2(errors[0] / errors[1])
        assert 1.8 <= order <= 2.3, (method, errors)


# -- steady state: shooting on the exact period map ------------------------------------------
@pytest.mark.parametrize("frequency", [300.0, 350.0, 450.0])
def test_exact_steady_state_against_the_independent_reference(frequency):
    """The Jenkins oscillator's periodic orbit by Newton on the exact period map, against the
    reference of tests/jenkins_reference.py (DOP853 with event-located stick/slip, fsolve on its
    own period map, started from this orbit): energies per cycle to 1e-9."""
    from jenkins_reference import periodic_orbit_energies

    from slipstep.steady.exact_orbit import periodic_orbit

    orbit = periodic_orbit(ss.load_system(JENKINS), frequency)
    assert orbit.converged and orbit.residual <= 1e-12
    assert np.all(np.abs(orbit.multipliers) < 1.0)
    mode = int(orbit.trajectory.phases[0].sm.state[0])
    ref = periodic_orbit_energies(M, C, K, KT, FS, F, frequency, orbit.x0[0], orbit.v0[0], orbit.w0[0], mode)
    assert orbit.friction_energy == pytest.approx(ref["friction_energy"], rel=1e-9)
    assert orbit.excitation_work == pytest.approx(ref["excitation_work"], rel=1e-9)
    assert orbit.amplitude[0] == pytest.approx(ref["amplitude"], rel=1e-6)  # both sampled


# -- states without a modal form: the augmented exponential (Van Loan) ------------------------
def free_body():
    """A 2-DOF body without structural stiffness or damping on a 2D contact with friction: in
    slip its tangential motion, in lift-off all of it, is a free rigid mode (K_S singular)."""
    structure = ss.Structure(np.diag([0.1, 0.1]), dof_names=("x", "y"))
    contact = ss.ContactElement("floor", [[1.0, 0.0], [0.0, -1.0]], 2e6, 3e6, 0.4)
    force = ss.Signal(("x", "y"), (ss.Harmonic(50.0, [8.0, 30.0], [0.0, 0.7]),))
    return ss.System(structure, (contact,), ss.Excitation(constant_force=[0.0, -10.0], force=force), name="free")


def test_free_flight_against_the_closed_form():
    """Flights (lift-off: a free body, K_S = 0) are marched by the augmented exponential; the
    flight is x'' = f_e(t) / m in closed form from the lift-off state; the energy balance closes."""
    run, ds = exact_run(free_body(), periods=3)
    traj = run.trajectory
    assert ds.attrs["status"] == "OK" and ds.attrs["events"] >= 3
    flights = [p for p in traj.phases if np.all(p.sm.state == LIFT) and p.t1 < traj.t_end]
    assert flights and not flights[0].sm.modal
    m, c = 0.1, np.array([0.0, -10.0])
    amp, phase, om = np.array([8.0, 30.0]), np.array([0.0, 0.7]), 2 * np.pi * 50.0
    for p in flights:
        x0, v0, _ = (r[0] for r in p.dofs(run.model, [p.t0]))
        t = np.linspace(p.t0, p.t1, 7)
        tau = (t - p.t0)[:, None]
        s0, c0 = np.sin(om * p.t0 + phase), np.cos(om * p.t0 + phase)
        s1, c1 = np.sin(om * t[:, None] + phase), np.cos(om * t[:, None] + phase)
        v_ref = v0 + (c * tau - amp / om * (c1 - c0)) / m
        x_ref = x0 + v0 * tau + (c * tau**2 / 2 - amp / om * ((s1 - s0) / om - tau * c0)) / m
        x, v, _ = p.dofs(run.model, t)
        assert np.abs(x - x_ref).max() <= 1e-10 * np.abs(x_ref).max()
        assert np.abs(v - v_ref).max() <= 1e-10 * np.abs(v_ref).max()
    balance = energy_balance(traj)
    assert abs(balance["residual"]) <= 1e-11 * abs(balance["input_work"])
    assert ds.normal_force.values.min() >= 0.0


def test_reference_frf_is_frf_with_method_events():
    """frf(..., solver="shoot", method="events"): the FRF layout, every point the exact orbit."""
    from jenkins_reference import periodic_orbit_energies

    from slipstep.frequency import frf
    from slipstep.output.frf_schema import FRF_SCHEMA

    ds = frf(ss.load_system(JENKINS), [300.0, 400.0], solver="shoot", method="events", direction="both")
    assert set(FRF_SCHEMA) <= set(ds.data_vars) and list(ds.sweep.values) == ["up", "down"]
    assert np.all(ds.status.values == "OK") and np.all(ds.error_estimate.values == 0.0)
    assert np.abs(ds.energy_balance_residual.values).max() < 1e-11
    up = ds.sel(sweep="up")
    for k, f in enumerate(up.frequency.values):
        from slipstep.steady.exact_orbit import periodic_orbit

        orbit = periodic_orbit(ss.load_system(JENKINS), float(f))
        mode = int(orbit.trajectory.phases[0].sm.state[0])
        ref = periodic_orbit_energies(M, C, K, KT, FS, F, float(f), orbit.x0[0], orbit.v0[0], orbit.w0[0], mode)
        assert float(up.energy_per_cycle.values[k].sum()) == pytest.approx(ref["friction_energy"], rel=1e-9)
        assert float(up.excitation_work.values[k]) == pytest.approx(ref["excitation_work"], rel=1e-9)
    with pytest.raises(InputError):
        frf(ss.load_system(JENKINS), [300.0], solver="march", method="events")


def test_shoot_with_method_events_is_the_exact_orbit():
    from slipstep.output.results import schema_problem
    from slipstep.steady import shoot

    steady = shoot(ss.load_system(JENKINS), method="events")
    assert steady.status == "OK" and steady.method == "events" and steady.change <= 1e-12
    assert schema_problem(steady.period) == ""
    x = steady.period.displacement.values[:, 0]
    assert abs(steady.final_state.x[0] - x[0]) <= 1e-10 * np.abs(x).max()  # periodic: x(T) = x(0)
    again = shoot(ss.load_system(JENKINS), method="events", initial=steady)
    assert again.newton_iterations == 1 and again.final_state.x[0] == pytest.approx(steady.final_state.x[0], rel=1e-10)


def random_system(rng):
    """3 DOFs, a quasi-3D and a 2D contact (both can lift off), random stiffnesses, masses,
    friction, Rayleigh damping and a harmonic force with random phases."""
    k = rng.uniform(1e5, 1e6, 3)
    K = np.diag(1.6 * k) + np.diag(-0.3 * k[:-1], 1) + np.diag(-0.3 * k[:-1], -1)
    structure = ss.Structure(np.diag(rng.uniform(0.05, 0.2, 3)), rng.uniform(0, 2e-4) * K, K, dof_names=("a", "b", "c"))
    A1 = np.zeros((3, 3))
    A1[0, 0], A1[1, 1], A1[2, 2] = 1.0, 1.0, -1.0
    A2 = np.zeros((2, 3))
    A2[0, 1], A2[1, 0] = 1.0, -0.5
    kts, kn, mu = rng.uniform(1e5, 1e6, 2), rng.uniform(1e5, 1e6, 2), rng.uniform(0.1, 0.6, 2)
    contacts = (
        ss.ContactElement("q3", A1, (kts[0], kts[1]), kn[0], mu[0]),
        ss.ContactElement("p2", A2, rng.uniform(1e5, 1e6), kn[1], mu[1]),
    )
    force = ss.Signal(
        ("a", "b", "c"), (ss.Harmonic(rng.uniform(20, 120), rng.uniform(5, 40, 3), rng.uniform(0, 3, 3)),)
    )
    return ss.System(structure, contacts, ss.Excitation(constant_force=[5.0, 0.0, -8.0], force=force), name="random")


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_systems_with_lift_off(seed):
    """Random 3-DOF systems with a quasi-3D and a 2D contact visiting every state: the energy
    balance, the law's bounds, and Method 3 at T / 8000 within 1e-4 (Method 3's slider carries an
    O(dt) error at a re-contact in some cases, docs/exact_events.md, so no order is asserted here)."""
    system = random_system(np.random.default_rng(seed))
    run, ds = exact_run(system, periods=3)
    assert ds.attrs["status"] == "OK"
    assert set(np.unique(ds.contact_state.values)) == {LIFT, STICK, SLIP_POS, SLIP_NEG}
    balance = energy_balance(run.trajectory)
    assert abs(balance["residual"]) <= 1e-11 * abs(balance["input_work"])
    N, T = ds.normal_force.values, ds.tangential_force.values
    own = [list(ds.contact.values).index(c) for c in ds.direction_contact.values]
    assert N.min() >= 0.0 and np.all(np.abs(T) <= (ds.friction_coefficient.values * N)[:, own] * (1 + 1e-12) + 1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m3 = ss.run(system, "piecewise-linear", periods=3, dt=run.plan.period / 8000, error_estimate=False)
    ref = run.trajectory.evaluate(m3.time.values)["x"]
    assert np.abs(m3.displacement.values - ref).max() <= 1e-4 * np.abs(ref).max()
