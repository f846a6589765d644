"""Issue 8 item 3: stability limits are known and obeyed; divergence is a status, never OK."""

import math

import numpy as np
import pytest

import slipstep as ss
from slipstep.errors import InputError, Status
from slipstep.integrators import simulate
from slipstep.kernels import march as K
from slipstep.methods.accuracy import energy_diverged, highest_frequency
from slipstep.methods.schemes import generalized_alpha, hht, newmark
from slipstep.model.system import System


def test_omega_crit_of_the_newmark_family():
    assert newmark().omega_crit == math.inf
    assert newmark(0.3, 0.5).omega_crit == math.inf
    assert newmark(1 / 6, 0.5).omega_crit == pytest.approx(2 * math.sqrt(3))
    assert newmark(1 / 12, 0.5).omega_crit == pytest.approx(math.sqrt(6))
    assert hht(0.1).omega_crit == math.inf and generalized_alpha(0.5).omega_crit == math.inf


def test_amplification_at_the_limit():
    """The linear Newmark amplification matrix of an undamped mode has spectral radius 1 up
    to Omega_crit and > 1 beyond it (independent check of the formula)."""
    for beta in (1 / 12, 1 / 6, 0.1):
        sch = newmark(beta, 0.5)
        for Om, stable in ((sch.omega_crit * 0.999, True), (sch.omega_crit * 1.01, False)):
            # x'' + w^2 x = 0 with dt = 1, w = Om: one Newmark step on (x, v, a)
            w2 = Om**2
            D = 1 + beta * w2
            # a1 = -w2 (x + v + (1/2 - beta) a) / D; build the map column by column
            Mmap = np.zeros((3, 3))
            for j in range(3):
                x, v, a = np.eye(3)[j]
                a1 = -w2 * (x + v + (0.5 - beta) * a) / D
                Mmap[:, j] = [x + v + (0.5 - beta) * a + beta * a1, v + 0.5 * (a + a1), a1]
            rho = np.abs(np.linalg.eigvals(Mmap)).max()
            assert (rho <= 1 + 1e-9) == stable, (beta, Om, rho)


@pytest.fixture(scope="module")
def paper():
    return ss.load_system("paper")


def test_conditionally_stable_newmark_is_capped_with_a_warning(paper):
    """newmark(1/12, 1/2) at step ratio 1 returned OK with max |x| = 4.6 m before issue 8."""
    with pytest.warns(UserWarning, match="stability limit"):
        ds = simulate(paper, "newmark(1/12, 1/2)", "fixed", periods=2)
    w = highest_frequency(paper.compile())
    assert ds.attrs["dt_s"] * w <= math.sqrt(6) * (1 + 1e-12)
    assert ds.attrs["status"] == "OK"
    assert np.abs(ds.displacement.values[:, :2]).max() < 2e-5  # micrometres, not metres
    ref = ss.run(paper, "newmark", periods=2)
    assert np.abs(ds.displacement.values[-1, :2] - ref.displacement.interp(time=ds.time[-1]).values[:2]).max() < 1e-6


def test_step_beyond_stability_is_refused(paper):
    w = highest_frequency(paper.compile())
    with pytest.raises(InputError, match="stability limit"):
        ss.Simulation(paper, "piecewise-linear", scheme=newmark(1 / 12, 0.5), dt=1.2 * math.sqrt(6) / w, periods=1)


def test_highest_frequency_covers_full_stick(paper):
    cs = paper.compile()
    t_min = ss.state_t_min(cs, np.ones(3, np.int8))
    assert highest_frequency(cs) >= 2 * math.pi / t_min * (1 - 1e-12)


def test_energy_criterion():
    """energy_diverged: a growing free oscillation (no source) is caught, a correct one not."""
    from slipstep.kernels.march import Outputs
    from slipstep.model.contact import ContactElement
    from slipstep.model.structure import Structure

    system = System(
        Structure(np.eye(1), stiffness=np.eye(1) * 1e4),
        (ContactElement("C", np.array([[1.0], [0.0]]), 1e4, 1e4, 0.3, normal_offset=1e-3),),
    )
    cs = system.compile()
    t = np.linspace(0, 0.1, 2001)
    w = 100.0

    def outputs(growth):
        x = 1e-3 * np.exp(growth * t) * np.cos(w * t)
        v = np.gradient(x, t)
        k = t.size
        f = np.zeros((k, 2))
        f[:, 1] = 10.0
        f[:, 0] = 0.0
        return Outputs(
            t,
            np.gradient(t),
            x[:, None],
            v[:, None],
            np.zeros((k, 1)),
            np.zeros((k, 2)),
            f,
            np.zeros((k, 1)),
            np.ones((k, 1), np.int8),
            np.zeros(k, np.int64),
            np.zeros(9, np.int64),
            np.arange(k),  # every step saved (slipstep.methods.save): step, dofs, rows, dirs, plan, times
            np.arange(1),
            np.arange(2),
            np.arange(1),
            np.array([k - 1, 1, k, k - 1, 0, 0]),
            np.array([-np.inf, np.nan, np.inf]),
        )

    zero = np.zeros((t.size, 1))
    assert energy_diverged(outputs(0.0), t.size - 1, cs, zero, np.zeros((t.size, 0))) == 0
    first = energy_diverged(outputs(60.0), t.size - 1, cs, zero, np.zeros((t.size, 0)))
    assert 0 < first < t.size - 1  # found while growing, before the end


def test_implicit_divergence_beyond_the_limit_is_diverged(paper):
    """Force a conditionally stable Newmark step past its limit (the set-up refuses it, so the
    kernel parameter is changed after it): the march ends DIVERGED with the step it was found."""
    sim = ss.Simulation(paper, "piecewise-linear", scheme=newmark(1 / 12, 0.5), periods=1, error_estimate=False)
    sim.settings = K.replace_settings(sim.settings, dt=sim.dt * 1.4)  # omega_max dt = 1.4 * sqrt(6) at most: unstable
    status = sim.march()
    ds = sim.dataset()
    assert status == Status.DIVERGED and ds.attrs["status"] == "DIVERGED"
    assert 0 < ds.attrs["failed_at_step"] <= ds.attrs["steps"]
    assert "stability limit" in ds.attrs["status_message"]
