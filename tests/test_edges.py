"""The edges, tested for real: interrupts and kills during a long run and during its save, a full
disk, a file size limit, a read-only directory, concurrent writers, crafted HDF5 files, internal
errors, terminal safety, the memory estimate, a light import. The slow ones run the CLI in a
subprocess on the paper case (a few seconds each); everything else is in-process.

Invariants checked everywhere: the previous good file survives every failure, no temporary
file is left behind by a failure the process survives, every failure is one line on stderr
with its exit code (0 ok, 1 stopped early, 2 bad input, 3 I/O, 4 internal, 130 aborted).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pty
import resource
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import slipstep as ss
from slipstep.output import io
from slipstep.cli.main import app
from slipstep.errors import OutputError

SRC = str(Path(__file__).resolve().parents[1] / "src")
CLI = [sys.executable, "-c", "import sys; from slipstep.cli.main import app; sys.argv[0] = 'slipstep'; app()"]
RESULT = "paper_newmark.nc"


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = SRC + os.pathsep + e.get("PYTHONPATH", "")
    e["COLUMNS"] = "160"
    return e


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def good_result(tmp_path_factory) -> Path:
    """A small good result file (paper, Method 1, 1 period) to be protected."""
    path = tmp_path_factory.mktemp("good") / RESULT
    ss.save_result(ss.run(ss.load_system("paper"), "newmark", periods=1), path)
    return path


def previous(good_result: Path, directory: Path) -> tuple[Path, str]:
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / RESULT
    target.write_bytes(good_result.read_bytes())
    return target, digest(target)


def temporaries(directory: Path) -> list[Path]:
    return sorted(directory.glob(".*.tmp"))


def one_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


# -- subprocess: signals during a long run and during its save ---------------------------------


def test_ctrl_c_during_long_run_keeps_partial_result_and_shows_progress(tmp_path, good_result):
    """SIGINT while the kernel marches (seen through the progress bar on a pseudo-terminal):
    the march stops at once, the partial result replaces the previous file, exit code 1."""
    target, _ = previous(good_result, tmp_path / "out")
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        CLI + ["run", "paper", "--periods", "20000", "--output-dir", str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=slave,
        env=env(),
        text=True,
    )
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + 120
    while b"steps/s" not in seen and time.monotonic() < deadline and proc.poll() is None:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            with contextlib.suppress(OSError):
                seen += os.read(master, 65536)
    assert b"steps/s" in seen, seen  # the progress bar: steps, rate, time left
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    stdout, _ = proc.communicate(timeout=120)
    with contextlib.suppress(OSError):
        while select.select([master], [], [], 0.1)[0]:
            chunk = os.read(master, 65536)
            if not chunk:
                break
            seen += chunk
    os.close(master)
    assert proc.returncode == 1, (stdout, seen)
    text = seen.decode(errors="replace")
    assert "INTERRUPTED" in text and "stopped at step" in text and str(target) in text, text
    ds = ss.load_result(target)
    assert ds.attrs["status"] == "INTERRUPTED"
    steps = ds.attrs["steps"]
    assert 0 < steps < 20000 * 187 and ds.sizes["time"] == steps + 1
    t = ds.time.values
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(ds.attrs["failed_at_time_s"])
    assert np.all(np.isfinite(ds.displacement.values)) and np.all(ds.normal_force.values >= 0)
    assert time.monotonic() - sent < 60  # stopped at once, then the partial result was saved
    assert not temporaries(target.parent)


def _start_and_wait_for_save(args, directory: Path):
    proc = subprocess.Popen(CLI + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env(), text=True)
    deadline = time.monotonic() + 120
    while not temporaries(directory):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.002)
    return proc


def test_sigkill_during_save_keeps_previous_file_and_next_write_cleans_up(tmp_path, good_result):
    target, before = previous(good_result, tmp_path / "out")
    proc = _start_and_wait_for_save(
        ["run", "paper", "--periods", "1000", "--output-dir", str(target.parent), "--json"], target.parent
    )
    proc.kill()
    proc.communicate(timeout=60)
    assert digest(target) == before and ss.load_result(target).attrs["steps"] == 187
    stale = temporaries(target.parent)
    assert stale and all(f".{RESULT}.{proc.pid}." in p.name for p in stale)
    ss.save_result(ss.load_result(target), target)  # the next write of the target removes them
    assert not temporaries(target.parent)


def test_two_ctrl_c_during_save_abort_it_and_keep_previous_file(tmp_path, good_result):
    """The first Ctrl-C during the save is noted (the save goes on), the second aborts it: exit
    130, one line, the previous file intact, the temporary file removed."""
    target, before = previous(good_result, tmp_path / "out")
    proc = _start_and_wait_for_save(
        ["run", "paper", "--periods", "1000", "--output-dir", str(target.parent), "--json"], target.parent
    )
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    lines = [line for line in stderr.splitlines() if line.strip()]
    print("double Ctrl-C during the save: exit code", proc.returncode, lines)
    if proc.returncode == 0:  # the save finished before the signals were handled: the new file is whole
        assert json.loads(stdout)["status"] == "OK" and ss.load_result(target).attrs["steps"] == 187000
    else:
        assert proc.returncode == 130, stderr
        assert "Traceback" not in stderr and lines[-1].startswith("interrupted:"), stderr
        assert digest(target) == before
    assert not temporaries(target.parent)


def test_two_processes_writing_the_same_file_leave_it_whole_for_readers(tmp_path, good_result):
    """Two processes save results to the same path 3 times each while this one reads it: every
    read sees a whole result (one writer's or the other's), none a partial file."""
    target, _ = previous(good_result, tmp_path / "out")
    code = (
        "import sys, slipstep as ss; ds = ss.load_result(sys.argv[1]).assign_attrs(writer=sys.argv[3])\n"
        "for _ in range(3): ss.save_result(ds, sys.argv[2])"
    )
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code, str(good_result), str(target), name],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env(),
            text=True,
        )
        for name in ("A", "B")
    ]
    writers = set()
    while any(p.poll() is None for p in procs):
        writers.add(ss.load_result(target).attrs.get("writer", "previous"))
        time.sleep(0.05)
    outputs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outputs
    assert ss.load_result(target).attrs["writer"] in ("A", "B") and writers <= {"A", "B", "previous"}
    assert not temporaries(target.parent)


def test_concurrent_writers_of_one_file_never_interleave(tmp_path):
    target = tmp_path / "same.bin"
    payloads = [bytes([i]) * 2_000_000 for i in range(6)]

    def writer(data):
        for _ in range(3):
            io.write_bytes(target, data)

    threads = [threading.Thread(target=writer, args=(p,)) for p in payloads]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert target.read_bytes() in payloads
    assert not temporaries(tmp_path)


# -- full disk, file size limit, read-only directory -------------------------------------------


@contextlib.contextmanager
def tmpfs(path: Path, size: str, readonly: bool = False):
    path.mkdir(parents=True, exist_ok=True)
    options = f"size={size}" + (",ro" if readonly else "")
    if (
        os.geteuid() != 0
        or subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True).returncode
        != 0
    ):
        pytest.skip("mounting a tmpfs needs root")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], capture_output=True)


def test_full_disk_keeps_previous_file_one_line_exit_3(tmp_path, good_result, monkeypatch):
    with tmpfs(tmp_path / "disk", "600k") as disk:
        target, before = previous(good_result, disk)
        # the disk fills during the write (the space check passed, then another writer took the space):
        # near a full disk the file is built in memory and written with plain writes, so the failure is an
        # ENOSPC of write(), not a crash of HDF5 (which segfaults when the disk fills under it)
        big = ss.load_result(good_result).assign(big=("n", np.zeros(200_000)))
        with monkeypatch.context() as m:
            m.setattr(io, "ensure_space", lambda path, nbytes: 1e6)
            with pytest.raises(OutputError, match="no space left"):
                ss.save_result(big, target)
        assert digest(target) == before and not temporaries(disk)
        with pytest.raises(OutputError, match="no space left .* it needs about"):  # refused before writing
            ss.save_result(big, target)
        assert digest(target) == before and not temporaries(disk)
        with pytest.raises(OutputError, match="no space left"):
            io.write_bytes(disk / "blob", b"x" * 2_000_000)
        assert not (disk / "blob").exists() and not temporaries(disk)
        # the command line: one line, exit 3, the previous result intact
        result = CliRunner().invoke(app, ["run", "paper", "--periods", "30", "--output-dir", str(disk)])
        assert result.exit_code == 3, result.output
        assert one_line(result.output).startswith(f"output error: {target}: cannot be written")
        assert digest(target) == before and not temporaries(disk)


def test_file_size_limit_fails_the_write_not_the_process(tmp_path, good_result):
    target, before = previous(good_result, tmp_path / "out")
    limit = lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, resource.RLIM_INFINITY))  # noqa: E731
    proc = subprocess.run(
        CLI + ["run", "paper", "--periods", "10", "--output-dir", str(target.parent)],
        capture_output=True,
        text=True,
        env=env(),
        timeout=180,
        preexec_fn=limit,
    )
    assert proc.returncode == 3, proc.stderr
    assert "file size limit" in one_line(proc.stderr)
    assert digest(target) == before and not temporaries(target.parent)


def test_read_only_directory_exit_3_before_the_run(tmp_path, good_result):
    directory = tmp_path / "ro"
    if os.geteuid() == 0:
        context = tmpfs(directory, "1m", readonly=True)
    else:
        directory.mkdir()
        directory.chmod(0o555)
        context = contextlib.nullcontext(directory)
    with context:
        for args in (
            ["run", "paper", "--periods", "1", "--output-dir", str(directory)],
            ["compare", "paper", "--periods", "1", "--output-dir", str(directory)],
            ["report", "paper", "-o", str(directory / "r.html")],
        ):
            start = time.monotonic()
            result = CliRunner().invoke(app, args)
            assert result.exit_code == 3, result.output
            line = one_line(result.output)
            assert (
                line.startswith(f"output error: {directory}")
                and "cannot be written" in line
                and ("read-only" in line or "permission" in line)
            ), line
            assert time.monotonic() - start < 5  # refused before the run, not after it


# -- crafted result files ----------------------------------------------------------------------


def _crafted(good_result: Path, tmp_path: Path, how: str) -> Path:
    """A copy of a real result whose `displacement` reads outside the file."""
    import h5py

    secret = tmp_path / "passwd"
    secret.write_bytes(np.arange(187 * 3 + 3, dtype=np.float64).tobytes())
    path = tmp_path / f"{how}.nc"
    path.write_bytes(good_result.read_bytes())
    with h5py.File(path, "r+") as f:
        shape, dtype, attrs = f["displacement"].shape, f["displacement"].dtype, dict(f["displacement"].attrs)
        del f["displacement"]
        if how == "external-storage":
            f.create_dataset(
                "displacement", shape=shape, dtype=dtype, external=[(str(secret), 0, secret.stat().st_size)]
            )
        elif how == "external-link":
            with h5py.File(tmp_path / "other.h5", "w") as g:
                g["data"] = np.zeros(shape)
            f["displacement"] = h5py.ExternalLink(str(tmp_path / "other.h5"), "/data")
            return path
        else:  # virtual dataset over another file
            with h5py.File(tmp_path / "source.h5", "w") as g:
                g["data"] = np.ones(shape)
            layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
            layout[:] = h5py.VirtualSource(str(tmp_path / "source.h5"), "data", shape=shape)
            f.create_virtual_dataset("displacement", layout)
        for key, value in attrs.items():
            if key not in ("DIMENSION_LIST",):
                f["displacement"].attrs[key] = value
    return path


@pytest.mark.parametrize("how", ["external-storage", "external-link", "virtual"])
def test_crafted_netcdf_reading_outside_the_file_is_refused(tmp_path, good_result, how):
    path = _crafted(good_result, tmp_path, how)
    with pytest.raises(ss.InputError, match="refused, it reads outside the file"):
        ss.load_result(path)
    result = CliRunner().invoke(app, ["plot", str(path), "-o", str(tmp_path / "figs")])
    assert result.exit_code == 2 and "refused" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "figs").exists() or not any((tmp_path / "figs").iterdir())


def test_result_schema_check(tmp_path, good_result):
    ds = ss.load_result(good_result)
    assert ds.attrs["status"] == "OK" and ds.sizes["time"] == 188
    broken = ds.drop_vars("tangential_force")
    ss.save_result(broken, tmp_path / "broken.nc")
    with pytest.raises(ss.InputError, match="variable 'tangential_force' missing"):
        ss.load_result(tmp_path / "broken.nc")
    wrong = ds.copy()
    wrong["normal_force"].attrs["units"] = "kN"
    ss.save_result(wrong, tmp_path / "units.nc")
    with pytest.raises(ss.InputError, match="units 'kN'"):
        ss.load_result(tmp_path / "units.nc")


# -- in-process: interrupts, exit codes, terminal safety, memory, imports ----------------------


def _stop_soon(sim, done: threading.Event):
    from slipstep.kernels.codes import C_PROGRESS, C_STOP

    def poke():
        while not done.is_set():
            if sim.out.counters[C_PROGRESS] > 1000:
                sim.out.counters[C_STOP] = 1
            time.sleep(0.005)

    threading.Thread(target=poke, daemon=True).start()


@pytest.mark.parametrize("scheme", ["implicit", "explicit"])
def test_stop_flag_interrupts_both_kernels_and_keeps_the_steps(scheme):
    system = ss.load_system("paper")
    if scheme == "implicit":
        sim = ss.Simulation(system, "piecewise-linear", periods=3000)
    else:
        from slipstep.integrators import get_integrator
        from slipstep.integrators.explicit_simulation import ExplicitSimulation

        sim = ExplicitSimulation(system, get_integrator("central-difference"), periods=3000, step_ratio=0.9)
    done = threading.Event()
    _stop_soon(sim, done)
    try:
        with pytest.raises(ss.Interrupted) as info:  # the library: a KeyboardInterrupt carrying the partial result
            sim.run()
    finally:
        done.set()
    ds = info.value.result
    assert isinstance(info.value, KeyboardInterrupt)
    assert ds.attrs["status"] == "INTERRUPTED" and 1000 <= ds.attrs["steps"] < 3000 * 187
    assert ds.sizes["time"] == ds.attrs["steps"] + 1 and np.all(np.diff(ds.time.values) > 0)
    sim.keep_interrupted = True
    done = threading.Event()
    _stop_soon(sim, done)
    try:
        assert sim.run().attrs["status"] == "INTERRUPTED"
    finally:
        done.set()
    assert sim.run(raise_on_failure=False).attrs["status"] == "OK"  # the flag is cleared for the next march


def test_deferred_interrupt_notes_the_first_and_aborts_on_the_second():
    from slipstep.methods.live import deferred_interrupt

    notes = []
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt(lambda: notes.append("first")):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
            assert notes == ["first"]
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1)
    with pytest.raises(KeyboardInterrupt):
        with deferred_interrupt(armed=True):  # after an interrupt of the march, the first one aborts
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_internal_error_is_one_line_exit_4_with_saved_traceback(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)

    def broken(*args, **kwargs):
        raise ZeroDivisionError("an internal slip")

    monkeypatch.setattr("slipstep.casefile.case.load_case", broken)
    result = CliRunner().invoke(app, ["run", "paper"])
    assert result.exit_code == 4
    line = one_line(result.output)
    assert line.startswith("internal error: ZeroDivisionError: an internal slip") and "report" in line
    saved = Path(line.rsplit("traceback is in ", 1)[1].rstrip(")"))
    assert saved.exists() and "ZeroDivisionError" in saved.read_text() and "broken" in saved.read_text()


def test_names_are_printed_as_text_not_markup_or_escapes(tmp_path):
    from test_bad_input import PAPER, edit

    case = tmp_path / "markup.toml"
    case.write_text(edit(PAPER, 'name = "paper"', 'name = "[/bad] [bold red]x[/bold red] \u2603"'))
    result = CliRunner().invoke(app, ["run", str(case), "--periods", "1", "--output-dir", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "[/bad] [bold red]x[/bold red] \u2603" in result.output
    assert (tmp_path / "markup_newmark.nc").exists()  # named after the file, not the case name
    from slipstep.cli.main import safe

    assert safe("a\x1b]0;t\x07b\u202ec\n") == "a\\x1b]0;t\\x07b\\u202ec\\x0a"


def test_memory_estimate_is_the_allocation_and_the_limit_is_checked_first():
    from slipstep.methods import memory
    from slipstep.methods.simulation import _allocate_outputs

    cs = ss.load_system("paper").compile()
    out = _allocate_outputs(cs, 999)
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    rows = out.t.shape[0]  # the 1000 points and the save plan's spare rows (slipstep.methods.save)
    per_point = sum(a.nbytes for a in out if a.shape and a.shape[0] == rows) / rows
    assert per_point == memory.point_bytes(n, nq, nd)
    # the workspace estimate is what _allocate_workspace allocates (direct and low-rank solves, 60-DOF chain)
    from slipstep.methods.simulation import _allocate_workspace, _workspace_bytes

    def allocated(obj):
        return sum(
            a.nbytes if isinstance(a, np.ndarray) else allocated(a) for a in obj if isinstance(a, (np.ndarray, tuple))
        )

    k = 2e6 * np.eye(60) - 1e6 * (np.eye(60, k=1) + np.eye(60, k=-1))
    gather = np.zeros((2, 60))
    gather[0, -1] = gather[1, 0] = 1.0
    chain = ss.System(
        ss.Structure(np.eye(60), stiffness=k),
        (ss.ContactElement("C", gather, 1e6, 1e6, 0.3, normal_offset=1e-6),),
        ss.Excitation(period=0.01),
    ).compile()
    for compiled, low_rank in ((cs, False), (chain, False), (chain, True)):
        assert _workspace_bytes(compiled, 20, low_rank) == pytest.approx(
            allocated(_allocate_workspace(compiled, 20, low_rank)), rel=0.2
        )
    with pytest.raises(ss.InputError) as info:
        ss.Simulation(ss.load_system("paper"), "newmark", periods=1e6)  # 187 M points: refused, nothing allocated
    assert "available" in str(info.value) and "--max-memory" in str(info.value)
    assert memory.parse_size("m", "1.5GB") == 1.5 * 2**30 and memory.parse_size("m", "500 MB") == 500 * 2**20


def test_light_imports_and_version():
    code = (
        "import sys, slipstep, slipstep.cli.main; heavy = {'numpy', 'numba', 'xarray', 'pydantic', 'scipy', "
        "'matplotlib'}; print(sorted(heavy & {m.split('.')[0] for m in sys.modules}))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env(), timeout=60)
    assert proc.stdout.strip() == "[]", proc.stdout + proc.stderr  # --help, cases, methods need none of them
    for command in ("--help", "cases", "methods"):
        code = (
            "import atexit, sys; from slipstep.cli.main import app; sys.argv = ['slipstep', %r]; heavy = {'numpy', "
            "'numba', 'xarray', 'pydantic', 'scipy', 'matplotlib'}; atexit.register(lambda: print(sorted(heavy & "
            "{m.split('.')[0] for m in sys.modules}), file=sys.stderr)); app()" % command
        )
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env(), timeout=60)
        assert proc.returncode == 0 and proc.stderr.strip() == "[]", (command, proc.stderr)
    from importlib.metadata import version

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"slipstep {version('slipstep')}"
    assert ss.__version__ == version("slipstep")


def test_plugins_are_discovered_and_a_broken_one_is_skipped(tmp_path, monkeypatch):
    import typer

    from slipstep import cli
    from slipstep.cli import main

    (tmp_path / "zz_fake.py").write_text(
        "import typer\n\ndef register(app):\n    app.command(name='fake')(lambda: print('fake ran'))\n"
    )
    (tmp_path / "zz_broken.py").write_text("raise ImportError('missing dependency')\n")
    monkeypatch.setattr(cli, "__path__", list(cli.__path__) + [str(tmp_path)])
    target = typer.Typer(cls=main._Group)
    target.command(name="noop")(lambda: None)
    main._register_plugins(target)
    names = {c.name for c in target.registered_commands}
    assert {"fake", "plot", "report", "advise"} <= names
    assert CliRunner().invoke(target, ["fake"]).output.strip() == "fake ran"


def test_atomic_path_modes_and_stale_temporaries(tmp_path):
    target = tmp_path / "a.txt"
    io.write_text(target, "one")
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask
    target.chmod(0o600)
    io.write_text(target, "two")
    assert target.stat().st_mode & 0o777 == 0o600 and target.read_text() == "two"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".a.txt.{dead.pid}.x1.tmp"
    alive = tmp_path / f".a.txt.{os.getppid()}.x2.tmp"  # a live process (our parent): kept
    stale.write_text("junk")
    alive.write_text("in progress")
    io.write_text(target, "three")
    assert not stale.exists() and alive.exists() and target.read_text() == "three"
    with pytest.raises(OutputError, match="is a directory"):
        io.write_text(tmp_path, "x")


def test_figures_draw_names_as_text_not_mathtext(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def figure(path):
        fig, ax = plt.subplots()
        ax.set_title("contact P$\\frac$1")  # a case-file name: mathtext would fail to parse it
        fig.tight_layout()
        io.save_figure(fig, path)
        plt.close(fig)
        return path

    with pytest.raises(ValueError):
        figure(tmp_path / "math.png")
    assert io.plain_text_figures(figure)(tmp_path / "text.png").read_bytes()[:4] == b"\x89PNG"
    assert matplotlib.rcParams["text.parse_math"]  # restored for the user's own figures
    plt.close("all")


def test_lazy_public_names_survive_submodule_imports():
    """`slipstep.advise` is the function even when its module, slipstep.study.advise, is imported first."""
    code = (
        "import importlib, slipstep; importlib.import_module('slipstep.study.advise'); import slipstep.study.report; "
        "print(callable(slipstep.advise), type(slipstep.post).__name__, slipstep.run.__module__)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env(), timeout=120)
    assert proc.stdout.split() == ["True", "module", "slipstep.methods.simulation"], proc.stdout + proc.stderr
