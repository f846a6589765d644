"""Move a system's harmonic excitation to a new fundamental frequency."""

from __future__ import annotations

import dataclasses

from slipstep.errors import InputError
from slipstep.model.excitation import Harmonic, Signal
from slipstep.model.validate import positive
from slipstep.model.system import System


def _retuned(signal: Signal | None, f_old: float, f_new: float, what: str) -> Signal | None:
    if signal is None:
        return None
    if signal.tables:
        raise InputError(
            f"excitation.{what}",
            "has tabulated components, which cannot be moved to another frequency",
            "describe the periodic excitation by harmonics ([[force]] / [[motion]])",
        )
    harmonics = tuple(Harmonic(h.frequency / f_old * f_new, h.amplitude, h.phase) for h in signal.harmonics)
    return dataclasses.replace(signal, harmonics=harmonics)


def retune(system: System, frequency_hz: float) -> System:
    """The system with its harmonic excitation (forces and motions) moved to the fundamental
    ``frequency_hz`` [Hz]: every harmonic frequency f_h becomes f_h * frequency_hz / f_1
    (f_1 the current fundamental; the fundamental itself becomes exactly frequency_hz), so multiples (engine orders, higher harmonics) and every
    amplitude and phase are kept; an explicit excitation period becomes 1 / frequency_hz."""
    f_new = positive("frequency", frequency_hz)
    f_old = system.excitation.fundamental_frequency
    if f_old is None:
        raise InputError(
            "excitation",
            "has no harmonic (tables only): there is no frequency to move",
            "give a harmonic force or motion",
        )
    exc = system.excitation
    new = dataclasses.replace(
        exc,
        force=_retuned(exc.force, f_old, f_new, "force"),
        motion=_retuned(exc.motion, f_old, f_new, "motion"),
        period=None if exc.period is None else 1.0 / f_new,
    )
    return dataclasses.replace(system, excitation=new)
