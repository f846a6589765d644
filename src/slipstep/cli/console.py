"""The console of the ``slipstep`` command line, shared by slipstep.cli.main and every command
module (``run``/``compare`` and the plugins ``frf``, ``sweep``, ``post``...): the two consoles
(stdout ``out``, stderr ``err``), plain-text printing (``safe``, ``say``), the exit codes and the
turning of a failure into one line and its code (``user_errors``, ``report_failure``), the
output directory check. Standard library, typer and rich only (the CLI's fast start).

Exit codes (every command): 0 success, 1 a march that stopped early (the partial result is still
written), 2 bad input (one red line naming the key and the fix), 3 an I/O or environment failure
(disk full, read-only directory, out of memory), 4 an internal error (one line; the traceback is
saved to a file), 130 aborted by Ctrl-C.
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from pathlib import Path

import typer
from rich.console import Console
from typer.exceptions import TyperException

from slipstep.errors import InputError, OutputError, SolverError
from slipstep.model.text import escape_text

EXIT_OK, EXIT_STOPPED, EXIT_INPUT, EXIT_IO, EXIT_INTERNAL, EXIT_ABORTED = 0, 1, 2, 3, 4, 130
_PASS_THROUGH = (typer.Exit, typer.Abort, TyperException, SystemExit)  # typer's own exits and usage errors

# a pipe or CI log gets 140 columns rather than rich's default 80, so tables keep their labels
out = Console(width=None if sys.stdout.isatty() else 140)
err = Console(stderr=True, width=None if sys.stderr.isatty() else 140)


def safe(value) -> str:
    """``value`` as plain text for the terminal: control characters escaped (print it with
    markup=False, or wrap it in rich.text.Text, so that '[/bad]' is not markup)."""
    return escape_text(value)


def say(text, console: Console | None = None, style: str | None = None) -> None:
    """Print one line of plain text (no markup, no highlighting, control characters escaped)."""
    (console or out).print(safe(text), style=style, markup=False, highlight=False, soft_wrap=True)


def fail_line(kind: str, message) -> None:
    say(f"{kind}: {' '.join(str(message).split())}", err, "bold red")


def report_failure(exc: BaseException) -> int:
    """Print the one-line message of a failure and return its exit code."""
    if isinstance(exc, InputError):
        fail_line("input error", exc)
        return EXIT_INPUT
    if isinstance(exc, SolverError):
        fail_line("solver error", exc)
        return EXIT_INPUT
    if isinstance(exc, OutputError):
        fail_line("output error", exc)
        return EXIT_IO
    if isinstance(exc, KeyboardInterrupt):
        fail_line("interrupted", "aborted by the user (Ctrl-C); files being written were not replaced")
        return EXIT_ABORTED
    if isinstance(exc, MemoryError):
        fail_line(
            "out of memory",
            "the process ran out of memory. Fix: simulate fewer periods or use --max-memory "
            "to be refused before the run",
        )
        return EXIT_IO
    if isinstance(exc, OSError):
        from slipstep.output.io import output_error

        fail_line("I/O error", output_error(getattr(exc, "filename", None) or "(file)", exc))
        return EXIT_IO
    path = _save_traceback(exc)
    where = f"the traceback is in {path}" if path else "the traceback could not be saved"
    fail_line(
        "internal error",
        f"{type(exc).__name__}: {str(exc)[:200]} -- this is a bug in slipstep; please report "
        f"it with the command you ran ({where})",
    )
    return EXIT_INTERNAL


def _save_traceback(exc: BaseException) -> str | None:
    import tempfile
    import time
    import traceback

    from slipstep.output.io import write_text

    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    name = f"slipstep-error-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
    for directory in (Path(tempfile.gettempdir()), Path.cwd()):
        try:
            return str(write_text(directory / name, f"slipstep {version()}\n{' '.join(sys.argv)}\n\n{text}"))
        except Exception:  # noqa: BLE001 (best effort)
            continue
    return None


@contextlib.contextmanager
def user_errors():
    """Show warnings as yellow lines on stderr (stdout stays clean for --json) and turn a failure
    into its one-line message and exit code (see :func:`report_failure`). A march compiled within
    has its out-of-line kernels compiled ahead by a second process (methods/compile_ahead.py)."""
    from slipstep.methods import compile_ahead

    with warnings.catch_warnings(record=True) as caught, compile_ahead.enabled():
        warnings.simplefilter("always")
        for category in _SILENT_WARNINGS:
            warnings.simplefilter("ignore", category)
        try:
            yield
        except _PASS_THROUGH:
            _show_warnings(caught)
            raise
        except BaseException as exc:  # noqa: BLE001
            _show_warnings(caught)  # before the failure line, which stays the last line
            raise typer.Exit(report_failure(exc)) from None
        _show_warnings(caught)


# library noise that is not the user's business (an import interrupted by Ctrl-C leaves unclosed files)
_SILENT_WARNINGS = (ResourceWarning, DeprecationWarning, PendingDeprecationWarning, ImportWarning)


def _show_warnings(caught: list) -> None:
    for w in caught:
        say(f"warning: {' '.join(str(w.message).split())}", err, "yellow")
    caught.clear()


def version() -> str:
    """The installed version (one place: pyproject.toml, read through importlib.metadata)."""
    from importlib.metadata import PackageNotFoundError, version as dist_version

    try:
        return dist_version("slipstep")
    except PackageNotFoundError:
        return "0+unknown"


def output_dir_option(path, option: str = "--output-dir", below: str = "") -> Path:
    """Create the output directory and check that it takes a file, before any long run:
    InputError (exit 2) for a path that cannot be a directory, OutputError (exit 3) for one
    the environment refuses (read-only, no permission, disk full)."""
    import tempfile

    if not str(path).strip():
        raise InputError(option, "is empty", "give a directory path (e.g. slipstep-out)")
    if "\x00" in str(path):
        raise InputError(option, "contains a NUL character", "give a directory path")
    path = Path(path) / below if below else Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(option, f"{str(path)!r} is an existing file, not a directory", "give a directory path")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(
            option, f"{str(path)!r} cannot be created (a part of it is a file)", "give a directory path"
        ) from None
    except NotADirectoryError:
        raise InputError(
            option, f"{str(path)!r} cannot be created (a part of it is a file)", "give a directory path"
        ) from None
    except OSError as exc:
        from slipstep.output.io import output_error

        raise output_error(path, exc) from None
    try:
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        from slipstep.output.io import output_error

        raise output_error(path, exc) from None
    return path
