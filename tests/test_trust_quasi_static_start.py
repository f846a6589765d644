"""Issue 8 item 6: a quasi-static run starts from the static equilibrium at p(0), f_e(0)."""

import numpy as np
import pytest

import slipstep as ss
from slipstep.casefile.case import CASES_DIR

CF = 200.0


def _residual(ds, system, k=0):
    """max |K x + A^T f - f_e(t_k)| at output point k."""
    cs = system.compile()
    f = np.zeros(cs.A.shape[0])
    f[cs.tangential_row] = ds.tangential_force.values[k]
    f[cs.normal_row] = ds.normal_force.values[k]
    x = ds.displacement.values[k]
    from slipstep.post.energy import external_force

    fe = external_force(system, ds.time.values[k : k + 1])[0]
    return np.abs(cs.K @ x + cs.A.T @ f - fe).max()


@pytest.mark.parametrize("phase", [90.0, 200.0])
def test_quasi_static_first_point_is_equilibrium_at_p0(tmp_path, phase):
    text = (
        (CASES_DIR / "paper.toml")
        .read_text()
        .replace("frequency_Hz = 200.0", f"frequency_Hz = 200.0\nphase_deg = {phase}")
    )
    path = tmp_path / "shifted.toml"
    path.write_text(text)
    system = ss.load_system(str(path))
    ds = ss.run(system, "quasi-static", periods=1, raise_on_failure=True, error_estimate=False)
    p0 = ds.prescribed_motion.values[0]
    assert np.abs(p0).max() > 5e-6  # the case really starts away from p = 0
    # equilibrium at t = 0 to the solver tolerance (it was 0.8 CF off before issue 8)
    assert _residual(ds, system, 0) < 1e-8 * CF
    # and the local q at t = 0 is the one of p(0): q = A x - B p(0) + g
    cs = system.compile()
    q = cs.A @ ds.displacement.values[0] - cs.B @ p0 + cs.g
    assert np.allclose(q[cs.normal_row], ds.normal_displacement.values[0], atol=1e-15)
    assert np.allclose(q[cs.tangential_row], ds.tangential_displacement.values[0], atol=1e-15)
    # Coulomb holds at t = 0
    T = ds.tangential_force.values[0]
    N = ds.normal_force.values[0]
    mu = ds.friction_coefficient.values
    assert np.all(N >= 0) and np.all(np.abs(T) <= mu * N * (1 + 1e-9) + 1e-9)
    # every later point is an equilibrium too
    assert _residual(ds, system, 5) < 1e-8 * CF


def test_quasi_static_zero_start_unchanged():
    """p(0) = 0: the first point is the preload itself (no extra solve)."""
    system = ss.load_system("paper")
    ds = ss.run(system, "quasi-static", periods=1, error_estimate=False)
    assert _residual(ds, system, 0) < 1e-8 * CF
    assert ds.attrs["steps"] == 300
