"""Loads and prescribed motions (paper Eq. 1: f_e(t) and p(t)).

A :class:`Signal` is a vector-valued function of time, the sum of

* harmonics:   a_c sin(2 pi f t + phi_c)       (per-component amplitude a_c and phase phi_c)
* tables:      linear interpolation of (t_k, y_k), held constant outside the table

optionally multiplied by a smooth start ``(1 - cos(pi t / t_ramp)) / 2`` for t < t_ramp
(a motion that starts with a jump hits an undamped damper like an impulse; ramp it).
Time t = 0 is the end of the static preload.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from slipstep.errors import InputError
from slipstep.model.validate import float_array, names, positive


def _components_vector(field: str, value) -> np.ndarray:
    """One value per signal component: a scalar or a vector, never a matrix."""
    arr = np.atleast_1d(float_array(field, value))
    if arr.ndim != 1:
        raise InputError(
            field, f"has shape {arr.shape}, not one value per component", "give a vector (one value per component)"
        )
    return arr


@dataclass(frozen=True)
class Harmonic:
    """``amplitude[c] * sin(2 pi frequency t + phase[c])``; frequency in Hz, phase in rad."""

    frequency: float
    amplitude: np.ndarray
    phase: np.ndarray | None = None

    def __post_init__(self):
        f = positive("harmonic.frequency", self.frequency)
        a = _components_vector("harmonic.amplitude", self.amplitude)
        ph = np.zeros_like(a) if self.phase is None else _components_vector("harmonic.phase", self.phase)
        if ph.shape != a.shape:
            raise InputError(
                "harmonic.phase", f"has {ph.size} values for {a.size} amplitudes", "give one phase per component"
            )
        object.__setattr__(self, "frequency", f)
        object.__setattr__(self, "amplitude", a)
        object.__setattr__(self, "phase", ph)


@dataclass(frozen=True)
class Tabulated:
    """Samples ``values[k, c]`` at strictly increasing ``times[k]`` [s], linearly interpolated."""

    times: np.ndarray
    values: np.ndarray

    def __post_init__(self):
        t = float_array("table.times", self.times, ndim=1)
        y = float_array("table.values", self.values)
        if y.ndim == 1:
            y = y[:, None]
        if y.ndim != 2 or y.shape[0] != t.size:
            raise InputError(
                "table.values", f"has shape {y.shape} for {t.size} times", "give one row of component values per time"
            )
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise InputError(
                "table.times",
                "must hold at least 2 strictly increasing times",
                "sort the table and remove repeated times",
            )
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", y)


@dataclass(frozen=True)
class Signal:
    """Sum of harmonics and tables over named components (DOFs or motion components)."""

    components: tuple[str, ...]
    harmonics: tuple[Harmonic, ...] = ()
    tables: tuple[Tabulated, ...] = ()
    ramp_time: float = 0.0

    def __post_init__(self):
        comps = names("signal.components", self.components, "component")
        nc = len(comps)
        for h in self.harmonics:
            if h.amplitude.size != nc:
                raise InputError(
                    "harmonic.amplitude",
                    f"has {h.amplitude.size} values for {nc} components {comps}",
                    f"give {nc} amplitudes",
                )
        for tab in self.tables:
            if tab.values.shape[1] != nc:
                raise InputError(
                    "table.values", f"has {tab.values.shape[1]} columns for {nc} components", f"give {nc} columns"
                )
        object.__setattr__(self, "components", comps)
        object.__setattr__(self, "harmonics", tuple(self.harmonics))
        object.__setattr__(self, "tables", tuple(self.tables))
        object.__setattr__(self, "ramp_time", positive("ramp_time", self.ramp_time, allow_zero=True))

    @property
    def fundamental_frequency(self) -> float | None:
        """Lowest harmonic frequency [Hz], or None for a signal made of tables only."""
        return min((h.frequency for h in self.harmonics), default=None)

    def evaluate(self, t) -> np.ndarray:
        """Values at times ``t`` (NumPy reference of the compiled evaluator), shape (nt, nc)."""
        return evaluate_compiled(compile_signal(self), np.atleast_1d(np.asarray(t, dtype=float)))


@dataclass(frozen=True)
class Excitation:
    """Constant DOF loads [N] (ramped in the static preload), varying DOF forces, prescribed motions."""

    constant_force: np.ndarray | None = None
    force: Signal | None = None
    motion: Signal | None = None
    period: float | None = field(default=None)

    def __post_init__(self):
        if self.period is not None:
            object.__setattr__(self, "period", positive("excitation.period", self.period))

    @property
    def fundamental_frequency(self) -> float | None:
        if self.period is not None:
            return 1.0 / self.period
        freqs = [s.fundamental_frequency for s in (self.force, self.motion) if s is not None]
        freqs = [f for f in freqs if f is not None]
        return min(freqs) if freqs else None


class CompiledSignal(NamedTuple):
    """Arrays the kernels evaluate: see :func:`slipstep.kernels.signals.evaluate_signal`."""

    frequency: np.ndarray  # (nh,) Hz
    sin_coefficient: np.ndarray  # (nc, nh)
    cos_coefficient: np.ndarray  # (nc, nh)
    table_time: np.ndarray  # (nt,) s, nt = 0 when there is no table
    table_value: np.ndarray  # (nc, nt)
    ramp_time: float


def compile_signal(signal: Signal | None, n_components: int = 0) -> CompiledSignal:
    """Turn a :class:`Signal` into arrays: a sin(wt+phi) = a cos(phi) sin(wt) + a sin(phi) cos(wt)."""
    if signal is None:
        return CompiledSignal(
            np.zeros(0),
            np.zeros((n_components, 0)),
            np.zeros((n_components, 0)),
            np.zeros(0),
            np.zeros((n_components, 0)),
            0.0,
        )
    nc = len(signal.components)
    freqs = np.array([h.frequency for h in signal.harmonics], dtype=float)
    sin_c = np.array([h.amplitude * np.cos(h.phase) for h in signal.harmonics], dtype=float).reshape(-1, nc).T.copy()
    cos_c = np.array([h.amplitude * np.sin(h.phase) for h in signal.harmonics], dtype=float).reshape(-1, nc).T.copy()
    if signal.tables:
        grid = np.unique(np.concatenate([tab.times for tab in signal.tables]))
        values = np.zeros((nc, grid.size))
        for tab in signal.tables:
            for c in range(nc):
                values[c] += np.interp(grid, tab.times, tab.values[:, c])
    else:
        grid, values = np.zeros(0), np.zeros((nc, 0))
    return CompiledSignal(freqs, sin_c, cos_c, grid, np.ascontiguousarray(values), float(signal.ramp_time))


def evaluate_compiled(sig: CompiledSignal, t: np.ndarray) -> np.ndarray:
    """Vectorised NumPy evaluation of a compiled signal, shape (len(t), nc)."""
    w = 2 * np.pi * sig.frequency
    out = np.sin(np.outer(t, w)) @ sig.sin_coefficient.T + np.cos(np.outer(t, w)) @ sig.cos_coefficient.T
    if sig.table_time.size:
        for c in range(sig.table_value.shape[0]):
            out[:, c] += np.interp(t, sig.table_time, sig.table_value[c])
    if sig.ramp_time > 0:
        ramp = np.where(t < sig.ramp_time, 0.5 * (1 - np.cos(np.pi * np.clip(t, 0, None) / sig.ramp_time)), 1.0)
        out *= ramp[:, None]
    return out


def force_signal(cs) -> CompiledSignal:
    """The force signal of a compiled system (slipstep.model.system.CompiledSystem): f_e(t) is
    ``evaluate_compiled(force_signal(cs), t) + cs.constant_force``."""
    return CompiledSignal(
        cs.force_frequency, cs.force_sin, cs.force_cos, cs.force_table_time, cs.force_table_value, cs.force_ramp
    )


def motion_signal(cs) -> CompiledSignal:
    """The prescribed motion p(t) of a compiled system: ``evaluate_compiled(motion_signal(cs), t)``."""
    return CompiledSignal(
        cs.motion_frequency, cs.motion_sin, cs.motion_cos, cs.motion_table_time, cs.motion_table_value, cs.motion_ramp
    )
