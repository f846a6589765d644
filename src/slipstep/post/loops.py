"""Hysteresis loops, dissipated energy and equivalent stiffness/damping per contact and interface.

Definitions (over one closed period of the steady state, trapezoid rule on stored points):

    E_diss  = closed integral of T du                     [J]   loop area (> 0 when dissipating)
    k_eq    = (T_max - T_min) / (u_max - u_min)           [N/m] secant stiffness of the loop
    E_el    = 1/2 k_eq ((u_max - u_min) / 2)^2             [J]   elastic energy at the amplitude
    zeta_eq = E_diss / (4 pi E_el)                        [-]   equivalent viscous damping ratio

In steady state the loop area equals the friction dissipation sum int T dw: with
T = k_t (u - w), closed integral of T du = closed integral of T dw + closed integral of
T dT / k_t and the last term vanishes on a closed loop.

A Jenkins element (spring k_t in series with a slider of limit mu N) driven on
u = x_a sin(...) gives E_diss = 4 mu N (x_a - mu N / k_t), k_eq = mu N / x_a.

Interfaces: contacts are grouped (e.g. the two points of a flat damper face on one
platform). An interface loop plots T_I = sum T_i against u_I = mean u_i; its energy E_I is
the exact sum of its contacts' loop energies, k_eq is the secant stiffness of the
(u_I, T_I) loop and zeta_eq = E_I / (4 pi E_el(u_I, T_I)).
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from slipstep.errors import InputError
from slipstep.post.periodic import last_period


def loop_energy(u: np.ndarray, T: np.ndarray) -> float:
    """Closed integral of T du [J] (trapezoid rule), closing the loop from the last point to
    the first if they differ."""
    u = np.asarray(u, float)
    T = np.asarray(T, float)
    if u.size < 2:
        return 0.0
    uc = np.append(u, u[0])
    Tc = np.append(T, T[0])
    return float(np.sum(0.5 * (Tc[1:] + Tc[:-1]) * np.diff(uc)))


def loop_properties(u: np.ndarray, T: np.ndarray) -> dict:
    """E_diss [J], k_eq [N/m], E_el [J], zeta_eq [-] and the ranges of one closed loop
    (definitions in the module docstring). zeta_eq is NaN when k_eq or the u range is 0."""
    u = np.asarray(u, float)
    T = np.asarray(T, float)
    E = loop_energy(u, T)
    u_min, u_max, T_min, T_max = u.min(), u.max(), T.min(), T.max()
    du = float(u_max - u_min)
    dT = float(T_max - T_min)
    k = dT / du if du > 0 else math.nan
    E_el = 0.5 * k * (du / 2) ** 2 if du > 0 else math.nan
    zeta = E / (4 * math.pi * E_el) if du > 0 and E_el > 0 else math.nan
    return {
        "energy_J": E,
        "k_eq_N_per_m": k,
        "elastic_energy_J": E_el,
        "zeta_eq": zeta,
        "u_min_m": float(u_min),
        "u_max_m": float(u_max),
        "T_min_N": float(T_min),
        "T_max_N": float(T_max),
    }


def interfaces_from_system(system) -> dict[str, list[str]]:
    """Group contacts into interfaces by the prescribed-motion columns they see (the
    platform they touch): contacts whose motion_gather has the same non-zero columns share
    an interface, named after the common prefix of those motion names ('left' for
    'left.x', 'left.y'); contacts that see no motion form the interface 'ground'."""
    groups: dict[tuple[int, ...], list[str]] = {}
    for c in system.contacts:
        B = c.motion_gather
        cols = () if B is None else tuple(int(j) for j in np.flatnonzero(np.any(B != 0, axis=0)))
        groups.setdefault(cols, []).append(c.name)
    out = {}
    for cols, names in groups.items():
        if not cols:
            label = "ground"
        else:
            motion = [system.motion_names[j] for j in cols]
            prefix = {m.split(".")[0] for m in motion}
            label = prefix.pop() if len(prefix) == 1 else "+".join(motion)
        if label in out:
            label = f"{label}#{len(out)}"
        out[label] = names
    return out


def _resolve_interfaces(ds: xr.Dataset, interfaces) -> dict[str, list[str]]:
    contacts = [str(c) for c in ds["contact"].values]
    if interfaces is None:
        return {c: [c] for c in contacts}
    if not isinstance(interfaces, dict):  # a System
        interfaces = interfaces_from_system(interfaces)
    for name, members in interfaces.items():
        for m in members:
            if m not in contacts:
                raise InputError(f"interfaces[{name}]", f"names unknown contact {m!r}", f"use contacts of {contacts}")
    return {str(k): [str(m) for m in v] for k, v in interfaces.items()}


def _directions_of(ds: xr.Dataset, contacts: list[str]) -> np.ndarray:
    owner = np.asarray([str(c) for c in ds["direction_contact"].values])
    return np.flatnonzero(np.isin(owner, contacts))


def contact_loops(ds: xr.Dataset, period: float | None = None) -> xr.Dataset:
    """The last period of ``ds`` restricted to the loop variables: tangential force T vs
    tangential displacement u (per direction) and normal force N vs normal approach v
    (per contact), with their units. Plot T against u for the hysteresis loop."""
    lp = last_period(ds, period)
    names = ["tangential_displacement", "tangential_force", "normal_displacement", "normal_force", "contact_state"]
    return lp[[n for n in names if n in lp]]


def interface_loops(ds: xr.Dataset, interfaces=None, period: float | None = None) -> xr.Dataset:
    """Per-interface loops over the last period: u_I = mean of its directions' u [m],
    T_I = sum of their T [N], N_I = sum of its contacts' N [N], dims (time, interface).
    ``interfaces``: a dict {name: [contact names]}, a System (grouped by
    :func:`interfaces_from_system`) or None (one interface per contact)."""
    groups = _resolve_interfaces(ds, interfaces)
    lp = last_period(ds, period)
    u = lp["tangential_displacement"].values
    T = lp["tangential_force"].values
    N = lp["normal_force"].values
    contacts = [str(c) for c in ds["contact"].values]
    uI, TI, NI = [], [], []
    for members in groups.values():
        d = _directions_of(ds, members)
        uI.append(u[:, d].mean(axis=1))
        TI.append(T[:, d].sum(axis=1))
        NI.append(N[:, [contacts.index(m) for m in members]].sum(axis=1))
    dims = ("time", "interface")
    return xr.Dataset(
        {
            "tangential_displacement": (
                dims,
                np.array(uI).T,
                {"units": "m", "long_name": "mean tangential displacement u_I"},
            ),
            "tangential_force": (dims, np.array(TI).T, {"units": "N", "long_name": "total tangential force T_I"}),
            "normal_force": (dims, np.array(NI).T, {"units": "N", "long_name": "total normal force N_I"}),
        },
        coords={
            "time": lp["time"],
            "interface": list(groups),
            "members": ("interface", [",".join(m) for m in groups.values()]),
        },
    )


def loop_summary(ds: xr.Dataset, interfaces=None, period: float | None = None) -> xr.Dataset:
    """Loop energy, secant stiffness and equivalent damping (module docstring) over the last
    period, per direction (dim ``direction``) and per interface (dim ``interface``).

    Variables: energy_J (per direction: closed integral of T du; per interface: the sum over
    its directions), k_eq_N_per_m, zeta_eq, T_min_N, T_max_N, u_min_m, u_max_m, with units.
    """
    groups = _resolve_interfaces(ds, interfaces)
    lp = last_period(ds, period)
    u = lp["tangential_displacement"].values
    T = lp["tangential_force"].values
    per_dir = [loop_properties(u[:, d], T[:, d]) for d in range(u.shape[1])]
    il = interface_loops(ds, groups, period)
    per_if = []
    for i, members in enumerate(groups.values()):
        props = loop_properties(il["tangential_displacement"].values[:, i], il["tangential_force"].values[:, i])
        e_sum = sum(per_dir[d]["energy_J"] for d in _directions_of(ds, members))
        props["zeta_eq"] = (
            e_sum / (4 * math.pi * props["elastic_energy_J"]) if props["elastic_energy_J"] > 0 else math.nan
        )
        props["energy_J"] = e_sum
        per_if.append(props)
    units = {
        "energy_J": "J",
        "k_eq_N_per_m": "N/m",
        "elastic_energy_J": "J",
        "zeta_eq": "1",
        "u_min_m": "m",
        "u_max_m": "m",
        "T_min_N": "N",
        "T_max_N": "N",
    }
    data = {}
    for key, unit in units.items():
        data[f"direction_{key}"] = ("direction", [p[key] for p in per_dir], {"units": unit})
        data[f"interface_{key}"] = ("interface", [p[key] for p in per_if], {"units": unit})
    return xr.Dataset(
        data,
        coords={
            "direction": ds["direction"].values,
            "interface": list(groups),
            "members": ("interface", [",".join(m) for m in groups.values()]),
        },
        attrs={"period_s": float(lp["time"].values[-1] - lp["time"].values[0])},
    )
