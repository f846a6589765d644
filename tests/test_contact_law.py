"""The compiled contact law (slipstep.kernels.contact) on small hand-made systems.

physics.md 2-3: predictor-corrector spring-slider law with variable normal load, its
piecewise-linear form, the compatibility check with a boundary tolerance, and the
assembled tangent K_D(S) = A^T K(S) A.
"""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import slipstep as ss
from slipstep.kernels.contact import (
    LIFT,
    SLIP_NEG,
    SLIP_POS,
    STICK,
    add_contact_stiffness,
    contact_law,
    generalised_force,
    is_compatible,
    linear_law,
    local_displacement,
)

# exactly representable parameters: limit = mu k_n v is exact in binary
KT, KN, MU = 8.0, 64.0, 0.5


def make_system(contacts, n_dofs):
    structure = ss.Structure(mass=np.eye(n_dofs))
    return ss.System(structure, tuple(contacts)).compile()


@pytest.fixture(scope="module")
def single():
    """One 2D contact whose local coordinates are the two DOFs: q = x = (u, v)."""
    return make_system([ss.ContactElement("c", np.eye(2), KT, KN, MU)], 2)


@pytest.fixture(scope="module")
def mixed():
    """A 2D and a quasi-3D contact on 4 DOFs with dense, non-trivial gather maps."""
    rng = np.random.default_rng(7)
    A1 = rng.normal(size=(2, 4))
    A2 = rng.normal(size=(3, 4))
    c1 = ss.ContactElement("a", A1, 3.0e6, 5.0e6, 0.3)
    c2 = ss.ContactElement("b", A2, (2.0e6, 4.0e6), 6.0e6, 0.45)
    return make_system([c1, c2], 4)


def law(cs, q, w_old):
    nq, nd = cs.A.shape[0], cs.kt.shape[0]
    f, w_new, state = np.zeros(nq), np.zeros(nd), np.zeros(nd, np.int8)
    contact_law(cs, np.asarray(q, float), np.asarray(w_old, float), f, w_new, state)
    return f, w_new, state


def lin(cs, state, q, w_old):
    nq, nd = cs.A.shape[0], cs.kt.shape[0]
    f, w_new = np.zeros(nq), np.zeros(nd)
    linear_law(cs, np.asarray(state, np.int8), np.asarray(q, float), np.asarray(w_old, float), f, w_new)
    return f, w_new


# --- an exactly known Jenkins path -------------------------------------------------------

# (u, v) -> expected (T, N, w after, state); k_t = 8, k_n = 64, mu = 0.5, w starts at 0
JENKINS_PATH = [
    ((0.5, 0.25), (4.0, 16.0, 0.0, STICK)),  # load: T* = 8 * 0.5 = 4 <= 0.5 * 16 = 8
    ((1.0, 0.25), (8.0, 16.0, 0.0, STICK)),  # exactly on the slip boundary: stick
    ((1.5, 0.25), (8.0, 16.0, 0.5, SLIP_POS)),  # T* = 12 > 8: slip, w = 1.5 - 8/8
    ((1.25, 0.25), (6.0, 16.0, 0.5, STICK)),  # unload: T* = 8 * 0.75 = 6
    ((0.0, 0.25), (-4.0, 16.0, 0.5, STICK)),  # reverse through zero
    ((-1.0, 0.25), (-8.0, 16.0, 0.0, SLIP_NEG)),  # T* = -12 < -8: slip-, w = -1 + 1
    ((-1.0, -0.125), (0.0, 0.0, -1.0, LIFT)),  # lift-off: T = N = 0, slider follows u
    ((-0.75, 0.25), (2.0, 16.0, -1.0, STICK)),  # re-contact: T starts from zero at w = -1
    ((-0.75, 0.125), (2.0, 8.0, -1.0, STICK)),  # normal load drops: limit 4
    ((-0.75, 0.0625), (2.0, 4.0, -1.0, STICK)),  # limit 2 = T*: on the boundary
    ((-0.75, 0.03125), (1.0, 2.0, -0.875, SLIP_POS)),  # limit 1 < T* = 2: slip by unloading
    ((-0.75, 0.0), (0.0, 0.0, -0.75, LIFT)),  # v = 0 exactly is lift-off (v <= 0)
]


def test_jenkins_path_exact_forces(single):
    w = np.zeros(1)
    for (u, v), (T, N, w_exp, s_exp) in JENKINS_PATH:
        f, w_new, state = law(single, [u, v], w)
        assert (f[0], f[1], w_new[0], state[0]) == (T, N, w_exp, s_exp), (u, v)
        # the piecewise-linear form in the returned state gives the same forces, bit for bit
        f_lin, w_lin = lin(single, state, [u, v], w)
        assert np.array_equal(f_lin, f) and np.array_equal(w_lin, w_new)
        assert is_compatible(single, state, np.array([u, v]), w, 0.0)
        w = w_new


def test_law_uses_the_old_slider_not_the_new_one(single):
    """Evaluating twice at the same q from the same w_old gives the same answer (no drift)."""
    w_old = np.array([0.25])
    a = law(single, [3.0, 0.25], w_old)
    b = law(single, [3.0, 0.25], w_old)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert w_old[0] == 0.25


# --- random paths (hypothesis) -----------------------------------------------------------

coords = st.floats(-2.0, 2.0, allow_nan=False, allow_subnormal=False)
path_2d = st.lists(st.tuples(coords, coords), min_size=2, max_size=30)


@settings(max_examples=200, deadline=None)
@given(path=path_2d)
def test_random_path_invariants(single, path):
    """|T| <= mu N, N >= 0, T = k_t (u - w) in contact, and the per-step friction work of the
    time-discrete law T_{n+1} (w_{n+1} - w_n) is never negative."""
    w = np.zeros(1)
    for u, v in path:
        f, w_new, state = law(single, [u, v], w)
        T, N = f
        assert N >= 0.0
        assert abs(T) <= MU * N * (1 + 1e-12) + 1e-12
        if state[0] != LIFT:
            assert T == pytest.approx(KT * (u - w_new[0]), rel=1e-12, abs=1e-12)
            assert T * (w_new[0] - w[0]) >= -1e-12
        else:
            assert T == 0.0 and N == 0.0 and w_new[0] == u
        w = w_new


def _closed_path_work(cs, nodes, substeps=40):
    """Trapezoid work sum 1/2 (f_n + f_{n+1}) . (q_{n+1} - q_n) along the closed polygon
    through ``nodes`` (each side cut in ``substeps``), starting with a relaxed slider.
    Also returns the trapezoid friction dissipation sum 1/2 (T_n + T_{n+1}) (w_{n+1} - w_n)."""
    nodes = np.vstack([nodes, nodes[:1]])
    pts = [nodes[0]]
    for a, b in zip(nodes[:-1], nodes[1:]):
        for s in range(1, substeps + 1):
            pts.append(a + (b - a) * s / substeps)
    w = np.array([nodes[0][0]])  # relaxed: T = 0 at the start
    f_prev, _, _ = law(cs, pts[0], w)
    work = dissipation = 0.0
    for q0, q1 in zip(pts[:-1], pts[1:]):
        f, w_new, _ = law(cs, q1, w)
        work += 0.5 * (f_prev + f) @ (q1 - q0)
        dissipation += 0.5 * (f_prev[0] + f[0]) * (w_new[0] - w[0])
        f_prev, w = f, w_new
    return work, dissipation


@settings(max_examples=100, deadline=None)
@given(nodes=st.lists(st.tuples(coords, st.floats(0.01, 2.0)), min_size=2, max_size=8))
def test_closed_path_work_is_not_negative(single, nodes):
    """Over any closed path in (u, v) kept in contact, the work done on the contact
    (= stored energy left in the spring + friction dissipation) is >= 0."""
    work, dissipation = _closed_path_work(single, np.array(nodes, float))
    scale = KN * 4.0 + KT * 4.0
    assert work >= -1e-12 * scale
    assert dissipation >= -1e-12 * scale


def test_closed_path_in_stick_does_no_work(single):
    nodes = np.array([[0.0, 1.0], [0.3, 1.2], [-0.2, 0.9]])  # |T*| <= 8 * 0.5 < mu k_n v = 28.8
    work, dissipation = _closed_path_work(single, nodes)
    assert abs(work) < 1e-12 and dissipation == 0.0


def test_closed_slip_cycle_dissipates_four_mu_n_times_slip(single):
    """Constant N = 16 (limit 8), u cycled between -2 and 2: the Jenkins loop dissipates
    4 mu N (u_a - mu N / k_t) per cycle once the first loading is done."""
    # start with the loop already established: go to +2 first, then measure one cycle
    w = np.zeros(1)
    f, w, _ = law(single, [2.0, 0.25], w)
    cycle = (
        [[2.0, 0.25]]
        + [[u, 0.25] for u in np.linspace(2.0, -2.0, 161)[1:]]
        + [[u, 0.25] for u in np.linspace(-2.0, 2.0, 161)[1:]]
    )
    dissipation = 0.0
    for q0, q1 in zip(cycle[:-1], cycle[1:]):
        f1, w1, _ = law(single, q1, w)
        dissipation += 0.5 * (f[0] + f1[0]) * (w1[0] - w[0])
        f, w = f1, w1
    N = 16.0
    assert dissipation == pytest.approx(4 * MU * N * (2.0 - MU * N / KT), rel=1e-12)


# --- piecewise-linear form ---------------------------------------------------------------


def random_point(cs, rng):
    n = cs.A.shape[1]
    x = rng.normal(size=n) * 1e-6
    w_old = rng.normal(size=cs.kt.shape[0]) * 1e-6
    q = np.zeros(cs.A.shape[0])
    local_displacement(cs, x, np.zeros(0), q)
    return x, q, w_old


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_linear_law_reproduces_the_law(mixed, seed):
    rng = np.random.default_rng(seed)
    _, q, w_old = random_point(mixed, rng)
    f, w_new, state = law(mixed, q, w_old)
    f_lin, w_lin = lin(mixed, state, q, w_old)
    assert np.array_equal(f, f_lin) and np.array_equal(w_new, w_lin)
    # and at any other point where that state is still compatible (strictly)
    q2 = q + rng.normal(size=q.size) * 1e-8
    if is_compatible(mixed, state, q2, w_old, 0.0):
        f2, w2, state2 = law(mixed, q2, w_old)
        f2_lin, w2_lin = lin(mixed, state, q2, w_old)
        assert np.allclose(f2_lin, f2, rtol=1e-12, atol=1e-12 * np.abs(f2).max(initial=1.0))
        assert np.allclose(w2_lin, w2, rtol=1e-12, atol=1e-20)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_is_compatible_accepts_the_laws_own_state(mixed, seed):
    rng = np.random.default_rng(seed)
    _, q, w_old = random_point(mixed, rng)
    _, _, state = law(mixed, q, w_old)
    assert is_compatible(mixed, state, q, w_old, 0.0)
    assert is_compatible(mixed, state, q, w_old, 1e-9)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_contact_stiffness_is_the_jacobian_within_a_state(mixed, seed):
    """add_contact_stiffness(S) = d(A^T f(A x))/dx, by central differences inside state S."""
    rng = np.random.default_rng(seed)
    x, q, w_old = random_point(mixed, rng)
    _, _, state = law(mixed, q, w_old)
    n = x.size
    h = 1e-12
    J = np.zeros((n, n))
    for j in range(n):
        cols = []
        for sign in (1.0, -1.0):
            xp = x.copy()
            xp[j] += sign * h
            qp = np.zeros_like(q)
            local_displacement(mixed, xp, np.zeros(0), qp)
            fp, _, sp = law(mixed, qp, w_old)
            assume(np.array_equal(sp, state))
            g = np.zeros(n)
            generalised_force(mixed, fp, g)
            cols.append(g)
        J[:, j] = (cols[0] - cols[1]) / (2 * h)
    KD = np.zeros((n, n))
    add_contact_stiffness(mixed, state, 1.0, KD)
    assert np.allclose(J, KD, rtol=1e-5, atol=1e-5 * np.abs(KD).max(initial=1.0))
    # the factor scales it
    KD2 = np.full((n, n), 1.0)
    add_contact_stiffness(mixed, state, 0.5, KD2)
    assert np.allclose(KD2 - 1.0, 0.5 * KD, rtol=1e-14, atol=1e-14 * np.abs(KD).max(initial=1.0))


def test_contact_stiffness_by_state_table(single):
    """Table 1 of physics.md 3 with A = I: K(stick), K(slip+/-), K(lift-off)."""
    expected = {
        STICK: [[KT, 0.0], [0.0, KN]],
        SLIP_POS: [[0.0, MU * KN], [0.0, KN]],
        SLIP_NEG: [[0.0, -MU * KN], [0.0, KN]],
        LIFT: [[0.0, 0.0], [0.0, 0.0]],
    }
    for s, K in expected.items():
        out = np.zeros((2, 2))
        add_contact_stiffness(single, np.array([s], np.int8), 1.0, out)
        assert np.array_equal(out, np.array(K)), s


# --- compatibility on the boundaries -------------------------------------------------------


def test_boundary_points_are_compatible_with_both_neighbours(single):
    w = np.zeros(1)
    # stick / slip+ boundary: k_t (u - w) = mu k_n v = 8 exactly
    q = np.array([1.0, 0.25])
    assert is_compatible(single, np.array([STICK], np.int8), q, w, 0.0)
    assert is_compatible(single, np.array([SLIP_POS], np.int8), q, w, 0.0)
    assert not is_compatible(single, np.array([SLIP_NEG], np.int8), q, w, 1e-9)
    # stick / slip- boundary
    q = np.array([-1.0, 0.25])
    assert is_compatible(single, np.array([STICK], np.int8), q, w, 0.0)
    assert is_compatible(single, np.array([SLIP_NEG], np.int8), q, w, 0.0)
    # contact / lift-off boundary v = 0 (with T* = 0)
    q = np.array([0.0, 0.0])
    assert is_compatible(single, np.array([LIFT], np.int8), q, w, 0.0)
    assert is_compatible(single, np.array([STICK], np.int8), q, w, 0.0)


def test_boundary_tolerance_accepts_rounding_and_rejects_real_violations():
    """A boundary point computed in floating point (u = w + mu k_n v / k_t with 'ugly'
    numbers) is accepted by the default tolerance 1e-9 whichever side rounding put it on;
    a point 1e-6 (relative) past the boundary is rejected."""
    kt, kn, mu = 13.0e6, 13.0e6, 0.4
    cs = make_system([ss.ContactElement("c", np.eye(2), kt, kn, mu)], 2)
    rng = np.random.default_rng(3)
    for _ in range(200):
        v = rng.uniform(1e-7, 1e-5)
        w = np.array([rng.normal() * 1e-6])
        for sign, slip in ((1.0, SLIP_POS), (-1.0, SLIP_NEG)):
            u = w[0] + sign * mu * kn * v / kt
            q = np.array([u, v])
            assert is_compatible(cs, np.array([STICK], np.int8), q, w, 1e-9)
            assert is_compatible(cs, np.array([slip], np.int8), q, w, 1e-9)
            past = np.array([w[0] + sign * mu * kn * v / kt * (1 + 1e-6), v])
            assert not is_compatible(cs, np.array([STICK], np.int8), past, w, 1e-9)
            inside = np.array([w[0] + sign * mu * kn * v / kt * (1 - 1e-6), v])
            assert not is_compatible(cs, np.array([slip], np.int8), inside, w, 1e-9)
    # lift-off postulated on an interference, and contact postulated on a clear gap: rejected
    w = np.zeros(1)
    L = cs.length_scale
    assert not is_compatible(cs, np.array([LIFT], np.int8), np.array([0.0, 1e-6 * L]), w, 1e-9)
    assert not is_compatible(cs, np.array([STICK], np.int8), np.array([0.0, -1e-6 * L]), w, 1e-9)


# --- quasi-3D: two uncoupled directions --------------------------------------------------------


@pytest.fixture(scope="module")
def quasi3d():
    """One quasi-3D contact (k_t1 = 8, k_t2 = 2) and, for comparison, two 2D contacts that
    share the same normal coordinate: q = (u1, u2, v)."""
    c3 = ss.ContactElement("q3", np.eye(3), (KT, 2.0), KN, MU)
    two = [
        ss.ContactElement("d1", np.array([[1.0, 0, 0], [0, 0, 1.0]]), KT, KN, MU),
        ss.ContactElement("d2", np.array([[0, 1.0, 0], [0, 0, 1.0]]), 2.0, KN, MU),
    ]
    return make_system([c3], 3), make_system(two, 3)


@settings(max_examples=100, deadline=None)
@given(path=st.lists(st.tuples(coords, coords, coords), min_size=1, max_size=20))
def test_quasi3d_directions_are_independent(quasi3d, path):
    """Each direction follows its own 1D law against the shared N: the quasi-3D contact
    equals two 2D contacts on the same v, and direction 1 does not see u2."""
    q3, two = quasi3d
    w3 = np.zeros(2)
    w2 = np.zeros(2)
    w_alone = np.zeros(2)
    for u1, u2, v in path:
        f3, w3_new, s3 = law(q3, [u1, u2, v], w3)
        q_two = np.zeros(4)
        local_displacement(two, np.array([u1, u2, v]), np.zeros(0), q_two)
        f2, w2_new, s2 = law(two, q_two, w2)
        # two: rows (u1, v, u2, v)
        assert f3[0] == f2[0] and f3[1] == f2[2] and f3[2] == f2[1] == f2[3]
        assert np.array_equal(w3_new, w2_new) and np.array_equal(s3, s2)
        # direction 1 with u2 replaced by anything: unchanged
        fa, wa, sa = law(q3, [u1, -u2 + 0.7, v], w_alone)
        assert fa[0] == law(q3, [u1, u2, v], w_alone)[0][0]
        assert abs(f3[0]) <= MU * f3[2] * (1 + 1e-12) + 1e-12
        assert abs(f3[1]) <= MU * f3[2] * (1 + 1e-12) + 1e-12
        w3, w2, w_alone = w3_new, w2_new, wa
        del sa


def test_quasi3d_can_slip_in_one_direction_and_stick_in_the_other(quasi3d):
    q3, _ = quasi3d
    # N = 16, limit 8: direction 1 T* = 8 * 2 = 16 (slip), direction 2 T* = 2 * 1 = 2 (stick)
    f, w, s = law(q3, [2.0, 1.0, 0.25], np.zeros(2))
    assert list(s) == [SLIP_POS, STICK]
    assert list(f) == [8.0, 2.0, 16.0]
    assert list(w) == [1.0, 0.0]
    # the combined tangential force may exceed mu N (uncoupled law: not a friction cone)
    f, w, s = law(q3, [2.0, 5.0, 0.25], np.zeros(2))
    assert list(s) == [SLIP_POS, SLIP_POS]
    assert np.hypot(f[0], f[1]) == pytest.approx(np.sqrt(2) * MU * f[2])
    # lift-off is shared by both directions
    f, w, s = law(q3, [2.0, 5.0, -0.1], np.zeros(2))
    assert list(s) == [LIFT, LIFT] and list(w) == [2.0, 5.0] and not f.any()


@pytest.mark.parametrize("u", [-3.0, -0.2, 0.0, 0.3, 3.0])
@pytest.mark.parametrize("v", [-0.5, 0.25, 1.0])
def test_slider_derivative_is_the_law_derivative(u, v):
    """laws.uncoupled.slider_derivative (the shooting sensitivity's and the event margins' dw/dq)
    is the derivative of the law's slider w_new(u, v) at fixed w_old in the state the law takes:
    dw = a du - s dv (lift-off: w = u), by central differences inside the state's region."""
    from slipstep.kernels.laws import uncoupled

    w_old, h = 0.1, 1e-6

    def w_new(uu, vv):
        if vv <= 0.0:
            return uu, LIFT
        _, w, s = uncoupled.law(KT, MU * KN * vv, uu, w_old)
        return w, s

    w0, state = w_new(u, v)
    a, s = uncoupled.slider_derivative(KT, MU * KN, state)
    assert w_new(u + h, v)[1] == w_new(u - h, v)[1] == state  # the region holds around the point
    assert (w_new(u + h, v)[0] - w_new(u - h, v)[0]) / (2 * h) == pytest.approx(a, abs=1e-6)
    assert -(w_new(u, v + h)[0] - w_new(u, v - h)[0]) / (2 * h) == pytest.approx(s, abs=1e-6)


@pytest.mark.parametrize("side", [0, 1])
def test_stick_margin_is_the_compatibility_test(side):
    """A stick margin a v - b (u - w) >= 0 (laws.uncoupled.stick_margin) holds exactly where the
    stick test of uncoupled.compatible holds on its side, and crosses into that side's slip."""
    from slipstep.kernels.laws import uncoupled

    a, b, crossed = uncoupled.stick_margin(KT, MU * KN, side)
    assert crossed == (SLIP_POS if side == 0 else SLIP_NEG)
    v, w = 1.0, 0.0
    for u in np.linspace(-8.0, 8.0, 65):  # the limit mu k_n v / k_t = 4 is on the grid
        margin = a * v - b * (u - w)
        trial = KT * (u - w)
        holds = trial <= MU * KN * v if side == 0 else trial >= -MU * KN * v
        assert (margin >= 0.0) == holds
        assert uncoupled.law(KT, MU * KN * v, u, w)[2] != crossed or margin < 0.0
