"""Periodic steady states of a system under periodic excitation, by marching period after
period (:func:`march_to_steady`) and by shooting, Newton on the one-period map
(:func:`shoot`). Both return a :class:`SteadyState`; harmonic balance cross-checks call them.
"""

from slipstep.steady.marching import march_to_steady
from slipstep.steady.shooting import shoot
from slipstep.steady.state import State, SteadyState

__all__ = ["State", "SteadyState", "march_to_steady", "shoot"]
