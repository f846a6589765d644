"""Sweeps on a real dask.distributed cluster: a scheduler and two worker processes on
127.0.0.1 (LocalCluster with processes, the way `slipstep sweep` starts one). Results equal
the serial executor's bit for bit; a killed worker's tasks are recomputed; a client killed
part-way (SIGKILL) loses nothing it wrote and a rerun computes only the missing cases."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from slipstep.sweep import (
    DaskExecutor,
    Parameter,
    SerialExecutor,
    SweepSpec,
    load_spec,
    make_plan,
    open_sweep,
    run_sweep,
)
from slipstep.sweep.execute import payload_of, run_case
from slipstep.sweep.store import VARYING

distributed = pytest.importorskip("distributed")

SRC = Path(__file__).resolve().parents[1] / "src"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def cluster():
    """The local cluster `slipstep sweep --workers 2` starts: a scheduler and two worker
    processes (each under a nanny), everything listening on 127.0.0.1 only."""
    with DaskExecutor(workers=2) as ex:
        c = ex.cluster
        info = ex.client.scheduler_info(n_workers=-1)
        assert c.scheduler_address.startswith("tcp://127.0.0.1:")
        assert len(info["workers"]) == 2 and all(a.startswith("tcp://127.0.0.1:") for a in info["workers"])
        assert all(w["nanny"].startswith("tcp://127.0.0.1:") for w in info["workers"].values())
        assert len(set(ex.client.run(os.getpid).values()) | {os.getpid()}) == 3  # separate processes
        yield c


def _spec(cf, amp, **kw):
    return SweepSpec(
        base="paper",
        run={"method": "quasi-static", "periods": 2, "steps_per_period": 60},
        parameters=(
            Parameter("damper.centrifugal_force_N", values=tuple(cf)),
            Parameter("motion.1.amplitude", values=tuple(amp)),
        ),
        **kw,
    )


def _assert_same(a, b):
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        if name not in VARYING:
            x, y = a[name].values, b[name].values
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name


def test_two_worker_processes_give_the_serial_numbers_exactly(cluster, tmp_path):
    spec = _spec((-10.0, 100.0, 200.0, 300.0), (5.0, 20.0, 40.0), batch_size=2)  # CF < 0: a failed case
    serial = run_sweep(spec, tmp_path / "serial.zarr", executor=SerialExecutor())
    dask = run_sweep(spec, tmp_path / "dask.zarr", executor=DaskExecutor(scheduler=cluster.scheduler_address))
    assert dask["executor"] == "dask" and dask["workers"] == 2 and dask["computed"] == serial["computed"] == 12
    assert dask["status_counts"] == serial["status_counts"] == {"OK": 9, "INPUT_ERROR": 3}
    a, b = open_sweep(tmp_path / "serial.zarr"), open_sweep(tmp_path / "dask.zarr")
    _assert_same(a, b)
    workers = set(b.worker.values)
    assert len(workers) == 2 and all(int(w.rsplit(":", 1)[1]) != os.getpid() for w in workers)


def test_a_killed_worker_does_not_stop_the_sweep(cluster, tmp_path):
    from dask.distributed import Client

    spec = _spec((100.0, 150.0, 200.0, 250.0, 300.0), (5.0, 10.0, 20.0, 30.0, 40.0, 50.0), batch_size=2)
    with Client(cluster.scheduler_address) as client:
        pids = client.run(os.getpid)
    victim = min(pids.values())
    killed = []

    def kill_one(state):
        if not killed and state["computed"]:
            os.kill(victim, signal.SIGKILL)
            killed.append(state["computed"])

    report = run_sweep(
        spec, tmp_path / "k.zarr", executor=DaskExecutor(scheduler=cluster.scheduler_address), progress=kill_one
    )
    assert killed and killed[0] < 30
    assert report["missing"] == 0 and report["status_counts"] == {"OK": 30}
    ds = open_sweep(tmp_path / "k.zarr")
    assert (ds.status.values == "OK").all()
    # the values of an uninterrupted serial run, case by case
    plan = make_plan(spec)
    payload = payload_of(plan)
    for i in range(plan.n_cases):
        ref = run_case(payload, plan.values[i])["summary"]
        assert ds.energy_per_cycle_J.values[i] == ref["energy_per_cycle_J"]
        assert ds.interface_zeta_eq.sel(interface="right").values[i] == ref["interface_zeta_eq[right]"]
        assert ds.solves.values[i] == ref["solves"]


def _count_done(path: Path) -> int:
    import zarr

    try:
        status = zarr.open_group(str(path), mode="r", use_consolidated=False)["status"][:]  # live, not the snapshot
    except (FileNotFoundError, KeyError, ValueError):  # the store does not exist yet
        return 0
    return int((np.asarray(status).astype(object) != "").sum())


def test_a_killed_client_loses_nothing_and_duplicates_nothing(cluster, tmp_path):
    """2,000 cases (CF x amplitude x mu) through the cluster; the client process is killed
    (SIGKILL) part-way, the same sweep is run again."""
    spec_file = tmp_path / "big.toml"
    spec_file.write_text(
        '[sweep]\nname = "big"\nbase = "paper"\nbatch_size = 20\n'
        '[run]\nmethod = "quasi-static"\nperiods = 1\nsteps_per_period = 40\n'
        '[[parameter]]\nkey = "damper.centrifugal_force_N"\nstart = 100.0\nstop = 300.0\nnum = 10\n'
        '[[parameter]]\nkey = "motion.1.amplitude"\nstart = 2.0\nstop = 60.0\nnum = 20\nscale = "log"\n'
        '[[parameter]]\nkey = "damper.contacts.*.friction_coefficient"\nstart = 0.1\nstop = 0.5\nnum = 10\n'
    )
    store = tmp_path / "big.zarr"
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # the client flushes every 0.2 s (the default 5 s would let a fast machine finish the
    # whole sweep before the first flush, and the kill would find nothing to keep)
    client = (
        "import sys; from slipstep.sweep.run import run_sweep; from slipstep.sweep.execute import DaskExecutor; "
        "run_sweep(sys.argv[1], sys.argv[2], executor=DaskExecutor(scheduler=sys.argv[3]), flush_seconds=0.2)"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", client, str(spec_file), str(store), cluster.scheduler_address],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 180
        while _count_done(store) < 100 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    before = open_sweep(store)
    done = before.status.values != ""
    assert 0 < done.sum() < 2000  # killed part-way (after >= 100 flushed, unless the machine is very slow)
    assert np.isfinite(before.energy_per_cycle_J.values[done]).all()
    assert not np.isfinite(before.energy_per_cycle_J.values[~done]).any()

    report = run_sweep(spec_file, store, executor=DaskExecutor(scheduler=cluster.scheduler_address))
    assert report["skipped"] == done.sum() and report["computed"] == 2000 - done.sum() and report["missing"] == 0
    after = open_sweep(store)
    assert after.sizes["case"] == 2000 and len(set(after.case_hash.values)) == 2000  # each case once
    assert np.array_equal(after.run_index.values, np.where(done, 0, 1))  # none computed twice
    assert (after.status.values == "OK").all()
    for name in after.data_vars:
        if name not in VARYING and done.any():
            x, y = before[name].values[done], after[name].values[done]
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name  # the flushed rows untouched
    # values equal to an uninterrupted run, on cases computed before and after the kill
    plan = make_plan(load_spec(spec_file))
    payload = payload_of(plan)
    rng = np.random.default_rng(0)
    picks = np.concatenate([rng.choice(np.flatnonzero(done), 15), rng.choice(np.flatnonzero(~done), 15)])
    for i in picks:
        ref = run_case(payload, plan.values[i])["summary"]
        for key in ("energy_per_cycle_J", "solves", "state_changes", "full_slip_share"):
            assert after[key].values[i] == ref[key], (i, key)
        assert after.interface_k_eq_N_per_m.sel(interface="left").values[i] == ref["interface_k_eq_N_per_m[left]"]


def test_a_killed_mistuning_sweep_resumes_to_the_serial_numbers(cluster, tmp_path):
    """A mistuning sweep of the ring (examples/ring_mistuning.toml at 2 levels x 10 samples and
    a coarse FRF): the client killed (SIGKILL) part-way, the same sweep run again; every case
    equals the serial executor's, the tuned reference is computed once and kept."""
    text = (EXAMPLES / "ring_mistuning.toml").read_text()
    text = text.replace("std = [0.01, 0.02, 0.04, 0.08]", "std = [0.02, 0.06]").replace("samples = 50", "samples = 10")
    text = text.replace("batch_size = 5", "batch_size = 1").replace("num = 21", "num = 7")
    text = text.replace("start_Hz = 280.0", "start_Hz = 295.0").replace("stop_Hz = 340.0", "stop_Hz = 325.0")
    text = text.replace("harmonics = [1, 3, 5, 7]", "harmonics = [1, 3]")
    spec_file = tmp_path / "ring_mistuning.toml"
    spec_file.write_text(text)
    assert make_plan(load_spec(spec_file)).n_cases == 20
    store = tmp_path / "ring.zarr"
    env = dict(os.environ, PYTHONPATH=str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    client = (
        "import sys; from slipstep.sweep.run import run_sweep; from slipstep.sweep.execute import DaskExecutor; "
        "run_sweep(sys.argv[1], sys.argv[2], executor=DaskExecutor(scheduler=sys.argv[3]), flush_seconds=0.2)"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", client, str(spec_file), str(store), cluster.scheduler_address],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 240
        while _count_done(store) < 3 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    before = open_sweep(store)
    done = before.status.values != ""
    assert 0 < done.sum() < 20
    assert np.isfinite(before.amplification_factor.values[done]).all()
    reference = before.attrs["mistuning_reference"]

    report = run_sweep(spec_file, store, executor=DaskExecutor(scheduler=cluster.scheduler_address))
    assert report["skipped"] == done.sum() and report["computed"] == 20 - done.sum() and report["missing"] == 0
    after = open_sweep(store)
    assert after.attrs["mistuning_reference"] == reference
    assert np.array_equal(after.run_index.values, np.where(done, 0, 1)) and (after.status.values == "OK").all()
    serial = tmp_path / "serial.zarr"
    run_sweep(spec_file, serial, executor=SerialExecutor())
    _assert_same(after, open_sweep(serial))
