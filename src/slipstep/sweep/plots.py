"""Design maps and design curves from a sweep store (matplotlib, Agg backend).

* :func:`design_map`    - a quantity over two parameters: filled contours (a grid) or a
  triangulated map with the sample points (sampled sweeps), colour bar with units, the
  optimum marked (star) and, on a grid, the best y for each x (the ridge a designer follows);
* :func:`design_curves` - a quantity against one parameter, one curve per value of another
  (the energy-vs-amplitude curve of a damper for several centrifugal loads);
* :func:`frf_curves`    - the stored frequency responses of one response DOF, one per case;
* :func:`mistuning_distribution` - a mistuning sweep's amplification factors: histogram and
  empirical CDF per mistuning level, with the tuned ring (1), the linear stuck-contact
  amplification factors (dashed CDFs) and Whitehead's linear limit (1 + sqrt(N)) / 2 marked;
* :func:`mistuning_levels` - the largest blade amplitude against the mistuning level, with
  dampers and without (contacts removed): median, 5-95 % band and maximum over the samples,
  the tuned values as horizontal lines (cases pooled over any other parameter).

A quantity is a store variable, with a label in brackets for the labelled ones:
``energy_per_cycle_J``, ``interface_energy_per_cycle_J[right]``, ``interface_zeta_eq[left]``.
Parameters not on the axes are held at the values of ``at`` (default: those of the optimum),
so the map goes through the optimum. Failed cases are drawn as grey crosses.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter  # noqa: E402
from matplotlib.tri import Triangulation  # noqa: E402

from slipstep.errors import InputError  # noqa: E402

_DISPLAY = {"J": (1e3, "mJ"), "N/m": (1e-6, "N/um"), "m": (1e6, "um")}


def quantity(ds, name: str) -> tuple[np.ndarray, str, str]:
    """Values over ``case`` of a quantity ``name`` (``var`` or ``var[label]``), its display
    unit and a label, values scaled to the display unit (J -> mJ, N/m -> N/um, m -> um)."""
    from slipstep.post.summary import field_of

    base, label = field_of(name)
    if base not in ds.data_vars:
        options = sorted(v for v in ds.data_vars if ds[v].dims[:1] == ("case",) and ds[v].dtype.kind == "f")
        raise InputError("quantity", f"{base!r} is not in the store", f"use one of {', '.join(options)}")
    var = ds[base]
    dims = [d for d in var.dims if d != "case"]
    if dims and label is None:
        labels = [str(v) for v in ds[dims[0]].values]
        raise InputError(
            "quantity",
            f"{base!r} has one value per {dims[0]}",
            f"pick one: {', '.join(f'{base}[{lab}]' for lab in labels)}",
        )
    if dims:
        labels = [str(v) for v in ds[dims[0]].values]
        if label not in labels:
            raise InputError(
                "quantity", f"{label!r} is not a {dims[0]} of the store", f"use one of {', '.join(labels)}"
            )
        var = var.isel({dims[0]: labels.index(label)})
    elif label is not None:
        raise InputError("quantity", f"{base!r} has no [{label}]", f"write {base}")
    units = var.attrs.get("units", "1")
    factor, shown = _DISPLAY.get(units, (1.0, units))
    text = var.attrs.get("long_name", base) + (f", {dims[0]} {label}" if label else "")
    return np.asarray(var.values, float) * factor, shown, text


def _param_label(ds, name: str) -> str:
    if name not in ds.coords:
        raise InputError(
            "parameter", f"{name!r} is not a parameter of the sweep", f"use one of {', '.join(ds.attrs['parameters'])}"
        )
    attrs = ds[name].attrs
    unit = attrs.get("units", "1")
    return f"{attrs.get('long_name', name)} [{unit if unit != '1' else '-'}]"


def _ok(ds) -> np.ndarray:
    return np.asarray(ds["status"].values).astype(str) == "OK"


def optimum(ds, name: str, minimize: bool = False) -> int | None:
    """The case index of the best OK case for the quantity (largest, or smallest)."""
    values, _, _ = quantity(ds, name)
    good = _ok(ds) & np.isfinite(values)
    if not good.any():
        return None
    masked = np.where(good, values, np.inf if minimize else -np.inf)
    return int(np.argmin(masked) if minimize else np.argmax(masked))


def _slice(ds, keep: list[str], at: dict | None, best: int | None) -> np.ndarray:
    """Cases whose other parameters equal the held values (``at`` or the optimum's)."""
    mask = np.ones(ds.sizes["case"], bool)
    if ds.attrs.get("grid_shape") is None:
        return mask  # sampled: every point (the other parameters vary along with them)
    for p in ds.attrs["parameters"]:
        if p in keep:
            continue
        values = ds[p].values
        if at and p in at:
            target = values[np.argmin(np.abs(values - at[p]))]
        elif best is not None:
            target = values[best]
        else:
            target = values[0]
        mask &= values == target
    return mask


def check_at(ds, at: dict | None) -> None:
    """Each held parameter is a parameter of the sweep and its value one of the sweep's."""
    if not at:
        return
    if ds.attrs.get("grid_shape") is None:
        raise InputError("at", "holds parameters of a sampled sweep", "remove it: a sampled map shows every point")
    for p, target in at.items():
        if p not in ds.attrs["parameters"]:
            raise InputError(
                "at", f"{p!r} is not a parameter of the sweep", f"use one of {', '.join(ds.attrs['parameters'])}"
            )
        values = np.unique(ds[p].values)
        if not np.isclose(values, target, rtol=1e-9, atol=1e-12).any():
            raise InputError(
                "at",
                f"{p} = {target:g} is not a value of the sweep",
                f"use one of {', '.join(f'{v:g}' for v in values)}",
            )


def _held_text(ds, keep: list[str], mask: np.ndarray) -> str:
    held = [p for p in ds.attrs["parameters"] if p not in keep]
    if not held or ds.attrs.get("grid_shape") is None:
        return ""
    i = int(np.flatnonzero(mask)[0])
    return ", ".join(f"{p} = {ds[p].values[i]:.4g}{_u(ds[p].attrs.get('units', '1'))}" for p in held)


def _scale_axis(ax, which: str, values: np.ndarray) -> None:
    """A log scale with plain tick labels (2, 5, 10, 20, ...) for values spanning 20x or more."""
    if not _log_axis(values):
        return
    getattr(ax, f"set_{which}scale")("log")
    axis = getattr(ax, f"{which}axis")
    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _triangulation(x: np.ndarray, y: np.ndarray) -> Triangulation:
    """Delaunay triangles of scattered points in the plotted coordinates (log where the axis
    is), each scaled to [0, 1] so that no parameter's unit decides the mesh."""

    def unit(v):
        w = np.log(v) if _log_axis(v) else np.asarray(v, float)
        span = np.ptp(w)
        return (w - w.min()) / span if span > 0 else w * 0.0

    return Triangulation(x, y, Triangulation(unit(x), unit(y)).triangles)


def _u(unit: str) -> str:
    return "" if unit in ("1", "") else f" {unit}"


def _log_axis(values: np.ndarray) -> bool:
    v = values[np.isfinite(values)]
    return v.size > 2 and v.min() > 0 and v.max() / v.min() >= 20


def design_map(
    ds,
    name: str = "energy_per_cycle_J",
    x: str | None = None,
    y: str | None = None,
    at: dict | None = None,
    minimize: bool = False,
    ax=None,
):
    """Filled contours of quantity ``name`` over parameters ``x`` and ``y`` (module docstring).
    Returns the matplotlib Figure."""
    params = list(ds.attrs["parameters"])
    if len(params) < 2:
        raise InputError("y", "the sweep has a single parameter", "plot design curves instead")
    x = x or params[1 if len(params) > 1 else 0]
    y = y or params[0]
    if x == y:
        raise InputError("y", f"is {y!r}, the same as x", "give two different parameters")
    values, unit, text = quantity(ds, name)
    check_at(ds, at)
    best = optimum(ds, name, minimize)
    mask = _slice(ds, [x, y], at, best)
    xs, ys, zs = ds[x].values[mask], ds[y].values[mask], values[mask]
    ok = _ok(ds)[mask] & np.isfinite(zs)
    own = ax is None
    fig = plt.figure(figsize=(7.2, 5.6), layout="constrained") if own else ax.figure
    ax = ax or fig.add_subplot()
    grid = ds.attrs.get("grid_shape") is not None
    finite = zs[ok]
    levels = 14
    if finite.size:  # every value inside the levels (a stuck loop's area is +-1e-18 J of round-off)
        levels = MaxNLocator(14).tick_values(finite.min(), finite.max())
        levels[0], levels[-1] = min(levels[0], finite.min()), max(levels[-1], finite.max())
    if grid:
        ux, uy = np.unique(xs), np.unique(ys)
        Z = np.full((uy.size, ux.size), np.nan)
        Z[np.searchsorted(uy, ys[ok]), np.searchsorted(ux, xs[ok])] = zs[ok]
        filled = ax.contourf(ux, uy, Z, levels=levels, cmap="viridis")
        ax.contour(ux, uy, Z, levels=filled.levels, colors="k", linewidths=0.4, alpha=0.5)
        ax.plot(xs, ys, ".", color="w", ms=2.5, alpha=0.6)
        spread = np.nanmax(Z) - np.nanmin(Z) if np.isfinite(Z).any() else 0.0
        ridge = [
            (ux[j], uy[np.nanargmin(Z[:, j]) if minimize else np.nanargmax(Z[:, j])])
            for j in range(ux.size)  # columns that vary (not a flat, all-stuck column)
            if np.isfinite(Z[:, j]).sum() > 1 and np.nanmax(Z[:, j]) - np.nanmin(Z[:, j]) > 1e-6 * spread
        ]
        if ridge:
            rx, ry = zip(*ridge)
            ax.plot(
                rx,
                ry,
                "--",
                color="#ff8c00",
                lw=1.4,
                marker="o",
                ms=4,
                mec="k",
                mew=0.5,
                label=f"best {y} for each {x}",
            )
    else:
        if ok.sum() < 3:
            raise InputError("quantity", f"only {ok.sum()} successful cases to map", "run more cases")
        filled = ax.tricontourf(_triangulation(xs[ok], ys[ok]), zs[ok], levels=levels, cmap="viridis")
        ax.plot(xs[ok], ys[ok], ".", color="k", ms=3, alpha=0.6, label="samples")
    if (~ok).any():
        ax.plot(xs[~ok], ys[~ok], "x", color="0.5", ms=6, label="failed cases")
    bar = fig.colorbar(filled, ax=ax)
    bar.set_label(f"{text} [{unit if unit != '1' else '-'}]")
    if best is not None and mask[best]:
        bx, by, bz = ds[x].values[best], ds[y].values[best], values[best]
        ax.plot(
            bx,
            by,
            marker="*",
            ms=18,
            color="#ff3030",
            mec="k",
            mew=1.0,
            ls="none",
            clip_on=False,
            zorder=5,
            label=f"{'minimum' if minimize else 'optimum'}: {bz:.4g}{_u(unit)} at {x} = {bx:.4g}, {y} = {by:.4g}",
        )
    ax.set_xlabel(_param_label(ds, x))
    ax.set_ylabel(_param_label(ds, y))
    _scale_axis(ax, "x", xs)
    _scale_axis(ax, "y", ys)
    held = _held_text(ds, [x, y], mask)
    ax.set_title(f"{ds.attrs.get('sweep_name', 'sweep')}: {text}" + (f"\n({held})" if held else ""))
    if own:
        fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    else:
        ax.legend(fontsize=8)
    return fig


def design_curves(
    ds,
    name: str = "energy_per_cycle_J",
    x: str | None = None,
    group: str | None = None,
    at: dict | None = None,
    minimize: bool = False,
    ax=None,
):
    """Quantity ``name`` against parameter ``x``, one curve per value of ``group`` (grid
    sweeps); returns the Figure."""
    params = list(ds.attrs["parameters"])
    x = x or params[-1]
    if group is None and len(params) > 1:
        group = next(p for p in params if p != x)
    if group == x:
        raise InputError("group", f"is {group!r}, the same as x", "give another parameter")
    if ds.attrs.get("grid_shape") is None:
        raise InputError("x", "design curves need a grid sweep", "use design_map for sampled sweeps")
    values, unit, text = quantity(ds, name)
    check_at(ds, at)
    best = optimum(ds, name, minimize)
    keep = [x] + ([group] if group else [])
    mask = _slice(ds, keep, at, best)
    ok = _ok(ds)
    fig = ax.figure if ax is not None else plt.figure(figsize=(7.2, 4.8), constrained_layout=True)
    ax = ax or fig.add_subplot()
    groups = np.unique(ds[group].values[mask]) if group else [None]
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, len(groups)))
    for g, color in zip(groups, colors):
        sel = mask & (ds[group].values == g) if group else mask.copy()
        order = np.argsort(ds[x].values[sel])
        xs, zs, good = ds[x].values[sel][order], values[sel][order], ok[sel][order]
        label = f"{group} = {g:.4g}{_u(ds[group].attrs.get('units', '1'))}" if group else None
        ax.plot(xs[good], zs[good], marker="o", ms=4, color=color, label=label)
        if (~good).any():
            ax.plot(xs[~good], np.zeros((~good).sum()), "x", color="0.5", ms=6)
    if best is not None and mask[best]:
        ax.plot(
            ds[x].values[best],
            values[best],
            marker="*",
            ms=16,
            color="#ff3030",
            mec="k",
            ls="none",
            clip_on=False,
            zorder=5,
            label=f"{'minimum' if minimize else 'optimum'}: {values[best]:.4g}{_u(unit)} at {x} = "
            f"{ds[x].values[best]:.4g}" + (f", {group} = {ds[group].values[best]:.4g}" if group else ""),
        )
    ax.set_xlabel(_param_label(ds, x))
    ax.set_ylabel(f"{text} [{unit if unit != '1' else '-'}]")
    _scale_axis(ax, "x", ds[x].values)
    ax.grid(alpha=0.3)
    held = _held_text(ds, keep, mask)
    ax.set_title(f"{ds.attrs.get('sweep_name', 'sweep')}: {text}" + (f"\n({held})" if held else ""))
    ax.legend(loc="best", fontsize=8)
    return fig


def frf_curves(ds, response: str | None = None, group: str | None = None, at: dict | None = None, ax=None):
    """The stored frequency responses (``frf_amplitude`` of one response DOF against frequency),
    one curve per case, or on a grid per value of ``group`` with the other parameters held at
    ``at`` (default: their first values); returns the Figure."""
    if "frf_amplitude" not in ds:
        raise InputError("store", "holds no frequency responses", "add an [outputs.frf] table to the sweep")
    responses = [str(r) for r in ds["response"].values]
    response = response or responses[0]
    if response not in responses:
        raise InputError(
            "response", f"{response!r} is not a response of the FRFs", f"use one of {', '.join(responses)}"
        )
    check_at(ds, at)
    params = list(ds.attrs["parameters"])
    group = group or params[0]
    if group not in params:
        raise InputError("group", f"{group!r} is not a parameter of the sweep", f"use one of {', '.join(params)}")
    mask = _slice(ds, [group], at, None) if ds.attrs.get("grid_shape") else np.ones(ds.sizes["case"], bool)
    amp = ds["frf_amplitude"].sel(response=response)
    factor, unit = _DISPLAY.get(amp.attrs.get("units", "").split()[0] if amp.attrs.get("units") else "", (1.0, ""))
    f = ds["frequency"].values
    fig = ax.figure if ax is not None else plt.figure(figsize=(7.2, 4.8), layout="constrained")
    ax = ax or fig.add_subplot()
    cases = np.flatnonzero(mask)
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, max(len(cases), 1)))
    for i, color in zip(cases, colors):
        ok = np.asarray(ds["frf_status"].values[i]).astype(str) == "OK"
        y = amp.values[i] * factor
        ax.plot(
            f[ok],
            y[ok],
            marker="o",
            ms=3,
            color=color,
            label=f"{group} = {ds[group].values[i]:.4g}{_u(ds[group].attrs.get('units', '1'))}",
        )
        if (~ok).any():
            ax.plot(f[~ok], np.zeros((~ok).sum()), "x", color="0.5", ms=6)
    ax.set_xlabel("excitation frequency [Hz]")
    ax.set_ylabel(f"response amplitude of {response} [{unit or amp.attrs.get('units', '-')}]")
    held = _held_text(ds, [group], mask)
    ax.set_title(f"{ds.attrs.get('sweep_name', 'sweep')}: frequency responses" + (f"\n({held})" if held else ""))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def write_figures(
    ds,
    output_dir,
    name: str = "energy_per_cycle_J",
    x: str | None = None,
    y: str | None = None,
    group: str | None = None,
    at: dict | None = None,
    minimize: bool = False,
) -> list:
    """design_map.png (two or more parameters), design_curves.png (grid sweeps) and
    frf_curves.png (sweeps with frequency responses) in ``output_dir``, each written atomically
    (slipstep.output.io.save_figure); returns the paths."""
    from pathlib import Path

    from slipstep.output.io import save_figure

    output_dir = Path(output_dir)
    check_at(ds, at)
    paths = []
    params = list(ds.attrs["parameters"])
    figures = []
    mistuned = "amplification_factor" in ds and "mistuning_reference" in ds.attrs
    if mistuned and name not in ds:  # an FRF-only mistuning sweep: no time summary to map
        params = []
    if len(params) >= 2:
        figures.append(("design_map.png", design_map(ds, name, x, y, at, minimize)))
    if ds.attrs.get("grid_shape") is not None and params:
        cx = x or params[-1]
        cg = group or (y if y and y != cx else None)
        figures.append(("design_curves.png", design_curves(ds, name, cx, cg, at, minimize)))
    if "frf_amplitude" in ds and not mistuned:
        figures.append(("frf_curves.png", frf_curves(ds, group=y, at=at)))
    if mistuned:
        figures.append(("mistuning_distribution.png", mistuning_distribution(ds)))
        figures.append(("mistuning_levels.png", mistuning_levels(ds)))
    for filename, fig in figures:
        path = output_dir / filename
        save_figure(fig, path, dpi=130)
        plt.close(fig)
        paths.append(path)
    return paths


def _mistuning_level(ds) -> str:
    """The level coordinate of a mistuning sweep (<name>_level)."""
    from slipstep.sweep.mistuning import LEVEL

    names = [p for p in ds.attrs["parameters"] if p.endswith(f"_{LEVEL}") and p[: -len(LEVEL)] + "sample" in ds]
    if not names:
        raise InputError("store", "is not a mistuning sweep", "plot a sweep with a [[parameter]] kind = mistuning")
    return names[0]


def _tuned(ds) -> dict:
    import json

    ref = json.loads(ds.attrs["mistuning_reference"])
    return ref[0] if ref else {}


def _ecdf(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The empirical CDF F(x_(i)) = i / n of the finite values, sorted."""
    v = np.sort(values[np.isfinite(values)])
    return v, np.arange(1, v.size + 1) / max(v.size, 1)


def mistuning_distribution(ds, ax=None):
    """Histogram (left) and empirical CDF (right) of the amplification factor per mistuning
    level (OK cases), the linear stuck-contact amplification factors as dashed CDFs, the tuned
    ring (AF = 1) and Whitehead's limit (1 + sqrt(N)) / 2 of a linear ring of N blades."""
    level = _mistuning_level(ds)
    ok = _ok(ds)
    n_blades = len(ds.attrs.get("mistuning_responses", [])) or None
    fig, (ax_h, ax_c) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    af_all = np.asarray(ds["amplification_factor"].values, float)[ok]
    bins = np.histogram_bin_edges(af_all[np.isfinite(af_all)], bins=20) if np.isfinite(af_all).any() else 10
    levels = np.unique(ds[level].values[ok])
    colours = plt.cm.viridis(np.linspace(0.1, 0.85, max(levels.size, 1)))
    for lev, c in zip(levels, colours):
        at = ok & (ds[level].values == lev)
        af = np.asarray(ds["amplification_factor"].values, float)[at]
        label = f"{level} = {lev:g} ({np.isfinite(af).sum()} samples)"
        ax_h.hist(af[np.isfinite(af)], bins=bins, color=c, alpha=0.55, label=label)
        x, F = _ecdf(af)
        ax_c.step(x, F, where="post", color=c, label=label)
        if "linear_stuck_amplification_factor" in ds:  # NaN where the stuck resonance is off the grid
            xs, Fs = _ecdf(np.asarray(ds["linear_stuck_amplification_factor"].values, float)[at])
            if xs.size:
                ax_c.step(xs, Fs, where="post", color=c, ls="--", lw=1, label=f"linear stuck, {level} = {lev:g}")
    for a in (ax_h, ax_c):
        a.axvline(1.0, color="k", lw=1.2, label="tuned (AF = 1)")
        if n_blades:
            a.axvline((1 + np.sqrt(n_blades)) / 2, color="grey", ls=":", label=f"Whitehead limit, {n_blades} blades")
        a.set_xlabel("amplification factor (largest blade amplitude / tuned) [1]")
    ax_h.set_ylabel("samples")
    ax_c.set_ylabel("empirical CDF [1]")
    ax_c.set_ylim(0, 1.02)
    ax_h.legend(fontsize=7)
    ax_c.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"{ds.attrs.get('sweep_name', 'sweep')}: amplification factor of the mistuned samples")
    return fig


def mistuning_levels(ds):
    """Largest blade amplitude against the mistuning level, with dampers (the FRF) and without
    (contacts removed, linear_free): median, 5-95 % band and maximum over the OK samples of each
    level; the tuned ring's values as horizontal lines."""
    level = _mistuning_level(ds)
    ok = _ok(ds)
    tuned = _tuned(ds)
    scale, unit = _DISPLAY["m"]
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    levels = np.unique(ds[level].values[ok])
    series = (
        ("peak_blade_amplitude", "with dampers", "C0"),
        ("linear_free_peak_amplitude", "without dampers (contacts removed)", "C3"),
    )
    for field, label, c in series:
        if field not in ds:
            continue
        rows = [np.asarray(ds[field].values, float)[ok & (ds[level].values == lev)] * scale for lev in levels]
        rows = [r[np.isfinite(r)] for r in rows]
        keep = [i for i, r in enumerate(rows) if r.size]
        if not keep:  # no finite peak (a linear limit resonating off the grid: sweep.mistuning.peaks)
            continue
        x = levels[keep]
        q = np.array([np.percentile(rows[i], [5, 50, 95]) for i in keep]).reshape(-1, 3)
        ax.fill_between(x, q[:, 0], q[:, 2], color=c, alpha=0.2, label=f"{label}: 5-95 %")
        ax.plot(x, q[:, 1], "o-", color=c, label=f"{label}: median")
        ax.plot(x, [rows[i].max() for i in keep], "^--", color=c, ms=5, lw=1, label=f"{label}: maximum")
        if field in tuned:
            ax.axhline(tuned[field] * scale, color=c, ls=":", lw=1.2, label=f"{label}: tuned")
    ax.set_xlabel(f"mistuning level {level} [{ds[level].attrs.get('units', '1')}]")
    ax.set_ylabel(f"largest blade amplitude [{unit}]")
    ax.legend(fontsize=7)
    ax.set_title(f"{ds.attrs.get('sweep_name', 'sweep')}: blade amplitude against mistuning")
    return fig
