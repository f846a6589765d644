"""Newmark-beta (paper A.2): the average-acceleration default and any user (beta, gamma).

    x_{n+1} = x_n + dt v_n + dt^2 ((1/2 - beta) a_n + beta a_{n+1})
    v_{n+1} = v_n + dt ((1 - gamma) a_n + gamma a_{n+1})
    M a_{n+1} + C v_{n+1} + K x_{n+1} + A^T f_{n+1} = f_e(t_{n+1})

beta = 1/4, gamma = 1/2: constant average acceleration (trapezoidal), unconditionally stable,
no numerical damping, order 2. beta = 1/6, gamma = 1/2: linear acceleration, order 2,
stable for omega dt <= 2 sqrt(3) (the modified-Newton limit dt < T_min / (2 pi sqrt(1/6))
= 0.390 T_min is the stricter one). gamma > 1/2 damps but drops to order 1.
Step limit: see :meth:`slipstep.integrators.base.ImplicitIntegrator.step_limit_factor`.
"""

from __future__ import annotations

from fractions import Fraction

from slipstep.integrators.base import ImplicitIntegrator
from slipstep.methods.registry import scheme_default
from slipstep.methods.schemes import newmark


class Newmark(ImplicitIntegrator):
    name = "newmark"

    def __init__(
        self, beta: float = scheme_default("newmark", "beta"), gamma: float = scheme_default("newmark", "gamma")
    ):
        self._scheme = newmark(float(beta), float(gamma))  # validates (InputError)
        self.order = 2 if abs(gamma - 0.5) < 1e-12 else 1

    def scheme(self):
        return self._scheme

    @property
    def label(self) -> str:
        """'newmark' or 'newmark(beta=1/6,gamma=1/2)' (exact fractions when they are simple)."""
        b, g = self._scheme.beta, self._scheme.gamma
        if (b, g) == (scheme_default("newmark", "beta"), scheme_default("newmark", "gamma")):
            return "newmark"
        frac = lambda v: (
            str(Fraction(v).limit_denominator(1000))
            if abs(float(Fraction(v).limit_denominator(1000)) - v) < 1e-15
            else repr(v)
        )
        return f"newmark(beta={frac(b)},gamma={frac(g)})"


class LinearAcceleration(Newmark):
    """Newmark with beta = 1/6, gamma = 1/2."""

    name = "linear-acceleration"

    @property
    def label(self) -> str:
        return self.name

    def __init__(self):
        super().__init__(1.0 / 6.0, 0.5)
