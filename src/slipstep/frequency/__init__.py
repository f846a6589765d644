"""Frequency response: the FRF driver, steady states per frequency, linear limits, harmonics.

The layout of every FRF Dataset (marched, shot, harmonic balance) is declared once, in
:mod:`slipstep.frequency.schema`.
"""

from slipstep.frequency.harmonics import harmonics
from slipstep.frequency.linear import linear_limits, linear_response
from slipstep.frequency.choice import choose_solver
from slipstep.frequency.response import SOLVERS, STEADY_SOLVERS, frf
from slipstep.frequency.retune import retune
from slipstep.frequency.schema import FRF_SCHEMA
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
