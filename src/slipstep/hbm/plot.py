"""The FRF figure of harmonic balance results: amplitude and friction energy per cycle against
frequency, the linear limits, overlaid FRFs of other solvers (same Dataset layout), and the
time-marching cross-check at the checked points (marched value and the relative differences).
"""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from slipstep.output.io import atomic_path


def _label(ds: xr.Dataset) -> str:
    solver = ds.attrs.get("solver", "")
    if solver == "hbm":
        h = [int(v) for v in np.atleast_1d(ds.attrs.get("harmonics", []))][1:]
        text = f"H = {h[-1]}" if h == list(range(1, len(h) + 1)) else "harmonics " + ",".join(map(str, h))
        return f"HBM, {text}"
    return f"{solver} ({ds.attrs.get('method', '')})" if ds.attrs.get("method") else str(solver)


def plot_frf(datasets, path=None, response: str | None = None):
    """Figure of one or more FRF Datasets (a Dataset or a list); returns the matplotlib Figure
    and writes it to ``path`` (atomically) when given. ``response``: the DOF plotted (default
    the one with the largest amplitude in the first Dataset)."""
    items = [datasets] if isinstance(datasets, xr.Dataset) else list(datasets)
    first = items[0]
    if response is None:
        response = str(first.response.values[int(np.nanargmax(np.nanmax(first.amplitude.values, axis=0)))])
    unit = str(first.response_unit.sel(response=response).values)
    scale, shown = (1e6, "um") if unit == "m" else ((1e3, "mrad") if unit == "rad" else (1.0, unit))
    fig, (ax_a, ax_e) = plt.subplots(2, 1, figsize=(7.5, 7), sharex=True)
    for key, style, name in (
        ("linear_free_amplitude", ":", "contacts removed (linear)"),
        ("linear_stuck_amplitude", "--", "contacts stuck (linear)"),
    ):
        lin = first[key].sel(response=response).values
        if np.any(np.isfinite(lin)):
            order = np.argsort(first.frequency.values)
            ax_a.plot(first.frequency.values[order], lin[order] * scale, style, color="gray", label=name)
    for ds in items:
        f = ds.frequency.values
        amp = ds.amplitude.sel(response=response).values * scale
        (line,) = ax_a.plot(f, amp, "-", label=_label(ds))
        ax_e.plot(f, ds.energy_per_cycle.sum("contact").values * 1e3, "-", color=line.get_color(), label=_label(ds))
        checked = np.flatnonzero(np.isfinite(ds.check_amplitude_rel_diff.values))
        if checked.size:
            summary = {row["index"]: row for row in json.loads(ds.attrs.get("check_summary", "[]"))}
            for i in checked:
                row = summary.get(int(i), {})
                marched = row.get("march_amplitude")
                if marched is not None and ds.response.size == 1:
                    ax_a.plot(f[i], marched * scale, "kx", ms=8)
                ax_a.plot(f[i], amp[i], "o", mfc="none", color=line.get_color(), ms=8)
                text = f"march: d amp {ds.check_amplitude_rel_diff.values[i]:.1e}"
                de = ds.check_energy_rel_diff.values[i]
                if np.isfinite(de):
                    text += f", d E {de:.1e}"
                ax_a.annotate(text, (f[i], amp[i]), textcoords="offset points", xytext=(6, 6), fontsize=8)
                if row.get("march_energy_J") is not None:
                    ax_e.plot(f[i], row["march_energy_J"] * 1e3, "kx", ms=8)
    ax_a.plot([], [], "kx", label="time-marching cross-check")
    ax_a.set_ylabel(f"amplitude of {response} [{shown}]")
    ax_a.set_yscale("log")
    ax_a.legend(loc="lower left", fontsize=8, framealpha=0.8)
    ax_a.set_title(f"{first.attrs.get('case', '')}: frequency response")
    ax_e.set_ylabel("friction energy per cycle [mJ]")
    ax_e.set_xlabel("frequency [Hz]")
    fig.tight_layout()
    if path is not None:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1] if "." in str(path) else "png")
    return fig
