"""Sweep commands of the ``slipstep`` CLI: ``sweep`` (run a design sweep into a zarr store)
and ``sweep-plot`` (design maps and curves from the store).

Registered on the main Typer app by :func:`register` (slipstep.cli.main calls it). Module-level
imports are typer and the standard library only; the work is in slipstep.sweep.
Exit codes: 0 every case OK; 1 some cases failed (recorded in the store) or the sweep was
interrupted (rerun the same command to continue); 2 bad input.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer


def sweep(
    spec: Path = typer.Argument(
        ..., help="sweep specification (TOML): \\[sweep], \\[run], \\[\\[parameter]], \\[outputs]"
    ),
    output: Path = typer.Option(
        ...,
        "--output",
        "-o",
        help="the zarr store (a folder, e.g. results.zarr); "
        "rerunning on an existing store computes only the cases it does not hold",
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="address of a running dask scheduler (tcp://HOST:8786); default: a local cluster on 127.0.0.1",
    ),
    workers: int | None = typer.Option(
        None, "--workers", "-w", help="worker processes of the local cluster (default: one per core)"
    ),
    threads: int = typer.Option(
        1,
        "--threads",
        help="threads per worker process of the local cluster (the "
        "kernels release the GIL; the Python set-up around them does not)",
    ),
    serial: bool = typer.Option(
        False, "--serial", help="run in this process, no dask (debugging; bit-identical numbers)"
    ),
    batch_size: int | None = typer.Option(
        None, "--batch-size", help="cases per task (default: the spec's sweep.batch_size, else automatic)"
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="replace an existing store of another sweep"),
    as_json: bool = typer.Option(False, "--json", help="no progress bar; print the final report as JSON"),
):
    """Run a design sweep: every case of SPEC, serially or on dask.distributed, into a zarr store."""
    from slipstep.cli.console import err, out, user_errors
    from slipstep.sweep.execute import DaskExecutor, SerialExecutor
    from slipstep.sweep.run import run_sweep

    report = None
    with user_errors():
        if serial and (scheduler or workers):
            from slipstep.errors import InputError

            raise InputError("serial", "is set together with --scheduler/--workers", "choose one executor")
        executor = SerialExecutor() if serial else DaskExecutor(scheduler=scheduler, workers=workers, threads=threads)
        try:
            if as_json:
                report = run_sweep(spec, output, executor=executor, batch_size=batch_size, overwrite=overwrite)
            else:
                report = _with_progress(run_sweep, spec, output, executor, batch_size, overwrite, out)
        except KeyboardInterrupt:
            err.print(
                f"interrupted: the finished cases are in {output}; rerun the same command to compute the rest",
                style="bold yellow",
                markup=False,
                soft_wrap=True,
            )
            raise typer.Exit(1) from None
    if as_json:
        print(json.dumps(report))
    else:
        _print_report(report, output, out)
    if report["missing"]:
        err.print(
            f"{report['missing']} case(s) are not in the store (their tasks were lost); rerun the same "
            "command to compute them",
            style="bold red",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)
    if report["failed"]:
        err.print(
            f"{report['failed']} case(s) failed; their status and message are in the store "
            "(variables status, status_message)",
            style="bold red",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)


def _with_progress(run_sweep, spec, output, executor, batch_size, overwrite, console):
    """run_sweep with a rich progress bar, shown once there are cases to compute."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn("[bold]sweep{task.fields[skipped]}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("cases"),
        TextColumn("{task.fields[failed]} failed", style="red"),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
    )
    bar = Progress(*columns, console=console)
    task = None

    def progress(state):
        nonlocal task
        if task is None:
            bar.start()
            task = bar.add_task("sweep", total=state["todo"], failed=0, rate="", skipped="")
        rate = state["computed"] / state["elapsed_s"] if state["elapsed_s"] > 0 else 0.0
        skipped = f" ({state['skipped']} of {state['total']} already in the store)" if state["skipped"] else ""
        bar.update(
            task, completed=state["computed"], failed=state["failed"], rate=f"{rate:.1f} cases/s", skipped=skipped
        )

    try:
        return run_sweep(spec, output, executor=executor, batch_size=batch_size, overwrite=overwrite, progress=progress)
    finally:
        if task is not None:
            bar.stop()


def _print_report(r: dict, output: Path, console) -> None:
    from rich.table import Table

    if r["computed"] == 0 and r["skipped"] == r["cases"]:
        console.print(
            f"all {r['cases']} cases are already in {output}: nothing to compute",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
        return
    table = Table(title=f"slipstep sweep: {output}", show_header=False)
    table.add_column("quantity", style="cyan")
    table.add_column("value")
    statuses = ", ".join(f"{k} {v}" for k, v in sorted(r["status_counts"].items())) or "-"
    ms = lambda s: "-" if math.isnan(s) else f"{s * 1e3:.3g} ms"  # noqa: E731
    rows = [
        ("cases in the sweep", r["cases"]),
        ("computed now", r["computed"]),
        ("already in the store", r["skipped"]),
        ("status of the computed cases", statuses),
        (
            "elapsed (cases)",
            (f"{r['elapsed_s']:.3g} s, after {r['startup_s']:.3g} s of start-up (warm-up case per worker, cluster)"),
        ),
        ("rate", f"{r['cases_per_s']:.3g} cases/s"),
        ("executor", f"{r['executor']}, {r['workers']} worker(s), {r['batch_size']} cases per task"),
        ("mean kernel time per case", ms(r["mean_kernel_time_s"])),
        ("mean time per case (build, run, summary)", ms(r["mean_case_time_s"])),
        ("per-case overhead outside the kernel", ms(r["overhead_per_case_s"])),
    ]
    best = _best_case(output)
    if best:
        rows.append(("largest energy per cycle (all interfaces)", best))
    worst = _worst_ring(output)
    if worst:
        rows.append(("largest amplification factor (mistuning)", worst))
    for name, value in rows:
        table.add_row(name, str(value))
    console.print(table)


def _worst_ring(store: Path) -> str:
    """The case of a mistuning store with the largest amplification factor, as text."""
    import numpy as np

    from slipstep.sweep.store import open_sweep

    ds = open_sweep(store)
    if "amplification_factor" not in ds:
        return ""
    af = np.where(ds.status.values == "OK", ds.amplification_factor.values, np.nan)
    if not np.isfinite(af).any():
        return ""
    i = int(np.nanargmax(af))
    where = ", ".join(f"{p} = {ds[p].values[i]:.4g}" for p in ds.attrs["parameters"])
    return (
        f"{af[i]:.4g} (blade {int(ds.peak_blade.values[i])} at {ds.peak_frequency_Hz.values[i]:.4g} Hz) "
        f"at {where} (case {i})"
    )


def _best_case(store: Path) -> str:
    """The case of the store that dissipates most per cycle, as text ('' if none is OK)."""
    import numpy as np

    from slipstep.sweep.store import open_sweep

    ds = open_sweep(store)
    if "energy_per_cycle_J" not in ds:
        return ""
    energy = np.where(ds.status.values == "OK", ds.energy_per_cycle_J.values, np.nan)
    if not np.isfinite(energy).any():
        return ""
    i = int(np.nanargmax(energy))
    unit = lambda p: "" if ds[p].attrs.get("units", "1") == "1" else f" {ds[p].attrs['units']}"  # noqa: E731
    where = ", ".join(f"{p} = {ds[p].values[i]:.4g}{unit(p)}" for p in ds.attrs["parameters"])
    return f"{energy[i] * 1e3:.4g} mJ at {where} (case {i})"


def sweep_plot(
    store: Path = typer.Argument(..., help="a sweep store written by `slipstep sweep` (.zarr folder)"),
    quantity: str = typer.Option(
        "energy_per_cycle_J",
        "--quantity",
        "-q",
        help="store variable, a label in brackets for labelled ones: "
        "'interface_energy_per_cycle_J[right]', 'interface_zeta_eq[left]'",
    ),
    x: str | None = typer.Option(None, "-x", help="parameter on the x axis (default: the last one)"),
    y: str | None = typer.Option(
        None, "-y", help="parameter on the y axis of the map, and the grouping of the curves (default: the first one)"
    ),
    at: list[str] = typer.Option(
        [], "--at", help="hold another parameter at a value: NAME=VALUE (repeatable; default: the optimum's values)"
    ),
    minimize: bool = typer.Option(False, "--minimize", help="the optimum is the smallest value"),
    output_dir: Path = typer.Option(Path("figures"), "--output-dir", "-o", help="folder for the PNG files"),
):
    """Design maps of a sweep: QUANTITY over two parameters (optimum marked) and curves over one."""
    from slipstep.cli.console import out, user_errors
    from slipstep.cli.console import output_dir_option as _output_dir
    from slipstep.errors import InputError

    with user_errors():
        from slipstep.sweep.plots import write_figures
        from slipstep.sweep.store import open_sweep

        held = {}
        for item in at:
            name, sep, value = item.partition("=")
            try:
                held[name.strip()] = float(value)
            except ValueError:
                raise InputError(
                    "at", f"{item!r} is not NAME=VALUE", "write e.g. --at centrifugal_force_N=200"
                ) from None
            if not sep:
                raise InputError("at", f"{item!r} is not NAME=VALUE", "write e.g. --at centrifugal_force_N=200")
        ds = open_sweep(store)
        paths = write_figures(ds, _output_dir(output_dir), quantity, x, y, y, held, minimize)
    for path in paths:
        out.print(f"wrote {path}", markup=False, highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add the sweep and sweep-plot commands to ``app`` (once)."""
    existing = {c.name for c in app.registered_commands}
    if "sweep" not in existing:
        app.command(name="sweep")(sweep)
    if "sweep-plot" not in existing:
        app.command(name="sweep-plot")(sweep_plot)
