"""Hilber-Hughes-Taylor alpha (HHT-alpha): Newmark relations with the balance at t_{n+1-alpha}

    M a_{n+1} + (1 - alpha) (C v_{n+1} + K x_{n+1} + A^T f_{n+1} - f_{e,n+1})
              + alpha (C v_n + K x_n + A^T f_n - f_{e,n}) = 0,
    gamma = 1/2 + alpha,  beta = (1 + alpha)^2 / 4,  0 <= alpha <= 1/3

(slipstep's alpha is Hughes' -alpha). Unconditionally stable, order 2, numerical damping
grows with omega dt: spectral radius at omega dt -> inf is (1 - alpha) / (1 + alpha); it damps
the damper's ~10 kHz ringing while keeping the 200 Hz response. Run by kernels.march
(alpha_m = 0, alpha_f = alpha). Step limit: dt < T_min / (2 pi sqrt(beta)) = T_min / (pi (1 + alpha)).
"""

from __future__ import annotations

from slipstep.integrators.base import ImplicitIntegrator
from slipstep.methods.registry import scheme_default
from slipstep.methods.schemes import hht


class HHT(ImplicitIntegrator):
    name = "hht"

    def __init__(self, alpha: float = scheme_default("hht", "alpha")):
        self._scheme = hht(float(alpha))

    def scheme(self):
        return self._scheme
