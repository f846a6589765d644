"""What a march stores (like diffrax's SaveAt): DOFs, contact quantities and the time grid.

    run(system, save=Save(dofs=["blade*"], contacts="all", every=10, last_periods=2))
    run(system, save={"dofs": "response", "times": np.linspace(0, 0.01, 101)})

Choices (each validated, bad input an InputError naming the ``save`` key it came from):

* ``dofs``: "all", "none", "response", or DOF names / shell patterns ("blade*"). The
  response DOFs are those the contacts see (non-zero columns of the gather map A), the
  forced DOFs (a non-zero constant, harmonic or tabulated force) and the DOFs named in
  ``response`` (names or patterns; TOML ``[save] response``).
* ``contacts``: "all", "none" or contact names; a contact brings its rows of q, f
  (tangential and normal) and its directions' sliders w and states.
* the time grid, one of
  - ``every = k``: every k-th step (k = 1: every step), the last step always;
  - ``last_periods = P`` (P >= 1, within the run): the steps of the last P excitation
    periods, from the step at or before t_end - P T (combined with ``every``);
  - ``times``: given times [s] in [t_start, t_end]. The kernel stores the two step ends
    around each time; the Dataset holds values at the given times: x by the cubic Hermite
    of (x, v) at the step ends, a linear in time and v by the Newmark relation
    v(tau) = v_0 + tau ((1 - gamma) a_0 + gamma a(tau)) (exact at both ends); quasi-static
    runs (no v): x linear. Contact q, f, w linear in time, the contact state of the
    nearest step end. Interpolation adds an O(dt^4) error to x (O(dt^2) to v, a),
    below the march's own O(dt^2).

Defaults (``save="auto"``): every DOF, every contact, every step for models of at most
FULL_SAVE_MAX_DOFS DOFs; above, the contact quantities and the response DOFs at every step.
The last step's full state (x, v, a, w, states) is always in the workspace
(``Simulation.ws``), whatever is saved (continuation, ``start_from``, shooting).
"""

from __future__ import annotations

import difflib
import fnmatch
import math
from dataclasses import dataclass, field

import numpy as np

from slipstep.errors import InputError
from slipstep.output.results import interpolate  # noqa: F401 (the Dataset's values at given times)

#: models with more DOFs than this save only the response DOFs and the contacts by default
FULL_SAVE_MAX_DOFS = 200

DOF_WORDS = ("all", "none", "response")
CONTACT_WORDS = ("all", "none")
KEYS = ("dofs", "contacts", "every", "last_periods", "times", "response")


@dataclass(frozen=True)
class Save:
    """What a march saves (module docstring): ``dofs``, ``contacts``, ``every``,
    ``last_periods``, ``times``, ``response`` (extra response DOF names / patterns)."""

    dofs: object = "all"
    contacts: object = "all"
    every: int = 1
    last_periods: float | None = None
    times: object = None
    response: tuple = field(default_factory=tuple)


@dataclass(frozen=True)
class Plan:
    """A resolved save: user DOF indices, contact indices, their directions and q/f rows,
    the grid (every, t_from, times) and a text of the choice (attr ``save``)."""

    dofs: np.ndarray
    contacts: np.ndarray
    directions: np.ndarray
    rows: np.ndarray
    every: int
    t_from: float
    times: np.ndarray | None
    text: str
    all_dofs: bool
    all_contacts: bool

    def attrs(self) -> dict:
        """The result attrs of the choice (slipstep.output.results.saved reads them)."""
        return {
            "save": self.text,
            "save_all_dofs": self.all_dofs,
            "save_all_contacts": self.all_contacts,
            "save_every_step": self.every == 1 and self.times is None,
            "save_whole_run": self.times is None and not math.isfinite(self.t_from),
        }

    @property
    def every_step(self) -> bool:
        """Every step is a row (row k = step k): what steady state, shooting, the divergence
        test and the accuracy estimate read from the outputs."""
        return self.every == 1 and self.times is None and not math.isfinite(self.t_from)


def kernel_dofs(cs, user: np.ndarray) -> np.ndarray:
    """The kernel's DOF index of each user DOF index (slipstep.model.system.kernel_dofs: the banded
    backend orders the DOFs by reverse Cuthill-McKee; identity for the dense one). The saved
    columns follow the user's order, so results never see the kernel's."""
    from slipstep.model.system import kernel_dofs as system_kernel_dofs

    return system_kernel_dofs(cs, user)


def as_save(value, key: str = "save") -> Save | str:
    """'auto', 'all', a Save or a dict of its fields (TOML [save]) -> Save or 'auto'."""
    if value is None or (isinstance(value, str) and value == "auto"):
        return "auto"
    if isinstance(value, str) and value == "all":
        return Save()
    if isinstance(value, Save):
        return value
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(KEYS))
        if unknown:
            raise InputError(f"{key}.{unknown[0]}", "is not a save key", f"use only {', '.join(KEYS)}")
        return Save(**value)
    raise InputError(key, f"is {value!r}", "give 'auto', 'all', slipstep.Save(...) or a dict of its keys")


def _names(key: str, value, words) -> list[str] | str:
    if isinstance(value, str):
        return value if value in words else [value]
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        return list(value)
    raise InputError(key, f"is {value!r}", f"give {', '.join(repr(w) for w in words)} or a list of names")


def match(key: str, patterns, names, what: str) -> np.ndarray:
    """Indices of ``names`` matching any of ``patterns`` (names or shell patterns), sorted;
    a pattern matching nothing is an InputError listing close names."""
    chosen: set[int] = set()
    for p in patterns:
        hit = [i for i, name in enumerate(names) if fnmatch.fnmatchcase(name, p)]
        if not hit:
            close = difflib.get_close_matches(p, list(names), n=4, cutoff=0.5) or list(names[:4])
            raise InputError(
                key, f"{p!r} matches no {what}", f"use {what} names or patterns such as {', '.join(close)}"
            )
        chosen.update(hit)
    return np.array(sorted(chosen), np.int64)


def response_dofs(system, cs, extra=()) -> np.ndarray:
    """The user DOF indices of the DOFs the contacts see (non-zero columns of A), the forced DOFs
    and those named in ``extra``. Found on the compiled arrays (kernel order: A in CSR, the
    forces) and mapped back through cs.dof_order (kernel DOF k is the user's dof_order[k])."""
    n = cs.M.shape[0]
    seen = np.zeros(n, bool)
    seen[np.asarray(cs.A_idx)[np.asarray(cs.A_val) != 0]] = True
    forced = np.asarray(cs.constant_force) != 0
    for amp in (cs.force_sin, cs.force_cos, cs.force_table_value):
        a = np.asarray(amp)
        if a.ndim == 2 and a.shape[0] == forced.size:
            forced |= np.abs(a).max(axis=1, initial=0.0) > 0
        elif a.ndim == 2 and a.shape[1] == forced.size:
            forced |= np.abs(a).max(axis=0, initial=0.0) > 0
    idx = set(np.asarray(cs.dof_order)[np.flatnonzero(seen | forced)].tolist())
    if extra:
        idx.update(match("save.response", list(extra), system.structure.dof_names, "DOF").tolist())
    return np.array(sorted(idx), np.int64)


def default_save(n_dofs: int) -> Save:
    """The save of ``save='auto'``: everything for at most FULL_SAVE_MAX_DOFS DOFs, else the
    contacts and the response DOFs, every step."""
    return Save() if n_dofs <= FULL_SAVE_MAX_DOFS else Save(dofs="response")


def resolve(value, system, cs, t_start: float, t_end: float, period: float | None) -> Plan:
    """The Plan of ``value`` (RunOptions.save) for this system and time span."""
    spec = as_save(value)
    if spec == "auto":
        spec = default_save(cs.M.shape[0])
    names = system.structure.dof_names
    n = len(names)
    if isinstance(spec.response, str):
        response = (spec.response,)
    elif isinstance(spec.response, (list, tuple)) and all(isinstance(r, str) for r in spec.response):
        response = tuple(spec.response)
    else:
        raise InputError("save.response", f"is {spec.response!r}", "give a list of DOF names or patterns")
    dofs = _names("save.dofs", spec.dofs, DOF_WORDS)
    if dofs == "all":
        idx = np.arange(n, dtype=np.int64)
    elif dofs == "none":
        idx = np.zeros(0, np.int64)
    elif dofs == "response":
        idx = response_dofs(system, cs, response)
    else:
        idx = match("save.dofs", dofs, names, "DOF")
    cnames = list(system.contact_names)
    contacts = _names("save.contacts", spec.contacts, CONTACT_WORDS)
    if contacts == "all":
        cidx = np.arange(len(cnames), dtype=np.int64)
    elif contacts == "none":
        cidx = np.zeros(0, np.int64)
    else:
        cidx = match("save.contacts", contacts, cnames, "contact")
    owner = np.asarray(cs.direction_contact)
    dirs = np.flatnonzero(np.isin(owner, cidx)).astype(np.int64)
    rows = np.concatenate([np.asarray(cs.tangential_row)[dirs], np.asarray(cs.normal_row)[cidx]]).astype(np.int64)
    every = spec.every
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError("save.every", f"is {every!r}", "give a whole number of steps >= 1 (1: every step)")
    t_from = -math.inf
    if spec.last_periods is not None:
        P = spec.last_periods
        if isinstance(P, bool) or not isinstance(P, (int, float)) or not P >= 1:
            raise InputError("save.last_periods", f"is {P!r}", "give a number of periods >= 1")
        if period is None:
            raise InputError(
                "save.last_periods", "needs a periodic excitation (the case has none)", "use save.times or every"
            )
        span = t_end - t_start
        if P * period > span * (1 + 1e-9):
            raise InputError(
                "save.last_periods",
                f"is {P}: {P * period:.4g} s, longer than the run ({span:.4g} s)",
                f"give at most {span / period:.4g} periods or simulate longer",
            )
        t_from = t_end - P * period
    times = None
    if spec.times is not None:
        if spec.last_periods is not None or every != 1:
            raise InputError(
                "save.times", "is given with every / last_periods", "give either times or every/last_periods"
            )
        try:
            times = np.asarray(spec.times, float).ravel()
        except (TypeError, ValueError):
            raise InputError("save.times", f"is {spec.times!r}", "give a list of times in seconds") from None
        if times.size == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise InputError(
                "save.times", "is not a non-empty increasing list of finite times", "give sorted times [s]"
            )
        tol = 1e-12 * max(abs(t_end), 1e-300)
        if times[0] < t_start - tol or times[-1] > t_end + tol:
            raise InputError(
                "save.times",
                f"spans [{times[0]:.4g}, {times[-1]:.4g}] s, outside the run [{t_start:.4g}, {t_end:.4g}] s",
                "give times within the simulated span",
            )
        times = np.clip(times, t_start, t_end)
    text = describe(idx.size == n, names, idx, len(cidx) == len(cnames), cnames, cidx, every, spec.last_periods, times)
    return Plan(idx, cidx, dirs, rows, int(every), t_from, times, text, idx.size == n, len(cidx) == len(cnames))


def describe(all_dofs, names, idx, all_contacts, cnames, cidx, every, last_periods, times) -> str:
    """The save choice as one line (result attr ``save``)."""
    dof_text = "all" if all_dofs else ("none" if idx.size == 0 else f"{idx.size} ({_short([names[i] for i in idx])})")
    contact_text = "all" if all_contacts else ("none" if cidx.size == 0 else _short([cnames[i] for i in cidx]))
    if times is not None:
        grid = f"{times.size} given times"
    else:
        grid = "every step" if every == 1 else f"every {every} steps"
        if last_periods is not None:
            grid += f" of the last {last_periods:g} periods"
    return f"dofs: {dof_text}; contacts: {contact_text}; {grid}"


def _short(items: list[str], most: int = 6) -> str:
    return ", ".join(items[:most]) + (f", ... ({len(items)})" if len(items) > most else "")


def rows_needed(plan: Plan, capacity: int, t_start: float, t_end: float) -> int:
    """Output rows to allocate for a march of at most ``capacity`` steps under ``plan``
    (an upper bound; 2 spare rows: the pending row and a bracket pair)."""
    steps = capacity + 1
    if plan.times is not None:
        return int(min(steps, 2 * plan.times.size + 2)) + 2
    if math.isfinite(plan.t_from):
        fraction = (t_end - plan.t_from) / max(t_end - t_start, 1e-300)
        steps = int(min(steps, math.ceil(steps * fraction * 1.5 + 16)))
    return int(math.ceil(steps / plan.every)) + 4


def kernel_arrays(plan: Plan, cs, capacity: int):
    """(dofs, rows, dirs, plan_int, times) for kernels.march.Outputs."""
    ip = np.array([capacity, plan.every, 0, -1, 0, 0], np.int64)  # kernels.march S_CAPACITY ... S_NEXT
    times = np.empty(3 + (0 if plan.times is None else plan.times.size))
    times[0], times[1], times[-1] = plan.t_from, math.nan, math.inf  # S_FROM, S_FAIL, ..., sentinel
    if plan.times is not None:
        times[2:-1] = plan.times
    return kernel_dofs(cs, plan.dofs), plan.rows.copy(), plan.directions.copy(), ip, times


def contact_columns(out, cs, directions=None, contacts=None) -> tuple[np.ndarray, np.ndarray]:
    """(columns of out.q / out.f holding the tangential rows of ``directions``, those holding
    the normal rows of ``contacts``); default: the saved ones (out.dirs, their contacts)."""
    column = {int(r): i for i, r in enumerate(np.asarray(out.rows))}
    dirs = np.asarray(out.dirs) if directions is None else np.asarray(directions)
    if contacts is None:
        normal = [int(r) for r in np.asarray(cs.normal_row) if int(r) in column]
    else:
        normal = [int(r) for r in np.asarray(cs.normal_row)[np.asarray(contacts)]]
    tan = np.array([column[int(r)] for r in np.asarray(cs.tangential_row)[dirs]], np.int64)
    return tan, np.array([column[r] for r in normal], np.int64)


def needs(plan, what: str, key: str = "save", fix: str = "drop the save option (save='auto' or 'all')") -> None:
    """Refuse a plan that lacks ``what`` ('all_dofs', 'all_contacts', 'every_step') for a
    computation (``key`` names it)."""
    if plan is None:
        return
    ok = {
        "all_dofs": plan.all_dofs,
        "all_contacts": plan.all_contacts,
        "every_step": plan.every_step,
        "contacts_every_step": plan.all_contacts and plan.every_step,
    }[what]
    if not ok:
        label = {
            "all_dofs": "every DOF",
            "all_contacts": "every contact",
            "every_step": "every DOF and contact at every step",
            "contacts_every_step": "every contact at every step",
        }[what]
        raise InputError("save", f"is {plan.text!r}: {key} needs {label}", fix)
