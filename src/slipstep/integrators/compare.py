"""Cost and accuracy of every scheme x variant on one system (issue 5; ``slipstep compare
--schemes all``): steps, linear solves, kernel time (median of ``repeats`` marches after a
warm-up march) and its ratio to the Newmark fixed-step reference, and the error against a
fine-step reference over the last excitation period:

    disp_error_um     max |x - x_ref| over the translational DOFs (unit 'm'), in um
    force_error_pct   max |f - f_ref| over all contact forces (T and N), in % of |CF|
                      (CF: the constant load; the largest reference force when there is none)

The reference (default: piecewise-linear Newmark at step_ratio 0.1) is interpolated onto each
run's own time points, so the interpolation error is that of the fine grid.
Combinations a scheme does not support (piecewise-linear for explicit ones) are listed with
status 'n/a' and not run.
"""

from __future__ import annotations

import statistics

import numpy as np

from slipstep.errors import InputError
from slipstep.integrators.base import VARIANTS
from slipstep.methods.registry import SCHEMES

DEFAULT_SCHEMES = tuple(SCHEMES)  # every registered scheme with its defaults (hht(alpha=0.1), ...)


def _last_period_errors(ds, ref, system, t_from: float) -> tuple[float, float]:
    t = ds.time.values
    sel = t >= t_from - 1e-12 * max(t[-1], 1e-300)
    tr = ref.time.values
    units = np.asarray(ds.dof_unit.values)
    lin = np.flatnonzero(units == "m")
    x, xr = ds.displacement.values, ref.displacement.values
    disp = max((np.abs(x[sel, j] - np.interp(t[sel], tr, xr[:, j])).max() for j in lin), default=np.nan)
    cf = (
        float(np.linalg.norm(system.excitation.constant_force)) if system.excitation.constant_force is not None else 0.0
    )
    forces = [(ds[name].values, ref[name].values) for name in ("tangential_force", "normal_force")]
    if cf == 0.0:
        cf = max(np.abs(fr).max(initial=0.0) for _, fr in forces) or 1.0
    ferr = 0.0
    for f, fr in forces:
        for j in range(f.shape[1]):
            ferr = max(ferr, np.abs(f[sel, j] - np.interp(t[sel], tr, fr[:, j])).max())
    return disp * 1e6, 100.0 * ferr / cf


def compare_schemes(
    system,
    schemes="all",
    variants=VARIANTS,
    periods: float = 2.0,
    repeats: int = 3,
    reference=None,
    reference_step_ratio: float = 0.1,
    **options,
) -> list[dict]:
    """One row per scheme x variant (see the module docstring). ``schemes``: 'all' or a list of
    scheme specs (``'hht(0.1)'``...). ``reference``: a Dataset to compare with (default: computed).
    Extra ``options`` go to every run (e.g. step_ratio)."""
    from slipstep.integrators import get_integrator
    from slipstep.methods.simulation import Simulation

    if isinstance(repeats, bool) or int(repeats) < 1:
        raise InputError("repeats", f"is {repeats!r}", "give a whole number >= 1")
    specs = DEFAULT_SCHEMES if schemes in ("all", None) else ([schemes] if isinstance(schemes, str) else list(schemes))
    integrators = [get_integrator(s) for s in specs]
    variants = [variants] if isinstance(variants, str) else list(variants)
    for v in variants:
        if v not in VARIANTS:
            raise InputError("variants", f"unknown variant {v!r}", f"use {', '.join(VARIANTS)}")
    if reference is None:
        ref_opts = {k: v for k, v in options.items() if k != "step_ratio"}
        ref_opts["step_rule"] = "t-min"  # the reference's step is reference_step_ratio T_min (the paper's rule)
        reference = Simulation(
            system, "piecewise-linear", periods=periods, step_ratio=reference_step_ratio, **ref_opts
        ).run()
    t_end = float(reference.time.values[-1])
    period = system.period
    t_from = t_end - period if period is not None and period < t_end else 0.0

    def timed(integrator, variant):
        # the implicit schemes on the paper's T_min rule, each with its own step limit factor
        rule = {"step_rule": "t-min"} if integrator.kind == "implicit" else {}
        sim = integrator.simulation(system, variant, periods=periods, **{**options, **rule})
        times = []
        for _ in range(int(repeats) + 1):  # the first march is the warm-up (compilation, caches)
            sim.march()
            times.append(sim.kernel_time)
        return sim.dataset(), statistics.median(times[1:])

    rows = []
    base_time = None
    for integ in integrators:
        for variant in variants:
            row = {"scheme": integ.label, "kind": integ.kind, "order": integ.order, "variant": variant}
            if variant not in integ.variants:
                row.update(
                    status="n/a",
                    steps=None,
                    solves=None,
                    kernel_time_s=None,
                    time_ratio=None,
                    disp_error_um=None,
                    force_error_pct=None,
                )
                rows.append(row)
                continue
            ds, kt = timed(integ, variant)
            disp, ferr = (
                _last_period_errors(ds, reference, system, t_from) if ds.attrs["status"] == "OK" else (np.nan,) * 2
            )
            row.update(
                status=ds.attrs["status"],
                steps=int(ds.attrs["steps"]),
                solves=int(ds.attrs["solves"]),
                kernel_time_s=kt,
                time_ratio=None,
                disp_error_um=float(disp),
                force_error_pct=float(ferr),
            )
            rows.append(row)
    ref_rows = [r for r in rows if r["scheme"] == "newmark" and r["variant"] == "fixed" and r["status"] == "OK"]
    if ref_rows:
        base_time = ref_rows[0]["kernel_time_s"]
    else:
        _, base_time = timed(get_integrator("newmark"), "fixed")
    for r in rows:
        if r["kernel_time_s"] is not None:
            r["time_ratio"] = r["kernel_time_s"] / base_time
    return rows


def format_table(rows: list[dict]) -> str:
    """The rows of :func:`compare_schemes` as a markdown table."""
    head = "| scheme | variant | status | steps | solves | kernel time [ms] | ratio to Newmark | disp. error [um] | force error [% CF] |"
    lines = [head, "|" + "---|" * 9]

    def fmt(v, spec):
        return "n/a" if v is None else format(v, spec)

    for r in rows:
        lines.append(
            f"| {r['scheme']} | {r['variant']} | {r['status']} | {fmt(r['steps'], 'd')} | "
            f"{fmt(r['solves'], 'd')} | {fmt(None if r['kernel_time_s'] is None else 1e3 * r['kernel_time_s'], '.3f')} | "
            f"{fmt(r['time_ratio'], '.2f')} | {fmt(r['disp_error_um'], '.3f')} | {fmt(r['force_error_pct'], '.2f')} |"
        )
    return "\n".join(lines)
