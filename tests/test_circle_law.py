"""The coupled 3D friction-circle law (kernels/laws/circle.py): |T| <= mu N as a vector
norm, N >= 0, the slip increment along T (the force -T on the structure opposes the slip
rate), non-negative dissipation, the consistent tangent against finite differences, and a
quasi-3D structure marched by Methods 1, 3 and full Newton to the same solution."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import slipstep as ss
from slipstep.errors import InputError
from slipstep.kernels.codes import LIFT, SLIP_COUPLED, STICK
from slipstep.kernels.contact import add_tangent_stiffness, contact_law, is_compatible, linear_law

KT, KN, MU = 8.0, 64.0, 0.5
ROOT = Path(__file__).resolve().parents[1]
NORM_RTOL = 1e-12  # |T| <= mu N (1 + NORM_RTOL): the radial return is exact up to rounding


def make(law):
    contact = ss.ContactElement("c", np.eye(3), KT, KN, MU, law=law)
    return ss.System(ss.Structure(mass=np.eye(3)), (contact,)).compile()


@pytest.fixture(scope="module")
def circle():
    return make("3d-circle")


def law(cs, q, w_old):
    f, w_new, state = np.zeros(3), np.zeros(2), np.zeros(2, np.int8)
    contact_law(cs, np.asarray(q, float), np.asarray(w_old, float), f, w_new, state)
    return f, w_new, state


coord = st.floats(-2, 2, allow_subnormal=False)
point = st.tuples(coord, coord, st.floats(-0.5, 2, allow_subnormal=False))


@settings(max_examples=200, deadline=None)
@given(path=st.lists(point, min_size=2, max_size=40))
def test_random_path_invariants(circle, path):
    w = np.zeros(2)
    for q in path:
        f, w_new, state = law(circle, q, w)
        T, N = f[:2], f[2]
        assert N >= 0.0
        assert np.hypot(*T) <= MU * N * (1 + NORM_RTOL)
        assert state[0] == state[1]
        if state[0] == LIFT:
            assert np.all(f == 0.0) and np.array_equal(w_new, q[:2])
        else:
            assert np.allclose(T, KT * (np.asarray(q[:2]) - w_new), rtol=1e-12, atol=1e-12)
            dw = w_new - w
            if state[0] == STICK:
                assert np.array_equal(w_new, w)
            else:  # slip: |T| = mu N and dw along T, so -T (on the structure) opposes the slip rate
                assert state[0] == SLIP_COUPLED
                assert np.hypot(*T) == pytest.approx(MU * N, rel=1e-12)
                if np.hypot(*dw) > 1e-12:  # (a slip by rounding only has no direction)
                    assert T @ dw >= (1 - 1e-9) * np.hypot(*T) * np.hypot(*dw)
            # the state returned is compatible and its force is the law's
            assert is_compatible(circle, state, np.asarray(q, float), w, 1e-12)
            f_lin, w_lin = np.zeros(3), np.zeros(2)
            linear_law(circle, state, np.asarray(q, float), w, f_lin, w_lin)
            assert np.allclose(f_lin, f, rtol=1e-14, atol=0) and np.allclose(w_lin, w_new, rtol=1e-14, atol=1e-15)
        w = w_new


@settings(max_examples=25, deadline=None)
@given(
    a=st.floats(0.2, 2.0),
    b=st.floats(0.2, 2.0),
    phase=st.floats(0, 6.3),
    v0=st.floats(0.1, 1.0),
    dv=st.floats(0.0, 0.09),
)
def test_closed_paths_dissipate(circle, a, b, phase, v0, dv):
    """Closed elliptical paths in the tangent plane with an oscillating normal approach (kept
    in contact): the friction dissipation of every step T_{n+1} . (w_{n+1} - w_n) is >= 0,
    and the work done on the contact minus the change of stored energy equals the
    dissipation (both by the trapezoid rule, to its error)."""
    s = np.linspace(0.0, 4 * np.pi, 2001)
    path = np.column_stack([a * np.cos(s + phase), b * np.sin(s), v0 + dv * np.sin(3 * s)])
    w = np.zeros(2)
    f_prev, w, _ = law(circle, path[0], w)
    work = dissipation = 0.0
    steps = []
    energy0 = f_prev[:2] @ f_prev[:2] / (2 * KT) + f_prev[2] ** 2 / (2 * KN)
    for q0, q1 in zip(path[:-1], path[1:]):
        f, w_new, _ = law(circle, q1, w)
        work += 0.5 * (f_prev + f) @ (q1 - q0)
        steps.append(f[:2] @ (w_new - w))
        dissipation += 0.5 * (f_prev[:2] + f[:2]) @ (w_new - w)
        f_prev, w = f, w_new
    energy1 = f[:2] @ f[:2] / (2 * KT) + f[2] ** 2 / (2 * KN)
    assert min(steps) >= 0.0 and dissipation >= 0.0
    assert work - (energy1 - energy0) == pytest.approx(dissipation, rel=1e-3, abs=1e-9)


def test_uncoupled_law_carries_sqrt2_mu_n_circle_does_not():
    q, w = np.array([5.0, 5.0, 1.0]), np.zeros(2)  # T* = (40, 40), mu N = 32
    f_unc, _, _ = law(make("quasi-3d-uncoupled"), q, w)
    f_cir, _, _ = law(make("3d-circle"), q, w)
    assert np.hypot(*f_unc[:2]) == pytest.approx(np.sqrt(2) * MU * KN)
    assert np.hypot(*f_cir[:2]) == pytest.approx(MU * KN)


@settings(max_examples=100, deadline=None)
@given(q=point, w=st.tuples(coord, coord))
def test_consistent_tangent_is_the_derivative(circle, q, w):
    """add_tangent_stiffness (A = I) against central differences of the law at fixed w_old."""
    q, w = np.asarray(q, float), np.asarray(w, float)
    f, _, state = law(circle, q, w)
    T_star = KT * np.hypot(*(q[:2] - w))
    limit = MU * KN * q[2]
    if q[2] < 1e-3 or abs(T_star - limit) < 1e-3 * (1 + limit) or (state[0] == SLIP_COUPLED and T_star < 1e-3):
        return  # too close to a state boundary for differences
    K = np.zeros((3, 3))
    add_tangent_stiffness(circle, state, q, w, 1.0, K)
    h = 1e-7
    fd = np.column_stack([(law(circle, q + h * e, w)[0] - law(circle, q - h * e, w)[0]) / (2 * h) for e in np.eye(3)])
    assert np.allclose(K, fd, rtol=1e-5, atol=1e-5 * (KT + KN))


def circle_shroud(tangential_stiffness=1.5e7):
    system, _ = ss.load_case(ROOT / "examples" / "shroud_pair.toml")
    contact = dataclasses.replace(system.contacts[0], law="3d-circle", tangential_stiffness=tangential_stiffness)
    return dataclasses.replace(system, contacts=(contact,))


def test_quasi_3d_case_methods_agree_to_the_solver_tolerance():
    """The shroud pair with a friction-circle contact (coupled slip visited): Method 1
    (modified Newton), Method 3 (coupled slip by Newton on the consistent tangent) and full
    Newton give one solution; the differences scale with the solver tolerance."""
    system = circle_shroud()
    diffs = []
    for tol in (1e-8, 1e-11):
        runs = {m: ss.run(system, m, periods=3, tolerance=tol) for m in ("1", "3", "full-newton")}
        L = runs["1"].attrs["length_scale_m"]
        for ds in runs.values():
            assert ds.attrs["status"] == "OK"
            T, N = ds.tangential_force.values, ds.normal_force.values[:, 0]
            assert np.all(np.hypot(T[:, 0], T[:, 1]) <= 0.3 * N * (1 + NORM_RTOL))
            assert np.all(N >= 0)
            assert np.any(ds.contact_state.values == SLIP_COUPLED)
        x1 = runs["1"].displacement.values
        for m in ("3", "full-newton"):
            d = np.abs(runs[m].displacement.values - x1).max()
            assert d <= 5e3 * tol * L, (m, tol, d)  # Method 1 accumulates about 1e3 tol L over 3 periods
        diffs.append(np.abs(runs["3"].displacement.values - x1).max())
    assert diffs[1] < 1e-2 * diffs[0]


def test_low_rank_solve_with_coupled_slip_matches_direct():
    """A 7-DOF chain (few contact coordinates: the low-rank state solve) with a friction-circle
    contact: the low-rank and direct solves of Method 3 agree."""
    n = 7
    K = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    A = np.zeros((3, n))
    A[0, 2], A[1, 3], A[2, 4] = 1.0, 1.0, 1.0
    contact = ss.ContactElement("C", A, 1e6, 1e6, 0.3, normal_offset=1e-5, law="3d-circle")
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(30.0, [0, 20.0, 0, -15.0, 0, 8.0, 0]),))
    system = ss.System(ss.Structure(np.eye(n) * 0.2, stiffness=K), (contact,), ss.Excitation(force=force))
    runs = [ss.run(system, "3", periods=1, linear_solver=s) for s in ("direct", "low-rank")]
    assert runs[1].attrs["linear_solver"] == "low-rank"
    assert all(ds.attrs["status"] == "OK" for ds in runs)
    assert np.any(runs[0].contact_state.values == SLIP_COUPLED)
    scale = np.abs(runs[0].displacement.values).max()
    assert np.abs(runs[0].displacement.values - runs[1].displacement.values).max() <= 1e-6 * scale


def test_toml_law_key(tmp_path):
    text = (ROOT / "examples" / "shroud_pair.toml").read_text()
    path = tmp_path / "c.toml"
    path.write_text(
        text.replace(
            "tangential_stiffness_N_per_m = [2e7, 1e7]", 'tangential_stiffness_N_per_m = 1.5e7\nlaw = "3d-circle"'
        )
    )
    system, _ = ss.load_case(path)
    assert system.contacts[0].law == "3d-circle"
    ds = ss.run(system, "3", periods=1)
    assert list(ds.contact_law.values) == ["3d-circle"]
    default, _ = ss.load_case(ROOT / "examples" / "shroud_pair.toml")
    assert default.contacts[0].law == "quasi-3d-uncoupled"
    path.write_text(text.replace("friction_coefficient = 0.3", 'friction_coefficient = 0.3\nlaw = "circle"'))
    with pytest.raises(InputError) as err:
        ss.load_case(path)
    assert "shroud" in err.value.field and err.value.field.endswith("law")
    path.write_text(text.replace("friction_coefficient = 0.3", 'friction_coefficient = 0.3\nlaw = "3d-circle"'))
    with pytest.raises(InputError) as err:
        ss.load_case(path)
    assert "tangential_stiffness" in err.value.field
    with pytest.raises(InputError) as err:
        ss.ContactElement("c", np.eye(2), KT, KN, MU, law="3d-circle")
    assert err.value.field == "contacts[c].law"
