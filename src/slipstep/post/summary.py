"""One result as a flat dict of numbers, the units in the keys: what a design sweep stores per case.

Over the last excitation period of the record (slipstep.post.periodic.last_period):

    interface_energy_per_cycle_J[I]   E_I = closed integral of T du, summed over I's directions
    interface_k_eq_N_per_m[I]         secant stiffness (T_max - T_min) / (u_max - u_min) of the (u_I, T_I) loop
    interface_zeta_eq[I]              E_I / (4 pi E_el), E_el = 1/2 k_eq ((u_max - u_min) / 2)^2
    interface_u_amplitude_m[I]        (u_max - u_min) / 2 of u_I (mean tangential displacement)
    interface_T_amplitude_N[I]        (T_max - T_min) / 2 of T_I (total tangential force)
    energy_per_cycle_J                sum of E_I over the interfaces
    direction_peak_T_over_muN[d]      max |T_d| / (mu N) over the times with N > 0 (<= 1: Coulomb's law)
    direction_stick_share[d], direction_slip_share[d], direction_lift_off_share[d]
                                      time shares of the states (slip = slip+ and slip-)
    contact_N_min_N[c], contact_N_max_N[c]   normal force range
    full_slip_share                   share of time with every direction slipping
    steady_error                      relative difference of the last two periods (post.periodic)

and from the run: status_code (slipstep.Status value), steps, solves, mean_solves_per_step,
state_changes, redone_steps, factorisations. Definitions of the loop quantities are in
slipstep.post.loops. A quantity that needs a full period is NaN when the run stopped before
one. Run timings (kernel_time_s, wall_time_s) are deliberately left out: they differ between
identical runs (:func:`timings` returns them). Keys with ``[label]`` belong to the dimension
named by their prefix (interface, contact, direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import xarray as xr

from slipstep.errors import InputError, Status
from slipstep.post.loops import interfaces_from_system, loop_summary
from slipstep.post.periodic import last_period, periodicity
from slipstep.post.timeline import LIFT, SLIP_NEG, SLIP_POS, STICK, full_slip_share, state_shares

# base name -> (units, long_name); one place for what the summary keys mean (all over the last
# period; the module docstring gives the definitions)
FIELDS: dict[str, tuple[str, str]] = {
    "status_code": ("1", "status of the march (slipstep.Status: 0 OK)"),
    "steps": ("1", "time steps"),
    "solves": ("1", "linear solves (iterations)"),
    "mean_solves_per_step": ("1", "linear solves per step"),
    "state_changes": ("1", "steps whose contact-state tuple differs from the previous one"),
    "redone_steps": ("1", "redone (adaptive) steps"),
    "factorisations": ("1", "matrix factorisations"),
    "energy_per_cycle_J": ("J", "friction energy per cycle, all interfaces"),
    "full_slip_share": ("1", "full-slip share of the period"),
    "steady_error": ("1", "relative difference between the last two periods of the displacement"),
    "interface_energy_per_cycle_J": ("J", "friction energy per cycle"),
    "interface_k_eq_N_per_m": ("N/m", "equivalent (secant) stiffness k_eq"),
    "interface_zeta_eq": ("1", "equivalent damping ratio zeta_eq"),
    "interface_u_amplitude_m": ("m", "tangential displacement amplitude"),
    "interface_T_amplitude_N": ("N", "tangential force amplitude"),
    "direction_peak_T_over_muN": ("1", "peak |T| / (mu N)"),
    "direction_stick_share": ("1", "stick share of the period"),
    "direction_slip_share": ("1", "slip share of the period"),
    "direction_lift_off_share": ("1", "lift-off share of the period"),
    "contact_N_min_N": ("N", "minimum normal force"),
    "contact_N_max_N": ("N", "maximum normal force"),
}

_NEEDED = ("displacement", "tangential_displacement", "tangential_force", "normal_force", "contact_state")
_RUN_COUNTS = ("steps", "solves", "mean_solves_per_step", "state_changes", "redone_steps", "factorisations")


def field_of(key: str) -> tuple[str, str | None]:
    """``'interface_zeta_eq[left]'`` -> ``('interface_zeta_eq', 'left')``; no label -> None."""
    if key.endswith("]") and "[" in key:
        base, label = key[:-1].split("[", 1)
        return base, label
    return key, None


def dimension_of(base: str) -> str | None:
    """The dimension of a labelled summary field (its prefix), None for a scalar one."""
    prefix = base.split("_", 1)[0]
    return prefix if prefix in ("interface", "contact", "direction") else None


def timings(ds: xr.Dataset) -> dict:
    """The run-to-run varying numbers of a result: kernel_time_s, wall_time_s."""
    return {k: float(ds.attrs.get(k, math.nan)) for k in ("kernel_time_s", "wall_time_s")}


def summarise(ds: xr.Dataset, interfaces=None, period: float | None = None) -> dict:
    """The flat summary of one result (module docstring). ``interfaces``: a System (contacts
    grouped by the platform they touch, post.loops.interfaces_from_system), a dict {name:
    [contacts]} or None (one interface per contact)."""
    a = ds.attrs
    out: dict = {"status_code": int(Status[a["status"]]) if a.get("status") in Status.__members__ else -1}
    for key in _RUN_COUNTS:
        value = a.get(key, math.nan)
        if key == "mean_solves_per_step" or math.isnan(value):
            out[key] = float(value)
        else:
            out[key] = int(value)
    ds = ds[[v for v in _NEEDED if v in ds]]  # fewer variables: every xarray selection below is cheaper
    try:
        lp = last_period(ds, period)
    except InputError:  # the run stopped before one full period: loop quantities are undefined
        lp = None
    out.update(_loops(ds, interfaces, period, lp))
    out.update(_contacts(ds, lp))
    out["full_slip_share"] = full_slip_share(lp) if lp is not None else math.nan
    out["steady_error"] = _steady_error(ds, period) if lp is not None else math.nan
    return out


def _loops(ds, interfaces, period, lp) -> dict:
    out = {}
    if lp is None:
        if interfaces is None:
            names = [str(c) for c in ds["contact"].values]
        else:
            names = list(interfaces if isinstance(interfaces, dict) else interfaces_from_system(interfaces))
        for name in names:
            for key in ("energy_per_cycle_J", "k_eq_N_per_m", "zeta_eq", "u_amplitude_m", "T_amplitude_N"):
                out[f"interface_{key}[{name}]"] = math.nan
        out["energy_per_cycle_J"] = math.nan
        return out
    s = loop_summary(ds, interfaces, period)
    v = {
        k: s[f"interface_{k}"].values
        for k in ("energy_J", "k_eq_N_per_m", "zeta_eq", "u_max_m", "u_min_m", "T_max_N", "T_min_N")
    }
    for i, name in enumerate(s["interface"].values):
        out[f"interface_energy_per_cycle_J[{name}]"] = float(v["energy_J"][i])
        out[f"interface_k_eq_N_per_m[{name}]"] = float(v["k_eq_N_per_m"][i])
        out[f"interface_zeta_eq[{name}]"] = float(v["zeta_eq"][i])
        out[f"interface_u_amplitude_m[{name}]"] = 0.5 * float(v["u_max_m"][i] - v["u_min_m"][i])
        out[f"interface_T_amplitude_N[{name}]"] = 0.5 * float(v["T_max_N"][i] - v["T_min_N"][i])
    out["energy_per_cycle_J"] = float(v["energy_J"].sum())
    return out


def _contacts(ds, lp) -> dict:
    out = {}
    directions = [str(d) for d in ds["direction"].values]
    contacts = [str(c) for c in ds["contact"].values]
    if lp is None:
        for d in directions:
            for key in ("peak_T_over_muN", "stick_share", "slip_share", "lift_off_share"):
                out[f"direction_{key}[{d}]"] = math.nan
        for c in contacts:
            out[f"contact_N_min_N[{c}]"] = out[f"contact_N_max_N[{c}]"] = math.nan
        return out
    T = lp["tangential_force"].values
    N = lp["normal_force"].values
    owner = [contacts.index(str(c)) for c in ds["direction_contact"].values]
    mu = ds["friction_coefficient"].values
    shares = state_shares(lp).values  # (direction, state)
    for j, d in enumerate(directions):
        c = owner[j]
        limit = mu[c] * N[:, c]
        loaded = limit > 0
        ratio = np.abs(T[loaded, j]) / limit[loaded]
        out[f"direction_peak_T_over_muN[{d}]"] = float(ratio.max()) if ratio.size else math.nan
        out[f"direction_stick_share[{d}]"] = float(shares[j, STICK])
        out[f"direction_slip_share[{d}]"] = float(shares[j, SLIP_POS] + shares[j, SLIP_NEG])
        out[f"direction_lift_off_share[{d}]"] = float(shares[j, LIFT])
    for k, c in enumerate(contacts):
        out[f"contact_N_min_N[{c}]"] = float(N[:, k].min())
        out[f"contact_N_max_N[{c}]"] = float(N[:, k].max())
    return out


def _steady_error(ds, period) -> float:
    try:
        errors = periodicity(ds, period=period).errors
    except InputError:  # nothing saved to compare (the save option)
        return math.nan
    return float(errors[-1]) if errors else math.nan


# -- the same summary from the kernel's arrays (the sweep's fast path: no Dataset) --------------


@dataclass(frozen=True)
class Record:
    """A march's record as plain arrays, what :func:`summarise_record` needs: time t [s] (n,),
    displacement x [m] (n, dof), tangential displacement u [m] and force T [N] (n, direction),
    normal force N [N] (n, contact), contact state S (n, direction), friction coefficient mu
    (contact), the names of the contacts, the directions and each direction's contact, the
    period [s], the length scale [m] and the run's attrs (status and counts)."""

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    T: np.ndarray
    N: np.ndarray
    S: np.ndarray
    mu: np.ndarray
    contacts: tuple
    directions: tuple
    direction_contact: tuple
    period: float | None
    length_scale: float
    attrs: dict


def record_of(sim) -> Record:
    """The Record of a marched Simulation with the default save (every step, every DOF and
    contact), from the kernel's output buffers (results.kernel_rows, as the Dataset is)."""
    from slipstep.kernels.codes import C_STEPS
    from slipstep.methods.buffers import saved_rows
    from slipstep.output.results import kernel_rows

    system, cs = sim.system, sim.compiled
    rows = saved_rows(sim.out, int(sim.out.counters[C_STEPS]))
    r, contacts, dirs, tan, nrm = kernel_rows(system, sim.out, rows - 1, cs, None, None, False)
    cnames, dnames = system.contact_names, system.direction_names()
    owner = np.asarray(cs.direction_contact)
    attrs = {"status": sim.status.name, "status_message": sim.status_message(), **sim.run_counts()}
    attrs.update(dt_s=sim.dt, t_end_s=sim.t_end, kernel_time_s=sim.kernel_time)
    return Record(
        t=r["t"],
        x=r["x"],
        u=r["q"][:, tan],
        T=r["f"][:, tan],
        N=r["f"][:, nrm],
        S=r["state"],
        mu=np.asarray(cs.mu)[contacts],
        contacts=tuple(cnames[i] for i in contacts),
        directions=tuple(dnames[d] for d in dirs),
        direction_contact=tuple(cnames[owner[d]] for d in dirs),
        period=sim.period,
        length_scale=float(cs.length_scale),
        attrs=attrs,
    )


def summarise_record(rec: Record, interfaces=None) -> dict:
    """:func:`summarise` of a Record, with numpy only (the same definitions, the same
    floating-point operations in the same order: equal to summarise of the run's Dataset)."""
    a = rec.attrs
    out: dict = {"status_code": int(Status[a["status"]]) if a.get("status") in Status.__members__ else -1}
    for key in _RUN_COUNTS:
        value = a.get(key, math.nan)
        out[key] = float(value) if key == "mean_solves_per_step" or math.isnan(value) else int(value)
    lp = _last_period_rows(rec)
    groups = _groups(rec, interfaces)
    out.update(_loops_record(rec, groups, lp))
    out.update(_contacts_record(rec, lp))
    out["full_slip_share"] = _full_slip(lp) if lp is not None else math.nan
    out["steady_error"] = _steady_record(rec) if lp is not None else math.nan
    return out


def _last_period_rows(rec: Record):
    """post.periodic.last_period on arrays: (t, u, T, N, S) of [t_end - T, t_end], None when
    shorter than one period."""
    from slipstep.post.periodic import _REL

    T = rec.period
    t = rec.t
    if T is None or not np.isfinite(T) or T <= 0 or t[-1] - t[0] < T * (1 - _REL):
        return None
    t0 = t[-1] - T
    j = int(np.argmin(np.abs(t - t0)))
    arrays = (rec.u, rec.T, rec.N, rec.S)
    if abs(t[j] - t0) <= _REL * T + 1e-12 * abs(t0):
        return (t[j:],) + tuple(v[j:] for v in arrays)
    k = int(np.searchsorted(t, t0, side="right"))
    i = min(max(k, 1), t.size - 1)
    s = (t0 - t[i - 1]) / (t[i] - t[i - 1])
    first = [v[i - 1] + s * (v[i] - v[i - 1]) for v in arrays[:3]] + [arrays[3][i - 1]]
    return (np.concatenate([[t0], t[k:]]),) + tuple(
        np.concatenate([f[None], v[k:]]).astype(v.dtype) for f, v in zip(first, arrays)
    )


def _groups(rec: Record, interfaces) -> dict:
    if interfaces is None:
        return {c: [c] for c in rec.contacts}
    return dict(interfaces if isinstance(interfaces, dict) else interfaces_from_system(interfaces))


def _loops_record(rec: Record, groups: dict, lp) -> dict:
    from slipstep.post.loops import loop_energy, loop_properties

    out = {}
    if lp is None:
        for name in groups:
            for key in ("energy_per_cycle_J", "k_eq_N_per_m", "zeta_eq", "u_amplitude_m", "T_amplitude_N"):
                out[f"interface_{key}[{name}]"] = math.nan
        out["energy_per_cycle_J"] = math.nan
        return out
    _, u, T, _, _ = lp
    per_dir = [loop_energy(u[:, d], T[:, d]) for d in range(u.shape[1])]
    energies = []
    for name, members in groups.items():
        d = np.array([k for k, c in enumerate(rec.direction_contact) if c in members], np.int64)
        p = loop_properties(u[:, d].mean(axis=1), T[:, d].sum(axis=1))
        e_sum = sum(per_dir[k] for k in d)
        zeta = e_sum / (4 * math.pi * p["elastic_energy_J"]) if p["elastic_energy_J"] > 0 else math.nan
        energies.append(e_sum)
        out[f"interface_energy_per_cycle_J[{name}]"] = float(e_sum)
        out[f"interface_k_eq_N_per_m[{name}]"] = float(p["k_eq_N_per_m"])
        out[f"interface_zeta_eq[{name}]"] = float(zeta)
        out[f"interface_u_amplitude_m[{name}]"] = 0.5 * float(p["u_max_m"] - p["u_min_m"])
        out[f"interface_T_amplitude_N[{name}]"] = 0.5 * float(p["T_max_N"] - p["T_min_N"])
    out["energy_per_cycle_J"] = float(np.array(energies, float).sum())
    return out


def _contacts_record(rec: Record, lp) -> dict:
    out = {}
    if lp is None:
        for d in rec.directions:
            for key in ("peak_T_over_muN", "stick_share", "slip_share", "lift_off_share"):
                out[f"direction_{key}[{d}]"] = math.nan
        for c in rec.contacts:
            out[f"contact_N_min_N[{c}]"] = out[f"contact_N_max_N[{c}]"] = math.nan
        return out
    t, _, T, N, S = lp
    contacts = list(rec.contacts)
    dt = np.diff(t)
    total = dt.sum()
    for j, d in enumerate(rec.directions):
        c = contacts.index(rec.direction_contact[j])
        limit = rec.mu[c] * N[:, c]
        loaded = limit > 0
        ratio = np.abs(T[:, j][loaded]) / limit[loaded]
        states = S[1:, j]
        share = {s: dt[states == s].sum() / total for s in (STICK, SLIP_POS, SLIP_NEG, LIFT)}
        out[f"direction_peak_T_over_muN[{d}]"] = float(ratio.max()) if ratio.size else math.nan
        out[f"direction_stick_share[{d}]"] = float(share[STICK])
        out[f"direction_slip_share[{d}]"] = float(share[SLIP_POS] + share[SLIP_NEG])
        out[f"direction_lift_off_share[{d}]"] = float(share[LIFT])
    low, high = N.min(axis=0), N.max(axis=0)
    for k, c in enumerate(contacts):
        out[f"contact_N_min_N[{c}]"] = float(low[k])
        out[f"contact_N_max_N[{c}]"] = float(high[k])
    return out


def _full_slip(lp) -> float:
    from slipstep.post.timeline import SLIP_STATES

    t, S = lp[0], lp[4]
    slip = np.zeros(S[1:].shape, bool)
    for state in SLIP_STATES:  # np.isin(S[1:], SLIP_STATES), without its set-up
        slip |= S[1:] == state
    all_slip = np.all(slip, axis=1)
    total = t[-1] - t[0]
    return float(np.diff(t)[all_slip].sum() / total) if total > 0 else 0.0


def _steady_record(rec: Record) -> float:
    """post.periodic.periodicity(...).errors[-1] of the displacement, on arrays."""
    from slipstep.post.periodic import _REL, _phase_compare

    t, P = rec.t, rec.period
    y = np.asarray(rec.x if rec.x.shape[1] > 0 or rec.T.shape[1] == 0 else rec.T, float).reshape(t.size, -1)
    if y.size == 0:
        return math.nan
    n = int(np.floor((t[-1] - t[0]) / P * (1 + _REL)))
    scale = max(float(np.ptp(y, axis=0).max(initial=0.0)), rec.length_scale * 1e-3, 1e-300)
    if n < 2:  # fewer than two periods: no pair to compare
        return math.nan
    return float(_phase_compare(t, y, t[0] + (n - 2) * P, P) / scale)  # the last pair (k = n - 1)
