"""The paper's methods as named combinations of a step solver and a step control.

| name                       | paper      | step solver (kernels.march) | step control          |
|----------------------------|------------|-----------------------------|-----------------------|
| newmark                    | Method 1   | modified Newton, stick J    | fixed r T_min(stick)/pi |
| newmark-adaptive           | Method 2   | modified Newton, J(S) of the step's state | contact-state adaptive |
| piecewise-linear           | Method 3   | piecewise linear            | fixed                 |
| piecewise-linear-adaptive  | Method 2+3 | piecewise linear            | contact-state adaptive |
| quasi-static               | Method 4   | piecewise linear, no inertia| fixed, steps per period |
| full-newton                | (option)   | Newton, current-state J     | fixed                 |
| newmark-adaptive-stick     | (variant)  | modified Newton, stick J    | contact-state adaptive |
| quasi-static-events        | (beyond)   | exact events, kernels/events.py | outputs every period/steps_per_period |
| quasi-static-dofs          | Method 3+4 | piecewise linear, chosen DOFs without inertia (methods/massless.py) | fixed, T_min of the dynamic part |
"""

from __future__ import annotations

from dataclasses import dataclass

from slipstep.errors import InputError
from slipstep.kernels.codes import EVENTS, FULL_NEWTON, MODIFIED_NEWTON, MODIFIED_NEWTON_STATE, PIECEWISE_LINEAR


@dataclass(frozen=True)
class Method:
    name: str
    paper_label: str
    solver: int
    adaptive: bool
    quasi_static: bool
    description: str
    massless: bool = False  # the DOFs of option massless_dofs without inertia (methods/massless.py)


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
        ),
        Method(
            "newmark-adaptive",
            "Method 2",
            MODIFIED_NEWTON_STATE,
            True,
            False,
            "standard Newmark with the step adapted to the contact state; modified Newton with the tangent of "
            "the state that set the step",
        ),
        Method(
            "piecewise-linear",
            "Method 3",
            PIECEWISE_LINEAR,
            False,
            False,
            "piecewise-linear Newmark: postulate the state, one solve, check, re-solve on a transition",
        ),
        Method(
            "piecewise-linear-adaptive",
            "Method 2+3",
            PIECEWISE_LINEAR,
            True,
            False,
            "piecewise-linear Newmark with the contact-state adaptive step",
        ),
        Method(
            "quasi-static",
            "Method 4",
            PIECEWISE_LINEAR,
            False,
            True,
            "quasi-static time marching (no inertia), piecewise-linear state loop",
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

PAPER_METHODS = ("newmark", "newmark-adaptive", "piecewise-linear", "piecewise-linear-adaptive", "quasi-static")
#: What ``slipstep compare`` runs by default: the paper's methods and the event-driven one beyond it.
COMPARE_METHODS = PAPER_METHODS + ("quasi-static-events",)


def get_method(name: str) -> Method:
    key = ALIASES.get(str(name).strip().lower(), str(name).strip().lower())
    if key not in METHODS:
        raise InputError(
            "method",
            f"unknown method {name!r}",
            f"use one of {', '.join(METHODS)} (or the paper's numbers 1, 2, 3, 2+3, 4)",
        )
    return METHODS[key]
