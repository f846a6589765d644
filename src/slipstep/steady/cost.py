"""The cost of a time-domain steady state of a system: whether shooting (and marching) to the
periodic orbit is affordable, or harmonic balance should take the point (rule 3 of the FRF
solver choice, slipstep.frequency.choice; the ``check="auto"`` of slipstep.hbm.frf).

One shooting Newton iteration propagates the one-period Jacobian over 2 n + n_d unknowns,
about N n (3 n + r) (2 n + n_d) multiply-adds (N = STEADY_STEPS_PER_PERIOD steps, r contact
DOFs, n_d sliders: kernels/sensitivity.py); a sparse structure above DENSE_MAX_N DOFs has no
dense Jacobian at all.
"""

from __future__ import annotations

import math

import numpy as np

from slipstep.model.structure import DENSE_MAX_N
from slipstep.model.system import System

SHOOTING_MAX_FLOP = 2e10  # multiply-adds of one period Jacobian above which auto takes harmonic balance


def time_domain_cost(system: System) -> tuple[float, str]:
    """(multiply-adds of one shooting Newton iteration, why it is too costly or ""): infinite for a
    sparse structure above DENSE_MAX_N (shooting needs the dense matrices); rule 3 of the module
    docstring."""
    n = system.n_dofs
    if system.structure.sparse and n > DENSE_MAX_N:
        return math.inf, (
            f"the structure is sparse with {n} DOFs (above {DENSE_MAX_N}), where shooting's Jacobian would be "
            "dense over 2n unknowns"
        )
    from slipstep.steady.marching import STEADY_STEPS_PER_PERIOD

    cs = system.compile("contacts")
    touched = int(np.count_nonzero(np.asarray(abs(cs.A).sum(axis=0)).ravel()))  # the contact DOFs
    nd = int(cs.kt.shape[0])
    flop = float(STEADY_STEPS_PER_PERIOD) * n * (3 * n + touched) * (2 * n + nd)
    if flop <= SHOOTING_MAX_FLOP:
        return flop, ""
    return flop, (
        f"one shooting Newton iteration would cost about {flop:.1e} multiply-adds ({n} DOFs, {nd} sliders; "
        f"above {SHOOTING_MAX_FLOP:.0e})"
    )
