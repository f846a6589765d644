"""One self-contained HTML report of a case: runs it, tabulates, embeds the figures.

``write_report(system, path)`` runs the quasi-static method (Method 4) and the
piecewise-linear Newmark (Method 3) for a few periods, filters the dynamic result
(slipstep.post.filtering), and writes ONE HTML file: summary tables (loads, loop energies
per interface, equivalent secant stiffness k_eq = (T_max - T_min) / (u_max - u_min) and
damping ratio zeta_eq = E_diss / (4 pi E_el), timings, state changes, the advisor's
findings) and every figure as a base64 PNG. No external resources (no scripts, styles,
fonts or images fetched from anywhere), so it opens in a browser with no network.
"""

from __future__ import annotations

import base64
import html
import io
import math
import time
import warnings
from pathlib import Path

import numpy as np

from slipstep.errors import InputError
from slipstep.output.io import plain_text_figures

_CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222;line-height:1.4}
table{border-collapse:collapse;margin:0.6em 0 1.2em}td,th{border:1px solid #bbb;padding:3px 9px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%;border:1px solid #ddd}
pre{background:#f6f6f6;padding:0.8em;white-space:pre-wrap;font-size:0.9em}.warn{color:#a40000}"""


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _table(header: list[str], rows: list[list]) -> str:
    def cell(v):
        if isinstance(v, float):
            return "-" if not math.isfinite(v) else f"{v:.4g}"
        return html.escape(str(v))

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _loop_rows(label: str, summary) -> list[list]:
    rows = []
    for i, name in enumerate(summary["interface"].values):
        rows.append(
            [
                label,
                f"{name} ({summary['members'].values[i]})",
                summary["interface_energy_J"].values[i] * 1e3,
                summary["interface_k_eq_N_per_m"].values[i] * 1e-6,
                summary["interface_zeta_eq"].values[i],
                summary["interface_T_min_N"].values[i],
                summary["interface_T_max_N"].values[i],
            ]
        )
    return rows


@plain_text_figures
def write_report(
    system,
    path,
    periods: float = 3.0,
    rotor_speed_rpm: float | None = None,
    radius_m: float | None = None,
    displacement_amplitude_m: float | None = None,
    comparison: list[dict] | None = None,
    dynamic_method: str = "piecewise-linear",
) -> Path:
    """Run ``system`` (quasi-static + ``dynamic_method``, ``periods`` periods), write the HTML
    report to ``path`` and return the path. ``comparison``: optional method-comparison rows
    ({'method', 'time_ratio', ...}) for the Fig. 8 bars."""
    from slipstep.post import plots
    from slipstep.study.advise import advise
    from slipstep.methods.simulation import run
    from slipstep.post.filtering import FilterWarning, filter_dataset
    from slipstep.post.loops import interfaces_from_system, loop_summary
    from slipstep.post.periodic import last_period, periodicity
    from slipstep.post.timeline import count_state_changes, full_slip_share, states_from_forces
    from slipstep.model.system import System

    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    if system.period is None:
        raise InputError("excitation", "has no period", "the report needs a periodic (harmonic) excitation")
    path = Path(path)
    start = time.perf_counter()
    results, timing = {}, []
    for method in ("quasi-static", dynamic_method):
        t0 = time.perf_counter()
        ds = run(system, method, periods=periods)
        results[method] = ds
        timing.append(
            [
                ds.attrs.get("paper_method", method),
                method,
                ds.attrs["status"],
                ds.attrs["steps"],
                ds.attrs["solves"],
                ds.attrs["mean_solves_per_step"],
                ds.attrs.get("kernel_time_s", math.nan) * 1e3,
                (time.perf_counter() - t0) * 1e3,
            ]
        )
    qs, dyn = results["quasi-static"], results[dynamic_method]
    warn_msgs = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", FilterWarning)
        filt = filter_dataset(dyn, system)
    warn_msgs += [str(w.message) for w in caught if issubclass(w.category, FilterWarning)]
    groups = interfaces_from_system(system)
    loop_rows = []
    for label, ds in (("quasi-static", qs), (f"{dynamic_method} raw", dyn), (f"{dynamic_method} filtered", filt)):
        loop_rows += _loop_rows(label, loop_summary(ds, groups))
    state_rows = []
    for label, ds, S in (
        ("quasi-static", qs, None),
        (f"{dynamic_method} raw", dyn, None),
        (f"{dynamic_method} filtered", filt, "forces"),
    ):
        lp = last_period(ds)
        states = states_from_forces(lp) if S else lp["contact_state"].values
        state_rows.append(
            [label, count_state_changes(states), 100 * full_slip_share(lp, states), periodicity(ds).text()]
        )
    advice = advise(system, rotor_speed_rpm, radius_m, displacement_amplitude_m)
    cs = system.compile_dense("the report")
    f0 = np.asarray(cs.constant_force, float)
    dof_names = list(system.structure.dof_names) or [f"dof {i}" for i in range(system.n_dofs)]
    load_rows = [
        [f"constant force on {n}", float(f), "N"]
        for n, f in zip(dof_names, f0)
        if abs(f) > 1e-9 * np.abs(f0).max(initial=0.0)
    ]
    msin, mcos = np.atleast_2d(cs.motion_sin), np.atleast_2d(cs.motion_cos)
    for k, f in enumerate(np.atleast_1d(cs.motion_frequency)):
        for j, name in enumerate(system.motion_names):
            amp = math.hypot(msin[j, k], mcos[j, k])
            if amp > 0:
                load_rows.append([f"motion {name}, {f:g} Hz", amp * 1e6, "um (amplitude)"])
    lp = last_period(qs)
    force_rows = [
        [
            str(d),
            float(lp["tangential_force"].values[:, i].min()),
            float(lp["tangential_force"].values[:, i].max()),
            float(lp["normal_force"].values[:, list(lp["contact"].values).index(c)].min()),
            float(lp["normal_force"].values[:, list(lp["contact"].values).index(c)].max()),
        ]
        for i, (d, c) in enumerate(zip(lp["direction"].values, lp["direction_contact"].values))
    ]

    figs = [
        ("Time histories, quasi-static and dynamic superposed (paper Fig. 7)", plots.plot_time_histories([qs, dyn])),
        ("Hysteresis loops per contact, raw and filtered (paper Fig. 6)", plots.plot_loops(dyn, filt)),
        ("Hysteresis loops per interface (platform), raw and filtered", plots.plot_loops(dyn, filt, interfaces=groups)),
        ("Quasi-static hysteresis loops", plots.plot_loops(qs)),
        ("Step size and contact states (paper Fig. 4b)", plots.plot_step_size(dyn)),
        ("Iterations per step (paper Fig. 5)", plots.plot_iterations([qs, dyn])),
        ("Contact-state timeline (quasi-static)", plots.plot_state_timeline(qs)),
    ]
    if comparison:
        figs.append(
            ("Computational time relative to Method 1 (paper Fig. 8)", plots.plot_method_comparison(comparison))
        )
    fig_html = "".join(
        f'<h3>{html.escape(t)}</h3><img alt="{html.escape(t)}" src="data:image/png;base64,{_png(f)}">' for t, f in figs
    )
    total = time.perf_counter() - start
    parts = [
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
        f"<title>slipstep report: {html.escape(system.name)}</title><style>{_CSS}</style></head><body>",
        f"<h1>slipstep report: {html.escape(system.name)}</h1>",
        f"<p>{periods:g} excitation periods of {system.period * 1e3:.4g} ms; tables refer to the last period. "
        f"Report built in {total:.2f} s.</p>",
        "<h2>Loads</h2>",
        _table(["load", "value", "unit"], load_rows),
        "<h2>Contact forces, last period (quasi-static)</h2>",
        _table(["direction", "T min [N]", "T max [N]", "N min [N]", "N max [N]"], force_rows),
        "<h2>Loop energies and equivalent stiffness / damping</h2>",
        "<p>E = closed integral of T du over the last period (sum over the interface's contacts); "
        "k_eq = (T_max - T_min)/(u_max - u_min) of the interface loop (T summed, u averaged); "
        "zeta_eq = E / (4 pi E_el), E_el = 1/2 k_eq (half range of u)^2.</p>",
        _table(["result", "interface", "E [mJ]", "k_eq [N/um]", "zeta_eq [-]", "T min [N]", "T max [N]"], loop_rows),
        "<h2>Contact states, last period</h2>",
        "<p>Instants at which any contact changes state. The raw dynamic count includes the chatter of the "
        "ringing; the filtered count uses states recovered from the filtered forces (slip when |T| &ge; 0.98 mu N), "
        "where the rounded corners of the filtered loops split simultaneous quasi-static transitions.</p>",
        _table(["result", "state changes", "full slip [% of period]", "periodicity"], state_rows),
        "<h2>Timings</h2>",
        _table(
            ["paper method", "method", "status", "steps", "solves", "solves/step", "kernel [ms]", "wall [ms]"], timing
        ),
    ]
    if warn_msgs:
        parts.append("".join(f'<p class="warn">Filter warning: {html.escape(m)}</p>' for m in warn_msgs))
    parts += [
        "<h2>Method advisor</h2>",
        f"<pre>{html.escape(advice.text())}</pre>",
        "<h2>Figures</h2>",
        fig_html,
        "</body></html>",
    ]
    from slipstep.output import io as sio

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise sio.output_error(path, exc) from None
    return sio.write_text(path, "".join(parts))
