"""What a periodic steady state is made of, and how close a period is to one.

The full state of a march at a period boundary is z = (x, v, a, w, S): displacements,
velocities, accelerations, sliders and contact states (quasi-static marches: x, w, S).
The change over one period is measured block by block, relative to the amplitude of the
period just marched:

    e = max( max_i |x_i(T) - x_i(0)| / s_x(i),  max_i |v_i(T) - v_i(0)| / s_v(i),
             max_d |w_d(T) - w_d(0)| / s_w )

with s_x(i) the largest half peak-to-peak range over the period among the DOFs sharing the
unit of DOF i (m, rad), s_v(i) the same for velocities and s_w the largest half range of the
contact tangential displacements u (at least the m-group's s_x). A group that barely moves
(a damper's rotation in a symmetric mode) is measured against 1e-3 of the largest group
scale instead (1 rad counted as 1 m there: round-off of the moving groups would otherwise
look like a change of the still one), and every scale is floored at 1e-12 of the system's
length scale (a motionless record then compares absolute changes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import xarray as xr


class State(NamedTuple):
    """A march state at a period boundary (what ``initial=`` accepts)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    w: np.ndarray
    states: np.ndarray  # int8 contact state per direction


@dataclass
class SteadyState:
    """A periodic steady state and how it was reached.

    period: the Dataset of the last period (time-domain schema, time from k T to (k+1) T);
    periods: excitation periods simulated in total (marches of one period each);
    status: "OK" or the failure name (NOT_STEADY: the cap was reached; a march status);
    change: the period-to-period change e of the last period (see the module docstring);
    final_state: the state at the end of the last period, to start the next point from;
    floquet_multipliers: eigenvalues of the one-period map's Jacobian at the orbit (shooting;
    None for marching), the neutral multipliers 1 of sliders stuck over the whole period
    removed (their number in ``neutral_directions``);
    orbit_history: the start of the orbit of this point and of the FRF point before it, with
    their frequencies (shooting's predictor for the next point).
    """

    period: xr.Dataset
    periods: int
    status: str
    message: str
    final_state: State
    change: float
    solver: str
    method: str
    floquet_multipliers: np.ndarray | None = None
    neutral_directions: int = 0
    newton_iterations: int = 0
    jacobians: int = 0
    changes: list[float] = field(default_factory=list)
    kernel_time_s: float = 0.0
    wall_time_s: float = 0.0
    orbit_history: tuple = ()  # shooting: ((f [Hz], orbit start State), ...) of this point and the one before

    @property
    def ok(self) -> bool:
        return self.status == "OK"


def state_of(ws, quasi_static: bool) -> State:
    """Copy of the carried state of a march workspace."""
    n = ws.x.shape[0]
    if quasi_static:
        return State(ws.x.copy(), np.zeros(n), np.zeros(n), ws.w.copy(), ws.state.copy())
    return State(ws.x.copy(), ws.v.copy(), ws.a.copy(), ws.w.copy(), ws.state.copy())


def as_state(initial, n: int, nd: int) -> State:
    """Accept a State, a SteadyState (its final state) or a mapping with x, v, a, w, states."""
    if isinstance(initial, SteadyState):
        return initial.final_state
    if isinstance(initial, State):
        return initial
    from slipstep.errors import InputError

    if isinstance(initial, dict):
        unknown = set(initial) - set(State._fields)
        if unknown or "x" not in initial:
            raise InputError(
                "initial", f"has keys {sorted(initial)}", f"give x and optionally {list(State._fields[1:])}"
            )
        get = initial.get
        return State(
            np.asarray(get("x"), float),
            None if get("v") is None else np.asarray(get("v"), float),
            None if get("a") is None else np.asarray(get("a"), float),
            None if get("w") is None else np.asarray(get("w"), float),
            None if get("states") is None else np.asarray(get("states"), np.int8),
        )
    raise InputError(
        "initial",
        f"is a {type(initial).__name__}",
        "give a SteadyState, its final_state, or a dict with x, v, a, w, states",
    )


STILL_GROUP = 1e-3  # a group scale is at least this fraction of the largest one


def _group_scale(values: np.ndarray, groups: np.ndarray, floor: float) -> np.ndarray:
    half = 0.5 * np.ptp(values, axis=0) if values.shape[0] else np.zeros(values.shape[1])
    out = np.empty_like(half)
    for g in np.unique(groups):
        sel = groups == g
        out[sel] = half[sel].max(initial=0.0)
    return np.maximum(out, max(STILL_GROUP * out.max(initial=0.0), floor))


@dataclass(frozen=True)
class Scales:
    """Block scales of the state (see the module docstring): per DOF for x and v, one for w."""

    x: np.ndarray
    v: np.ndarray
    w: float

    def vector(self, quasi_static: bool, nd: int) -> np.ndarray:
        """Scales of the unknowns z = (x, v, w) (quasi-static: (x, w))."""
        parts = [self.x] if quasi_static else [self.x, self.v]
        return np.concatenate(parts + [np.full(nd, self.w)])


def period_scales(out, n_steps: int, cs, dof_units, quasi_static: bool) -> Scales:
    """The scales s_x, s_v, s_w of the period stored in kernel outputs ``out[0..n_steps]``."""
    floor = 1e-12 * cs.length_scale
    groups = np.unique(np.asarray(dof_units), return_inverse=True)[1]
    k = n_steps + 1
    sx = _group_scale(out.x[:k], groups, floor)
    omega = 2 * np.pi / max(out.t[n_steps] - out.t[0], 1e-300)
    sv = sx * omega if quasi_static else _group_scale(out.v[:k], groups, floor * omega)
    u = out.q[:k][:, np.asarray(cs.tangential_row)]
    m_group = sx[np.asarray(dof_units) == "m"]
    sw = max(0.5 * np.ptp(u, axis=0).max(initial=0.0) if u.size else 0.0, m_group.max(initial=0.0), floor)
    return Scales(sx, sv, float(sw))


def period_change(start: State, end: State, scales: Scales, quasi_static: bool) -> float:
    """e of the module docstring between the states at the start and the end of a period."""
    e = float(np.max(np.abs(end.x - start.x) / scales.x, initial=0.0))
    if not quasi_static:
        e = max(e, float(np.max(np.abs(end.v - start.v) / scales.v, initial=0.0)))
    if start.w.size:
        e = max(e, float(np.max(np.abs(end.w - start.w), initial=0.0)) / scales.w)
    return e
