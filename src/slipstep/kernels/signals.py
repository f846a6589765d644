"""Compiled evaluation of a signal (see slipstep.model.excitation):

    y_c(t) = ramp(t) * [ sum_h (S_ch sin(2 pi f_h t) + C_ch cos(2 pi f_h t)) + interp(t; t_k, Y_ck) ]   (no table: nt = 0)
    ramp(t) = (1 - cos(pi t / t_r)) / 2 for 0 <= t < t_r, else 1
"""

import numpy as np
from numba import njit

#: harmonic_basis: exact sin / cos at least every ANCHOR_EVERY steps (rotations in between)
ANCHOR_EVERY = 32
#: harmonic_basis: a step within this relative difference of the rotation step is rotated (then corrected)
ROTATE_RTOL = 1e-6


@njit(cache=True, error_model="numpy", inline="always")
def evaluate_signal(t, freq, sin_c, cos_c, tab_t, tab_v, ramp_time, out):
    nc = out.shape[0]
    for c in range(nc):
        out[c] = 0.0
    for h in range(freq.shape[0]):
        wt = 2.0 * np.pi * freq[h] * t
        s = np.sin(wt)
        co = np.cos(wt)
        for c in range(nc):
            out[c] += sin_c[c, h] * s + cos_c[c, h] * co
    nt = tab_t.shape[0]
    if nt == 0:
        pass
    elif t <= tab_t[0]:
        for c in range(nc):
            out[c] += tab_v[c, 0]
    elif t >= tab_t[nt - 1]:
        for c in range(nc):
            out[c] += tab_v[c, nt - 1]
    else:
        k = np.searchsorted(tab_t, t, side="right") - 1
        r = (t - tab_t[k]) / (tab_t[k + 1] - tab_t[k])
        for c in range(nc):
            out[c] += (1.0 - r) * tab_v[c, k] + r * tab_v[c, k + 1]
    if ramp_time > 0.0 and t < ramp_time:
        fac = 0.5 * (1.0 - np.cos(np.pi * max(t, 0.0) / ramp_time))
        for c in range(nc):
            out[c] *= fac


@njit(cache=True, nogil=True, error_model="numpy")
def motion_at(sys, t, out):
    """Prescribed motion p(t)."""
    evaluate_signal(t, sys.motion_frequency, sys.motion_sin, sys.motion_cos,
                    sys.motion_table_time, sys.motion_table_value, sys.motion_ramp, out)


@njit(cache=True, nogil=True, error_model="numpy")
def force_at(sys, t, load_factor, out):
    """External force f_e(t) = load_factor * f_const + f_var(t)."""
    evaluate_signal(t, sys.force_frequency, sys.force_sin, sys.force_cos,
                    sys.force_table_time, sys.force_table_value, sys.force_ramp, out)
    for i in range(out.shape[0]):
        out[i] += load_factor * sys.constant_force[i]


@njit(cache=True, error_model="numpy", inline="always")
def harmonic_basis(t, freq_f, freq_m, basis, clock):
    """The harmonic basis of the loads and motions at time t: basis[0, h] = sin(2 pi f_h t),
    basis[1, h] = cos(2 pi f_h t), the force harmonics first (freq_f), then the motion ones
    (freq_m). On a march of steps of one size the basis is advanced by rotation instead of
    sin / cos calls:

        sin(w (t_p + d)) = sin(w t_p) cos(w d) + cos(w t_p) sin(w d)
        cos(w (t_p + d)) = cos(w t_p) cos(w d) - sin(w t_p) sin(w d)

    with the rotation of the step d held in basis[2], basis[3] (cos(w d), sin(w d)), then
    corrected to first order for the round-off of the accumulated time, e = (t - t_p) - d
    (|w e| < 1e-15: the second-order term is below 1e-30): s += w e c, c -= w e s.
    Exact sin / cos at least every ANCHOR_EVERY steps and whenever the step differs from d by
    more than ROTATE_RTOL; the rotation of a new step size is computed at its second step
    (a step size used once costs no more than before). clock = [t_p, d, rotations since the
    exact anchor, the previous step]; clock[1] = nan: no rotation yet. Round-off: that of
    the sin / cos calls plus < 2e-15 (tests/test_signals.py)."""
    nf = freq_f.shape[0]
    nh = nf + freq_m.shape[0]
    if nh == 0:
        return
    delta = t - clock[0]
    step = clock[1]
    if abs(delta - step) <= ROTATE_RTOL * step and clock[2] < ANCHOR_EVERY:
        e = delta - step
        for h in range(nh):
            w = 2.0 * np.pi * (freq_f[h] if h < nf else freq_m[h - nf])
            s0, c0 = basis[0, h], basis[1, h]
            s1 = s0 * basis[2, h] + c0 * basis[3, h]
            c1 = c0 * basis[2, h] - s0 * basis[3, h]
            basis[0, h] = s1 + w * e * c1
            basis[1, h] = c1 - w * e * s1
        clock[2] += 1.0
    else:
        if not abs(delta - step) <= ROTATE_RTOL * step and abs(delta - clock[3]) <= ROTATE_RTOL * delta:
            for h in range(nh):  # the second step of this size: its rotation
                wd = 2.0 * np.pi * (freq_f[h] if h < nf else freq_m[h - nf]) * delta
                basis[2, h] = np.cos(wd)
                basis[3, h] = np.sin(wd)
            clock[1] = delta
        for h in range(nh):
            wt = 2.0 * np.pi * (freq_f[h] if h < nf else freq_m[h - nf]) * t
            basis[0, h] = np.sin(wt)
            basis[1, h] = np.cos(wt)
        clock[2] = 0.0
    clock[3] = delta
    clock[0] = t


@njit(cache=True, error_model="numpy", inline="always")
def signal_from_basis(sin_c, cos_c, basis, h0, out):
    """out_c = sum_h (S_ch sin_h + C_ch cos_h) with the basis columns h0 + h (harmonics only:
    no table, no ramp)."""
    for c in range(out.shape[0]):
        out[c] = 0.0
    for h in range(sin_c.shape[1]):
        s = basis[0, h0 + h]
        co = basis[1, h0 + h]
        for c in range(out.shape[0]):
            out[c] += sin_c[c, h] * s + cos_c[c, h] * co
