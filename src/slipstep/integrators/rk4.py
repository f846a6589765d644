"""Classical 4th-order Runge-Kutta on the first-order form (paper App. A.1.1, Eq. A4):

    y = [x, v],  y' = F(t, y) = [v, M^-1 (f_e(t) - C v - K x - A^T f(q(x, t), w_n))]
    k1 = F(t_n, y_n), k2 = F(t_n + dt/2, y_n + dt/2 k1), k3 = F(t_n + dt/2, y_n + dt/2 k2),
    k4 = F(t_n + dt, y_n + dt k3),   y_{n+1} = y_n + dt/6 (k1 + 2 k2 + 2 k3 + k4)

The sliders w (contact history) stay at w_n in every stage and are updated once, by the
law at q(x_{n+1}), when the step is accepted (kernel: slipstep.kernels.explicit).
Order 4 on smooth problems (the contact's kinks reduce it locally).

Stability limit. A mode of the first-order system has eigenvalue lambda = omega
(-zeta +/- i sqrt(1 - zeta^2)), |lambda| = omega. RK4 is stable when
|1 + z + z^2/2 + z^3/6 + z^4/24| <= 1, z = lambda dt. The region reaches |z| = 2.828
(= 2 sqrt 2) on the imaginary axis (undamped) and 2.785 on the negative real axis;
slipstep uses Omega_crit = 2.785: dt <= 2.785 / omega_max = 0.4433 T_min, exact for
overdamped modes and 1.5 % inside the limit for undamped ones. (Between the axes the region
is narrower: 2.62 at zeta = 0.5; for heavily damped models use step_ratio <= 0.94.)
"""

from __future__ import annotations

from slipstep.integrators.base import ExplicitIntegrator
from slipstep.kernels.explicit import RK4 as RK4_KIND


class RK4(ExplicitIntegrator):
    name = "rk4"
    order = 4
    omega_crit = 2.785
    kernel_kind = RK4_KIND
