"""The AFT contact forces and the exact Jacobians of the harmonic balance (issue 13 item 1).

- dF/dZ of the AFT (the piecewise-linear tangent per sample, through the slider memory,
  transformed to the frequency domain) against central finite differences, on cycles that
  stick, slip both ways and lift off (2D and quasi-3D contacts, variable normal load);
- dR/dZ, dR/dOmega, dR/dlambda of the condensed residual against finite differences;
- the AFT force of a Jenkins element under u = a cos(theta): the analytic loop energy
  4 F_s (a - F_s / k_t).
"""

import numpy as np
import pytest
from hbm_cases import base_driven, jenkins_1dof, jenkins_2dof, wedge

from slipstep.hbm import HarmonicBalance
from slipstep.hbm.energy import contact_energy


def _fd(fun, z, eps):
    cols = []
    for i in range(z.size):
        zp, zm = z.copy(), z.copy()
        zp[i] += eps
        zm[i] -= eps
        cols.append((fun(zp) - fun(zm)) / (2 * eps))
    return np.array(cols).T


def _solved(system, H, f):
    hb = HarmonicBalance(system, H, 64)
    return hb, hb.solve(2 * np.pi * f)


@pytest.mark.parametrize("make, f", [(jenkins_1dof, 350.0), (jenkins_2dof, 300.0), (wedge, 200.0)])
def test_aft_jacobian_matches_finite_differences(make, f):
    hb, pt = _solved(make(), 5, f)
    assert pt.converged
    states = set(np.unique(hb.aft.st))
    assert {1, 2, 3} <= states  # stick and slip both ways in the cycle
    if make is wedge:
        assert 0 in states  # lift-off too
    Z = pt.Z
    _, J = hb.aft.evaluate(Z)
    eps = 1e-9 * np.abs(Z).max()
    Jfd = _fd(lambda z: hb.aft.evaluate(z.reshape(Z.shape), False)[0].ravel(), Z.ravel(), eps)
    assert np.abs(J - Jfd).max() <= 1e-6 * np.abs(J).max()
    # the tangent is not the sample-wise one: the slider memory couples samples
    assert np.abs(J).max() > 0


@pytest.mark.parametrize("condense", ["dofs", "contacts"])
@pytest.mark.parametrize("make, f", [(jenkins_2dof, 300.0), (wedge, 200.0), (base_driven, 300.0)])
def test_residual_jacobians_match_finite_differences(make, f, condense):
    hb = HarmonicBalance(make(), 5, 64, condense=condense)
    pt = hb.solve(2 * np.pi * f)
    w = pt.omega
    Z = pt.Y * 1.01  # off the solution
    _, J, dw, dl = hb.evaluate(Z, w, 1.0)
    eps = 1e-9 * np.abs(Z).max()
    Jfd = _fd(lambda z: hb.evaluate(z.reshape(Z.shape), w, 1.0, jacobian=False), Z.ravel(), eps)
    assert np.abs(J - Jfd).max() <= 1e-6 * np.abs(J).max()
    e = 1e-6 * w
    dw_fd = (hb.evaluate(Z, w + e, 1.0, jacobian=False) - hb.evaluate(Z, w - e, 1.0, jacobian=False)) / (2 * e)
    assert np.abs(dw - dw_fd).max() <= 1e-6 * np.abs(dw).max()
    dl_fd = (hb.evaluate(Z, w, 1 + 1e-6, jacobian=False) - hb.evaluate(Z, w, 1 - 1e-6, jacobian=False)) / 2e-6
    assert np.abs(dl - dl_fd).max() <= 1e-6 * np.abs(dl).max()


@pytest.mark.parametrize("a_over_slip", [1.5, 4.0])
def test_aft_jenkins_loop_energy_is_analytic(a_over_slip):
    hb = HarmonicBalance(jenkins_1dof(), 3, 4096)
    kt, fs = 1.0e7, 50.0
    a = a_over_slip * fs / kt
    Z = hb.local(hb.initial_guess(), 1.0)  # q at the static preload
    Z[1, 0] = a  # u = a cos(theta)
    F, _ = hb.aft.evaluate(Z, False)
    assert hb.aft.periods == 2  # the cycle converges after one period of memory
    E = contact_energy(hb, Z, F)[0]
    exact = 4 * fs * (a - fs / kt)
    assert abs(E - exact) <= 2e-6 * exact
    assert np.abs(hb.aft.ft[:, 0]).max() <= fs * (1 + 1e-12)  # |T| <= mu N
