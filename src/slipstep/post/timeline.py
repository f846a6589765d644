"""Contact-state timeline, state-change counts, full-slip share, uniform resampling.

State codes: slipstep.kernels.codes (0 lift-off, 1 stick, 2 slip+, 3 slip-, 4 slip-circle).
The state stored at t_i is the state of the step (t_{i-1}, t_i]; time shares weight each
state by that step's length.

A quasi-static state can be recovered from (filtered) forces with a band tolerance eps:

    N <= eps * max N                       -> lift-off
    |T| >= (1 - eps) mu N, sign of T       -> slip+ (T > 0) / slip- (T < 0)
    (friction-circle contacts: |T| the vector norm of the contact's T -> slip-circle)
    otherwise                              -> stick

(filtered dynamic forces approach the Coulomb limit from below, so eps ~ 1-3 % counts
the slips of the filtered signal; the raw dynamic states chatter with the ringing).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.model.contact import CONTACT_LAWS
from slipstep.kernels.codes import LIFT, SLIP_COUPLED, SLIP_NEG, SLIP_POS, SLIP_STATES, STATE_NAMES, STICK


def state_segments(ds: xr.Dataset) -> dict[str, list[tuple[float, float, str]]]:
    """Per direction, the runs of constant state: [(t_start [s], t_end [s], state name)]."""
    t = ds["time"].values
    S = ds["contact_state"].values
    out = {}
    for d, name in enumerate(ds["direction"].values):
        segs, start = [], 0
        for i in range(1, t.size + 1):
            if i == t.size or S[i, d] != S[start, d]:
                t0 = t[start - 1] if start > 0 else t[0]
                segs.append((float(t0), float(t[i - 1]), STATE_NAMES[int(S[start, d])]))
                start = i
        out[str(name)] = segs
    return out


def count_state_changes(states: np.ndarray) -> int:
    """Number of instants at which the state vector changes (any direction), for a state
    array (nt, nd); simultaneous changes of several directions count once."""
    S = np.asarray(states)
    if S.shape[0] < 2:
        return 0
    return int(np.any(S[1:] != S[:-1], axis=1).sum())


def change_times(ds: xr.Dataset, states: np.ndarray | None = None) -> np.ndarray:
    """Times [s] at which the state vector changes (the first time of the new state)."""
    S = ds["contact_state"].values if states is None else np.asarray(states)
    t = ds["time"].values
    return t[1:][np.any(S[1:] != S[:-1], axis=1)]


def states_from_forces(ds: xr.Dataset, eps: float = 0.02) -> np.ndarray:
    """Quasi-static contact states (nt, nd) int8 from the tangential and normal forces with
    band tolerance ``eps`` (module docstring). Used on filtered results."""
    if not 0 <= eps < 1:
        raise InputError("eps", f"is {eps}", "give a small fraction such as 0.02")
    T = ds["tangential_force"].values
    N = ds["normal_force"].values
    owner = ds["direction_contact"].values
    contacts = list(ds["contact"].values)
    col = np.array([contacts.index(c) for c in owner])
    mu = ds["friction_coefficient"].values[col]
    Nd = N[:, col]
    lim = mu * Nd
    S = np.full(T.shape, STICK, np.int8)
    slip = np.abs(T) >= (1 - eps) * lim
    S[slip & (T > 0)] = SLIP_POS
    S[slip & (T < 0)] = SLIP_NEG
    laws = ds["contact_law"].values if "contact_law" in ds.coords else ()
    for c, law in enumerate(laws):
        if getattr(CONTACT_LAWS.get(str(law)), "coupled_slip", False):
            cols = np.flatnonzero(col == c)
            norm = np.sqrt((T[:, cols] ** 2).sum(axis=1))
            S[:, cols] = np.where(norm >= (1 - eps) * lim[:, cols[0]], SLIP_COUPLED, STICK)[:, None]
    S[Nd <= eps * max(float(np.abs(N).max(initial=0.0)), 1e-300)] = LIFT
    return S


def debounce(ds: xr.Dataset, states: np.ndarray, min_duration: float) -> np.ndarray:
    """States with every run shorter than ``min_duration`` [s] (per direction) replaced by
    the state before it: removes the flicker of a filtered force hovering at mu N."""
    t = ds["time"].values
    S = np.array(states, copy=True)
    for d in range(S.shape[1]):
        i = 1
        while i < S.shape[0]:
            if S[i, d] != S[i - 1, d]:
                j = i
                while j + 1 < S.shape[0] and S[j + 1, d] == S[i, d]:
                    j += 1
                if j + 1 < S.shape[0] and t[j] - t[i - 1] < min_duration:
                    S[i : j + 1, d] = S[i - 1, d]
                i = j + 1
            else:
                i += 1
    return S


def full_slip_share(ds: xr.Dataset, states: np.ndarray | None = None) -> float:
    """Share (0..1) of the record's time with every direction slipping (state 2, 3 or 4),
    each stored state weighted by the length of the step that ends there."""
    S = ds["contact_state"].values if states is None else np.asarray(states)
    t = ds["time"].values
    dt = np.diff(t)
    all_slip = np.all(np.isin(S[1:], SLIP_STATES), axis=1)
    total = t[-1] - t[0]
    return float(dt[all_slip].sum() / total) if total > 0 else 0.0


def state_shares(ds: xr.Dataset) -> xr.DataArray:
    """Time share (0..1) of each state per direction, dims (direction, state)."""
    S = ds["contact_state"].values[1:]
    dt = np.diff(ds["time"].values)
    total = dt.sum()
    shares = np.array([[dt[S[:, d] == s].sum() / total for s in range(len(STATE_NAMES))] for d in range(S.shape[1])])
    return xr.DataArray(
        shares,
        dims=("direction", "state"),
        coords={"direction": ds["direction"].values, "state": list(STATE_NAMES)},
        attrs={"units": "1", "long_name": "share of time in each contact state"},
    )


def is_uniform(t: np.ndarray, rtol: float = 1e-6) -> bool:
    """True when the time steps of ``t`` are equal within ``rtol``."""
    dt = np.diff(np.asarray(t, float))
    return dt.size == 0 or float(np.ptp(dt)) <= rtol * float(np.abs(dt).max())


def resample_uniform(ds: xr.Dataset, dt: float | None = None, n: int | None = None) -> xr.Dataset:
    """The Dataset on a uniform time grid from t_0 to t_end: float variables by linear
    interpolation (numpy.interp), integer variables (contact state, solves) by holding
    the value of the step that contains each new time (the state of (t_{i-1}, t_i]).

    Grid: ``n`` points, or step ``dt`` [s] (rounded so the grid ends at t_end), default
    the smallest stored step. Variables without a time dimension are kept.
    """
    t = ds["time"].values
    if n is None:
        step = float(np.diff(t).min()) if dt is None else float(dt)
        if step <= 0:
            raise InputError("dt", f"is {step}", "give a positive time step in seconds")
        n = int(np.ceil((t[-1] - t[0]) / step * (1 - 1e-12))) + 1
    n = max(int(n), 2)
    tu = np.linspace(t[0], t[-1], n)
    idx = np.clip(np.searchsorted(t, tu, side="left"), 0, t.size - 1)
    out = {}
    for name, var in ds.data_vars.items():
        if "time" not in var.dims:
            out[name] = var
            continue
        v = var.transpose("time", ...).values
        flat = v.reshape(t.size, -1)
        if np.issubdtype(v.dtype, np.floating):
            new = np.column_stack(
                [np.interp(tu, t, flat[:, j]) for j in range(flat.shape[1])] or [np.zeros((n, 0))]
            )  # e.g. no prescribed motion component
        else:
            new = flat[idx]
        dims = ("time",) + tuple(d for d in var.dims if d != "time")
        out[name] = xr.Variable(dims, new.reshape((n,) + v.shape[1:]).astype(v.dtype), var.attrs)
    coords = {k: c for k, c in ds.coords.items() if "time" not in c.dims}
    coords["time"] = ("time", tu, ds["time"].attrs)
    res = xr.Dataset(out, coords=coords, attrs=dict(ds.attrs))
    res.attrs["resampled_uniform"] = 1
    return res
