"""What the ``slipstep frf --solver hbm`` command needs beyond slipstep.hbm.frf: parsing
``--harmonics``, a progress bar over the continuation steps, and the summary (a flat dict of
numbers with units in the keys, and a rich table) with the cross-check beside the answer."""

from __future__ import annotations

import json
import math

from slipstep.errors import InputError


def harmonics_text(h) -> str:
    """'0..15' for a full set, else the list '1,3,5' (the mean, always retained, left out)."""
    hs = [int(v) for v in h if int(v) > 0]
    return f"0..{hs[-1]}" if hs == list(range(1, len(hs) + 1)) else ",".join(map(str, hs))


def parse_harmonics(text: str):
    """'1,3,5' -> (1, 3, 5) (a chosen set); '15' -> 15 (all of 0..15)."""
    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    try:
        values = [int(p) for p in parts]
    except ValueError:
        values = []
    if not values or min(values) < 0 or max(values) < 1:
        raise InputError("--harmonics", f"is {text!r}", "give H (all harmonics 0..H, e.g. 15) or a list like 1,3,5")
    return values[0] if len(values) == 1 else tuple(values)


class ContinuationProgress:
    """A rich progress bar over the frequency (or level) range of a continuation: the bar
    shows how far along the range the latest point is, the text the point count and value."""

    def __init__(self, start: float, end: float, unit: str = "Hz", console=None, to_parameter=None):
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.start, self.end, self.unit = start, end, unit
        self.to_parameter = to_parameter or (lambda pt: pt.omega / (2 * math.pi))
        self.count = 0
        self.progress = Progress(
            TextColumn("[bold]HBM continuation"),
            BarColumn(),
            TextColumn("{task.description}"),
            TimeElapsedColumn(),
            console=console,
            transient=False,
        )
        self.task = self.progress.add_task("", total=1000)

    def __enter__(self):
        self.progress.__enter__()
        return self

    def __exit__(self, *exc):
        return self.progress.__exit__(*exc)

    def __call__(self, point):
        self.count += 1
        value = self.to_parameter(point)
        span = self.end - self.start
        frac = 1.0 if span == 0 else min(max((value - self.start) / span, 0.0), 1.0)
        self.progress.update(
            self.task, completed=int(1000 * frac), description=f"step {self.count}: {value:.5g} {self.unit}"
        )


def summary(ds) -> dict:
    """Flat summary of an HBM FRF Dataset (keys carry units)."""
    import numpy as np

    amp = ds.amplitude.values
    i, j = np.unravel_index(int(np.nanargmax(amp)), amp.shape)
    out = {
        "case": ds.attrs.get("case"),
        "solver": "hbm",
        "harmonics": [int(h) for h in np.atleast_1d(ds.attrs["harmonics"])],
        "samples": int(ds.attrs["samples"]),
        "points": int(ds.frequency.size),
        "continuation_status": ds.attrs.get("continuation_status"),
        "turning_points": int(ds.attrs.get("turning_points", 0)),
        "peak_frequency_Hz": float(ds.frequency.values[i]),
        "peak_response": str(ds.response.values[j]),
        "peak_amplitude": float(amp[i, j]),
        "peak_energy_per_cycle_J": float(ds.energy_per_cycle.values[i].sum()),
        "max_harmonic_truncation_estimate": float(ds.attrs.get("max_harmonic_truncation_estimate", math.nan)),
        "solve_time_s": float(ds.attrs.get("solve_time_s", math.nan)),
        "time_per_point_s": float(ds.attrs.get("time_per_point_s", math.nan)),
        "wall_time_s": float(ds.attrs.get("wall_time_s", math.nan)),
        "checks": json.loads(ds.attrs.get("check_summary", "[]")),
    }
    return out


def summary_table(ds):
    """A rich Table of :func:`summary`, the cross-check rows beside the HBM answer."""
    from rich.table import Table

    s = summary(ds)
    table = Table(title=f"slipstep frf: {s['case']}, harmonic balance", show_header=False)
    table.add_column("quantity", style="cyan")
    table.add_column("value")
    rows = [
        ("harmonics", harmonics_text(s["harmonics"])),
        ("AFT samples per period", s["samples"]),
        ("points (continuation)", f"{s['points']} ({s['continuation_status']}, {s['turning_points']} turning points)"),
        ("peak", f"{s['peak_amplitude']:.6g} ({s['peak_response']}) at {s['peak_frequency_Hz']:.6g} Hz"),
        ("friction energy per cycle at the peak", f"{s['peak_energy_per_cycle_J'] * 1e3:.6g} mJ"),
        ("harmonic truncation estimate (max)", f"{s['max_harmonic_truncation_estimate']:.2e}"),
        ("time per point", f"{s['time_per_point_s'] * 1e3:.4g} ms"),
        ("wall time", f"{s['wall_time_s']:.3g} s"),
    ]
    for c in s["checks"]:
        de = c["energy_rel_diff"]
        rows.append(
            (
                f"cross-check at {c['frequency_Hz']:.6g} Hz ({c['march_status']}, {c['march_periods']} periods)",
                (
                    f"amplitude diff {c['amplitude_rel_diff']:.2e}, energy diff "
                    f"{'n/a' if de is None or not math.isfinite(de) else f'{de:.2e}'}"
                ),
            )
        )
    for name, value in rows:
        table.add_row(name, str(value))
    return table


def run_command(
    system,
    frequencies,
    *,
    harmonics,
    samples=None,
    check_frequencies=(),
    check="auto",
    responses=None,
    output,
    plot_path=None,
    console=None,
    progress=True,
    as_json=False,
    level=1.0,
):
    """The body of ``slipstep frf CASE --solver hbm``: the HBM FRF with a progress bar over the
    continuation steps, saved (netCDF, atomically) to ``output``, the summary returned (and,
    unless ``as_json``, printed as a table with the cross-check beside the answer), the
    figure written to ``plot_path`` when given. Returns (Dataset, summary dict)."""
    from slipstep.hbm.frf import frf
    from slipstep.output.results import save

    hs = parse_harmonics(harmonics) if isinstance(harmonics, str) else harmonics
    kwargs = {
        "harmonics": hs,
        "samples": samples,
        "check": check,
        "check_frequencies": check_frequencies,
        "responses": responses,
        "level": level,
    }
    if progress and not as_json:
        with ContinuationProgress(float(frequencies[0]), float(frequencies[-1]), console=console) as bar:
            ds = frf(system, frequencies, progress=bar, **kwargs)
    else:
        ds = frf(system, frequencies, **kwargs)
    save(ds, output)
    if plot_path is not None:
        from slipstep.hbm.plot import plot_frf

        plot_frf(ds, plot_path)
    s = summary(ds)
    s["output"] = str(output)
    if plot_path is not None:
        s["figure"] = str(plot_path)
    if not as_json and console is not None:
        console.print(summary_table(ds))
    return ds, s
