"""Figures from result Datasets only (matplotlib, Agg backend), after the paper's figures.

* :func:`plot_time_histories` - contact forces and damper displacements, quasi-static and
  dynamic superposed (paper Fig. 7)
* :func:`plot_loops`          - hysteresis loops T vs u, raw and filtered (Fig. 6)
* :func:`plot_step_size`      - step-size history with the contact states (Fig. 4b)
* :func:`plot_iterations`     - histogram of linear solves per step (Fig. 5)
* :func:`plot_method_comparison` - CPU time relative to Method 1 (Fig. 8), from rows
  {"method": ..., "time_ratio": ...} (as written by slipstep.study.compare)
* :func:`plot_state_timeline` - contact states over time per direction

Units come from the Dataset attributes and are converted at the edge: m -> um, rad -> mrad,
s -> ms (time) or us (steps), J -> mJ.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from slipstep.output.io import plain_text_figures as _plain_text_figures  # noqa: E402
from slipstep.output.results import STATE_NAMES  # noqa: E402

STATE_COLORS = ("#bbbbbb", "#2b83ba", "#d7191c", "#fdae61", "#7b3294")  # one per STATE_NAMES entry
_SCALE = {"m": (1e6, "um"), "rad": (1e3, "mrad"), "N": (1.0, "N"), "s": (1e3, "ms"), "J": (1e3, "mJ")}

plt.rcParams.update(
    {"font.size": 10, "axes.titlesize": 11, "axes.labelsize": 10, "legend.fontsize": 9, "figure.dpi": 100}
)


def _unit(units: str) -> tuple[float, str]:
    """Display factor and unit for a Dataset unit string (first token: 'm or rad' -> m)."""
    key = str(units).split()[0] if units else ""
    return _SCALE.get(key, (1.0, key))


def _label(ds: xr.Dataset) -> str:
    m = ds.attrs.get("paper_method") or ds.attrs.get("method", "result")
    name = ds.attrs.get("method", "")
    return f"{m} ({name})" if name and name != m else str(m)


def _time_ms(ds: xr.Dataset) -> np.ndarray:
    f, _ = _unit(ds["time"].attrs.get("units", "s"))
    return ds["time"].values * f


def _as_list(datasets) -> list[tuple[str, xr.Dataset]]:
    if isinstance(datasets, xr.Dataset):
        return [(_label(datasets), datasets)]
    if isinstance(datasets, dict):
        return list(datasets.items())
    return [(_label(d), d) for d in datasets]


def save_figure(fig, path) -> Path:
    """Write ``fig`` as PNG (150 dpi, tight) and close it."""
    from slipstep.output import io

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        io.save_figure(fig, path, dpi=150, bbox_inches="tight")
    except OSError as exc:
        raise io.output_error(path, exc) from None
    finally:
        plt.close(fig)
    return path


def plot_time_histories(datasets, last_periods: float | None = 1.0):
    """Tangential and normal contact forces and DOF displacements against time, every
    Dataset superposed (e.g. quasi-static and dynamic, paper Fig. 7). ``last_periods``:
    show only the last periods (None: everything)."""
    items = _as_list(datasets)
    ref = items[0][1]
    nd, nc, nx = ref.sizes["direction"], ref.sizes["contact"], ref.sizes["dof"]
    nrow = max(nd, nc, nx)
    fig, axes = plt.subplots(nrow, 3, figsize=(13, 2.3 * nrow + 0.8), sharex=True, squeeze=False)
    styles = ["-", "--", ":", "-."]
    for k, (label, ds) in enumerate(items):
        t = _time_ms(ds)
        sel = np.ones(t.size, bool)
        T = ds.attrs.get("period_s")
        if last_periods and T:
            sel = ds["time"].values >= ds["time"].values[-1] - last_periods * T * (1 + 1e-9)
        ls, lw = styles[k % 4], 1.6 if k == 0 else 1.1
        for col, (var, dim) in enumerate(
            (("tangential_force", "direction"), ("normal_force", "contact"), ("displacement", "dof"))
        ):
            f, u = _unit(ds[var].attrs.get("units"))
            for i, name in enumerate(ds[dim].values):
                ax = axes[i, col]
                fu, uu = f, u
                if var == "displacement" and "dof_unit" in ds.coords:
                    fu, uu = _unit(str(ds["dof_unit"].values[i]))
                ax.plot(t[sel], ds[var].values[sel, i] * fu, ls, lw=lw, label=label)
                short = {"tangential_force": "T", "normal_force": "N", "displacement": ""}[var]
                ax.set_ylabel(f"{short} {name} [{uu}]".strip())
    for col, title in enumerate(("tangential force", "normal force", "damper displacement")):
        axes[0, col].set_title(title)
        axes[-1, col].set_xlabel("time [ms]")
    for ax in axes.ravel():
        if not ax.lines:
            ax.set_visible(False)
        ax.grid(alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=len(items), bbox_to_anchor=(0.5, 1.0), frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return fig


def plot_loops(ds: xr.Dataset, filtered: xr.Dataset | None = None, period: float | None = None, interfaces=None):
    """Hysteresis loops T vs u over the last period, one panel per direction, or per
    interface when ``interfaces`` is given (a dict {name: [contacts]} or a System: T summed,
    u averaged, see slipstep.post.loops); the raw result and (if given) the filtered one
    superposed (paper Fig. 6)."""
    from slipstep.post.loops import interface_loops
    from slipstep.post.periodic import last_period

    def loops_of(d):
        if d is None:
            return None
        if interfaces is not None:
            il = interface_loops(d, interfaces, period)
            return il, list(il["interface"].values)
        lp = last_period(d, period)
        return lp, [f"contact {n}" for n in lp["direction"].values]

    (lp, names), lf = loops_of(ds), loops_of(filtered)
    n = len(names)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n + 0.4, 3.8), squeeze=False)
    fu, uu = _unit(lp["tangential_displacement"].attrs.get("units"))
    ft, ut = _unit(lp["tangential_force"].attrs.get("units"))
    for d, name in enumerate(names):
        ax = axes[0, d]
        ax.plot(
            lp["tangential_displacement"].values[:, d] * fu,
            lp["tangential_force"].values[:, d] * ft,
            lw=0.9,
            color="#999999" if lf is not None else "C0",
            label="raw",
        )
        if lf is not None:
            fc = filtered.attrs.get("filter_cutoff_Hz")
            lab = f"filtered ({fc / 1e3:.2g} kHz low-pass)" if fc else "filtered"
            ax.plot(
                lf[0]["tangential_displacement"].values[:, d] * fu,
                lf[0]["tangential_force"].values[:, d] * ft,
                lw=1.6,
                color="C3",
                label=lab,
            )
        ax.set_title(name if interfaces is None else f"interface {name}")
        ax.set_xlabel(
            f"tangential displacement u [{uu}]" if interfaces is None else f"mean tangential displacement [{uu}]"
        )
        ax.set_ylabel(f"tangential force T [{ut}]" if interfaces is None else f"total tangential force [{ut}]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best")
    fig.suptitle(f"Hysteresis loops, last period - {_label(ds)}")
    fig.tight_layout()
    return fig


def _state_strip(ax, ds: xr.Dataset):
    """Colour strip of the contact states, one row per direction."""
    t = _time_ms(ds)
    S = ds["contact_state"].values
    names = list(ds["direction"].values)
    for d in range(S.shape[1]):
        for s in range(4):
            mask = S[1:, d] == s
            if mask.any():
                ax.broken_barh(
                    [(a, b - a) for a, b in zip(t[:-1][mask], t[1:][mask])],
                    (d - 0.4, 0.8),
                    facecolors=STATE_COLORS[s],
                    edgecolor="none",
                )
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    ax.invert_yaxis()
    ax.legend(
        handles=[Patch(color=c, label=n) for c, n in zip(STATE_COLORS, STATE_NAMES)],
        loc="lower center",
        bbox_to_anchor=(0.5, 1.0),
        ncol=4,
        frameon=False,
        fontsize=9,
    )


def plot_step_size(ds: xr.Dataset):
    """Step size [us] against time with the contact states underneath (paper Fig. 4b)."""
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    t = _time_ms(ds)
    h = ds["step_size"].values[1:] * 1e6
    ax.step(t[1:], h, where="pre", lw=1.2, color="C0")
    tmin = ds.attrs.get("t_min_s")
    if tmin:
        ax.axhline(tmin / np.pi * 1e6, color="k", ls="--", lw=0.9, label="T_min(stick)/pi")
        ax.legend(loc="upper right")
    ax.set_ylabel("time step [us]")
    ax.set_title(f"Step size and contact states - {_label(ds)}")
    ax.grid(alpha=0.3)
    if ds.sizes.get("direction", 0):
        _state_strip(ax2, ds)
    ax2.set_xlabel("time [ms]")
    fig.tight_layout()
    return fig


def plot_iterations(datasets):
    """Histogram of linear solves (iterations) per step for each Dataset (paper Fig. 5)."""
    items = _as_list(datasets)
    fig, ax = plt.subplots(figsize=(7, 4))
    top = max(int(ds["solves"].values[1:].max(initial=1)) for _, ds in items)
    bins = np.arange(0.5, top + 1.5)
    for k, (label, ds) in enumerate(items):
        s = ds["solves"].values[1:]
        ax.hist(s, bins=bins, alpha=0.6, label=f"{label}: mean {s.mean():.2f}", color=f"C{k}")
    ax.set_xlabel("linear solves per step [-]")
    ax.set_ylabel("number of steps [-]")
    ax.set_title("Iterations per time step")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_method_comparison(rows: list[dict]):
    """Bars of CPU time relative to Method 1 (paper Fig. 8) from rows with keys 'method'
    and 'time_ratio' (other keys ignored; 'paper_method' used as label when present)."""
    if not rows:
        raise ValueError("rows: no comparison rows to plot")
    labels = [str(r.get("paper_method") or r["method"]) for r in rows]
    ratios = [float(r["time_ratio"]) for r in rows]
    fig, ax = plt.subplots(figsize=(max(5.0, 1.3 * len(rows)), 4))
    bars = ax.bar(range(len(rows)), ratios, color=[f"C{i}" for i in range(len(rows))])
    for b, r in zip(bars, ratios):
        ax.annotate(f"{r:.2f}", (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom")
    ax.set_xticks(
        range(len(rows)),
        labels,
        rotation=20 if max(map(len, labels)) > 10 else 0,
        ha="right" if max(map(len, labels)) > 10 else "center",
    )
    ax.set_ylabel("CPU time / Method 1 [-]")
    ax.set_title("Computational time relative to Method 1")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_ylim(0, max(ratios) * 1.18)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return fig


def plot_state_timeline(ds: xr.Dataset):
    """Contact states per direction against time."""
    fig, ax = plt.subplots(figsize=(9, 0.55 * ds.sizes["direction"] + 1.9))
    _state_strip(ax, ds)
    ax.set_xlabel("time [ms]")
    ax.set_title(f"Contact states - {_label(ds)}", pad=24)
    fig.tight_layout()
    return fig


@_plain_text_figures
def write_figures(
    ds: xr.Dataset,
    output_dir,
    reference: xr.Dataset | None = None,
    system=None,
    comparison: list[dict] | None = None,
    prefix: str = "",
) -> list[Path]:
    """Every figure that applies to ``ds`` as PNG files in ``output_dir``: time histories
    (with ``reference`` superposed), loops (filtered too when ``ds`` is dynamic and
    ``system`` is given), step size, iterations, state timeline, method comparison (if
    ``comparison`` rows are given). Returns the paths."""
    out = Path(output_dir)
    paths = []
    sets = [ds] if reference is None else [reference, ds]
    contacts = ds.sizes.get("direction", 0) > 0  # the save option may have left them out
    if max(ds.sizes.get("direction", 0), ds.sizes.get("contact", 0), ds.sizes.get("dof", 0)) > 0:
        paths.append(save_figure(plot_time_histories(sets), out / f"{prefix}time_histories.png"))
    filtered = None
    if not contacts:
        paths.append(save_figure(plot_step_size(ds), out / f"{prefix}step_size.png"))
        paths.append(save_figure(plot_iterations(sets), out / f"{prefix}iterations.png"))
        return paths
    if system is not None and not ds.attrs.get("quasi_static") and ds.attrs.get("period_s"):
        import warnings

        from slipstep.post.filtering import filter_dataset

        with warnings.catch_warnings():
            warnings.simplefilter("always")
            filtered = filter_dataset(ds, system)
    if ds.attrs.get("period_s"):
        paths.append(save_figure(plot_loops(ds, filtered), out / f"{prefix}loops.png"))
        if system is not None:
            paths.append(save_figure(plot_loops(ds, filtered, interfaces=system), out / f"{prefix}interface_loops.png"))
    paths.append(save_figure(plot_step_size(ds), out / f"{prefix}step_size.png"))
    paths.append(save_figure(plot_iterations(sets), out / f"{prefix}iterations.png"))
    paths.append(save_figure(plot_state_timeline(ds), out / f"{prefix}states.png"))
    if comparison:
        paths.append(save_figure(plot_method_comparison(comparison), out / f"{prefix}methods.png"))
    return paths
