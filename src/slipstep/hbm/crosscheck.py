"""The time-marching cross-check of harmonic balance points (issue 13 item 4).

At a chosen point (frequency, excitation level) the periodic steady state of the SAME
System is computed by time marching (exact for the discrete model, no harmonic truncation)
and compared with the HBM answer:

    check_amplitude_rel_diff = max_j |A_j(HBM) - A_j(march)| / max_j A_j(march)
    check_energy_rel_diff    = |sum_c E_c(HBM) - sum_c E_c(march)| / |sum_c E_c(march)|

A: half peak-to-peak amplitude of the response DOFs over one steady period, E_c: friction
energy per cycle of contact c (slipstep.post.energy.friction_energy_per_period on the
marched period). The whole cross-check sits behind :func:`steady_reference`, which uses
``slipstep.steady.march_to_steady`` when it is available and otherwise marches from the
static preload with ``slipstep.run`` for a growing number of periods until two consecutive
periods agree to ``tolerance`` (relative to the amplitude).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from slipstep.model.excitation import Excitation, Harmonic, Signal
from slipstep.model.system import System


@dataclass
class SteadyReference:
    """The marched steady state at one point."""

    frequency_hz: float
    level: float
    amplitude: np.ndarray  # (n_responses,) half peak-to-peak
    energy: np.ndarray  # (n_contacts,) friction energy per cycle [J]
    periods: int
    status: str
    message: str
    method: str


def _scaled_signal(sig: Signal | None, ratio: float, level: float) -> Signal | None:
    if sig is None:
        return None
    harmonics = tuple(Harmonic(h.frequency * ratio, h.amplitude * level, h.phase) for h in sig.harmonics)
    return Signal(sig.components, harmonics, sig.tables, sig.ramp_time)


def retuned(system: System, frequency_hz: float, level: float = 1.0) -> System:
    """The system with its harmonic excitation moved to fundamental ``frequency_hz`` (multiples
    kept) and scaled by ``level`` (constant loads unchanged)."""
    try:  # the shared retune (issue 11), when it exists
        from slipstep.model.retune import retune as _retune
    except ImportError:
        _retune = None
    if _retune is not None and level == 1.0:
        return _retune(system, frequency_hz)
    exc = system.excitation
    f0 = exc.fundamental_frequency
    ratio = frequency_hz / f0
    new = Excitation(
        exc.constant_force,
        _scaled_signal(exc.force, ratio, level),
        _scaled_signal(exc.motion, ratio, level),
        None if exc.period is None else exc.period / ratio,
    )
    if _retune is not None:
        return _retune(replace(system, excitation=new), frequency_hz)
    return replace(system, excitation=new)


def _periodic_change(x: np.ndarray, n_per: int) -> float:
    """max |x(last period) - x(previous period)| / amplitude, on a grid of n_per steps per period."""
    last, prev = x[-n_per - 1 :], x[-2 * n_per - 1 : -n_per]
    amp = max(0.5 * (last.max(axis=0) - last.min(axis=0)).max(), 1e-300)
    return float(np.abs(last - prev).max() / amp)


def _march_own(system, responses, method, tolerance, max_periods, steps_per_period, **run_options):
    from slipstep.methods.simulation import run

    T = system.period
    periods = 25
    while True:
        ds = run(
            system,
            method,
            periods=periods,
            max_step=T / steps_per_period,
            **{"sensitivity_check": False, **run_options},
        )
        if ds.attrs["status"] != "OK":
            return ds, periods, ds.attrs["status"], ds.attrs["status_message"]
        n_per = round(T / ds.attrs["dt_s"])
        change = _periodic_change(ds.displacement.values, n_per)
        if change <= tolerance:
            return ds, periods, "OK", f"steady after {periods} periods (change {change:.2g})"
        if periods >= max_periods:
            return ds, periods, "NOT_CONVERGED", f"not steady after {periods} periods (change {change:.2g})"
        periods = min(2 * periods, max_periods)


def hbm_initial_state(hb, point) -> dict:
    """The state at t = 0 of a harmonic balance solution, to start a march from: x(0), v(0)
    from the DOF phasors, the sliders and states before the AFT cycle's first sample."""
    h, w = hb.basis.h, point.omega
    x0 = np.real(point.X.sum(axis=0))
    v0 = np.real((1j * h[:, None] * w * point.X).sum(axis=0))
    return {"x": x0, "v": v0, "w": hb.aft.wt[-1].copy(), "states": hb.aft.st[-1].copy()}


def steady_reference(
    system: System,
    frequency_hz: float,
    level: float,
    responses: np.ndarray,
    *,
    method: str = "piecewise-linear",
    tolerance: float = 1e-6,
    max_periods: int = 400,
    steps_per_period: int = 2000,
    initial: dict | None = None,
    **run_options,
) -> SteadyReference:
    """The marched periodic steady state of ``system`` at (frequency_hz, level): amplitudes of
    the response DOFs (indices ``responses``) and friction energy per cycle per contact.
    ``initial``: a start state (:func:`hbm_initial_state`; used by slipstep.steady only, the
    fallback marches from the static preload)."""
    from slipstep.post.energy import friction_energy_per_period

    sys_f = retuned(system, frequency_hz, level)
    T = 1.0 / frequency_hz
    try:
        from slipstep.steady import march_to_steady
    except ImportError:
        march_to_steady = None
    if march_to_steady is not None:
        st = march_to_steady(
            sys_f,
            method,
            tolerance=tolerance,
            max_periods=max_periods,
            initial=initial,
            min_steps_per_period=steps_per_period,
            **run_options,
        )
        last = st.period
        periods, status, message = int(st.periods), str(getattr(st.status, "name", st.status)), str(st.message)
        x = last.displacement.values
        energy = friction_energy_per_period(last, T).values
    else:
        ds, periods, status, message = _march_own(
            sys_f, responses, method, tolerance, max_periods, steps_per_period, **run_options
        )
        t = ds.time.values
        last = ds.isel(time=slice(int(np.searchsorted(t, t[-1] - T * (1 + 1e-9))), None))
        x = last.displacement.values
        energy = friction_energy_per_period(ds, T).values
    amp = 0.5 * (x.max(axis=0) - x.min(axis=0))[responses]
    return SteadyReference(frequency_hz, level, amp, energy, periods, status, message, method)


def relative_differences(
    amp_hbm: np.ndarray, energy_hbm: np.ndarray, ref: SteadyReference, work: float
) -> tuple[float, float]:
    """(amplitude, energy) relative differences, as defined in the module docstring. The energy
    difference is NaN where the marched friction energy is below 1e-9 of the excitation work
    ``work`` (no friction dissipation to compare: a stuck or lifted point)."""
    a = float(np.abs(amp_hbm - ref.amplitude).max() / max(ref.amplitude.max(), 1e-300))
    e_ref, e = float(ref.energy.sum()), float(np.sum(energy_hbm))
    if abs(e_ref) <= 1e-9 * abs(work):
        return a, math.nan
    return a, abs(e - e_ref) / abs(e_ref)
