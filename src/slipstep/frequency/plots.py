"""Figures of frequency-response Datasets (the layout of slipstep.output.frf_schema): the
response amplitude against frequency with both linear limits, and the friction energy per
cycle of each contact. A leaf: reads Datasets only (matplotlib, Agg backend).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from slipstep.output.io import atomic_path

_DISPLAY = {"m": (1e6, "um"), "rad": (1e3, "mrad")}
MAX_CONTACT_LINES = 6  # beyond this many contacts the energy panel shows their total and range
_SWEEP_STYLE = {
    "up": ("C0", "o", "upward sweep"),
    "down": ("C3", "v", "downward sweep"),
    None: ("C0", "o", "friction contacts"),
}


def _sweeps(ds: xr.Dataset):
    if "sweep" in ds.dims:
        return [(str(s), ds.sel(sweep=s)) for s in ds["sweep"].values]
    return [(None, ds)]


def default_response(ds: xr.Dataset) -> str:
    """The response DOF with the largest amplitude (the one a designer looks at first), among
    the translational DOFs (unit m) if there are any: amplitudes in m and rad do not compare."""
    amp = ds["amplitude"]
    peak = amp.max([d for d in amp.dims if d != "response"], skipna=True).fillna(-1.0).values
    metres = np.asarray(ds["response_unit"].values) == "m"
    if metres.any():
        peak = np.where(metres, peak, -np.inf)
    return str(ds["response"].values[int(np.argmax(peak))])


def plot_frf(
    ds: xr.Dataset, path, response: str | None = None, title: str | None = None, linear: xr.Dataset | None = None
) -> Path:
    """Amplitude of ``response`` (default :func:`default_response`) against frequency with the
    linear limits (contacts removed, every contact stuck), and the friction energy per cycle
    of each contact; written as PNG to ``path``. ``linear``: the linear limits on a finer grid
    (:func:`fine_linear_limits`), drawn instead of their values at the FRF's points (a coarse
    grid draws a linear resonance as a triangle)."""
    response = response or default_response(ds)
    unit = str(ds["response_unit"].sel(response=response).values)
    factor, label = _DISPLAY.get(unit, (1.0, unit))
    f = ds["frequency"].values
    solver = ds.attrs.get("solver", "")
    has_energy = np.isfinite(ds["energy_per_cycle"].values).any()
    fig, axes = plt.subplots(
        2 if has_energy else 1, 1, figsize=(7.5, 7.5 if has_energy else 4.5), sharex=True, squeeze=False
    )
    ax = axes[0, 0]
    labelled = set()
    for name, part in _sweeps(ds):
        color, marker, text = _SWEEP_STYLE.get(name, _SWEEP_STYLE[None])
        y = part["amplitude"].sel(response=response).values * factor
        ok = np.asarray(part["status"].values) == "OK"
        ax.plot(f, y, "-", color=color, marker=marker, ms=3.5, lw=1.2, label=f"{text} ({solver})")
        unstable = part["floquet_multiplier_max"].values > 1.0 + 1e-6  # beyond round-off of |mu| = 1
        inaccurate = _above_rtol(part, ds.attrs.get("rtol"))
        for mask, style, text in (
            (~ok, "x", "not steady / failed"),
            (unstable, "s", "unstable orbit (|Floquet| > 1)"),
            (inaccurate & ok, "^", f"error estimate above rtol {ds.attrs.get('rtol', 0):g}"),
        ):
            if mask.any():
                ax.plot(f[mask], y[mask], style, mfc="none", color="k", ms=7, label=None if text in labelled else text)
                labelled.add(text)
    for name, style, text in (
        ("linear_free_amplitude", "--", "linear: contacts removed"),
        ("linear_stuck_amplitude", ":", "linear: contacts stuck"),
    ):
        lim = (linear if linear is not None and response in linear["response"].values else ds)[name]
        if "sweep" in lim.dims:
            lim = lim.isel(sweep=0)
        y = lim.sel(response=response).values * factor
        if np.isfinite(y).any():
            ax.plot(lim["frequency"].values, y, style, color="0.35", lw=1.2, label=text)
    ax.set_yscale("log")
    ax.set_ylabel(f"amplitude of {response} [{label}]")
    ax.set_title(title or f"{ds.attrs.get('case', '')}: forced response ({response})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best")
    if has_energy:
        ax = axes[1, 0]
        contacts = list(ds["contact"].values)
        for name, part in _sweeps(ds):
            ls = "-" if name != "down" else "--"
            suffix = f" ({name})" if name else ""
            e = part["energy_per_cycle"].values * 1e3
            if len(contacts) <= MAX_CONTACT_LINES:
                for j, contact in enumerate(contacts):
                    ax.plot(f, e[:, j], ls, color=f"C{j}", marker=".", ms=3, label=f"{contact}{suffix}")
            else:  # many contacts: the total, and the range over the contacts
                color = _SWEEP_STYLE.get(name, _SWEEP_STYLE[None])[0]
                ax.plot(
                    f, e.sum(axis=1), ls, color=color, marker=".", ms=3, label=f"all {len(contacts)} contacts{suffix}"
                )
                ax.fill_between(
                    f, e.min(axis=1), e.max(axis=1), color=color, alpha=0.2, label=f"range over the contacts{suffix}"
                )
        ax.set_ylabel("friction energy per cycle [mJ]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", ncol=2)
    axes[-1, 0].set_xlabel("excitation frequency [Hz]")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return path


FINE_POINTS = 400  # frequencies of the linear limits drawn beside an FRF
FINE_MAX_DOFS = 300  # above this the factorisation per frequency costs more than a figure is worth


def fine_linear_limits(system, ds: xr.Dataset, response: str | None = None) -> xr.Dataset | None:
    """The linear limits of ``response`` (default :func:`default_response`) on FINE_POINTS
    frequencies spanning the FRF's grid (slipstep.steady.linear.linear_limits), for
    :func:`plot_frf`; None for a structure above FINE_MAX_DOFS DOFs or a grid of one point."""
    from slipstep.steady.linear import linear_limits

    f = np.asarray(ds["frequency"].values, float)
    if system.n_dofs > FINE_MAX_DOFS or f.size < 2 or not np.ptp(f) > 0:
        return None
    response = response or default_response(ds)
    return linear_limits(system, np.linspace(f.min(), f.max(), FINE_POINTS), responses=[response])


def _above_rtol(part, rtol) -> np.ndarray:
    """Points whose error estimate exceeds rtol (none when the Dataset has no estimate)."""
    if rtol is None or "error_estimate" not in part:
        return np.zeros(part.sizes["frequency"], bool)
    return np.asarray(part["error_estimate"].values, float) > float(rtol)
