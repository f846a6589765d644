"""Every kernel path, compiled in a fresh process with numba's bounds checking on: an
out-of-bounds read or write (which numba does not check by default, and which corrupts
memory silently) fails here with an IndexError instead."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent("""
    import numpy as np, slipstep
    from slipstep.integrators import simulate

    paper = slipstep.load_system("paper")
    # quasi-static-dofs needs a dynamic part besides the contact-held DOFs: run on `blades`
    ALL = [m for m in slipstep.METHODS if not slipstep.METHODS[m].massless]
    for method in ALL:
        assert slipstep.run(paper, method, periods=0.5).attrs["status"] == "OK", method
    blades = slipstep.load_system("blades")
    for method in ("quasi-static-dofs", "piecewise-linear"):
        for solver in ("direct", "low-rank"):
            assert slipstep.run(blades, method, periods=2, linear_solver=solver).attrs["status"] == "OK", method
    for scheme in ("central-difference", "rk4"):
        for variant in ("fixed", "adaptive"):
            assert simulate(paper, scheme, variant, periods=0.5).attrs["status"] == "OK", (scheme, variant)
    assert slipstep.run(paper, "newmark", periods=0.5, scheme=slipstep.hht(0.1)).attrs["status"] == "OK"
    for method in ("newmark", "piecewise-linear-adaptive"):  # the accuracy control (rtol) path
        assert slipstep.run(paper, method, periods=0.5, rtol=1e-3).attrs["status"] == "OK", method

    # a structure with more DOFs than contact coordinates and a quasi-3D contact (rows != columns)
    n = 5
    K = 2e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    A3 = np.zeros((3, n)); A3[0, 1] = A3[1, 2] = 1.0; A3[2, 3] = 1.0
    A2 = np.zeros((2, n)); A2[0, 4] = 1.0
    contacts = (slipstep.ContactElement("Q", A3, (1e6, 2e6), 1e6, 0.3, normal_offset=1e-5),
                slipstep.ContactElement("J", A2, 1e6, 1e6, 0.2, normal_offset=2e-5))
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(20.0, [0, 30.0, 0, -20.0, 10.0]),))
    chain = slipstep.System(slipstep.Structure(np.eye(n) * 0.5, stiffness=K), contacts,
                            slipstep.Excitation(force=force))
    for method in ALL:
        for solver in ("direct", "low-rank"):
            ds = slipstep.run(chain, method, periods=0.5, linear_solver=solver)
            assert ds.attrs["status"] == "OK", (method, solver)
    # a friction-circle contact that slips (coupled slip: Newton on the consistent tangent)
    n = 7
    K = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    A = np.zeros((3, n)); A[0, 2] = A[1, 3] = A[2, 4] = 1.0
    circle = slipstep.ContactElement("C", A, 1e6, 1e6, 0.3, normal_offset=1e-5, law="3d-circle")
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(30.0, [0, 20.0, 0, -15.0, 0, 8.0, 0]),))
    ring = slipstep.System(slipstep.Structure(np.eye(n) * 0.2, stiffness=K), (circle,),
                           slipstep.Excitation(force=force))
    for method in ALL:
        if method in ("quasi-static-events", "events"):  # piecewise-linear laws only
            continue
        for solver in ("direct", "low-rank"):
            ds = slipstep.run(ring, method, periods=0.5, linear_solver=solver)
            assert ds.attrs["status"] == "OK", (method, solver)
            assert (ds.contact_state.values == 4).any(), (method, solver)
    # the T_min routine of kernels/eigen.py: dense B (diagonal, Cholesky and zero-pivot factors)
    # and the restarted Krylov iteration (n above DENSE_LIMIT and MAX_BASIS), symmetric or not
    from slipstep.kernels import eigen as KE
    from slipstep.methods.eigen import mass_factor
    rng = np.random.default_rng(0)
    for n in (5, KE.DENSE_LIMIT + 6):
        R = rng.standard_normal((n, n))
        Kr = R @ R.T + n * np.eye(n)
        Mr = np.eye(n) + 0.1 * (R + R.T) / n
        Mz = Mr.copy(); Mz[-2:, :] = 0.0; Mz[:, -2:] = 0.0
        for Ke in (Kr, Kr + 0.2 * rng.standard_normal((n, n))):
            for L in (mass_factor(np.diag(np.diag(Mr))), mass_factor(Mr), mass_factor(Mz)):
                for f in (KE.largest_eigenvalue_modulus, KE.krylov_largest_modulus):
                    assert f(Ke, L, KE.EIG_RTOL, KE.MAX_BASIS, KE.MAX_RESTARTS) > 0
    print("all kernel paths ran with bounds checking")
""")


def start(directory) -> subprocess.Popen:
    """The bounds-checked run of SCRIPT in a fresh process; its numba cache (so that nothing
    compiled with bounds checking reaches the real cache) and its output in ``directory``."""
    directory = Path(directory)
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(directory / "numba-cache"))
    with open(directory / "stdout.txt", "w") as out, open(directory / "stderr.txt", "w") as err:
        return subprocess.Popen([sys.executable, "-c", SCRIPT], env=env, stdout=out, stderr=err)


def test_kernels_stay_in_bounds(boundscheck_run):
    """``boundscheck_run`` (tests/conftest.py): (the process started when the tests were
    collected, its directory), so that its compilation (most of its 3-7 minutes) runs on the
    second core beside the rest of the suite."""
    process, directory = boundscheck_run
    process.wait(timeout=1800)
    stderr = (Path(directory) / "stderr.txt").read_text()
    assert process.returncode == 0, stderr[-3000:]
    assert "all kernel paths ran with bounds checking" in (Path(directory) / "stdout.txt").read_text()
