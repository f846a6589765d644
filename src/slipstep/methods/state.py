"""The carried state of a march at one instant (docs/architecture.md, "State").

    State(t, x, v, a, w, contact_state)

in the user's DOF order (the banded backend's reordering is the marcher's business): t [s],
displacements x, velocities v [/s], accelerations a [/s^2] (DOF units), slider positions w [m]
(one per tangential direction) and the law's state codes (int8, kernels/codes.py). A field
left None is completed when a march starts from the state (methods/start.py
``consistent_start``): v = 0, a = M^-1 (f_e - C v - K x - A^T f(x, w)), the contact state the
law gives at (x, w); quasi-static marches carry v = a = 0.

The unknowns of a periodic orbit are z = (x, v, w) (quasi-static: z = (x, w)):
:meth:`State.unknowns` and :meth:`State.from_unknowns`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np


class StartTerms(NamedTuple):
    """The force terms of a march's first point, in the user's DOF order: f_e(t) and A^T f
    (n), the local contact displacements q and forces f (nq). Set by the functions that
    compute them exactly (methods/start.py: the contact law's forces at the static preload,
    the elastic form elsewhere); a state without them is completed by ``consistent_start``."""

    fe: np.ndarray
    gf: np.ndarray
    q: np.ndarray
    f: np.ndarray


@dataclass(frozen=True, eq=False)
class State:
    """The state of a march at time t (module docstring); frozen (a new instant is a new State)."""

    t: float
    x: np.ndarray
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    w: np.ndarray | None = None
    contact_state: np.ndarray | None = None
    #: the first point's force terms when known (:class:`StartTerms`), else None
    terms: StartTerms | None = field(default=None, repr=False)

    @property
    def states(self) -> np.ndarray | None:
        """The contact state codes (the field's former name)."""
        return self.contact_state

    def at(self, t: float) -> "State":
        """The same state at another time (a periodic orbit's start k T later); the force
        terms are dropped (they depend on the time through the excitation)."""
        return replace(self, t=float(t), terms=None)

    def unknowns(self, quasi_static: bool) -> np.ndarray:
        """z = (x, v, w), quasi-static z = (x, w)."""
        return np.concatenate([self.x, self.w] if quasi_static else [self.x, self.v, self.w])

    @classmethod
    def from_unknowns(cls, z: np.ndarray, n: int, quasi_static: bool, contact_state=None, t: float = 0.0) -> "State":
        """The state of unknowns z (:meth:`unknowns`) with these contact states; quasi-static:
        v = a = 0; dynamic: a left to the consistent start."""
        if quasi_static:
            return cls(t, z[:n].copy(), np.zeros(n), np.zeros(n), z[n:].copy(), contact_state)
        return cls(t, z[:n].copy(), z[n : 2 * n].copy(), None, z[2 * n :].copy(), contact_state)


#: the fields a mapping given as a state may name (``initial=`` of the steady solvers)
FIELDS = ("x", "v", "a", "w", "states", "contact_state")
