"""Post-processing commands of the ``slipstep`` CLI: ``plot``, ``report``, ``advise``.

Registered on the main Typer app by :func:`register` (slipstep.cli.main calls it). No numerics
here: the commands call slipstep.post.plots, slipstep.study.report and slipstep.study.advise. Bad input
(InputError, a missing file) prints one red line on stderr and exits with code 2.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from slipstep.errors import InputError

from slipstep.casefile.files import case_stem
from slipstep.cli.console import output_dir_option, say, user_errors as _user_errors  # one console setup


def _load_case(case: str):
    from slipstep.casefile.case import load_system

    return load_system(case)


def plot(
    result: Path = typer.Argument(..., help="a result file written by `slipstep run` (.nc)"),
    output_dir: str = typer.Option("figures", "--output-dir", "-o", help="folder for the PNG files"),
    case: Optional[str] = typer.Option(
        None,
        "--case",
        help="the case of the result, to filter the loops "
        "(default: the case named in the result, if it is a built-in one)",
    ),
):
    """Write the figures of a result (time histories, loops, step size, iterations, states) as PNG."""
    with _user_errors():
        from slipstep.post import plots
        from slipstep.casefile.case import builtin_cases
        from slipstep.output.results import load

        ds = load(result, field="RESULT")  # refuses foreign, corrupt and HDF5-external files
        directory = output_dir_option(output_dir, "--output-dir")
        name = case or ds.attrs.get("case")
        system = _load_case(name) if name and (case or name in builtin_cases()) else None
        paths = plots.write_figures(ds, directory, system=system, prefix=f"{result.stem}_")
        for p in paths:
            say(p)


def report(
    case: str = typer.Argument(..., help="built-in case name (e.g. paper) or TOML case file"),
    output: Optional[str] = typer.Option(None, "--output", "-o", help="HTML file (default CASE_report.html)"),
    periods: float = typer.Option(3.0, help="excitation periods to simulate"),
    rotor_speed_rpm: Optional[float] = typer.Option(None, help="rotor speed [rpm] for the Eq. 9 check"),
    radius_m: Optional[float] = typer.Option(None, help="radius of the damper [m]"),
    displacement_um: Optional[float] = typer.Option(None, help="damper displacement amplitude [um]"),
):
    """Run CASE (quasi-static + Method 3) and write one self-contained HTML report."""
    with _user_errors():
        from slipstep.study.report import write_report

        path = Path(output) if output is not None else Path(f"{case_stem(case)}_report.html")
        if output is not None and not output.strip():
            raise InputError("--output", "is empty", "give an HTML file name such as paper_report.html")
        if path.is_dir():
            raise InputError(
                "--output",
                f"{str(path)!r} is a directory",
                f"give an HTML file name such as {str(path / (case_stem(case) + '_report.html'))!r}",
            )
        if path.parent.exists() and not path.parent.is_dir():
            raise InputError(
                "--output", f"{str(path.parent)!r} is a file, not a directory", "give a path in a directory"
            )
        output_dir_option(path.parent, "--output")  # a read-only directory fails now, not after the run
        system = _load_case(case)
        xd = None if displacement_um is None else displacement_um * 1e-6
        write_report(
            system,
            path,
            periods=periods,
            rotor_speed_rpm=rotor_speed_rpm,
            radius_m=radius_m,
            displacement_amplitude_m=xd,
        )
        say(path)


def advise(
    case: str = typer.Argument(..., help="built-in case name (e.g. paper) or TOML case file"),
    rotor_speed_rpm: Optional[float] = typer.Option(None, help="rotor speed [rpm] (paper Eq. 9)"),
    radius_m: Optional[float] = typer.Option(None, help="radius of the damper [m]"),
    displacement_um: Optional[float] = typer.Option(None, help="damper displacement amplitude [um]"),
    as_json: bool = typer.Option(False, "--json", help="print the findings as JSON"),
):
    """Which method suits CASE and why: Eq. 9 inertia ratio, T_min per state, flutter, steps."""
    with _user_errors():
        from slipstep.study.advise import advise as _advise

        system = _load_case(case)
        xd = None if displacement_um is None else displacement_um * 1e-6
        result = _advise(system, rotor_speed_rpm, radius_m, xd)
        if as_json:
            print(json.dumps(_jsonable(result.to_dict())))
        else:
            for line in result.text().splitlines():
                say(line)


def _jsonable(value):
    import math

    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item"):
        return _jsonable(value.item())
    return value


def register(app: typer.Typer) -> None:
    """Add the plot, report and advise commands to ``app`` (once)."""
    existing = {c.name or (c.callback.__name__ if c.callback else None) for c in app.registered_commands}
    for func in (plot, report, advise):
        if func.__name__ not in existing:
            app.command(name=func.__name__)(func)
