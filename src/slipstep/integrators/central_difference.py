"""Central difference (explicit; Newmark beta = 0, gamma = 1/2), order 2.

    x_{n+1} = x_n + dt v_n + dt^2/2 a_n,   contact law at q(x_{n+1}) with w_n,
    (M + dt/2 C) a_{n+1} = f_e(t_{n+1}) - K x_{n+1} - A^T f_{n+1} - C (v_n + dt/2 a_n),
    v_{n+1} = v_n + dt/2 (a_n + a_{n+1})          (kernel: slipstep.kernels.explicit)

Stability limit. For an undamped mode x'' = -omega^2 x the scheme is
x_{n+1} - (2 - omega^2 dt^2) x_n + x_{n-1} = 0, with roots of modulus 1 while
|2 - omega^2 dt^2| <= 2, i.e. omega dt <= 2 (Omega_crit = 2, unchanged by viscous damping
for gamma = 1/2). Hence dt <= 2 / omega_max = T_min / pi: numerically the same number as
the implicit Newmark's convergence limit, but here exceeding it makes the march diverge.
The contact stiffness enters omega_max: full stick is the most restrictive state; the
adaptive variant uses T_min(S_n) of the current contact state.

Adaptive variant: default step_ratio 0.9. Each step map of the variable-step scheme is
stable for omega dt <= 2, but near that limit the maps of different dt (and different
contact states) do not share eigenvectors and their product can grow (the stick/slip
switching acts like a parametric excitation): on the paper case step_ratio 0.95 and 1.0
diverge, 0.9 and below do not. The fixed variant rounds dt down to a whole number of steps
per period and keeps a single dt, so it runs at step_ratio 1.
"""

from __future__ import annotations

from slipstep.integrators.base import ExplicitIntegrator
from slipstep.kernels.explicit import CENTRAL_DIFFERENCE


class CentralDifference(ExplicitIntegrator):
    name = "central-difference"
    order = 2
    omega_crit = 2.0
    kernel_kind = CENTRAL_DIFFERENCE
    adaptive_step_ratio = 0.9
