"""The quasi-static march of Method 4 in its own kernel (kernels/quasi_static.py) against the
implicit march's quasi-static mode (kernels/march.py with inertia off), which it replaces for
the timed march: the same steps and states, the numbers to rounding (bit for bit where both
solve for the increment), on every structure backend and contact law, the fallback included,
and the quasi-static equilibrium (paper Eq. 10) with |T| <= mu N, N >= 0 at every step."""

import numpy as np
import pytest

import slipstep
from slipstep.kernels import march as K
from slipstep.kernels.codes import P_MU, SLIP_COUPLED
from slipstep.kernels.quasi_static import quasi_static_kernel
from slipstep.methods.simulation import march_kernel
from slipstep.methods.registry import get_method
from test_banded import chain_system


def _ring(law):
    """7 DOFs in a chain, one quasi-3D contact on three of them, harmonic forces."""
    n = 7
    K_ = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    A = np.zeros((3, n))
    A[0, 2] = A[1, 3] = A[2, 4] = 1.0
    contact = slipstep.ContactElement("C", A, 1e6, 1e6, 0.3, normal_offset=1e-5, law=law)
    force = slipstep.Signal(
        tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(30.0, [0, 20.0, 0, -15.0, 0, 8.0, 0]),)
    )
    return slipstep.System(
        slipstep.Structure(np.eye(n) * 0.2, stiffness=K_), (contact,), slipstep.Excitation(force=force)
    )


CASES = [  # (label, system, linear solvers, options)
    ("paper", lambda: slipstep.load_system("paper"), ("direct", "low-rank"), {}),
    ("ring-uncoupled", lambda: _ring("quasi-3d-uncoupled"), ("direct", "low-rank"), {}),
    # one postulate per step: every state change cycles and is solved by the fallback (dx form)
    ("ring-uncoupled-fallback", lambda: _ring("quasi-3d-uncoupled"), ("direct",), {"max_state_iterations": 1}),
    ("ring-circle", lambda: _ring("3d-circle"), ("direct",), {}),  # coupled slip: Newton on the tangent
    ("chain-2d-banded", lambda: chain_system(60, 6, "2d", offset=6e-5), ("banded",), {}),
]


def test_method_4_marches_with_the_quasi_static_kernel():
    assert march_kernel(get_method("quasi-static")) is quasi_static_kernel
    for name in ("newmark", "piecewise-linear", "piecewise-linear-adaptive", "quasi-static-dofs"):
        assert march_kernel(get_method(name)) is K.implicit_kernel


@pytest.mark.parametrize("label, build, solvers, options", CASES, ids=[c[0] for c in CASES])
def test_quasi_static_kernel_equals_the_implicit_march(label, build, solvers, options):
    """The same steps, states, solves and counters; x, q, f, w to rounding where the kernel
    solves for x_{n+1} (no friction circle), bit for bit where it solves for dx like the march."""
    system = build()
    for solver in solvers:
        sim = slipstep.Simulation(
            system, "quasi-static", periods=1, linear_solver=solver, error_estimate=False, **options
        )
        assert sim.march() == slipstep.Status.OK, (label, solver)
        lean = {name: np.array(getattr(sim.out, name), copy=True) for name in sim.out._fields}
        assert sim.march(K.implicit_kernel) == slipstep.Status.OK, (label, solver)
        assert int(lean["counters"][K.C_STEPS]) > 100
        exact = label == "ring-circle"
        for name in sim.out._fields:
            ref, got = getattr(sim.out, name), lean[name]
            if exact or got.dtype.kind != "f" or name in ("t", "dt", "times", "v", "a"):
                np.testing.assert_array_equal(got, ref, err_msg=f"{label} {solver} {name}")
            else:
                scale = np.abs(ref).max()
                np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale, err_msg=f"{label} {solver} {name}")
        assert not lean["v"].any() and not lean["a"].any()  # never written: the zeros of the allocation
        if label == "ring-circle":  # the coupled slip was reached
            assert (lean["state"] == SLIP_COUPLED).any()
        if "fallback" in label:
            assert lean["counters"][K.C_FALLBACKS] > 0


def test_every_step_is_a_quasi_static_equilibrium_inside_the_friction_cone():
    sim = slipstep.Simulation(slipstep.load_system("paper"), "quasi-static", periods=1)
    assert sim.march() == slipstep.Status.OK
    cs, out = sim.compiled, sim.out
    rows, n, nq = int(out.plan[K.S_ROWS]), cs.K.shape[0], cs.A.shape[0]
    assert rows > 300 and out.dofs.size == n and out.rows.size == nq  # every DOF and contact row saved
    x, f = np.zeros((rows, n)), np.zeros((rows, nq))
    x[:, out.dofs], f[:, out.rows] = out.x[:rows], out.f[:rows]
    # K x + A^T f = f_e (the paper case: constant loads only, the motion enters through q)
    residual = x @ cs.K.T + f @ cs.A - cs.constant_force
    assert np.abs(residual).max() <= 1e-9 * np.abs(cs.constant_force).max(), np.abs(residual).max()
    N = f[:, cs.normal_row]
    assert (N >= 0).all() and (N > 0).any()
    for c in range(cs.normal_row.size):
        limit = cs.law_par[c, P_MU] * N[:, c]
        for d in range(cs.first_direction[c], cs.first_direction[c] + cs.n_directions[c]):
            assert (np.abs(f[:, cs.tangential_row[d]]) <= limit + 1e-9 * np.abs(N).max()).all(), (c, d)
