"""Start-up time of the command line and of ``import slipstep`` against ``import numpy``, measured in
the same run (median of N fresh processes each, warm file cache).

    python benchmarks/bench_startup.py [N]

``slipstep --help``, ``slipstep cases`` and ``slipstep methods`` import only typer, rich's console and
the light slipstep modules; ``import slipstep`` imports nothing until a name is used (PEP 562).
"""

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")
CLI = "import sys; from slipstep.cli.main import app; sys.argv[0] = 'slipstep'; app()"
COMMANDS = {
    "python -c 'import numpy' (baseline)": [sys.executable, "-c", "import numpy"],
    "python -c 'pass' (interpreter)": [sys.executable, "-c", "pass"],
    "import slipstep": [sys.executable, "-c", "import slipstep"],
    "slipstep --help": [sys.executable, "-c", CLI, "--help"],
    "slipstep cases": [sys.executable, "-c", CLI, "cases"],
    "slipstep methods": [sys.executable, "-c", CLI, "methods"],
    "import slipstep; slipstep.Simulation (numba, xarray)": [
        sys.executable,
        "-c",
        "import slipstep; slipstep.Simulation",
    ],
}


def median_time(cmd, n: int, env) -> float:
    times = []
    for _ in range(n):
        start = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(n: int = 7) -> None:
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for cmd in COMMANDS.values():  # warm the file cache and the bytecode
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, check=True)
    results = {label: median_time(cmd, n, env) for label, cmd in COMMANDS.items()}
    base = results["python -c 'import numpy' (baseline)"]
    print(f"median of {n} processes each")
    for label, t in results.items():
        print(f"{label:55s} {t * 1e3:7.0f} ms  {t / base:5.2f} x import numpy")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
