"""The named tuples the march kernels take instead of index-packed parameter arrays.

* :class:`MarchSettings`: the typed scalars of one march (scheme coefficients, step rule,
  tolerances, time span, solver choice, structure backend). The one definition of the
  settings: kernels.march (implicit), kernels.events (event-driven) and kernels.explicit read
  the fields they need from it; Python builds it with :func:`march_settings` and changes it
  with :func:`replace_settings` (both cast every field to its declared type, so that numba
  compiles one overload whatever Python number type a caller used).
* :class:`ContactLaw`: the contact-law table (the septuple every law call takes).
* :class:`StateCache`: the cache of factorisations per contact state (kernels/state_solve.py).
* :class:`StepVectors`: the vectors of the step being solved (shared by the step solvers).
"""

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.extending import register_jitable


# The defaults of the march's controls, one place: MarchSettings and the user's RunOptions
# (methods/options.py) both take them.
NEWTON_TOL = 1e-11  # Newton tolerance (relative)
STATE_RTOL = 1e-9  # compatibility tolerance of a postulated state (relative)
SINGULAR_RTOL = 1e-12  # pivot below SINGULAR_RTOL * max|J|: singular
MAX_ITER = 500  # Newton iterations per step
MAX_STATE_ITER = 20  # postulated states per piecewise-linear step
MAX_REDO = 4  # redone steps (adaptive / accuracy control)


class MarchSettings(NamedTuple):
    """The scalars of a march. Fields a kernel does not use keep their defaults."""

    beta: float = 0.25  # Newmark beta
    gamma: float = 0.5  # Newmark gamma
    alpha_m: float = 0.0  # generalised-alpha (0 and 0: Newmark; alpha_m 0: HHT)
    alpha_f: float = 0.0
    dt: float = 0.0  # s, the fixed step (quasi-static: 1 / steps per period; events: the output grid)
    step_factor: float = 0.0  # adaptive: dt = step_factor * T_min(S), capped at dt_max
    dt_max: float = np.inf  # s
    tol: float = NEWTON_TOL
    state_rtol: float = STATE_RTOL
    singular_rtol: float = SINGULAR_RTOL
    t_start: float = 0.0  # s
    t_end: float = 0.0  # s
    rtol: float = 0.0  # accuracy control on when > 0 (the piecewise-linear solve then keeps dt <= dt_max only)
    err_scale: float = 0.0  # m, local error bound = rtol * err_scale
    divergence: float = np.inf  # m, explicit marches: |q| beyond it is DIVERGED
    solver: int = 0  # kernels.codes step solver (march); explicit_march: CENTRAL_DIFFERENCE / RK4
    adaptive: bool = False  # the contact-state adaptive step (Method 2)
    inertia: bool = True  # False: quasi-static (Lin = K)
    max_iter: int = MAX_ITER
    max_state_iter: int = MAX_STATE_ITER
    max_redo: int = MAX_REDO
    fallback: bool = True  # piecewise linear: modified Newton when the states cycle
    signals: bool = True  # evaluate the time signals (False: p = 0, f_e = load_factor f_const)
    preload: int = 0  # N > 0: N quasi-static increments of the constant loads at t = 0
    structure: int = 0  # structure backend (kernels/structure_ops.py: DENSE, LOW_RANK)


_CASTS = {name: MarchSettings.__annotations__[name] for name in MarchSettings._fields}


def march_settings(**fields) -> MarchSettings:
    """A MarchSettings with every given field cast to its declared type (float, int, bool)."""
    return MarchSettings(**{k: _CASTS[k](v) for k, v in fields.items()})


def replace_settings(settings: MarchSettings, **changes) -> MarchSettings:
    """``settings`` with some fields changed (cast like :func:`march_settings`)."""
    return settings._replace(**{k: _CASTS[k](v) for k, v in changes.items()})


class ContactLaw(NamedTuple):
    """The contact-law table of kernels/contact.py (nc contacts, nd tangential directions)."""

    nrow: np.ndarray  # (nc) int64 normal row of each contact in q
    lcode: np.ndarray  # (nc) int64 law code (codes.LAW_*)
    lpar: np.ndarray  # (nc, N_LAW_PAR) law parameters (k_n, mu)
    fdir: np.ndarray  # (nc) int64 first direction of each contact
    ndir: np.ndarray  # (nc) int64 number of directions
    trow: np.ndarray  # (nd) int64 tangential row of each direction in q
    kt: np.ndarray  # (nd) N/m


@register_jitable
def contact_table(sys):
    """The ContactLaw of a CompiledSystem (callable from Python and from the kernels: the one
    place that maps the system's fields to the law's table)."""
    return ContactLaw(sys.normal_row, sys.law, sys.law_par, sys.first_direction, sys.n_directions,
                      sys.tangential_row, sys.kt)


class StateCache(NamedTuple):
    """The factorisations of J(S) per key (S, dt state) (kernels/state_solve.py). Slot cap
    is scratch (a shortened last step), slot cap + 1 scratch for a coupled slip."""

    key: np.ndarray  # int8 (2 nd): [S for K_D, S for dt], scratch
    dt_state: np.ndarray  # int8 (nd): the state whose T_min set the step (0 on a fixed step)
    stick: np.ndarray  # int8 (nd) all STICK
    keys: np.ndarray  # int8 (cap, 2 nd)
    used: np.ndarray  # bool (cap)
    ok: np.ndarray  # bool (cap + 2): factorisation not singular
    lu: np.ndarray  # (cap + 2, s, s) factors (direct: J(S); low rank: C(S))
    piv: np.ndarray  # int64 (cap + 2, s)
    lr: tuple  # state_solve.LowRank: the low-rank arrays (placeholders in direct mode)


@njit(cache=True, error_model="numpy", inline="always")
def state_cache(ws):
    """The StateCache of a march Workspace."""
    return StateCache(ws.key, ws.dt_state, ws.stick, ws.cache_keys, ws.cache_used, ws.cache_ok, ws.cache_lu,
                      ws.cache_piv, ws.lr)


class StepVectors(NamedTuple):
    """The vectors of one implicit step (views of the Workspace)."""

    r0: np.ndarray  # (n) residual base (dx-independent part)
    qbase: np.ndarray  # (nq) q_base = A x_n - B p_{n+1} + g
    w: np.ndarray  # (nd) sliders w_n
    dx: np.ndarray  # (n) the increment solved for
    delta: np.ndarray  # (n) Newton correction
    r: np.ndarray  # (n) residual
    q1: np.ndarray  # (nq) q_{n+1}
    f1: np.ndarray  # (nq) f_{n+1}
    w1: np.ndarray  # (nd) w_{n+1}
    state1: np.ndarray  # int8 (nd) S_{n+1}
    gf1: np.ndarray  # (n) A^T f_{n+1}


@njit(cache=True, error_model="numpy", inline="always")
def step_vectors(ws):
    """The StepVectors of a march Workspace."""
    return StepVectors(ws.r0, ws.qbase, ws.w, ws.dx, ws.delta, ws.r, ws.q1, ws.f1, ws.w1, ws.state1, ws.gf1)
