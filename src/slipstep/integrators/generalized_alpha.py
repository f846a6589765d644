"""Generalised-alpha (Chung & Hulbert 1993), parametrised by the high-frequency spectral
radius rho_inf in [0, 1]:

    M a_{n+1-am} + C v_{n+1-af} + K x_{n+1-af} + A^T f_{n+1-af} = f_e(t_{n+1-af}),
    y_{n+1-a} = (1 - a) y_{n+1} + a y_n,
    am = (2 rho - 1)/(rho + 1), af = rho/(rho + 1), gamma = 1/2 - am + af, beta = (1 - am + af)^2 / 4

Unconditionally stable, order 2, minimal low-frequency damping for the given high-frequency
damping (rho_inf = 1: trapezoidal rule, no damping; rho_inf = 0: asymptotic annihilation).
Run by kernels.march. Step limit: dt < T_min / (2 pi sqrt(beta)).
"""

from __future__ import annotations

from slipstep.integrators.base import ImplicitIntegrator
from slipstep.methods.registry import scheme_default
from slipstep.methods.schemes import generalized_alpha


class GeneralizedAlpha(ImplicitIntegrator):
    name = "generalized-alpha"

    def __init__(self, rho_inf: float = scheme_default("generalized-alpha", "rho_inf"), rho: float | None = None):
        self._scheme = generalized_alpha(float(rho_inf if rho is None else rho))

    def scheme(self):
        return self._scheme
