"""The one registry of what slipstep can march with: methods (a step solver and a step
control, the paper's Methods 1-4 and their variants) x time-integration schemes (paper App. A)
x variants (fixed / adaptive step, Newton / piecewise-linear solve).

* :data:`METHODS`: name -> :class:`Method` (paper label, solver code, step control, the
  scheme variant it is, the kernel that marches it); :data:`ALIASES`: the paper's numbers.
* :data:`SCHEMES`: name -> :class:`SchemeEntry` (the integrator class, its parameters with THE
  defaults, used by ``slipstep.newmark()/hht()/generalized_alpha()`` and by the integrator
  classes alike); :data:`SCHEME_ALIASES`.
* :data:`VARIANTS`, :data:`VARIANT_METHODS`: a scheme's variant -> the method that runs it.

The CLI help (``slipstep run --help``), ``slipstep methods`` and the method and scheme tables of
the documentation's methods page are generated from here (the tables by
slipstep.integrators.tables, which adds what each integrator class says of its scheme;
``slipstep methods --markdown`` prints them; tests/test_registry.py checks the page and the command).
The registry names each integrator class and each method's march kernel by its path
(``module:name``) and never imports them (no numba here).
"""

from __future__ import annotations

from dataclasses import dataclass

from slipstep.errors import InputError
from slipstep.kernels.codes import (
    EVENTS,
    EXACT_EVENTS,
    FULL_NEWTON,
    MODIFIED_NEWTON,
    MODIFIED_NEWTON_STATE,
    PIECEWISE_LINEAR,
)


#: the implicit march (kernels/march.py): every step solver, fixed or adaptive step, the preload
IMPLICIT_KERNEL = "slipstep.kernels.march:implicit_kernel"


@dataclass(frozen=True)
class Method:
    name: str
    paper_label: str
    solver: int
    adaptive: bool
    quasi_static: bool
    description: str
    massless: bool = False  # the DOFs of option massless_dofs without inertia (methods/massless.py)
    #: the paper's CPU time relative to Method 1 on its case (Section 6, Fig. 8; physics.md 7):
    #: (wording, value), e.g. ("about", 0.8) or ("below", 0.1); None for methods beyond the paper
    paper_time_ratio: tuple[str, float] | None = None
    #: the kernel that marches it after the preload, ``module:function`` with function(backend) -> the
    #: numba kernel(args, st) of that structure backend (args: kernels.arguments.KernelArguments;
    #: methods.marcher.march_kernel loads it); None: a runner of its own, no march kernel
    kernel: str | None = IMPLICIT_KERNEL

    @property
    def variant(self) -> str | None:
        """The scheme variant this method is (:data:`VARIANT_METHODS`), None if none."""
        return next((v for v, m in VARIANT_METHODS.items() if m == self.name), None)

    @property
    def number(self) -> str | None:
        """The paper's number of the method ('1', '2+3', ...), None if it has none."""
        return next((k for k, v in ALIASES.items() if v == self.name and k not in HIDDEN_ALIASES), None)


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method(
            "newmark",
            "Method 1",
            MODIFIED_NEWTON,
            False,
            False,
            "standard Newmark: modified Newton with the full-stick tangent, fixed step",
            paper_time_ratio=("about", 1.0),
        ),
        Method(
            "newmark-adaptive",
            "Method 2",
            MODIFIED_NEWTON_STATE,
            True,
            False,
            "standard Newmark with the step adapted to the contact state; modified Newton with the tangent of "
            "the state that set the step",
            paper_time_ratio=("about", 0.8),
        ),
        Method(
            "piecewise-linear",
            "Method 3",
            PIECEWISE_LINEAR,
            False,
            False,
            "piecewise-linear Newmark: postulate the state, one solve, check, re-solve on a transition",
            paper_time_ratio=("about", 0.5),
        ),
        Method(
            "piecewise-linear-adaptive",
            "Method 2+3",
            PIECEWISE_LINEAR,
            True,
            False,
            "piecewise-linear Newmark with the contact-state adaptive step",
            paper_time_ratio=("about", 0.4),
        ),
        Method(
            "quasi-static",
            "Method 4",
            PIECEWISE_LINEAR,
            False,
            True,
            "quasi-static time marching (no inertia), piecewise-linear state loop",
            paper_time_ratio=("below", 0.1),
            kernel="slipstep.kernels.quasi_static:quasi_static_kernel",
        ),
        Method(
            "full-newton",
            "Newton",
            FULL_NEWTON,
            False,
            False,
            "Newmark with full Newton (current-state tangent), fixed step",
        ),
        Method(
            "quasi-static-dofs",
            "Method 3+4",
            PIECEWISE_LINEAR,
            False,
            False,
            "piecewise-linear Newmark with the DOFs of option massless_dofs (default: the dampers') "
            "quasi-static, without inertia",
            massless=True,
        ),
        Method(
            "quasi-static-events",
            "beyond the paper",
            EVENTS,
            False,
            True,
            "event-driven quasi-static: exact state-transition instants by root finding in each linear phase, "
            "outputs on the steps_per_period grid (harmonic excitation, piecewise-linear laws)",
            kernel="slipstep.kernels.events:event_kernel",
        ),
        Method(
            "events",
            "beyond the paper",
            EXACT_EVENTS,
            False,
            False,
            "exact event-driven dynamics: each linear phase by its exact propagator (modal form, harmonic and "
            "constant loads in closed form), state changes located by root finding on the exact solution "
            "(harmonic excitation, piecewise-linear laws)",
            kernel=None,  # methods/exact_events.py: ExactEventRun
        ),
        Method(
            "newmark-adaptive-stick",
            "Method 2 (stick tangent)",
            MODIFIED_NEWTON,
            True,
            False,
            "Method 2 iterating with the full-stick tangent like Method 1 (slower: longer slip steps contract "
            "more slowly)",
        ),
    )
}

#: when to use each method (the advice the advisor's rules and the measurements support): the
#: methods page prints it beside each method
METHOD_ADVICE: dict[str, str] = {
    "newmark": "you want the reference: the standard method, the baseline of every comparison",
    "newmark-adaptive": "you study the paper's Method 2; prefer Method 2+3, which takes the same steps at "
    "a tenth of the solves",
    "piecewise-linear": "dynamics matter (near a resonance, light dampers, high frequency, lift-off): "
    "Method 1's solution at about one solve per step; the default choice for dynamic runs",
    "piecewise-linear-adaptive": "slip or lift-off dominate the period: longer steps in the softer states, "
    "partly paid back in redone steps",
    "quasi-static": "the excitation is far below the damper's resonances (inertia below 5 % of the "
    "centrifugal load, paper Eq. 9) and every visited state has a static equilibrium: about 300 steps "
    "per period, no ringing to filter",
    "full-newton": "Method 1 needs many iterations per step (strong slip): fewer iterations, one factorisation each",
    "quasi-static-events": "the same conditions as Method 4 with harmonic excitation and piecewise-linear laws: "
    "exact transition instants, a few solves per state change instead of per step (the paper case: 32 solves "
    "in 3 periods against Method 4's 922)",
    "events": "you want the reference without a time step (harmonic excitation, piecewise-linear laws): each "
    "linear phase exact, the state changes located to round-off; the fastest method when states change rarely "
    "(docs/exact_events.md)",
    "newmark-adaptive-stick": "you reproduce the paper's Method 2 exactly (the full-stick tangent in every "
    "state); slower than `newmark-adaptive`",
    "quasi-static-dofs": "a structure (blades) carries light dampers whose internal modes are far above the "
    "excitation (at least 5x and 1 kHz, paper Remark 3): the dampers without inertia, the rest dynamic; the "
    "step is set by the structure, not the damper (`slipstep advise` says when it applies)",
}

ALIASES = {
    "1": "newmark",
    "2": "newmark-adaptive",
    "3": "piecewise-linear",
    "2+3": "piecewise-linear-adaptive",
    "23": "piecewise-linear-adaptive",
    "4": "quasi-static",
    "3+4": "quasi-static-dofs",
    "34": "quasi-static-dofs",
}

HIDDEN_ALIASES = ("23", "34")  # accepted spellings not shown in the tables

PAPER_METHODS = ("newmark", "newmark-adaptive", "piecewise-linear", "piecewise-linear-adaptive", "quasi-static")
#: What ``slipstep compare`` runs by default: the paper's methods and the event-driven one beyond it.
COMPARE_METHODS = PAPER_METHODS + ("quasi-static-events",)


#: a scheme's variants, and the method that runs each (implicit schemes: kernels/march.py)
VARIANTS = ("fixed", "adaptive", "piecewise-linear", "both")
VARIANT_METHODS = {
    "fixed": "newmark",
    "adaptive": "newmark-adaptive",
    "piecewise-linear": "piecewise-linear",
    "both": "piecewise-linear-adaptive",
}
#: explicit schemes solve nothing for the contacts: no piecewise-linear variants
EXPLICIT_VARIANTS = ("fixed", "adaptive")


@dataclass(frozen=True)
class SchemeEntry:
    """A time-integration scheme: its integrator class (``module:Class``), its parameters in
    call order with their defaults, and what it is in a few words (kind, order and step limit
    are the class's: slipstep.integrators.base)."""

    name: str
    cls: str
    kind: str  # 'implicit' (kernels/march.py, every variant) or 'explicit' (kernels/explicit.py)
    parameters: tuple[tuple[str, float], ...] = ()
    summary: str = ""

    @property
    def variants(self) -> tuple[str, ...]:
        return VARIANTS if self.kind == "implicit" else EXPLICIT_VARIANTS

    def default(self, parameter: str) -> float:
        return dict(self.parameters)[parameter]


SCHEMES: dict[str, SchemeEntry] = {
    e.name: e
    for e in (
        SchemeEntry(
            "newmark",
            "slipstep.integrators.newmark:Newmark",
            "implicit",
            (("beta", 0.25), ("gamma", 0.5)),
            "Newmark-beta; the default average acceleration (1/4, 1/2) is the paper's scheme",
        ),
        SchemeEntry(
            "linear-acceleration",
            "slipstep.integrators.newmark:LinearAcceleration",
            "implicit",
            (),
            "Newmark beta = 1/6, gamma = 1/2 (conditionally stable, omega dt <= 2 sqrt 3)",
        ),
        SchemeEntry(
            "hht",
            "slipstep.integrators.hht:HHT",
            "implicit",
            (("alpha", 0.1),),
            "Hilber-Hughes-Taylor alpha, 0 <= alpha <= 1/3: numerical damping of the high frequencies",
        ),
        SchemeEntry(
            "generalized-alpha",
            "slipstep.integrators.generalized_alpha:GeneralizedAlpha",
            "implicit",
            (("rho_inf", 0.8),),
            "generalised alpha (Chung & Hulbert 1993), high-frequency spectral radius 0 <= rho_inf <= 1",
        ),
        SchemeEntry(
            "central-difference",
            "slipstep.integrators.central_difference:CentralDifference",
            "explicit",
            (),
            "explicit central difference (Newmark beta = 0, gamma = 1/2)",
        ),
        SchemeEntry(
            "rk4",
            "slipstep.integrators.rk4:RK4",
            "explicit",
            (),
            "explicit classical Runge-Kutta 4 on the first-order form [x, v]",
        ),
    )
}

SCHEME_ALIASES = {
    "generalised-alpha": "generalized-alpha",
    "gen-alpha": "generalized-alpha",
    "alpha": "generalized-alpha",
    "hht-alpha": "hht",
    "cd": "central-difference",
    "central": "central-difference",
    "runge-kutta": "rk4",
    "runge-kutta-4": "rk4",
    "average-acceleration": "newmark",
}


def scheme_default(scheme: str, parameter: str) -> float:
    """The default of one scheme parameter (the one value every entry point uses)."""
    return SCHEMES[scheme].default(parameter)


def scheme_spec(entry: SchemeEntry) -> str:
    """'hht(alpha=0.1)': the scheme with its defaults, as ``--scheme`` / ``simulate`` read it."""
    if not entry.parameters:
        return entry.name
    return f"{entry.name}({', '.join(f'{p}={_number(v)}' for p, v in entry.parameters)})"


def _number(v: float) -> str:
    return f"{v:g}"


def get_method(name: str) -> Method:
    key = ALIASES.get(str(name).strip().lower(), str(name).strip().lower())
    if key not in METHODS:
        raise InputError(
            "method",
            f"unknown method {name!r}",
            f"use one of {', '.join(METHODS)} (or the paper's numbers 1, 2, 3, 2+3, 4)",
        )
    return METHODS[key]


# -- generated texts: CLI help, `slipstep methods` (the tables: slipstep.integrators.tables) ----------
def method_choices() -> str:
    """'newmark|1, newmark-adaptive|2, ..., full-newton, ...': every method with its number."""
    return ", ".join(m.name + (f"|{m.number}" if m.number else "") for m in METHODS.values())


def scheme_choices() -> str:
    """'newmark(beta=0.25, gamma=0.5), linear-acceleration, hht(alpha=0.1), ...' with the defaults."""
    return ", ".join(scheme_spec(e) for e in SCHEMES.values())


def methods_rows() -> list[tuple[str, str, str, str]]:
    """(name, paper label, number or '-', description) per method, in registry order."""
    return [(m.name, m.paper_label, m.number or "-", m.description) for m in METHODS.values()]
