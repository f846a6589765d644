"""Peak memory of a long run and its save against the kernel's output buffer: the PEAK_FACTOR of
slipstep.methods.memory (the estimate checked before any allocation).

    python benchmarks/bench_memory.py [periods]

Runs the paper case with Method 1 once for 1 period (imports, compilation) and then for
``periods`` periods (default 2000: 374,000 steps, 94 MB of outputs), saves the result, and
prints the growth of the peak resident memory (ru_maxrss) over the output buffer's bytes,
beside the estimate the run was checked against.
"""

import resource
import sys
import tempfile
from pathlib import Path

import slipstep as ss
from slipstep.methods import memory


def peak_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def main(periods: float = 2000.0) -> None:
    system = ss.load_system("paper")
    ss.run(system, "newmark", periods=1)  # imports, compilation
    before = peak_bytes()
    sim = ss.Simulation(system, "newmark", periods=periods)
    cs = sim.compiled
    points = sim.out.t.shape[0]
    buffer = points * memory.point_bytes(cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0])
    ds = sim.run()
    after_run = peak_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        ss.save_result(ds, Path(tmp) / "r.nc")
    after_save = peak_bytes()
    print(
        f"{points} output points, buffer {buffer / 1e6:.1f} MB, estimate {sim.memory_estimate / 1e6:.1f} MB "
        f"(PEAK_FACTOR {memory.PEAK_FACTOR})"
    )
    print(
        f"peak growth: run + Dataset {(after_run - before) / 1e6:.1f} MB = {(after_run - before) / buffer:.2f} x "
        f"buffer; with the save {(after_save - before) / 1e6:.1f} MB = {(after_save - before) / buffer:.2f} x buffer"
    )


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 2000.0)
