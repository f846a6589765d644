"""The ``slipstep frf`` command: the forced response of a case against frequency.

    slipstep frf CASE --frequencies 150:450:61 [--solver auto|march|shoot|hbm] [--direction up|down|both]
                      [--rtol 1e-2] [--harmonics 1,3,5] [--samples N] [--check-frequencies f1,f2]
                      [--sine-sweep] [-o DIR] [--json]

Writes ``DIR/<case-stem>_frf.nc`` (the layout of slipstep.output.frf_schema) and
``DIR/<case-stem>_frf.png`` (amplitude with both linear limits, energy per cycle). No
numerics here: every solver is slipstep.frequency.frf (the sine sweep: sine_sweep). The
default solver is auto (slipstep.frequency.choice), printed with its reason.
Exit codes: 0 every point converged, 1 some point not converged (results written; an error
estimate above --rtol warns without changing the code), 2 bad input.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import typer

from slipstep.casefile.files import case_stem as _case_stem
from slipstep.cli.console import err as _err
from slipstep.cli.console import out as _out
from slipstep.cli.console import output_dir_option as _output_dir
from slipstep.cli.console import user_errors as _user_errors
from slipstep.errors import InputError
from slipstep.output.frf_schema import FRF_SOLVERS, solver_help  # (standard library only: start-up time)


def _steady(system, frequencies, direction, options, progress):
    from slipstep.frequency import frf

    return frf(system, frequencies, direction=direction, progress=progress, **options)


def _sine_sweep(system, frequencies, direction, options, progress):
    from slipstep.frequency import sine_sweep
    from slipstep.output.frf_dataset import concat_sweeps

    keep = {k: v for k, v in options.items() if k in ("method", "responses", "min_steps_per_period")}
    keep["method"] = keep.get("method") or "piecewise-linear"
    keep["min_steps_per_period"] = keep.get("min_steps_per_period") or 50
    parts = []
    for i, d in enumerate(("up", "down") if direction == "both" else (direction,)):
        parts.append(sine_sweep(system, frequencies, direction=d, **keep))
        if progress is not None:
            progress(i + 1, 2 if direction == "both" else 1, None, None)
    return parts[0] if len(parts) == 1 else concat_sweeps(*parts)


def json_safe(value):
    """``value`` with every non-finite float as None (JSON has no NaN or Infinity)."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def frf(
    case: str = typer.Argument(..., help="built-in case name or TOML case file"),
    frequencies: str = typer.Option(
        ..., "--frequencies", "-f", help="start:stop:count [Hz], both ends included, or a comma list"
    ),
    solver: str = typer.Option("auto", "--solver", help=solver_help()),
    direction: str = typer.Option("up", "--direction", help="up, down or both (shows jumps)"),
    sine_sweep: bool = typer.Option(
        False, "--sine-sweep", help="one transient run with the frequency swept (envelope), not steady states"
    ),
    method: str | None = typer.Option(
        None, "--method", "-m", help="time-marching method (default: auto's choice, else piecewise-linear)"
    ),
    tolerance: float = typer.Option(1e-6, help="steady state: relative change of the state over one period"),
    rtol: float = typer.Option(
        1e-2,
        "--rtol",
        help="relative error of the energy per cycle allowed per point (the step is refined, then it warns)",
    ),
    max_refinements: int = typer.Option(3, help="march/shoot: step halvings beyond the step doubling of each point"),
    max_periods: int = typer.Option(200, help="periods marched at most per frequency point"),
    harmonics: str = typer.Option(
        "5",
        help="march/shoot: harmonics 0..H reported per response DOF; hbm: the "
        "retained harmonics, H (all of 0..H) or a set such as 1,3,5",
    ),
    samples: int | None = typer.Option(None, help="hbm: AFT time samples per period (default 8 H, a power of 2)"),
    check_at: str | None = typer.Option(
        None,
        "--check-frequencies",
        help="hbm: comma list of frequencies [Hz] cross-checked by time marching besides the peak",
    ),
    min_steps_per_period: int | None = typer.Option(None, help="at least this many steps per period"),
    responses: str | None = typer.Option(None, help="comma list of response DOFs (default all)"),
    output_dir: Path = typer.Option(Path("slipstep-out"), "--output-dir", "-o", help="folder for the results"),
    as_json: bool = typer.Option(False, "--json", help="print one JSON object (no progress bar)"),
):
    """Forced response of CASE against frequency: steady state per point (each from the previous
    one) with its error estimate, harmonics, energies per cycle, both linear limits; netCDF + PNG."""
    with _user_errors():
        from rich.markup import escape
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
        )

        from slipstep.casefile.case import load_system
        from slipstep.frequency.response import check_frequencies, parse_frequencies
        from slipstep.frequency.plots import fine_linear_limits, plot_frf
        from slipstep.output.results import save as save_netcdf
        from slipstep.model.text import escape_text

        if direction not in ("up", "down", "both"):
            raise InputError("--direction", f"is {direction!r}", "use up, down or both")
        if not sine_sweep and solver not in FRF_SOLVERS:
            raise InputError("--solver", f"is {solver!r}", f"use one of {', '.join(FRF_SOLVERS)}")
        freqs = check_frequencies(parse_frequencies(frequencies))
        system = load_system(case)
        reason = ""
        if solver == "auto" and not sine_sweep:
            from slipstep.frequency.choice import choose

            chosen = choose(system, method)
            solver, method, reason = chosen.solver, chosen.method, chosen.reason
            if not as_json:
                _err.print(f"solver: {solver} ({reason})", markup=False, highlight=False, soft_wrap=True)
        hbm = solver == "hbm" and not sine_sweep
        if hbm:
            from slipstep.cli.hbm import parse_harmonics

            kept = parse_harmonics(harmonics)
            if direction == "both":
                _err.print(
                    "note: harmonic balance follows the whole branch by continuation (turning points "
                    "included); --direction both gives the same curve as up",
                    style="yellow",
                )
                direction = "up"
        else:
            try:
                kept = int(harmonics)
            except ValueError:
                raise InputError(
                    "--harmonics",
                    f"is {harmonics!r}",
                    "give the highest reported harmonic H as a whole number (a set like 1,3,5 is for --solver hbm)",
                ) from None
        options = dict(
            solver=solver,
            method=method,
            tolerance=tolerance,
            rtol=rtol,
            max_periods=max_periods,
            harmonics=kept,
            responses=None if responses is None else [r.strip() for r in responses.split(",")],
        )
        if min_steps_per_period is not None:
            options["min_steps_per_period"] = min_steps_per_period
        if hbm:
            options.update(
                check_frequencies=[]
                if check_at is None
                else list(parse_frequencies(check_at, field="--check-frequencies"))
            )
            if samples is not None:
                options["samples"] = samples
        else:
            options["max_refinements"] = max_refinements
        folder = _output_dir(output_dir)
        start = time.perf_counter()
        run = _sine_sweep if sine_sweep else _steady
        total = freqs.size * (2 if direction == "both" else 1)
        with Progress(
            TextColumn("[bold]frf[/] {task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeRemainingColumn(),
            console=_err,
            transient=True,
            disable=as_json,
        ) as bar:
            label = escape(escape_text(_case_stem(case)))  # a file name is text, never markup
            task = bar.add_task(
                f"{label} ({'sine sweep' if sine_sweep else solver})",
                total=2 if sine_sweep and direction == "both" else (1 if sine_sweep else total),
            )
            done = [0]

            def progress(i, n, f, steady):
                done[0] += 1
                if steady is None and f is not None:  # a continuation step (hbm): i of n along the range
                    text = f" step {done[0]}: {f:.5g} Hz"
                    bar.update(task, completed=i, description=f"{label}{text}")
                    return
                text = "" if f is None else f" {f:.4g} Hz: {steady.status}, {steady.periods} periods"
                bar.update(task, completed=done[0], description=f"{label}{text}")

            ds = run(system, freqs, direction, options, progress)
        if reason:
            ds.attrs["solver_reason"] = reason
        stem = _case_stem(case)
        nc, png = folder / f"{stem}_frf.nc", folder / f"{stem}_frf.png"
        save_netcdf(ds, nc)
        if hbm:
            from slipstep.cli.hbm import summary as hbm_summary
            from slipstep.hbm.plot import plot_frf as plot_hbm

            plot_hbm(ds, png)
        else:
            plot_frf(ds, png, linear=fine_linear_limits(system, ds))
        summary = _summary(ds, time.perf_counter() - start)
        if hbm:
            extra = hbm_summary(ds)
            summary.update(
                {
                    k: extra[k]
                    for k in (
                        "harmonics",
                        "samples",
                        "turning_points",
                        "checks",
                        "max_harmonic_truncation_estimate",
                        "time_per_point_s",
                    )
                }
            )
        summary.update(output=str(nc), figure=str(png))
        if as_json:
            print(json.dumps(json_safe(summary), allow_nan=False))
        else:
            _out.print(_text(summary), markup=False, highlight=False, soft_wrap=True)
        if summary["points_not_ok"]:
            raise typer.Exit(1)


def _summary(ds, wall: float) -> dict:
    import numpy as np

    status = np.asarray(ds["status"].values).astype(str)
    from slipstep.frequency.plots import default_response

    amp = ds["amplitude"]
    other = [d for d in amp.dims if d not in ("frequency", "response")]
    peak_each = amp.max(other) if other else amp
    values = np.nan_to_num(peak_each.values, nan=-1.0)
    j = list(ds["response"].values).index(default_response(ds))
    i = int(np.argmax(values[:, j]))
    periods = ds["periods_to_steady"].values
    return {
        "case": ds.attrs.get("case"),
        "solver": ds.attrs.get("solver"),
        "sweep": ds.attrs.get("sweep"),
        "points": int(status.size),
        "points_not_ok": int((status != "OK").sum()),
        "peak_frequency_Hz": float(ds["frequency"].values[i]),
        "peak_response": str(ds["response"].values[j]),
        "peak_amplitude": float(values[i, j]),
        "peak_unit": str(ds["response_unit"].values[j]),
        "periods_total": float(np.nansum(periods)) if np.isfinite(periods).any() else None,
        "wall_time_s": wall,
        **_accuracy(ds),
    }


def _accuracy(ds) -> dict:
    """The error estimates of the points (slipstep.frequency.error_estimate): rtol, the largest
    estimate, the points above rtol, the steps per period (AFT samples for hbm) used."""
    import numpy as np

    if "error_estimate" not in ds:  # (a Dataset without the error variables)
        return {}
    est = np.asarray(ds["error_estimate"].values, float).ravel()
    steps = np.asarray(ds["steps_per_period"].values, float).ravel()
    rtol = ds.attrs.get("rtol")
    finite = est[np.isfinite(est)]
    return {
        "solver_reason": ds.attrs.get("solver_reason", ""),
        "rtol": rtol,
        "max_error_estimate": float(finite.max()) if finite.size else None,
        "points_without_estimate": int(est.size - finite.size),
        "points_above_rtol": int((est > rtol).sum()) if rtol is not None else 0,
        "steps_per_period_min": float(np.nanmin(steps)) if np.isfinite(steps).any() else None,
        "steps_per_period_max": float(np.nanmax(steps)) if np.isfinite(steps).any() else None,
    }


def _text(s: dict) -> str:
    scale, unit = (1e6, "um") if s["peak_unit"] == "m" else ((1e3, "mrad") if s["peak_unit"] == "rad" else (1, ""))
    lines = [
        f"{s['case']}: {s['points']} points ({s['solver']}, {s['sweep']}) in {s['wall_time_s']:.2f} s",
        f"peak {s['peak_amplitude'] * scale:.4g} {unit} of {s['peak_response']} at {s['peak_frequency_Hz']:.4g} Hz",
    ]
    if s["periods_total"] is not None:
        lines.append(f"periods marched: {s['periods_total']:.0f}")
    if s["points_not_ok"]:
        lines.append(f"{s['points_not_ok']} point(s) not steady or failed (see the status variable)")
    if s.get("rtol") is not None:
        worst = s["max_error_estimate"]
        steps = s["steps_per_period_min"], s["steps_per_period_max"]
        kind = "AFT samples" if "checks" in s else "steps"
        lines.append(
            f"error estimate (energy per cycle): max {'n/a' if worst is None else f'{worst:.2g}'}, rtol {s['rtol']:g}"
            + ("" if steps[0] is None else f"; {steps[0]:.0f}-{steps[1]:.0f} {kind} per period")
            + (f"; {s['points_without_estimate']} point(s) without an estimate" if s["points_without_estimate"] else "")
        )
        if s["points_above_rtol"]:
            lines.append(f"WARNING: {s['points_above_rtol']} point(s) above rtol (see the status_message variable)")
    if "checks" in s:  # harmonic balance: the retained harmonics, the adequacy estimate, the cross-check
        from slipstep.cli.hbm import harmonics_text

        lines.append(
            f"harmonics {harmonics_text(s['harmonics'])} ({s['samples']} AFT samples), "
            f"{s['time_per_point_s'] * 1e3:.3g} ms per point, {s['turning_points']} turning point(s); "
            f"harmonic truncation estimate (max) {s['max_harmonic_truncation_estimate']:.2e}"
        )
        for c in s["checks"]:
            de = c["energy_rel_diff"]
            lines.append(
                f"cross-check by marching at {c['frequency_Hz']:.5g} Hz ({c['march_status']}, "
                f"{c['march_periods']} periods): amplitude differs by {c['amplitude_rel_diff']:.2e}, "
                f"friction energy by {'n/a' if de is None or math.isnan(de) else f'{de:.2e}'}"
            )
    lines += [s["output"], s["figure"]]
    return "\n".join(lines)


def register(app: typer.Typer) -> None:
    """Add the frf command to ``app`` (once)."""
    existing = {c.name or (c.callback.__name__ if c.callback else None) for c in app.registered_commands}
    if "frf" not in existing:
        app.command(name="frf")(frf)
