"""Implicit time-integration schemes of the Newmark / generalised-alpha family (paper App. A).

All are the generalised-alpha balance of :mod:`slipstep.kernels.march` with parameters:

    Newmark(beta, gamma):        alpha_m = alpha_f = 0
    HHT(alpha), alpha in [0, 1/3]: alpha_m = 0, alpha_f = alpha, gamma = 1/2 + alpha, beta = (1 + alpha)^2 / 4
    Generalised-alpha(rho_inf)  (Chung & Hulbert 1993):
        alpha_m = (2 rho - 1)/(rho + 1), alpha_f = rho/(rho + 1),
        gamma = 1/2 - alpha_m + alpha_f, beta = (1 - alpha_m + alpha_f)^2 / 4
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

from slipstep.errors import InputError
from slipstep.methods import step_control as SC
from slipstep.methods.registry import scheme_default


@dataclass(frozen=True)
class Scheme:
    name: str
    beta: float = scheme_default("newmark", "beta")
    gamma: float = scheme_default("newmark", "gamma")
    alpha_m: float = 0.0
    alpha_f: float = 0.0

    @property
    def step_limit_factor(self) -> float:
        """dt <= factor * T_min, factor = 1 / (2 pi sqrt(beta)): the modified-Newton convergence
        limit (paper 4.2; slipstep.methods.step_control.convergence_factor)."""
        return SC.convergence_factor(self.beta)

    @property
    def omega_crit(self) -> float:
        """Stability limit Omega_crit = omega_max dt (inf: unconditionally stable;
        slipstep.methods.step_control.newmark_omega_crit)."""
        return SC.newmark_omega_crit(self.beta, self.gamma, self.alpha_m, self.alpha_f)

    @property
    def stability_limit_factor(self) -> float:
        """dt <= factor * T_min for stability, factor = Omega_crit / (2 pi) (inf if unconditional)."""
        return SC.stability_factor(self.omega_crit)


def newmark(
    beta: float = scheme_default("newmark", "beta"), gamma: float = scheme_default("newmark", "gamma")
) -> Scheme:
    """Newmark(beta, gamma), default average acceleration (defaults: slipstep.methods.registry.SCHEMES)."""
    if not (beta > 0 and gamma >= 0.5):
        raise InputError(
            "scheme.beta/gamma",
            f"beta={beta}, gamma={gamma} is not a usable implicit Newmark scheme",
            "use beta > 0 and gamma >= 1/2 (average acceleration: 1/4, 1/2)",
        )
    default = (scheme_default("newmark", "beta"), scheme_default("newmark", "gamma"))
    name = "newmark" if (beta, gamma) == default else f"newmark(beta={_exact(beta)},gamma={_exact(gamma)})"
    return Scheme(name, beta, gamma)


def hht(alpha: float = scheme_default("hht", "alpha")) -> Scheme:
    """HHT-alpha, 0 <= alpha <= 1/3 (default: slipstep.methods.registry.SCHEMES)."""
    if not 0 <= alpha <= 1 / 3:
        raise InputError("scheme.alpha", f"is {alpha}", "give 0 <= alpha <= 1/3")
    return Scheme(f"hht(alpha={alpha:g})", (1 + alpha) ** 2 / 4, 0.5 + alpha, 0.0, alpha)


def generalized_alpha(rho_inf: float = scheme_default("generalized-alpha", "rho_inf")) -> Scheme:
    """Generalised alpha, 0 <= rho_inf <= 1 (default: slipstep.methods.registry.SCHEMES)."""
    if not 0 <= rho_inf <= 1:
        raise InputError("scheme.rho_inf", f"is {rho_inf}", "give 0 <= rho_inf <= 1")
    am = (2 * rho_inf - 1) / (rho_inf + 1)
    af = rho_inf / (rho_inf + 1)
    return Scheme(f"generalized-alpha(rho_inf={rho_inf:g})", (1 - am + af) ** 2 / 4, 0.5 - am + af, am, af)


def _exact(x: float) -> str:
    """1/6 rather than 0.166667 when x is a simple fraction."""
    frac = Fraction(x).limit_denominator(100)
    return str(frac) if abs(float(frac) - x) < 1e-12 * max(abs(x), 1.0) else f"{x:.12g}"
