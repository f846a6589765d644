"""An independent reference for the single-DOF Jenkins oscillator under a harmonic force:
the periodic orbit of the exact continuous equations, by scipy (solve_ivp, DOP853 with
event-located stick/slip transitions) and a Newton shooting on the one-period map (fsolve).

    m x'' + c x' + k x + T = F sin(w t)
    stick:  T = k_t (x - w_s)        until |T| reaches Fs          (w_s the slider)
    slip:   T = +/- Fs, w_s = x -/+ Fs/k_t   until x' changes sign  (then stick)

Returns the half peak-to-peak amplitude of x, the friction energy per cycle (Fs times the
slid distance) and the excitation work per cycle (the integral of F sin(w t) x' dt, carried
as a third state of the integration). Nothing here uses slipstep.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

STICK, SLIP_POS, SLIP_NEG = 1, 2, 3


def _period_map(params, x0, v0, w0, mode, record=False):
    m, c, k, kt, fs, force, omega = params
    T = 2 * np.pi / omega
    t, x, v, w = 0.0, x0, v0, w0
    xs, energy, work = [x0], 0.0, 0.0
    while t < T * (1 - 1e-13):
        if mode == STICK:

            def rhs(tt, y, w=w):
                f = force * np.sin(omega * tt)
                return [y[1], (f - c * y[1] - k * y[0] - kt * (y[0] - w)) / m, f * y[1]]

            def to_pos(tt, y, w=w):
                return kt * (y[0] - w) - fs

            def to_neg(tt, y, w=w):
                return kt * (y[0] - w) + fs

            to_pos.terminal = to_neg.terminal = True
            to_pos.direction, to_neg.direction = 1, -1
            events = [to_pos, to_neg]
        else:
            s = 1.0 if mode == SLIP_POS else -1.0

            def rhs(tt, y, s=s):
                f = force * np.sin(omega * tt)
                return [y[1], (f - c * y[1] - k * y[0] - s * fs) / m, f * y[1]]

            def reverse(tt, y):
                return y[1]

            reverse.terminal = True
            reverse.direction = -1 if mode == SLIP_POS else 1
            events = [reverse]

        def extreme(tt, y):
            return y[1]

        sol = solve_ivp(
            rhs,
            (t, T),
            [x, v, 0.0],
            method="DOP853",
            rtol=1e-12,
            atol=[1e-18, 1e-18, 1e-30],
            events=events + [extreme],
            dense_output=record,
        )
        if record:
            xs += list(sol.sol(np.linspace(t, sol.t[-1], 4000))[0]) + [float(ye[0]) for ye in sol.y_events[-1]]
        x_start = x
        t, x, v = sol.t[-1], sol.y[0, -1], sol.y[1, -1]
        work += sol.y[2, -1]
        if mode != STICK:
            energy += fs * abs(x - x_start)
            w = x - (fs / kt if mode == SLIP_POS else -fs / kt)
        hit = [i for i, te in enumerate(sol.t_events[:-1]) if te.size]
        if not hit:
            break
        if mode == STICK:
            mode = SLIP_POS if hit[0] == 0 else SLIP_NEG
        else:
            mode = STICK  # the slider stays where the slip left it
    return x, v, w, mode, energy, xs, work


def periodic_orbit(m, c, k, kt, fs, force, frequency, x0, v0, w0, mode):
    """(amplitude [m], friction energy per cycle [J]) of the periodic orbit through the guess
    (x0, v0, w0) with the contact in ``mode`` at t = 0 (1 stick, 2 slip+, 3 slip-)."""
    orbit = periodic_orbit_energies(m, c, k, kt, fs, force, frequency, x0, v0, w0, mode)
    return orbit["amplitude"], orbit["friction_energy"]


def periodic_orbit_energies(m, c, k, kt, fs, force, frequency, x0, v0, w0, mode) -> dict:
    """The periodic orbit through the guess (as :func:`periodic_orbit`): amplitude [m],
    friction_energy and excitation_work per cycle [J]."""
    params = (m, c, k, kt, fs, force, 2 * np.pi * frequency)
    slaved = mode != STICK  # in slip the slider follows x: w = x -/+ Fs / k_t

    def slider(x, w):
        return x - fs / kt if mode == SLIP_POS else (x + fs / kt if mode == SLIP_NEG else w)

    def residual(z):
        x, v = z[0], z[1]
        w = slider(x, z[2] if not slaved else 0.0)
        x1, v1, w1, _, _, _, _ = _period_map(params, x, v, w, mode)
        r = [(x1 - x) / scale_x, (v1 - v) / scale_v]
        return r if slaved else r + [(w1 - w) / scale_x]

    scale_x, scale_v = max(abs(x0), 1e-9), max(abs(v0), 1e-6)
    guess = [x0, v0] if slaved else [x0, v0, w0]
    z, info, ok, msg = fsolve(residual, guess, full_output=True, xtol=1e-11, epsfcn=1e-14)
    assert np.abs(info["fvec"]).max() < 1e-8, msg
    x, v = z[0], z[1]
    _, _, _, _, energy, xs, work = _period_map(params, x, v, slider(x, z[2] if not slaved else 0.0), mode, record=True)
    return {"amplitude": 0.5 * (max(xs) - min(xs)), "friction_energy": energy, "excitation_work": work}
