"""Compiled evaluation of a signal (see slipstep.model.excitation):

    y_c(t) = ramp(t) * [ sum_h (S_ch sin(2 pi f_h t) + C_ch cos(2 pi f_h t)) + interp(t; t_k, Y_ck) ]   (no table: nt = 0)
    ramp(t) = (1 - cos(pi t / t_r)) / 2 for 0 <= t < t_r, else 1
"""

import numpy as np
from numba import njit


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
