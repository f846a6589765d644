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
