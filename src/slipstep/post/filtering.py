"""The paper's a posteriori low-pass filter (Section 5.1, Fig. 6; Remarks 2-3).

An undamped damper rings at its internal frequencies f_d after every contact transition.
When f_d is far above the excitation f_e the ringing is removed by a zero-phase low-pass
filter: a Butterworth filter of order ``order`` applied forward and backward
(scipy.signal.butter + sosfiltfilt), whose amplitude response is

    |H(f)|^2 = 1 / (1 + (f / f_c)^(2 order))       (no phase shift)

Automatic cut-off:
    f_e  = highest excitation frequency of the system (harmonic force / motion components)
    f_d  = lowest internal frequency of the visited contact states, from the eigenvalues
           lambda of M^-1 (K + K_D(S)): f = sqrt(Re lambda) / (2 pi) (slipstep.methods.step_control.state_eigenvalues);
           singular states (a zero eigenvalue: mechanism) contribute their non-zero ones;
           in an assembly, those of the contact-held DOFs (the damper) with the rest fixed
    h    = harmonics kept: min(max_harmonics, floor(f_d / (3 f_e))), at least 1
    f_c  = sqrt(h f_e * f_d)                        (geometric mean of the two bands)

Remark 3: when f_d < separation * f_e (default 5) the two cannot be separated safely; a
:class:`FilterWarning` is issued (never a silent result) and the filter still runs with
h = 1, so the user sees how much the loops change.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy import signal

from slipstep.errors import InputError
from slipstep.post.timeline import is_uniform, resample_uniform

FILTERED_VARIABLES = (
    "displacement",
    "velocity",
    "acceleration",
    "tangential_displacement",
    "normal_displacement",
    "tangential_force",
    "normal_force",
    "slider",
)


class FilterWarning(UserWarning):
    """The excitation and the damper's internal frequencies are too close to filter safely."""


@dataclass(frozen=True)
class CutOff:
    """The chosen cut-off and the frequencies it was chosen from (Hz)."""

    cutoff_Hz: float
    excitation_Hz: float
    internal_Hz: float
    harmonics: int
    separated: bool

    @property
    def ratio(self) -> float:
        return self.internal_Hz / self.excitation_Hz


def excitation_frequencies(system) -> np.ndarray:
    """Frequencies [Hz] of the harmonic force and motion components with non-zero amplitude."""
    cs = system.compile_dense("the filtered contact-state analysis")
    out = []
    for f, s, c in (
        (cs.force_frequency, cs.force_sin, cs.force_cos),
        (cs.motion_frequency, cs.motion_sin, cs.motion_cos),
    ):
        for k, fk in enumerate(np.atleast_1d(f)):
            if np.any(np.asarray(s)[k] != 0) or np.any(np.asarray(c)[k] != 0):
                out.append(float(fk))
    if not out and system.period is not None:
        out.append(1.0 / system.period)
    return np.array(sorted(set(out)))


def state_frequencies(system, state) -> np.ndarray:
    """Internal frequencies [Hz] of one contact state: sqrt(Re lambda) / 2 pi over the
    eigenvalues lambda of M^-1 (K + K_D(S)) with Re lambda > 1e-9 max |lambda| (zero
    eigenvalues of a mechanism are skipped). In an assembly (some DOFs held by contacts only,
    a damper, and others not, blades) the ringing is the damper's: its frequencies with the
    other DOFs fixed (M_mm^-1 (K + K_D(S))_mm, paper Remark 2), the blades' modes being physics."""
    from slipstep.methods.massless import contact_held_dofs
    from slipstep.methods.step_control import effective_stiffness, state_eigenvalues

    cs = system.compile_dense("the filtered contact-state analysis")
    held = contact_held_dofs(system)
    if 0 < held.size < cs.M.shape[0]:
        K = effective_stiffness(cs, np.asarray(state, np.int8))
        ev = np.linalg.eigvals(np.linalg.solve(cs.M[np.ix_(held, held)], K[np.ix_(held, held)]))
    else:
        ev = state_eigenvalues(cs, np.asarray(state, np.int8))
    lam = np.asarray(ev)
    big = float(np.abs(lam).max(initial=0.0))
    keep = lam.real > 1e-9 * big
    return np.sort(np.sqrt(lam.real[keep]) / (2 * math.pi))


def visited_states(ds: xr.Dataset) -> np.ndarray:
    """The distinct contact-state vectors of a result, (k, nd) int8."""
    return np.unique(ds["contact_state"].values.astype(np.int8), axis=0)


def lowest_internal_frequency(system, states) -> float:
    """Lowest internal frequency [Hz] over the given states (see :func:`state_frequencies`)."""
    fmin = math.inf
    for s in np.atleast_2d(states):
        f = state_frequencies(system, s)
        if f.size:
            fmin = min(fmin, float(f[0]))
    return fmin


def choose_cutoff(
    excitation_Hz: float, internal_Hz: float, max_harmonics: int = 10, separation: float = 5.0, warn: bool = True
) -> CutOff:
    """f_c from the module docstring; warns (:class:`FilterWarning`) when
    internal_Hz < separation * excitation_Hz (paper Remark 3)."""
    if not (excitation_Hz > 0 and math.isfinite(excitation_Hz)):
        raise InputError("excitation_Hz", f"is {excitation_Hz}", "give the highest excitation frequency in Hz")
    if not internal_Hz > 0:
        raise InputError("internal_Hz", f"is {internal_Hz}", "give the lowest internal frequency in Hz")
    ratio = internal_Hz / excitation_Hz
    separated = ratio >= separation
    h = int(max(1, min(max_harmonics, math.floor(ratio / 3.0)))) if separated else 1
    fc = math.sqrt(h * excitation_Hz * internal_Hz)
    if not separated and warn:
        warnings.warn(
            f"the damper's lowest internal frequency ({internal_Hz:.4g} Hz) is only {ratio:.2f} times the excitation "
            f"({excitation_Hz:.4g} Hz), less than {separation:g}: the low-pass filter (cut-off {fc:.4g} Hz) cannot "
            "separate the ringing from the response and distorts the loops (paper Remark 3). Compare the raw and "
            "filtered results, or use the quasi-static method only if inertia is negligible.",
            FilterWarning,
            stacklevel=3,
        )
    return CutOff(fc, excitation_Hz, internal_Hz, h, separated)


def lowpass(
    y: np.ndarray, dt: float, cutoff_Hz: float, order: int = 6, axis: int = 0, period_samples: int | None = None
) -> np.ndarray:
    """Zero-phase Butterworth low-pass of samples ``y`` at uniform step ``dt`` [s]
    (scipy.signal.butter(order, f_c, fs=1/dt, output='sos') + sosfiltfilt).

    End effects: with ``period_samples`` P (samples per excitation period, the record
    holding at least one period) the record is continued past its end by repeating its
    last period (the steady-state continuation), so the last period, the one loops are
    taken from, is filtered as if the signal went on; the start uses scipy's odd extension.
    """
    fs = 1.0 / dt
    if not 0 < cutoff_Hz < fs / 2:
        raise InputError(
            "cutoff_Hz",
            f"is {cutoff_Hz:.4g} Hz with a Nyquist frequency of {fs / 2:.4g} Hz",
            "give a cut-off below half the sampling rate (or resample finer)",
        )
    sos = signal.butter(order, cutoff_Hz, btype="low", fs=fs, output="sos")
    y = np.moveaxis(np.asarray(y, float), axis, 0)
    n = y.shape[0]
    if period_samples is not None and 2 <= period_samples < n:
        P = int(period_samples)
        reps = int(math.ceil(max(4 * fs / cutoff_Hz, 3 * (2 * len(sos) + 1)) / P)) + 1
        ext = np.concatenate([y] + [y[n - P :]] * reps, axis=0)
        out = signal.sosfiltfilt(sos, ext, axis=0)[:n]
    else:
        out = signal.sosfiltfilt(sos, y, axis=0)
    return np.moveaxis(out, 0, axis)


def samples_per_period(t: np.ndarray, period: float | None) -> int | None:
    """P when the uniform grid ``t`` holds a whole number P of steps per ``period``, else None."""
    if not period or t.size < 2:
        return None
    P = period / (t[1] - t[0])
    return int(round(P)) if abs(P - round(P)) < 1e-6 * P else None


def filter_dataset(
    ds: xr.Dataset,
    system=None,
    cutoff_Hz: float | None = None,
    excitation_Hz: float | None = None,
    internal_Hz: float | None = None,
    order: int = 6,
    max_harmonics: int = 10,
    separation: float = 5.0,
) -> xr.Dataset:
    """The zero-phase low-pass filtered result (module docstring).

    Non-uniform (adaptive) grids are first resampled onto a uniform one (about the smallest
    step, a whole number of steps per period). The end of the record is continued by its
    last period (see :func:`lowpass`).
    The cut-off is ``cutoff_Hz`` if given, else chosen from excitation_Hz (default: the
    system's highest excitation frequency, or 1/period_s) and internal_Hz (default: the
    lowest internal frequency of the states visited in ``ds``; needs ``system``).
    Filtered: the float contact and DOF variables; contact_state is kept raw. Attributes
    filter_cutoff_Hz, filter_excitation_Hz, filter_internal_Hz, filter_order are added.
    """
    period = ds.attrs.get("period_s")
    if not is_uniform(ds["time"].values):
        t = ds["time"].values
        steps = np.diff(t)
        # the smallest step, ignoring round-off slivers (a fixed dt that does not divide the
        # duration ends with a last step of ~1e-12 s, which would ask for a grid of 1e11 points)
        step = float(steps[steps > 1e-6 * steps.max()].min())
        if period:
            step = period / math.ceil(period / step * (1 - 1e-12))
        ds = resample_uniform(ds, dt=step)
    t = ds["time"].values
    dt = float(t[1] - t[0])
    P = samples_per_period(t, period)
    cut = None
    if cutoff_Hz is None:
        if excitation_Hz is None:
            if system is not None:
                fe = excitation_frequencies(system)
                excitation_Hz = float(fe.max()) if fe.size else None
            if excitation_Hz is None and ds.attrs.get("period_s"):
                excitation_Hz = 1.0 / float(ds.attrs["period_s"])
        if internal_Hz is None:
            if system is None:
                raise InputError(
                    "system",
                    "is needed to find the internal frequencies of the visited states",
                    "pass the System, or internal_Hz / cutoff_Hz",
                )
            internal_Hz = lowest_internal_frequency(system, visited_states(ds))
        if excitation_Hz is None:
            raise InputError(
                "excitation_Hz", "the result has no excitation frequency", "pass excitation_Hz or cutoff_Hz"
            )
        cut = choose_cutoff(excitation_Hz, internal_Hz, max_harmonics, separation)
        cutoff_Hz = cut.cutoff_Hz
    out = ds.copy(deep=True)
    for name in FILTERED_VARIABLES:
        if name in out:
            var = out[name].transpose("time", ...)
            out[name] = var.copy(data=lowpass(var.values, dt, cutoff_Hz, order, period_samples=P))
    out.attrs.update(filter_cutoff_Hz=float(cutoff_Hz), filter_order=order, filtered=1)
    if cut is not None:
        out.attrs.update(
            filter_excitation_Hz=cut.excitation_Hz,
            filter_internal_Hz=cut.internal_Hz,
            filter_harmonics=cut.harmonics,
            filter_separated=int(cut.separated),
        )
    return out
