"""The contract every time-integration scheme of slipstep follows (paper Appendix A).

Adding a scheme takes one module in this package and one line in ``INTEGRATORS``
(:mod:`slipstep.integrators`). The module defines a subclass of :class:`Integrator`.
"""

from __future__ import annotations

import abc
import math

from slipstep.errors import InputError
from slipstep.methods.registry import EXPLICIT_VARIANTS, VARIANT_METHODS, VARIANTS  # noqa: F401  (re-exported)


class Integrator(abc.ABC):
    """A direct time-integration scheme for ``M a + C v + K x + A^T f(q, w) = f_e(t)``.

    Contract for adding a scheme (like ``scipy.integrate.OdeSolver``):

    1. ``name``: the registry key (lower case, dashes), also written to the result's
       ``scheme`` attribute (with parameters where the scheme has any).
    2. ``kind``: ``'implicit'`` (an equation system per step, iterated for the contacts)
       or ``'explicit'`` (the new state follows from the old one by evaluations only).
    3. ``order``: the order of accuracy p, global error O(dt^p) on a smooth linear problem
       (``tests/test_integrators.py`` measures it against the matrix exponential).
    4. ``step_limit_factor``: the step limit dt <= factor * T_min, T_min = 2 pi / omega_max,
       omega_max^2 = max |eig(M^-1 (K + K_D(S)))| (paper Eq. 8), derived in the docstring:
         - explicit: the stability limit Omega_crit = omega_max dt of the linear
           amplification, factor = Omega_crit / (2 pi). Central difference: Omega_crit = 2,
           dt <= T_min / pi. RK4: Omega_crit = 2.785 (real-axis end of the RK4 region),
           dt <= 0.4433 T_min.
         - implicit Newmark family: unconditionally stable, but the modified-Newton
           iteration with the full-stick tangent is a fixed-point iteration that converges
           only if dt < T_min / (2 pi sqrt(beta)) (paper 4.2): factor = 1 / (2 pi sqrt(beta)),
           i.e. :attr:`slipstep.methods.schemes.Scheme.step_limit_factor`.
       The fixed step uses factor * T_min(all stick) * step_ratio (rounded down to a whole
       number of steps per period); the adaptive step uses factor * T_min(S_n) * step_ratio
       and redoes a step whose end state has a shorter limit (shared kernels).
    5. ``variants``: the subset of :data:`VARIANTS` it supports: 'fixed' (fixed step; for
       implicit schemes the modified-Newton iteration of paper A.3), 'adaptive' (paper
       4.2), 'piecewise-linear' (paper A.4, implicit only), 'both' (4.2 + A.4).
       Requesting another variant raises :class:`~slipstep.errors.InputError`.
    6. ``simulation(system, variant, **options)``: an object with ``.run() -> Dataset``,
       ``.march() -> Status``, ``.kernel_time`` [s] and ``.dataset()``, like
       :class:`slipstep.methods.simulation.Simulation`. Implicit schemes return that class
       with a :class:`~slipstep.methods.schemes.Scheme` (the march kernel is shared);
       explicit ones :class:`~slipstep.integrators.explicit_simulation.ExplicitSimulation`
       with ``kernel_kind`` selecting the step in :mod:`slipstep.kernels.explicit`.
       The step control and the piecewise-linear machinery live in the kernels, never
       in the scheme module.
    7. The result is the standard Dataset of :mod:`slipstep.output.results` (``run``).
    """

    name: str = ""
    kind: str = ""
    order: int = 0
    variants: tuple[str, ...] = ()
    kernel_kind: int | None = None  # explicit kernel selector (kernels.explicit), None for implicit

    @property
    @abc.abstractmethod
    def step_limit_factor(self) -> float:
        """dt <= step_limit_factor * T_min (see the class docstring, item 4)."""

    @property
    def label(self) -> str:
        """Name with parameters, e.g. ``hht(alpha=0.1)``."""
        return self.name

    @abc.abstractmethod
    def simulation(self, system, variant: str = "fixed", **options):
        """Set up (and preload) a run; see item 6."""

    def run(self, system, variant: str = "fixed", **options):
        """Preload + march + Dataset."""
        return self.simulation(system, variant, **options).run()

    def check_variant(self, variant: str) -> str:
        v = str(variant).strip().lower()
        if v not in self.variants:
            raise InputError(
                "variant",
                f"{variant!r} is not available for {self.label} ({self.kind})",
                f"use one of {', '.join(self.variants)}",
            )
        return v

    def __repr__(self) -> str:
        return (
            f"<{type(self).__name__} {self.label}: {self.kind}, order {self.order}, dt <= "
            f"{self.step_limit_factor:.4g} T_min>"
        )


class ImplicitIntegrator(Integrator):
    """A member of the Newmark / generalised-alpha family, run by kernels.march through
    :class:`slipstep.methods.simulation.Simulation` with :meth:`scheme`."""

    kind = "implicit"
    order = 2
    variants = VARIANTS
    _METHOD = VARIANT_METHODS  # variant -> method (slipstep.methods.registry)

    @abc.abstractmethod
    def scheme(self):
        """The :class:`slipstep.methods.schemes.Scheme` (beta, gamma, alpha_m, alpha_f)."""

    @property
    def label(self) -> str:
        return self.scheme().name

    @property
    def step_limit_factor(self) -> float:
        """Convergence of the modified-Newton iteration: dt < T_min / (2 pi sqrt(beta)).

        Derivation (paper 4.2). The iteration dx_{k+1} = dx_k + J_s^-1 r(dx_k) uses the
        full-stick tangent J_s = a0 M + K + K_D(stick) (a0 = 1/(beta dt^2); alpha factors
        omitted) while the true tangent in the state S reached is J(S); its error map is
        e_{k+1} = J_s^-1 (K_D(stick) - K_D(S)) e_k. While the inertia term dominates J_s the
        map is ~ beta dt^2 M^-1 dK, with eigenvalues up to beta dt^2 omega_max^2 (dK is at
        most the stick stiffness; slip adds the non-symmetric mu k_n coupling). Contraction
        needs beta dt^2 omega_max^2 < 1, i.e. omega_max dt < 1/sqrt(beta):
            dt < T_min / (2 pi sqrt(beta))   (= T_min / pi for beta = 1/4).
        A sufficient, not a sharp, condition; it is the paper's Method 1/2 step. HHT and
        generalised alpha use their own beta ((1 + alpha)^2 / 4 for HHT), so their step is
        slightly shorter than Newmark's.
        """
        return self.scheme().step_limit_factor

    def simulation(self, system, variant: str = "fixed", **options):
        from slipstep.methods.simulation import Simulation

        return Simulation(system, self._METHOD[self.check_variant(variant)], scheme=self.scheme(), **options)


class ExplicitIntegrator(Integrator):
    """An explicit scheme run by :mod:`slipstep.kernels.explicit` (no piecewise-linear solve:
    nothing is solved for the contacts)."""

    kind = "explicit"
    variants = EXPLICIT_VARIANTS
    omega_crit: float = math.nan  # omega_max dt at the stability limit
    #: default step_ratio of the adaptive variant (the fixed one rounds dt down to whole steps per period)
    adaptive_step_ratio: float = 1.0

    @property
    def step_limit_factor(self) -> float:
        """Omega_crit / (2 pi): the stability limit is the step limit (step_control.stability_factor)."""
        from slipstep.methods.step_control import stability_factor

        return stability_factor(self.omega_crit)

    def simulation(self, system, variant: str = "fixed", **options):
        from slipstep.integrators.explicit_simulation import ExplicitSimulation

        adaptive = self.check_variant(variant) == "adaptive"
        if adaptive and "step_ratio" not in options:
            options["step_ratio"] = self.adaptive_step_ratio
        return ExplicitSimulation(system, self, adaptive=adaptive, **options)
