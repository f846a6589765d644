"""Harmonic balance starts for shooting points that did not converge (issue 24).

Shooting steps in frequency from the previous point's orbit. Where the orbit the FRF follows is
unstable (a largest Floquet multiplier modulus above 1, e.g. on the overhanging side of a
softening resonance), marching never settles on it and Newton from the previous orbit or from
the preload can fail. Harmonic balance does not march: its pseudo-arclength continuation
(slipstep.hbm.continuation.trace) follows the branch from the previous frequency f_prev to
the failed one f whatever the stability, and the state at t = 0 of its solution,

    x(0) = Re sum_h X_h,   v(0) = Re sum_h i h omega X_h,   sliders and states of the AFT cycle,

(slipstep.hbm.crosscheck.hbm_initial_state) is a start within the truncation error of the orbit,
from which Newton on the exact period map of the discrete march converges. The orbit returned
is the shooting one (no harmonic truncation), with its Floquet multipliers.
"""

from __future__ import annotations

import math

import numpy as np

from slipstep.errors import InputError
from slipstep.model.system import System

SEED_HARMONICS = 7
"""Harmonics 0..H of the seeding balance: the start only needs to lie in Newton's basin."""

SEED_STEPS = 4
"""Continuation steps at most per frequency interval between the previous and the failed point."""


class HbmSeeder:
    """Starts from harmonic balance for the points of one FRF sweep of ``system`` (the base
    system; frequencies in Hz). The balance is built once, at the first point that needs it,
    and each solution is the continuation start of the next."""

    def __init__(self, system: System, harmonics: int = SEED_HARMONICS):
        self.system = system
        self.harmonics = harmonics
        self.hb = None
        self.unavailable = ""  # why the balance cannot seed this system ("" while it can)
        self.last = None  # the last solved balance point (Point)

    def _balance(self):
        from slipstep.hbm.residual import HarmonicBalance

        if self.hb is None and not self.unavailable:
            try:
                self.hb = HarmonicBalance(self.system, self.harmonics)
            except InputError as exc:  # e.g. a law without a piecewise-linear form
                self.unavailable = str(exc)
        return self.hb

    def start(self, f_previous: float | None, f: float) -> tuple[dict | None, str]:
        """(initial state at t = 0 for the shooting solver at ``f`` [Hz], text): the balance
        continued from ``f_previous`` (or solved at ``f`` alone without one); (None, why) when it
        did not converge."""
        from slipstep.hbm.continuation import solve_point, trace
        from slipstep.hbm.crosscheck import hbm_initial_state

        hb = self._balance()
        if hb is None:
            return None, f"no harmonic balance start: {self.unavailable}"
        omega = 2.0 * math.pi * f
        point = self.last if self.last is not None and _same(self.last.omega, omega) else None
        if point is None and f_previous is not None and f_previous != f:
            omega0 = 2.0 * math.pi * f_previous
            if self.last is None or not _same(self.last.omega, omega0):
                self.last = solve_point(hb, omega0, 1.0, None if self.last is None else self.last.Y)
            if self.last.converged:
                branch = trace(hb, "omega", omega0, omega, 1.0, max_dp=abs(omega - omega0) / SEED_STEPS, Z0=self.last.Y)
                end = branch.points[-1] if branch.points else None
                if end is not None and end.converged and _same(end.omega, omega):
                    point = end
        if point is None:
            point = solve_point(hb, omega, 1.0, None if self.last is None else self.last.Y)
        if not point.converged:
            self.last = None
            return None, f"no harmonic balance start: the balance (H = {self.harmonics}) did not converge at {f:.6g} Hz"
        self.last = point
        hb.linear.at(point.omega, point.level)  # the AFT cycle of this point: its sliders at t = 0
        hb.aft.evaluate(point.Z, False)
        return hbm_initial_state(hb, point), f"started from harmonic balance (H = {self.harmonics})"


def _same(omega_a: float, omega_b: float) -> bool:
    """One frequency to the continuation's landing accuracy."""
    return bool(np.isclose(omega_a, omega_b, rtol=1e-9, atol=0.0))
