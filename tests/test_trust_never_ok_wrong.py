"""Issue 29 item 3: Method 1 never OK when wrong, on seeded systems of slipstep.study.trust_systems
that were silently wrong before the residual floor left out the inertia term (kernels/march.py:
``tol L max diag J(stick)`` with J's a0 M exceeded the step's forces by 1e3-1e5 on a response far
below the length scale L, and steps 1e-8 of their forces off their equation passed as converged).

Each system: full Newton and the piecewise-linear solve, both at 1e-13, agree to 1e-8 of the range
(decidable); Method 1 at its defaults must then be within 1e-6 of the range of them, or not OK, or
flagged (``steps_above_tolerance``). The balance residual of every step, recomputed from the rows
(invariants.step_residuals, relative to the step's physical forces), must stay within 1e3 x tolerance.
"""

import numpy as np
import pytest

from slipstep.methods.invariants import step_residuals
from slipstep.methods.simulation import Simulation
from slipstep.study.trust_systems import GENERATORS, newmark_check, trust_system

# (generator, index) of trust_system(default_rng([1, GENERATORS.index(generator), index]), generator):
# Method 1 was OK, unflagged and 2.1e-5, 9.7e-6, 1.8e-6 of the range off before the fix
SILENT_BEFORE = [("broad", 175), ("shared-dof", 21), ("lever-map", 185)]


def system_of(generator, index):
    return trust_system(np.random.default_rng([1, GENERATORS.index(generator), index]), generator)


@pytest.mark.parametrize("generator, index", SILENT_BEFORE)
def test_method1_reaches_the_discrete_solution(generator, index):
    system = system_of(generator, index)
    row = newmark_check(system)
    assert row["decidable"]
    assert row["status"] != "OK" or row["flagged"] or row["error"] <= 1e-6, row
    sim = Simulation(system, "newmark", periods=2, error_estimate=False)
    sim.run()
    rho = step_residuals(sim)
    assert rho is not None and rho.max() <= 1e3 * sim.options.tolerance, rho.max()


def test_generators_draw_their_families():
    """Each generator draws what its docstring says: one DOF and one contact for stick-1dof, two contacts
    on a shared DOF for shared-dof, rows mixing DOFs for lever-map, a load period 1-100 T_min."""
    from slipstep.methods.eigen import omega_max
    from slipstep.methods.step_control import t_min_of_omega

    for generator in GENERATORS:
        for i in range(5):
            system = system_of(generator, i)
            cs = system.compile_dense("test")
            n, nc = cs.M.shape[0], len(system.contacts)
            if generator == "stick-1dof":
                assert n == 1 and nc == 1
            if generator == "shared-dof":
                assert nc == 2 and np.abs(cs.A[cs.tangential_row]).astype(bool).all(axis=0).any()
            if generator == "lever-map":
                assert (np.count_nonzero(cs.A, axis=1) >= 2).all()
            Keff = cs.K + sum(cs.kn[c] * np.outer(cs.A[r], cs.A[r]) for c, r in enumerate(cs.normal_row))
            Keff = Keff + sum(cs.kt[d] * np.outer(cs.A[r], cs.A[r]) for d, r in enumerate(cs.tangential_row))
            period = 1.0 / system.excitation.force.harmonics[0].frequency
            assert 1.0 - 1e-9 <= period / t_min_of_omega(omega_max(cs.M, Keff)) <= 100.0 * (1 + 1e-9)
