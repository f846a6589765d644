"""Where a command's time goes with an empty (or warm) numba cache: a per-function compile profile.

    python benchmarks/bench_compile.py [run|compare|both] [--cache-dir DIR] [--src TREE/src] [--json FILE]

Each command (``slipstep run paper``, ``slipstep compare paper``) runs in a fresh child process with
``NUMBA_CACHE_DIR`` set to a new temporary directory (or to ``--cache-dir``: run twice with the same
directory to see the warm cache). The child wraps numba's ``Dispatcher.compile`` (the profiler only,
never the package): every new specialisation is timed, its own time (minus the callees it compiled
inside) attributed to its function, and a disk-cache load told apart from a compile. Inlined helpers
(``inline="always"``) are typed and compiled inside their callers and count there.

Printed per command: function, specialisations compiled (and loaded from the cache), seconds (own time,
compile), seconds per specialisation, numba's own LLVM timer (wall, with callees) and the seconds of
cache loads; then the command's CPU and wall time split into compile, cache load, import (a second child that only imports the modules the command loaded) and the rest (run, I/O).
On a warm cache any line under "compiled" is a function that is recompiled in every process.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")
COMMANDS = {"run": ["run", "paper"], "compare": ["compare", "paper"]}

CHILD = r"""
import json, os, sys, time
from numba.core import dispatcher

records = []
stack = []
orig = dispatcher.Dispatcher.compile


def compile(self, sig):
    from numba.core import sigutils

    args, _ = sigutils.normalize_signature(sig)
    if tuple(args) in self.overloads:
        return orig(self, sig)
    hits = sum(self._cache_hits.values())
    stack.append(0.0)
    c0, w0 = time.process_time(), time.perf_counter()
    try:
        return orig(self, sig)
    finally:
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        inner = stack.pop()
        if stack:
            stack[-1] += cpu
        py = self.py_func
        cres = self.overloads.get(tuple(args))
        timers = (getattr(cres, "metadata", None) or {}).get("timers", {}) if cres is not None else {}
        records.append(
            {
                "name": (py.__module__ or "?").replace("slipstep.", "") + "." + py.__qualname__,
                "sig": str(tuple(args)),
                "hit": sum(self._cache_hits.values()) > hits,
                "cpu": cpu,
                "own": cpu - inner,
                "wall": wall,
                "top": not stack,
                "llvm": timers.get("llvm_lock", 0.0),
            }
        )


dispatcher.Dispatcher.compile = compile
out = sys.argv.pop(1)
c0, w0 = time.process_time(), time.perf_counter()
from slipstep.cli.main import app

sys.argv[0] = "slipstep"
try:
    app()
except SystemExit as e:
    code = e.code
else:
    code = 0
mods = sorted(m for m in sys.modules if m.startswith("slipstep") or m in ("xarray", "scipy", "matplotlib"))
json.dump(
    {"records": records, "cpu": time.process_time() - c0, "wall": time.perf_counter() - w0, "code": code,
     "modules": mods},
    open(out, "w"),
)
"""

IMPORT_ONLY = r"""
import importlib, json, sys, time
mods = json.load(open(sys.argv[1]))
c0, w0 = time.process_time(), time.perf_counter()
for m in mods:
    try:
        importlib.import_module(m)
    except Exception:
        pass
print(json.dumps({"cpu": time.process_time() - c0, "wall": time.perf_counter() - w0}))
"""


def child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def profile(name: str, args: list[str], cache_dir: str, workdir: str, src: str = SRC) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("NUMBA_DISABLE_JIT", None)
    out = os.path.join(workdir, f"{name}.json")
    cpu0, w0 = child_cpu(), time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, out, *COMMANDS[name], *args],
        cwd=workdir,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    cpu, wall = child_cpu() - cpu0, time.perf_counter() - w0
    if proc.returncode != 0:
        print(proc.stdout[-3000:])
        raise SystemExit(f"slipstep {' '.join(COMMANDS[name])} failed ({proc.returncode})")
    data = json.load(open(out))
    mods = os.path.join(workdir, f"{name}-modules.json")
    json.dump(data["modules"], open(mods, "w"))
    imp = subprocess.run(
        [sys.executable, "-c", IMPORT_ONLY, mods], cwd=workdir, env=env, capture_output=True, text=True, check=True
    )
    data.update(process_cpu=cpu, process_wall=wall, imports=json.loads(imp.stdout), output=proc.stdout)
    return data


def table(name: str, data: dict) -> None:
    rows: dict[str, dict] = {}
    for r in data["records"]:
        row = rows.setdefault(r["name"], {"n": 0, "hits": 0, "own": 0.0, "load": 0.0, "llvm": 0.0, "sigs": []})
        if r["hit"]:
            row["hits"] += 1
            row["load"] += r["own"]
        else:
            row["n"] += 1
            row["own"] += r["own"]
            row["llvm"] += r.get("llvm", 0.0)
            row["sigs"].append(r["sig"])
    compiled = sum(r["own"] for r in data["records"] if not r["hit"])
    loaded = sum(r["own"] for r in data["records"] if r["hit"])
    print(f"\n== slipstep {' '.join(COMMANDS[name])}: per-function compile profile (CPU seconds, own time)")
    print(
        f"{'function':58s} {'compiled':>8s} {'loaded':>6s} {'seconds':>8s} {'s/spec':>7s} {'%':>5s} {'llvm':>6s} {'load s':>6s}"
    )
    for fn, row in sorted(rows.items(), key=lambda kv: -kv[1]["own"] - kv[1]["load"]):
        per = row["own"] / row["n"] if row["n"] else 0.0
        share = 100 * row["own"] / compiled if compiled else 0.0
        print(
            f"{fn:58s} {row['n']:8d} {row['hits']:6d} {row['own']:8.2f} {per:7.2f} {share:5.1f} {row['llvm']:6.1f} {row['load']:6.2f}"
        )
    n_comp = sum(r["n"] for r in rows.values())
    n_hit = sum(r["hits"] for r in rows.values())
    print(f"{'total':58s} {n_comp:8d} {n_hit:6d} {compiled:8.2f}")
    dupes = {fn: row["sigs"] for fn, row in rows.items() if row["n"] > 1}
    if dupes:
        print("\nfunctions compiled for more than one signature:")
        for fn, sigs in dupes.items():
            print(f"  {fn}:")
            for s in sigs:
                print(f"      {s[:300]}")
    cpu, wall = data["process_cpu"], data["process_wall"]
    imp = data["imports"]["cpu"]
    rest = cpu - compiled - loaded - imp
    print(f"\nprocess: {cpu:.1f} s CPU, {wall:.1f} s wall (exit {data['code']})")
    print(f"  compile    {compiled:7.1f} s CPU  {100 * compiled / cpu:5.1f} %")
    print(f"  cache load {loaded:7.1f} s CPU  {100 * loaded / cpu:5.1f} %")
    print(f"  import     {imp:7.1f} s CPU  {100 * imp / cpu:5.1f} %  (a process that only imports the same modules)")
    print(f"  run, I/O   {rest:7.1f} s CPU  {100 * rest / cpu:5.1f} %  (the rest)")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("command", nargs="?", default="both", choices=["run", "compare", "both"])
    p.add_argument("--cache-dir", help="NUMBA_CACHE_DIR to use (default: a fresh empty directory)")
    p.add_argument("--src", default=SRC, help="the slipstep source tree to profile (default: this one's src/)")
    p.add_argument("--json", help="also write the raw records to this file")
    p.add_argument("extra", nargs="*", help="extra arguments for the command (after --)")
    a = p.parse_args()
    names = ["run", "compare"] if a.command == "both" else [a.command]
    cache_dir = a.cache_dir or tempfile.mkdtemp(prefix="bench-compile-cache-")
    print(f"NUMBA_CACHE_DIR={cache_dir} ({'given' if a.cache_dir else 'fresh, empty'}); source tree {a.src}")
    results = {}
    with tempfile.TemporaryDirectory(prefix="bench-compile-") as workdir:
        for name in names:
            if not a.cache_dir and name != names[0]:  # each command from its own empty cache
                cache_dir = tempfile.mkdtemp(prefix="bench-compile-cache-")
            results[name] = profile(name, a.extra, cache_dir, workdir, a.src)
            table(name, results[name])
    if a.json:
        json.dump(results, open(a.json, "w"))
    if not a.cache_dir:
        print(
            "(the fresh cache directories are left in the temporary directory: pass one as --cache-dir to profile warm)"
        )


if __name__ == "__main__":
    main()
