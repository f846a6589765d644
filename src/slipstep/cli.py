"""The ``slipstep`` command line: run a case, compare the paper's methods, list cases/methods.

No numerics here: commands load a case (slipstep.config), call slipstep.methods /
slipstep.compare, and print. Exit codes: 0 success, 1 a march that stopped early
(the partial result is still written), 2 bad input (one red line naming the field and the fix).
"""

from __future__ import annotations

import contextlib
import json
import sys
import math
import warnings
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from slipstep.config import CASES_DIR, builtin_cases, load_case, read_toml
from slipstep.errors import InputError, SolverError
from slipstep.methods.registry import ALIASES, COMPARE_METHODS, METHODS, get_method

app = typer.Typer(
    name="slipstep",
    help=(
        "Time-marching simulation of structures with friction contacts (Gastaldi & Berruti 2018 methods).\n\n"
        "CASE is a built-in case name (see `slipstep cases`, e.g. `paper`) or a TOML case file.\n"
        "Methods: newmark (1), newmark-adaptive (2), piecewise-linear (3), piecewise-linear-adaptive (2+3), "
        "quasi-static (4), full-newton.\n\n"
        "Exit codes: 0 ok; 1 the march stopped early (partial result written); 2 bad input."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# a pipe or CI log gets 140 columns rather than rich's default 80, so tables keep their labels
out = Console(width=None if sys.stdout.isatty() else 140)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 140)


@contextlib.contextmanager
def user_errors():
    """Turn InputError / SolverError into one red line on stderr and exit code 2; show warnings
    as yellow lines on stderr (stdout stays clean for --json)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield
        except (InputError, SolverError, FileNotFoundError) as exc:
            kind = "solver error" if isinstance(exc, SolverError) else "input error"
            err.print(f"{kind}: {' '.join(str(exc).split())}", style="bold red", markup=False,
                      highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None
        finally:
            for w in caught:
                err.print(f"warning: {' '.join(str(w.message).split())}", style="yellow", markup=False,
                          highlight=False, soft_wrap=True)


def _output_dir(path: Path) -> Path:
    """Create the output directory or raise an InputError naming --output-dir."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError("output_dir", f"{str(path)!r} cannot be created ({exc.strerror})",
                         "give a writable directory path (--output-dir)") from None
    return path


def _case_stem(case: str) -> str:
    return Path(case).stem if Path(case).suffix else case


def _run_options(spec, periods, step_ratio, steps_per_period) -> dict:
    """Command-line options over the case's \\[run] table; unset ones keep RunOptions defaults."""
    opts = {}
    for key, cli_value, case_value in (("periods", periods, spec.periods), ("step_ratio", step_ratio, spec.step_ratio),
                                       ("steps_per_period", steps_per_period, spec.steps_per_period)):
        value = cli_value if cli_value is not None else case_value
        if value is not None:
            opts[key] = value
    if spec.duration_s is not None and periods is None:
        opts["duration"] = spec.duration_s
    return opts


def _fmt(value, digits: int = 4) -> str:
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.{digits}g}"
    return str(value)


def _json_value(value):
    if hasattr(value, "item"):
        return value.item()
    return value


@app.command()
def run(
    case: str = typer.Argument(..., help="Built-in case name (e.g. paper) or path to a .toml case file."),
    method: Optional[str] = typer.Option(
        None, "--method", "-m",
        help="Method name or paper number: newmark|1, newmark-adaptive|2, piecewise-linear|3, "
             "piecewise-linear-adaptive|2+3, quasi-static|4, full-newton. Default: the case's \\[run] method, "
             "else newmark."),
    periods: Optional[float] = typer.Option(None, help="Excitation periods to simulate after the static preload "
                                                       "(default: the case's \\[run] value, else 3)."),
    step_ratio: Optional[float] = typer.Option(None, help="r in dt = r T_min/pi for dynamic methods (default 1)."),
    steps_per_period: Optional[int] = typer.Option(None, help="Steps per period of the quasi-static method "
                                                              "(default 300)."),
    output_dir: Path = typer.Option(Path("slipstep-out"), help="Directory of the result file <case>_<method>.nc."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (no table) for scripts."),
):
    """Simulate CASE with one method; print a summary and write the result Dataset (netCDF)."""
    from slipstep.methods.simulation import Simulation
    from slipstep.results import save

    with user_errors():
        system, spec = load_case(case)
        chosen = get_method(method or spec.method or "newmark")
        sim = Simulation(system, chosen, **_run_options(spec, periods, step_ratio, steps_per_period))
        ds = sim.run()
        path = _output_dir(output_dir) / f"{_case_stem(case)}_{chosen.name}.nc"
        save(ds, path)
    a = ds.attrs
    keys = ("case", "method", "paper_method", "status", "status_message", "steps", "iterations", "solves",
            "mean_solves_per_step", "state_changes", "dt_s", "t_min_s", "t_end_s", "kernel_time_s", "wall_time_s")
    summary = {k: _json_value(a[k]) for k in keys if k in a}
    summary["output"] = str(path)
    if as_json:
        print(json.dumps(summary))
    else:
        table = Table(title=f"slipstep run: {a['case']}, {a['method']} ({a['paper_method']})", show_header=False)
        table.add_column("quantity", style="cyan")
        table.add_column("value")
        rows = [("method", f"{a['method']} ({a['paper_method']})"), ("status", a["status"]),
                ("steps", a["steps"]), ("iterations (linear solves)", a["iterations"]),
                ("mean iterations per step", _fmt(a["mean_solves_per_step"])),
                ("state changes", a["state_changes"]), ("dt", f"{a['dt_s'] * 1e6:.4g} us"),
                ("T_min (full stick)", f"{a['t_min_s'] * 1e6:.4g} us"),
                ("kernel time", f"{a['kernel_time_s'] * 1e3:.4g} ms"),
                ("wall time", f"{a['wall_time_s'] * 1e3:.4g} ms"), ("output", str(path))]
        for name, value in rows:
            table.add_row(name, str(value))
        out.print(table)
    if a["status"] != "OK":
        err.print(f"solver stopped early: {a['status_message']}", style="bold red", markup=False, soft_wrap=True)
        raise typer.Exit(1)


COMPARE_ROWS = (  # (label, key, scale or None for integers/text)
    ("method", "method", None), ("status", "status", None),
    ("kernel time [ms] (median)", "kernel_time_s", 1e3), ("time ratio to Method 1", "time_ratio", 1.0),
    ("kernel time [ms] (min)", "kernel_time_min_s", 1e3), ("time ratio, min to min", "time_ratio_min", 1.0),
    ("timing spread (IQR/median)", "time_spread", 1.0),
    ("steps", "steps", None), ("solves (iterations)", "solves", None),
    ("mean solves per step", "mean_solves_per_step", 1.0), ("single-solve step share", "single_solve_share", 1.0),
    ("state changes (raw)", "state_changes", None), ("state changes, last period", "state_changes_last_period", None),
    ("max disp. diff. [um]", "max_disp_diff_um", 1.0), ("max force diff. [% CF]", "max_force_diff_pct_cf", 1.0),
    ("  after low-pass [um]", "max_disp_diff_filtered_um", 1.0),
    ("  after low-pass [% CF]", "max_force_diff_filtered_pct_cf", 1.0),
)


@app.command()
def compare(
    case: str = typer.Argument(..., help="Built-in case name (e.g. paper) or path to a .toml case file."),
    periods: Optional[float] = typer.Option(None, help="Periods per run (default: the case's \\[run] value, else 3)."),
    repeats: int = typer.Option(21, help="Timed kernel runs per method, interleaved across the methods after every "
                                        "kernel is warmed; the median and the minimum are reported."),
    methods: str = typer.Option(",".join(COMPARE_METHODS), help="Comma-separated methods (names or paper numbers); "
                                                              "Method 1 (newmark) always runs as the reference."),
    output_dir: Path = typer.Option(Path("slipstep-out"), help="Directory for comparison.csv/.json, "
                                                               "fig8_time_ratios.png, fig5_iterations.png."),
    as_json: bool = typer.Option(False, "--json", help="Print the table as a JSON list (one object per method)."),
    schemes: Optional[str] = typer.Option(None, help="Compare integration schemes instead (paper App. A): 'all' or "
                                                     "a comma list, e.g. 'newmark,hht(0.1),rk4'; every scheme in "
                                                     "every variant it supports (fixed, adaptive, "
                                                     "piecewise-linear, both)."),
):
    """Run the paper's methods on CASE side by side (paper Figs. 5 and 8).

    Reports kernel time ratios to Method 1, steps, solves per step, state changes, and the largest difference
    from Method 1 over the last period (raw and low-pass filtered; displacements in um, contact forces in % of
    the constant load CF).

    Writes comparison.csv, comparison.json, fig8_time_ratios.png and fig5_iterations.png to OUTPUT_DIR.
    """
    from slipstep import compare as cmp

    if schemes is not None:
        return _compare_schemes(case, schemes, periods, repeats, output_dir, as_json)
    with user_errors():
        system, spec = load_case(case)
        _output_dir(output_dir)
        opts = _run_options(spec, periods, None, None)
        n_periods = opts.pop("periods", 3)
        datasets: dict = {}
        rows = cmp.compare(system, methods=methods, periods=n_periods, repeats=repeats, datasets=datasets, **opts)
        files = cmp.write_outputs(rows, datasets, output_dir, title=f"{system.name}: kernel time relative to Method 1")
    if as_json:
        print(json.dumps(rows, default=_json_value))
        return
    table = Table(title=f"slipstep compare: {system.name}, {n_periods:g} period(s), "
                        f"{repeats} interleaved kernel runs per method after warming every kernel")
    table.add_column("", style="cyan")
    for r in rows:
        table.add_column(r["paper_method"], justify="right")
    for label, key, scale in COMPARE_ROWS:
        cells = [str(r[key]) if scale is None else _fmt(r[key] * scale, 3) for r in rows]
        table.add_row(escape(label), *cells)
    out.print(table)
    out.print(f"CF = {rows[0]['force_scale_N']:.4g} N; differences over the last period vs Method 1; "
              f"low-pass cut-off {rows[0]['filter_cutoff_Hz']:.4g} Hz.", soft_wrap=True)
    for path in files.values():
        out.print(f"wrote {path}", markup=False, highlight=False, soft_wrap=True)
    failed = [r["method"] for r in rows if r["status"] != "OK"]
    if failed:
        err.print(f"methods that stopped early: {', '.join(failed)}", style="bold red", soft_wrap=True)
        raise typer.Exit(1)


def _compare_schemes(case, schemes, periods, repeats, output_dir, as_json):
    """`compare --schemes`: every scheme x variant, cost and error against a fine-step reference."""
    from slipstep.integrators.compare import compare_schemes, format_table

    with user_errors():
        system, spec = load_case(case)
        _output_dir(output_dir)
        chosen = "all" if schemes.strip() == "all" else [s.strip() for s in schemes.split(",") if s.strip()]
        n_periods = periods if periods is not None else (spec.periods if spec.periods is not None else 3)
        rows = compare_schemes(system, schemes=chosen, periods=n_periods, repeats=repeats)
    path = output_dir / "schemes.json"
    path.write_text(json.dumps(rows, default=_json_value, indent=1))
    (output_dir / "schemes.md").write_text(format_table(rows) + "\n")
    if as_json:
        print(json.dumps(rows, default=_json_value))
        return
    out.print(format_table(rows), markup=False, highlight=False, soft_wrap=True)
    out.print(f"errors: last period against piecewise-linear Newmark at step ratio 0.1; wrote {path} and "
              f"{output_dir / 'schemes.md'}", markup=False, highlight=False, soft_wrap=True)


@app.command()
def cases():
    """List the built-in cases."""
    table = Table(title="built-in cases (use the name as CASE)")
    table.add_column("name", style="cyan")
    table.add_column("description")
    with user_errors():
        for name in builtin_cases():
            table.add_row(name, str(read_toml(CASES_DIR / f"{name}.toml").get("description", "")))
    out.print(table)


@app.command()
def methods():
    """List the time-marching methods and their paper numbers."""
    numbers = {v: k for k, v in ALIASES.items() if k != "23"}
    table = Table(title="methods (use the name or the paper number with --method)")
    for header in ("name", "paper", "number", "description"):
        table.add_column(header)
    for m in METHODS.values():
        table.add_row(m.name, m.paper_label, numbers.get(m.name, "-"), m.description)
    out.print(table)


def _register_plugins() -> None:
    """Post-processing commands (plot/report/...) live in slipstep.cli_post when installed."""
    try:
        from slipstep.cli_post import register
    except ModuleNotFoundError as exc:
        if exc.name != "slipstep.cli_post":
            raise
        return
    register(app)


_register_plugins()


if __name__ == "__main__":  # pragma: no cover
    app()
