"""Frequency response: the FRF driver, steady states per frequency, linear limits, harmonics.

The layout of every FRF Dataset (marched, shot, harmonic balance) is declared once, in
:mod:`slipstep.output.frf_schema`. Re-exported here from the packages below that harmonic
balance shares: the linear limits (:mod:`slipstep.steady.linear`) and ``retune``
(:mod:`slipstep.model.retune`).
"""

from slipstep.frequency.harmonics import harmonics
from slipstep.steady.linear import linear_limits, linear_response
from slipstep.frequency.choice import choose_solver
from slipstep.frequency.response import SOLVERS, STEADY_SOLVERS, frf
from slipstep.model.retune import retune
from slipstep.output.frf_schema import FRF_SCHEMA
from slipstep.frequency.slow_sweep import sine_sweep

__all__ = [
    "FRF_SCHEMA",
    "SOLVERS",
    "STEADY_SOLVERS",
    "choose_solver",
    "frf",
    "harmonics",
    "linear_limits",
    "linear_response",
    "retune",
    "sine_sweep",
]
