"""The ``slipstep`` command line: run a case, compare the paper's methods, list cases/methods.

No numerics here: commands load a case (slipstep.casefile.case), call slipstep.methods /
slipstep.study.compare, and print. The consoles, the exit codes and the turning of a failure into
one line are slipstep.cli.console's, shared with the command modules.

Fast start: this module imports only typer, rich's console and light slipstep modules; the
numerical stack (numpy, numba, xarray, pydantic) is imported inside the commands that need
it. The other modules of this package that define ``register(app)`` (``slipstep/cli/<name>.py``)
are command modules, found and registered by :func:`_register_plugins`; they import only typer,
the standard library and slipstep.cli.console at module level, and never this module.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import Annotated, Optional

import typer
from typer.core import TyperGroup

from slipstep.casefile.files import CASES_DIR, builtin_cases, case_stem, read_toml
from slipstep.cli.console import (  # noqa: F401 (safe, say, user_errors: the names tests and callers know here)
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_IO,
    EXIT_OK,
    EXIT_STOPPED,
    _PASS_THROUGH,
    err,
    out,
    output_dir_option,
    report_failure,
    safe,
    say,
    user_errors,
    version,
)
from slipstep.errors import InputError
from slipstep.methods.registry import COMPARE_METHODS, PAPER_METHODS, method_choices, scheme_choices

_FAST_COMMANDS = ("cases", "methods")  # listings that take no argument: answered without typer's coercion


class _Group(TyperGroup):
    """The command group: any exception escaping a command becomes one line and an exit code;
    ``--version`` is answered here (a typed option on the callback would make typer build its
    pydantic adapters, 150 ms, for commands such as ``cases`` that need none)."""

    def parse_args(self, ctx, args):
        if args[:1] == ["--version"]:
            print(f"slipstep {version()}")
            ctx.exit(0)
        command = self.commands.get(args[0]) if len(args) == 1 and args[0] in _FAST_COMMANDS else None
        if command is not None and not any(p.required for p in command.params) and command.callback is not None:
            # a listing called without arguments (cases, methods; options keep their Python defaults):
            # called directly, without typer's parameter machinery, which imports pydantic (150 ms) to
            # coerce the implicit --help flag
            try:
                command.callback()
            except _PASS_THROUGH:
                raise
            except BaseException as exc:  # noqa: BLE001
                ctx.exit(report_failure(exc))
            ctx.exit(0)
        return super().parse_args(ctx, args)

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except _PASS_THROUGH:
            raise
        except BaseException as exc:  # noqa: BLE001 (every failure gets its exit code)
            raise typer.Exit(report_failure(exc)) from None


app = typer.Typer(
    name="slipstep",
    cls=_Group,
    help=(
        "Time-marching simulation of structures with friction contacts (Gastaldi & Berruti 2018 methods).\n\n"
        "CASE is a built-in case name (see `slipstep cases`, e.g. `paper`) or a TOML case file.\n"
        "Methods: newmark (1), newmark-adaptive (2), piecewise-linear (3), piecewise-linear-adaptive (2+3), "
        "quasi-static (4), full-newton.\n\n"
        "Exit codes: 0 ok; 1 the march stopped early (partial result written); 2 bad input; "
        "3 I/O or environment failure; 4 internal error; 130 aborted (Ctrl-C).\n\n"
        "`slipstep --version` prints the version."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def main():
    """Time-marching simulation of structures with friction contacts."""
    _ignore_file_size_signal()


def _ignore_file_size_signal() -> None:
    """A file size limit (ulimit -f) then fails the write with EFBIG (exit 3, previous file
    kept) instead of killing the process with SIGXFSZ."""
    import signal

    with contextlib.suppress(AttributeError, ValueError, OSError):
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


# -- options shared by the commands ------------------------------------------------------------


def _method(cli_value: Optional[str], spec):
    from slipstep.methods.registry import get_method

    field, value = ("--method", cli_value) if cli_value is not None else ("[run] method", spec.method)
    if value is None:
        return get_method("newmark")
    if not value.strip():
        raise InputError(field, "is empty", "give a method name or paper number (see `slipstep methods`)")
    try:
        return get_method(value)
    except InputError as exc:
        raise InputError(field, exc.problem, exc.fix) from None


def _run_options(
    spec, periods, step_ratio, steps_per_period, max_memory=None, duration=None, save=None
) -> tuple[dict, dict]:
    """Command-line options over the case's \\[run] table; unset ones keep RunOptions defaults.
    Returns (options, where each option came from: the flag or the case key). --duration wins
    over --periods, as duration does in RunOptions; a --periods given on the command line wins
    over the case's duration_s."""
    opts, origin = {}, {}
    for key, cli_value, case_value in (
        ("periods", periods, spec.periods),
        ("step_ratio", step_ratio, spec.step_ratio),
        ("steps_per_period", steps_per_period, spec.steps_per_period),
    ):
        flag = "--" + key.replace("_", "-")
        if cli_value is not None:
            opts[key], origin[key] = cli_value, flag
        elif case_value is not None:
            opts[key], origin[key] = case_value, f"[run] {key}"
        else:
            origin[key] = flag
    if duration is not None:
        opts["duration"], origin["duration"] = duration, "--duration"
    elif spec.duration_s is not None and periods is None:
        opts["duration"], origin["duration"] = spec.duration_s, "[run] duration_s"
    else:
        origin["duration"] = "[run] duration_s"
    if max_memory is not None:
        from slipstep.methods.memory import parse_size

        opts["max_memory"] = parse_size("--max-memory", max_memory)
    origin["max_memory"] = "--max-memory"
    for key in ("step_rule", "tolerance"):  # `slipstep run --step-rule`, `--tolerance` win
        if getattr(spec, key) is not None:
            opts[key], origin[key] = getattr(spec, key), f"[run] {key}"
        else:
            origin[key] = "--" + key.replace("_", "-")
    _save_options(spec, save or {}, opts, origin)
    return opts, origin


SAVE_FLAGS = {"dofs": "--save-dofs", "contacts": "--save-contacts", "every": "--save-every"}
SAVE_FLAGS.update(last_periods="--save-last-periods", times="--save-times")


def _save_options(spec, flags: dict, opts: dict, origin: dict) -> None:
    """The ``save`` option: the case's [run.save] table, each key overridden by its --save-* flag
    (flags: {key: command-line text}); origins per key for messages ('save.dofs' -> the flag)."""
    table = spec.save.options() if getattr(spec, "save", None) is not None else {}
    origin["save"] = "[run.save]" if table else "--save-dofs"
    for key in ("dofs", "contacts", "every", "last_periods", "times", "response"):
        origin[f"save.{key}"] = f"[run.save] {'times_s' if key == 'times' else key}"
    for key, text in flags.items():
        if text is None:
            continue
        flag = SAVE_FLAGS[key]
        origin[f"save.{key}"] = flag
        if key in ("dofs", "contacts"):
            names = [p.strip() for p in str(text).split(",") if p.strip()]
            table[key] = names[0] if len(names) == 1 and names[0] in ("all", "none", "response") else names
        elif key == "times":
            table[key] = _times(flag, text)
        else:
            table[key] = text
    if table:
        opts["save"] = table


def _times(flag: str, text: str) -> list[float]:
    """'0.1:0.2:101' (start:stop:count, seconds) or '0.1,0.15,0.2' -> times [s]."""
    import numpy as np

    try:
        if ":" in text:
            start, stop, count = text.split(":")
            return np.linspace(float(start), float(stop), int(count)).tolist()
        return [float(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise InputError(flag, f"is {text!r}", "give start:stop:count (seconds) or a comma-separated list") from None


@contextlib.contextmanager
def option_names(origin: dict):
    """Re-raise an InputError about a run option under the name the user gave it."""
    try:
        yield
    except InputError as exc:
        if exc.field in origin:
            raise InputError(origin[exc.field], exc.problem, exc.fix) from None
        raise


def _fmt(value, digits: int = 4) -> str:
    if isinstance(value, float):
        return "-" if math.isnan(value) else f"{value:.{digits}g}"
    return str(value)


def _json_value(value):
    if hasattr(value, "item"):
        return value.item()
    return value


def _table(title, *columns, show_header: bool = True):
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(safe(title)) if title else None, show_header=show_header)
    for col in columns:
        table.add_column(col)
    return table


def _error_estimate_text(a: dict) -> str:
    """The step-doubling estimates in percent, or why there are none (error_estimate_method)."""
    energy, peak = a["energy_error_estimate"], a["peak_force_error_estimate"]
    if math.isnan(energy) and math.isnan(peak):
        return f"not estimated: {a.get('error_estimate_method', 'none')}"
    return f"{100 * energy:.2g} % / {100 * peak:.2g} %"


def _row(table, *cells):
    from rich.text import Text

    table.add_row(*(Text(safe(c)) for c in cells))


MAX_MEMORY_HELP = (
    "Memory a run may take, e.g. 8GB (default: half of the available memory); the estimate is "
    "checked before anything is allocated."
)


@app.command()
def run(
    case: str = typer.Argument(..., help="Built-in case name (e.g. paper) or path to a .toml case file."),
    method: Optional[str] = typer.Option(
        None,
        "--method",
        "-m",
        help=f"Method name or paper number: {method_choices()}. Default: the case's \\[run] method, else newmark.",
    ),
    scheme: Optional[str] = typer.Option(
        None,
        "--scheme",
        help=f"Time-integration scheme (paper App. A), with parameters in parentheses: {scheme_choices()}. "
        "Default newmark. Explicit schemes run the method's variant: newmark (fixed step) or newmark-adaptive.",
    ),
    periods: Optional[float] = typer.Option(
        None,
        help="Excitation periods to simulate after the static preload (default: the case's \\[run] value, else 3).",
    ),
    step_ratio: Optional[float] = typer.Option(None, help="r in dt = r T_min/pi for dynamic methods (default 1)."),
    steps_per_period: Optional[int] = typer.Option(
        None, help="Steps per period of the quasi-static method (default 300)."
    ),
    duration: Optional[float] = typer.Option(
        None,
        help="Simulated time \\[s] after the preload, instead of periods (default: the case's \\[run] duration_s).",
    ),
    output_dir: str = typer.Option(
        "slipstep-out", "--output-dir", "-o", help="Directory of the result file <case-file-stem>_<method>.nc."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object (no table, no progress bar)."),
    max_memory: Optional[str] = typer.Option(None, help=MAX_MEMORY_HELP),
    rtol: Optional[float] = typer.Option(
        None,
        help="Accuracy to reach (dynamic methods), e.g. 1e-3: the step follows "
        "the local error estimate, never beyond the method's step limit.",
    ),
    step_rule: Optional[str] = typer.Option(
        None,
        help="What sets the step: accuracy (the cap and the error estimate; default of the "
        "piecewise-linear methods) or t-min (the paper's T_min rule; default of the others).",
    ),
    tolerance: Optional[float] = typer.Option(
        None,
        help="Newton tolerance of the methods that iterate within a step (newmark, newmark-adaptive, full-newton), "
        "0 < tolerance < 1 (default 1e-11; the case's \\[run] tolerance); the piecewise-linear methods ignore it.",
    ),
    save_dofs: Optional[str] = typer.Option(
        None,
        help="DOFs to save: all, none, response (those the contacts see, the forced ones) or "
        "comma-separated names / patterns ('blade*'). Default: all up to 200 DOFs, else response.",
    ),
    save_contacts: Optional[str] = typer.Option(None, help="Contacts to save: all, none or comma-separated names."),
    save_every: Optional[int] = typer.Option(None, help="Save every k-th step (and the last one)."),
    save_last_periods: Optional[float] = typer.Option(None, help="Save only the last P >= 1 excitation periods."),
    save_times: Optional[str] = typer.Option(
        None, help="Save at given times \\[s]: start:stop:count or a comma-separated list (interpolated)."
    ),
):
    """Simulate CASE with one method; print a summary and write the result Dataset (netCDF).

    A run longer than about a second shows a progress bar on a terminal. Ctrl-C stops the march at
    the current step and writes the partial result (status INTERRUPTED, exit code 1); a second
    Ctrl-C aborts. The result file is replaced atomically: an interrupted or failed write keeps
    the previous file.
    """
    with user_errors():
        from slipstep.casefile.case import load_case
        from slipstep.methods.live import deferred_interrupt
        from slipstep.output.results import save

        system, spec = load_case(case)
        chosen = _method(method, spec)
        flags = dict(
            dofs=save_dofs, contacts=save_contacts, every=save_every, last_periods=save_last_periods, times=save_times
        )
        opts, origin = _run_options(spec, periods, step_ratio, steps_per_period, max_memory, duration, flags)
        if rtol is not None:
            opts["rtol"], origin["rtol"] = rtol, "--rtol"
        if step_rule is not None:
            opts["step_rule"], origin["step_rule"] = step_rule, "--step-rule"
        if tolerance is not None:
            opts["tolerance"], origin["tolerance"] = tolerance, "--tolerance"
        directory = output_dir_option(output_dir)
        with option_names(origin):
            sim, label = _simulation(system, chosen, scheme, opts, origin)
        sim.progress = err.is_terminal and not as_json
        sim.keep_interrupted = True
        ds = sim.run()
        path = directory / f"{case_stem(case)}_{label}.nc"
        with deferred_interrupt(
            lambda: say("saving the result: Ctrl-C again aborts the save (the previous file is kept)", err, "yellow"),
            armed=ds.attrs["status"] == "INTERRUPTED",
        ):
            save(ds, path)
    from slipstep.methods.invariants import flagged

    a = ds.attrs
    keys = (
        "case",
        "method",
        "paper_method",
        "status",
        "status_message",
        "steps",
        "iterations",
        "solves",
        "mean_solves_per_step",
        "state_changes",
        "dt_s",
        "step_rule",
        "t_min_s",
        "t_end_s",
        "kernel_time_s",
        "wall_time_s",
        "energy_error_estimate",
        "peak_force_error_estimate",
        "tolerance_over_range",
        "twin_difference",
    )
    summary = {k: _json_value(a[k]) for k in keys if k in a}
    if "twin_difference" in summary and not math.isfinite(summary["twin_difference"]):
        summary["twin_difference"] = None  # JSON has no NaN (the twin failed)
    # Methods 1 and 2 (invariants), and every run whose sensitivity twin ran (methods/sensitivity_twin.py)
    trusted = any(k in a for k in ("tolerance_over_range", "steps_above_tolerance", "twin_difference"))
    if trusted:
        summary["trust_flags"] = flagged(a)  # why the result may be off its discrete solution ([] none)
    summary["output"] = str(path)
    if as_json:
        print(json.dumps(summary))
    else:
        table = _table(f"slipstep run: {a['case']}, {a['method']} ({a['paper_method']})", show_header=False)
        table.add_column("quantity", style="cyan")
        table.add_column("value")
        rows = [
            ("method", f"{a['method']} ({a['paper_method']})"),
            ("status", a["status"]),
            ("steps", a["steps"]),
            ("iterations (linear solves)", a["iterations"]),
            ("mean iterations per step", _fmt(a["mean_solves_per_step"])),
            ("state changes", a["state_changes"]),
            ("dt", f"{a['dt_s'] * 1e6:.4g} us"),
            ("T_min (full stick)", f"{a['t_min_s'] * 1e6:.4g} us"),
            ("est. error, loop energy / peak force", _error_estimate_text(a)),
            *(
                [("tolerance / response range", _fmt(float(a["tolerance_over_range"]), 2))]
                if "tolerance_over_range" in a
                else []
            ),
            *(
                [("sensitivity twin / response range", _fmt(float(a["twin_difference"]), 2))]
                if "twin_difference" in a
                else []
            ),
            *([("trust flag", "; ".join(flagged(a)) or "none")] if trusted else []),
            ("kernel time", f"{a['kernel_time_s'] * 1e3:.4g} ms"),
            ("wall time", f"{a['wall_time_s'] * 1e3:.4g} ms"),
            ("output", str(path)),
        ]
        for name, value in rows:
            _row(table, name, value)
        out.print(table)
    if a["status"] != "OK":
        say(f"solver stopped early: {a['status_message']}; the partial result is in {path}", err, "bold red")
        raise typer.Exit(EXIT_STOPPED)


def _simulation(system, method, scheme: Optional[str], opts: dict, origin: dict):
    """(the runner of METHOD with --scheme, the result file's label): implicit schemes run the
    method itself with that scheme; explicit ones the variant the method is (fixed: newmark,
    adaptive: newmark-adaptive), with the options an explicit run understands (options from the
    case's \\[run] table that do not apply are left out; command-line ones are refused)."""
    from slipstep.methods.simulation import Simulation, _exact_events

    if _exact_events(method):  # exact event-driven dynamics: no steps, no scheme (methods/exact_events.py)
        if scheme is not None:
            raise InputError("--scheme", "does not apply to method events (it has no time step)", "drop --scheme")
        from slipstep.methods.exact_events import ExactEventRun

        return ExactEventRun(system, **opts), method.name
    if scheme is None:
        return Simulation(system, method, **opts), method.name
    from slipstep.integrators import get_integrator

    if not scheme.strip():
        raise InputError("--scheme", "is empty", f"give a scheme, e.g. {scheme_choices()}")
    try:
        integ = get_integrator(scheme)
    except InputError as exc:
        raise InputError("--scheme", exc.problem, exc.fix) from None
    label = f"{method.name}_{integ.name}"
    if integ.kind == "implicit":
        return Simulation(system, method, scheme=integ.scheme(), **opts), label
    from slipstep.integrators.explicit_simulation import EXPLICIT_OPTIONS

    if method.variant not in integ.variants:
        raise InputError(
            "--scheme",
            f"{integ.name} is explicit: it marches a fixed or adaptive step with nothing solved for the "
            f"contacts, not method {method.name}",
            "use --method newmark (fixed step) or newmark-adaptive (adaptive step), or an implicit scheme",
        )
    for key in [k for k in opts if k not in EXPLICIT_OPTIONS]:
        if origin.get(key, "").startswith("--"):
            raise InputError(origin[key], f"does not apply to the explicit scheme {integ.name}", "drop it")
        opts = {k: v for k, v in opts.items() if k != key}
    return integ.simulation(system, method.variant, **opts), label


COMPARE_ROWS = (  # (label, key, scale or None for integers/text)
    ("method", "method", None),
    ("status", "status", None),
    ("kernel time [ms] (median)", "kernel_time_s", 1e3),
    ("time ratio to Method 1", "time_ratio", 1.0),
    ("kernel time [ms] (min)", "kernel_time_min_s", 1e3),
    ("time ratio, min to min", "time_ratio_min", 1.0),
    ("timing spread (IQR/median)", "time_spread", 1.0),
    ("steps", "steps", None),
    ("solves (iterations)", "solves", None),
    ("mean solves per step", "mean_solves_per_step", 1.0),
    ("single-solve step share", "single_solve_share", 1.0),
    ("state changes (raw)", "state_changes", None),
    ("state changes, last period", "state_changes_last_period", None),
    ("max disp. diff. [um]", "max_disp_diff_um", 1.0),
    ("max force diff. [% CF]", "max_force_diff_pct_cf", 1.0),
    ("  after low-pass [um]", "max_disp_diff_filtered_um", 1.0),
    ("  after low-pass [% CF]", "max_force_diff_filtered_pct_cf", 1.0),
)

PAPER_METHODS_TEXT = ",".join(PAPER_METHODS)
COMPARE_METHODS_TEXT = ",".join(COMPARE_METHODS)


@app.command()
def compare(
    case: str = typer.Argument(..., help="Built-in case name (e.g. paper) or path to a .toml case file."),
    periods: Optional[float] = typer.Option(None, help="Periods per run (default: the case's \\[run] value, else 3)."),
    repeats: int = typer.Option(
        21,
        help="Timed kernel runs per method, interleaved across the methods after every "
        "kernel is warmed; the median and the minimum are reported.",
    ),
    methods: str = typer.Option(
        COMPARE_METHODS_TEXT,
        help="Comma-separated methods (names or paper numbers); Method 1 (newmark) always runs as the reference.",
    ),
    output_dir: str = typer.Option(
        "slipstep-out",
        "--output-dir",
        "-o",
        help="Directory of the comparisons: the files go to OUTPUT_DIR/<case-file-stem>/.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the table as a JSON list (one object per method)."),
    schemes: Optional[str] = typer.Option(
        None,
        help="Compare integration schemes instead (paper App. A): 'all' or "
        f"a comma list of {scheme_choices()}; every scheme in "
        "every variant it supports (fixed, adaptive, "
        "piecewise-linear, both).",
    ),
    max_memory: Optional[str] = typer.Option(None, help=MAX_MEMORY_HELP),
):
    """Run the paper's methods on CASE side by side (paper Figs. 5 and 8).

    Reports kernel time ratios to Method 1, steps, solves per step, state changes, and the largest difference
    from Method 1 over the last period (raw and low-pass filtered; displacements in um, contact forces in % of
    the constant load CF).

    Writes comparison.csv, comparison.json, fig8_time_ratios.png and fig5_iterations.png to
    OUTPUT_DIR/<case-file-stem>/ (schemes.json and schemes.md with --schemes).
    """
    if schemes is not None:
        return _compare_schemes(case, schemes, periods, repeats, output_dir, as_json)
    with user_errors():
        from slipstep.study import compare as cmp
        from slipstep.casefile.case import load_case

        system, spec = load_case(case)
        if not methods.strip():
            raise InputError("--methods", "is empty", f"give a comma list of methods, e.g. {PAPER_METHODS_TEXT}")
        opts, origin = _run_options(spec, periods, None, None, max_memory)
        directory = output_dir_option(output_dir, below=case_stem(case))
        n_periods = opts.pop("periods", 3)
        datasets: dict = {}
        with option_names({**origin, "repeats": "--repeats", "method": "--methods"}):
            rows = cmp.compare(system, methods=methods, periods=n_periods, repeats=repeats, datasets=datasets, **opts)
        files = cmp.write_outputs(rows, datasets, directory, title=f"{system.name}: kernel time relative to Method 1")
    if as_json:
        print(json.dumps(rows, default=_json_value))
        return
    table = _table(
        f"slipstep compare: {system.name}, {n_periods:g} period(s), {repeats} interleaved kernel runs "
        "per method after warming every kernel"
    )
    table.add_column("", style="cyan")
    for r in rows:
        table.add_column(safe(r["paper_method"]), justify="right")
    for label, key, scale in COMPARE_ROWS:
        _row(table, label, *(str(r[key]) if scale is None else _fmt(r[key] * scale, 3) for r in rows))
    out.print(table)
    say(
        f"CF = {rows[0]['force_scale_N']:.4g} N; differences over the last period vs Method 1; "
        f"low-pass cut-off {rows[0]['filter_cutoff_Hz']:.4g} Hz."
    )
    for path in files.values():
        say(f"wrote {path}")
    failed = [r["method"] for r in rows if r["status"] != "OK"]
    if failed:
        say(f"methods that stopped early: {', '.join(failed)}", err, "bold red")
        raise typer.Exit(EXIT_STOPPED)


def _compare_schemes(case, schemes, periods, repeats, output_dir, as_json):
    """`compare --schemes`: every scheme x variant, cost and error against a fine-step reference."""
    with user_errors():
        from slipstep.casefile.case import load_case
        from slipstep.integrators.compare import compare_schemes, format_table
        from slipstep.output.io import write_text

        system, spec = load_case(case)
        if not schemes.strip():
            raise InputError("--schemes", "is empty", "give 'all' or a comma list such as newmark,hht(0.1),rk4")
        chosen = "all" if schemes.strip() == "all" else [s.strip() for s in schemes.split(",") if s.strip()]
        n_periods = periods if periods is not None else (spec.periods if spec.periods is not None else 3)
        directory = output_dir_option(output_dir, below=case_stem(case))
        with option_names({"scheme": "--schemes", "periods": "--periods", "repeats": "--repeats"}):
            rows = compare_schemes(system, schemes=chosen, periods=n_periods, repeats=repeats)
        path = write_text(directory / "schemes.json", json.dumps(rows, default=_json_value, indent=1))
        table_path = write_text(directory / "schemes.md", format_table(rows) + "\n")
    if as_json:
        print(json.dumps(rows, default=_json_value))
        return
    for line in format_table(rows).splitlines():
        say(line)
    say(f"errors: last period against piecewise-linear Newmark at step ratio 0.1; wrote {path} and {table_path}")


@app.command()
def cases():
    """List the built-in cases."""
    with user_errors():
        table = _table("built-in cases (use the name as CASE)")
        table.add_column("name", style="cyan")
        table.add_column("description")
        for name in builtin_cases():
            _row(table, name, str(read_toml(CASES_DIR / f"{name}.toml").get("description", "")))
    out.print(table)


@app.command()
def methods(
    markdown: Annotated[
        bool,
        typer.Option(
            "--markdown", help="Print the method and scheme tables of the documentation's methods page (markdown)."
        ),
    ] = False,
):
    """List the time-marching methods (with their paper numbers) and the time-integration schemes."""
    from slipstep.methods import registry as R

    if markdown:
        from slipstep.integrators import tables as T

        print(f"{T.TABLE_BLOCKS[0][0]}\n{T.methods_markdown()}\n{T.TABLE_BLOCKS[0][1]}\n")
        print(f"{T.TABLE_BLOCKS[1][0]}\n{T.schemes_markdown()}\n{T.TABLE_BLOCKS[1][1]}")
        return
    table = _table("methods (use the name or the paper number with --method)", "name", "paper", "number", "description")
    for row in R.methods_rows():
        _row(table, *row)
    out.print(table)
    table = _table(
        "schemes (--scheme; parameters in parentheses, defaults shown)", "scheme", "kind", "variants", "what it is"
    )
    for e in R.SCHEMES.values():
        _row(table, R.scheme_spec(e), e.kind, ", ".join(e.variants), e.summary)
    out.print(table)


def _register_plugins(target: typer.Typer | None = None) -> None:
    """Register every command module ``slipstep/cli/<name>.py`` (its ``register(app)``) on
    ``target`` (default: the slipstep app), in name order. A module that cannot be imported is
    skipped with a warning on stderr, so one broken plugin never takes the command line down."""
    import importlib

    from slipstep import cli

    target = app if target is None else target
    own = {"__init__", Path(__file__).stem}
    stems = sorted({p.stem for d in cli.__path__ for p in Path(d).glob("*.py")} - own)
    for stem in stems:
        name = f"slipstep.cli.{stem}"
        try:
            module = importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001
            say(f"warning: command module {name} not loaded ({type(exc).__name__}: {exc})", err, "yellow")
            continue
        register = getattr(module, "register", None)
        if callable(register):
            register(target)


_register_plugins()


if __name__ == "__main__":  # pragma: no cover
    app()
