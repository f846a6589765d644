"""Where `compare` times the kernels: a fresh process that loads them from numba's cache
(slipstep.study.compare.fresh_process_times), or this process when that one cannot run."""

import math
import multiprocessing
import os
import queue
import threading

import slipstep
from slipstep.study.compare import CompilingHelper, compare, compile_ahead, fresh_process_times


def test_fresh_process_times_every_method_repeats_times():
    paper = slipstep.load_system("paper")
    names = ["newmark", "quasi-static"]
    samples, where = fresh_process_times(paper, names, 0.5, 3, {})
    assert where == "a fresh process"
    assert sorted(samples) == sorted(names)
    for name in names:
        assert len(samples[name]) == 3
        assert all(math.isfinite(t) and t > 0 for t in samples[name])


def test_a_fresh_process_that_cannot_start_says_why_and_compare_times_here():
    samples, where = fresh_process_times(lambda: None, ["newmark"], 0.5, 1, {})  # a lambda does not pickle
    assert samples is None
    assert where.startswith("a fresh process failed: ")
    rows = compare(slipstep.load_system("paper"), methods="newmark", periods=0.5, repeats=2, fresh_process=False)
    assert [row["timed_in"] for row in rows] == ["this process"]
    assert rows[0]["kernel_time_s"] > 0


def test_the_compile_ahead_process_marches_the_methods_and_ends_cleanly():
    paper = slipstep.load_system("paper")
    helper = compile_ahead(paper, ["quasi-static", "newmark"], {"step_rule": "t-min"})
    if len(os.sched_getaffinity(0)) < 2:
        assert helper is None  # one CPU: nothing to compile beside
        return
    helper.process.join(timeout=600)
    assert helper.process.exitcode == 0
    said = [helper.progress.get(timeout=10) for _ in range(4)]
    assert said == [("start", "quasi-static"), ("done", "quasi-static"), ("start", "newmark"), ("done", "newmark")]


def test_the_command_waits_for_the_method_the_helper_is_marching_and_only_for_it():
    """CompilingHelper on a thread and a queue that play the helper process: it marches "events"
    until released."""
    progress, release = queue.Queue(), threading.Event()

    def helper_body():
        progress.put(("start", "events"))
        release.wait(60)
        progress.put(("done", "events"))

    thread = threading.Thread(target=helper_body)
    thread.start()
    helper = CompilingHelper(thread, progress)
    while helper.marching != "events":
        helper._read(wait=1.0)
    helper.wait_for("newmark")  # not the helper's: returns at once, the helper still at "events"
    assert helper.marching == "events" and thread.is_alive()
    threading.Timer(0.2, release.set).start()
    helper.wait_for("events")  # returns on the helper's ("done", "events")
    assert helper.marching is None
    thread.join(5)


def test_waiting_ends_when_the_helper_ends_without_a_word():
    progress = queue.Queue()
    thread = threading.Thread(target=lambda: progress.put(("start", "events")))  # then it dies
    thread.start()
    thread.join(5)
    helper = CompilingHelper(thread, progress)
    helper.wait_for("events")
    assert helper.marching == "events"  # said it started, never that it was done: not waited for


def test_compare_stops_the_compile_ahead_process_when_its_runs_are_done():
    rows = compare(slipstep.load_system("paper"), methods="newmark,quasi-static", periods=0.5, repeats=1)
    assert [row["method"] for row in rows] == ["newmark", "quasi-static"]
    assert not [p for p in multiprocessing.active_children() if p.name == "slipstep-compile-ahead"]
