"""The harmonic basis of the loads and motions advanced by rotation (kernels/signals.py,
harmonic_basis): as accurate as sin / cos calls at the same times over a million steps, exact
after a change of step size, and the march results equal to those of exact evaluation."""

import numpy as np
import pytest
from numba import njit

import slipstep
from slipstep.kernels.signals import ANCHOR_EVERY, harmonic_basis


@njit(cache=True)
def _march_basis(freq_f, freq_m, steps, t0):
    """The basis at t_k = t_{k-1} + steps[k] (accumulated like the march's time), and clock[2]."""
    nh = freq_f.shape[0] + freq_m.shape[0]
    basis = np.zeros((4, nh))
    clock = np.array([t0, np.nan, 0.0, np.nan])
    ts = np.empty(steps.shape[0])
    out = np.empty((steps.shape[0], 2, nh))
    rotated = 0
    t = t0
    for k in range(steps.shape[0]):
        t = t + steps[k]
        harmonic_basis(t, freq_f, freq_m, basis, clock)
        rotated += clock[2] > 0.0
        ts[k] = t
        out[k, 0] = basis[0]
        out[k, 1] = basis[1]
    return ts, out, rotated


def _truth(freq, ts):
    """sin, cos of 2 pi f t in extended precision (the phase reduced to one period first)."""
    phase = 2 * np.longdouble(np.pi) * ((np.longdouble(freq) * ts.astype(np.longdouble)) % 1)
    return np.sin(phase), np.cos(phase)


@pytest.mark.parametrize(
    "freq_f, freq_m, dt, t0",
    [([], [200.0], 1 / 200 / 300, 0.0), ([37.3, 1000.0], [200.0], 1.7e-5, 0.0), ([37.3], [], 3.3e-6, 5.0)],
)
def test_rotation_as_accurate_as_sin_cos_over_a_million_steps(freq_f, freq_m, dt, t0):
    steps = np.full(1_000_000, dt)
    ts, out, rotated = _march_basis(np.array(freq_f, float), np.array(freq_m, float), steps, t0)
    assert rotated > 0.9 * steps.size  # the rotation is used (exact every ANCHOR_EVERY steps)
    for h, f in enumerate(list(freq_f) + list(freq_m)):
        s_true, c_true = _truth(f, ts)
        calls = max(
            np.abs(np.sin(2.0 * np.pi * f * ts) - s_true).max(), np.abs(np.cos(2.0 * np.pi * f * ts) - c_true).max()
        )
        rot = max(np.abs(out[:, 0, h] - s_true).max(), np.abs(out[:, 1, h] - c_true).max())
        assert rot <= calls + 2e-15, (f, rot, calls)
        # pointwise: within 3e-15 plus the round-off of the sin argument itself (4 ulp of 2 pi f t)
        bound = 3e-15 + 4 * np.spacing(2.0 * np.pi * f * ts)
        assert (np.abs(out[:, 0, h] - np.sin(2.0 * np.pi * f * ts)) <= bound).all()
        assert (np.abs(out[:, 1, h] - np.cos(2.0 * np.pi * f * ts)) <= bound).all()


def test_changing_steps_are_exact():
    """Steps that change every few steps: the basis equals sin / cos to round-off (exact
    evaluations, and rotations of a repeated step only)."""
    rng = np.random.default_rng(3)
    steps = np.repeat(rng.uniform(1e-5, 3e-5, 3000), rng.integers(1, 5, 3000))
    ts, out, rotated = _march_basis(np.array([50.0]), np.array([200.0, 410.0]), steps, 0.0)
    assert 0 < rotated < steps.size
    for h, f in enumerate([50.0, 200.0, 410.0]):
        bound = 3e-15 + 4 * np.spacing(2.0 * np.pi * f * ts)
        assert (np.abs(out[:, 0, h] - np.sin(2.0 * np.pi * f * ts)) <= bound).all()
        assert (np.abs(out[:, 1, h] - np.cos(2.0 * np.pi * f * ts)) <= bound).all()
    assert ANCHOR_EVERY >= 2


@pytest.mark.parametrize("method", ["quasi-static", "newmark", "piecewise-linear-adaptive"])
def test_march_local_displacements_match_exact_motion(method):
    """The march's local displacements q = A x - B p(t) + g, with p(t) from the rotated basis,
    against A x - B p(t) + g recomputed with p(t) evaluated by sin / cos in Python (paper case:
    harmonic motion, fixed or piecewise-constant steps): equal to round-off (1e-12 of the scale)."""
    from slipstep.methods.simulation import _motion_signal
    from slipstep.model.excitation import evaluate_compiled

    sim = slipstep.Simulation(slipstep.load_system("paper"), method, periods=2)
    assert sim.march() == slipstep.Status.OK
    cs, out = sim.compiled, sim.out
    k = int(out.counters[0]) + 1
    assert out.step[k - 1] == k - 1 and out.dofs.size == cs.M.shape[0]  # every step and DOF saved (default)
    p = evaluate_compiled(_motion_signal(cs), out.t[:k])
    q = (out.x[:k] @ cs.A.T - p @ cs.B.T + cs.g)[:, out.rows]  # the saved contact rows, in their order
    scale = np.abs(q).max()
    assert np.abs(out.q[:k] - q).max() <= 1e-12 * scale
